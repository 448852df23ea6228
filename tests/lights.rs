//! Directional (sun) and spot lights against oracles that share no code with them: the
//! closed forms E = irradiance cos(theta) and intensity falloff cos / r^2 (the glTF
//! KHR_lights_punctual cone, written out here again from its specification), the CPU ray
//! caster's visibility, and numerical integrals over the patches for the first-shot table.
//! Also what the loader accepts and refuses, and `--no-first-shot`.

mod common;

use common::ray_caster::{Caster, camera_ray};
use common::scratch::Scratch;
use firstshot::Error;
use firstshot::first_shot::LightWindow;
use firstshot::image::Image;
use firstshot::render::{RenderOptions, check_options, render};
use firstshot::scene::load::load_str;
use firstshot::scene::{self, Light, LightSample, SampleKind, Scene, SpotCone};
use glam::DVec3;
use std::f64::consts::PI;
use std::path::Path;

/// A grey floor 3 x 3 at y = 0 (albedo 0.6) and a tilted triangle above it.
const FLOOR_AND_OCCLUDER: &str = r#"
format = 1
[settings]
patch_size = 0.5
hemicube_resolution = 512
[materials.grey]
type = "diffuse"
albedo = [0.6, 0.6, 0.6]
[[shapes]]
type = "quad"
vertices = [[-1.5, 0.0, -1.5], [-1.5, 0.0, 1.5], [1.5, 0.0, 1.5], [1.5, 0.0, -1.5]]
material = "grey"
[[shapes]]
type = "triangle"
vertices = [[-0.4, 0.6, -0.3], [-0.1, 0.7, 0.5], [0.5, 0.55, 0.0]]
material = "grey"
[camera]
position = [0.1, 3.0, 0.05]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov_y = 60.0
width = 48
height = 48
"#;

const ALBEDO: f64 = 0.6;

/// The glTF KHR_lights_punctual spot falloff, as its specification writes it.
fn gltf_falloff(cos_to_axis: f64, inner_degrees: f64, outer_degrees: f64) -> f64 {
    let (cos_inner, cos_outer) = (inner_degrees.to_radians().cos(), outer_degrees.to_radians().cos());
    let light_angle_scale = 1.0 / f64::max(0.001, cos_inner - cos_outer);
    let light_angle_offset = -cos_outer * light_angle_scale;
    let factor = (cos_to_axis * light_angle_scale + light_angle_offset).clamp(0.0, 1.0);
    factor * factor
}

fn load(test: &str, text: &str) -> (Scratch, Scene) {
    common::scenes::load_text("lights", test, text)
}

/// What one camera ray sees of a light, by the caster: the reflected radiance, the triangle
/// hit and whether the light reaches that point. `light(x, n)` gives, for a point x of normal
/// n, the point the light comes from and what multiplies albedo / pi (the irradiance there
/// if unoccluded).
fn seen_along(
    caster: &Caster,
    origin: DVec3,
    dir: DVec3,
    light: &dyn Fn(DVec3, DVec3) -> (DVec3, f64),
) -> (f64, Option<usize>, bool) {
    let Some((t, i)) = caster.hit(origin, dir, 1e-9, f64::INFINITY) else { return (0.0, None, false) };
    let tri = &caster.tris[i];
    if tri.n.dot(-dir) <= 0.0 {
        return (0.0, Some(i), false);
    }
    let x = origin + t * dir;
    let (from, irradiance) = light(x, tri.n);
    if irradiance <= 0.0 || caster.occluded(x, from) {
        return (0.0, Some(i), false);
    }
    (tri.albedo / PI * irradiance, Some(i), true)
}

/// Compares every pixel of `image` with the caster: away from edges (where a pixel's points
/// disagree on the surface or on its light) the pixel's mean over an 8 x 8 grid of its
/// points, within `relative` (plus `absolute`); on edges, within the range of its points.
/// Returns (exact pixels, edge pixels, pixels on a surface in full shadow).
fn compare_per_pixel(
    image: &Image,
    scene: &Scene,
    light: &dyn Fn(DVec3, DVec3) -> (DVec3, f64),
    relative: f64,
    absolute: f64,
) -> (u32, u32, u32) {
    let caster = Caster::new(scene);
    let (w, h) = (image.width, image.height);
    let (mut exact, mut edges, mut shadowed) = (0, 0, 0);
    let (mut worst_relative, mut worst_absolute) = (0.0f64, 0.0f64);
    for py in 0..h {
        for px in 0..w {
            const N: u32 = 8;
            let mut values = Vec::new();
            let mut kinds = std::collections::BTreeSet::new();
            for k in 0..N * N {
                let (sx, sy) = ((k % N) as f64 + 0.5, (k / N) as f64 + 0.5);
                let (o, d) = camera_ray(&scene.camera, w, h, px as f64 + sx / N as f64, py as f64 + sy / N as f64);
                let (value, tri, lit) = seen_along(&caster, o, d, light);
                values.push(value);
                kinds.insert((tri, lit));
            }
            let mut border = Vec::new();
            for k in 0..9 {
                let (sx, sy) = ((k % 3) as f64 * 0.5, (k / 3) as f64 * 0.5);
                let (o, d) = camera_ray(&scene.camera, w, h, px as f64 + sx, py as f64 + sy);
                let (value, tri, lit) = seen_along(&caster, o, d, light);
                border.push(value);
                kinds.insert((tri, lit));
            }
            let expected = values.iter().sum::<f64>() / values.len() as f64;
            let ours = image.at(px, py)[0] as f64;
            if kinds.len() > 1 {
                edges += 1;
                let (lo, hi) =
                    values.iter().chain(&border).fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
                assert!(ours >= lo - 1e-3 && ours <= hi + 1e-3, "edge pixel ({px}, {py}): {ours} outside [{lo}, {hi}]");
                continue;
            }
            exact += 1;
            if expected > 0.0 {
                worst_relative = worst_relative.max((ours - expected).abs() / expected);
            }
            worst_absolute = worst_absolute.max((ours - expected).abs());
            if expected == 0.0 && kinds.iter().all(|k| k.0.is_some()) {
                shadowed += 1;
            }
            assert!(
                (ours - expected).abs() <= relative * expected + absolute,
                "pixel ({px}, {py}): ours {ours}, closed form {expected}"
            );
        }
    }
    eprintln!(
        "{exact} pixels exact (worst error {worst_relative:.2e} relative, {worst_absolute:.2e} absolute), {edges} edge pixels, {shadowed} in full shadow"
    );
    (exact, edges, shadowed)
}

/// The sun of tests 01 and 03: 50 degrees from the vertical, turned 30 degrees about it.
fn sun_direction() -> (DVec3, f64) {
    let (theta, phi) = (50f64.to_radians(), 30f64.to_radians());
    (DVec3::new(theta.sin() * phi.cos(), -theta.cos(), theta.sin() * phi.sin()), theta)
}

#[test]
fn test01_sun_gives_irradiance_times_cos_and_a_sharp_shadow_per_pixel() {
    let (d, theta) = sun_direction();
    let text = format!(
        "{FLOOR_AND_OCCLUDER}\n[[lights]]\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = [2.0, 2.0, 2.0]\n",
        d.x, d.y, d.z
    );
    let (_scratch, scene) = load("sun", &text);
    let Some(image) = common::render_direct(&scene, 16) else { return };
    // The floor's closed form: E = irradiance cos(theta), radiance albedo / pi E.
    let floor = ALBEDO / PI * 2.0 * theta.cos();
    let mut lit_floor = 0;
    let sun = |x: DVec3, n: DVec3| (x - 100.0 * d, 2.0 * n.dot(-d).max(0.0));
    let (_, _, shadowed) = compare_per_pixel(&image, &scene, &sun, 5e-3, 1e-6);
    // The floor pixels away from the shadow: exactly the closed form (no caster needed).
    let caster = Caster::new(&scene);
    for py in 0..image.height {
        for px in 0..image.width {
            let (o, dir) = camera_ray(&scene.camera, image.width, image.height, px as f64 + 0.5, py as f64 + 0.5);
            let ours = image.at(px, py)[0] as f64;
            // The floor quad is the caster's triangles 0 and 1.
            let on_floor = matches!(caster.hit(o, dir, 1e-9, f64::INFINITY), Some((_, 0 | 1)));
            if on_floor && (ours - floor).abs() <= 5e-3 * floor {
                lit_floor += 1;
            }
        }
    }
    eprintln!("floor closed form {floor:.6}: {lit_floor} floor pixels at it; {shadowed} in the shadow");
    assert!(lit_floor > 1000, "most of the floor is lit at E = irradiance cos(theta) ({lit_floor} pixels)");
    assert!(shadowed > 20, "the occluder must cast a shadow on the floor ({shadowed} pixels)");
}

#[test]
fn test02_spot_follows_the_gltf_falloff_per_pixel() {
    // Straight above the floor, tilted a little, with its outer cone inside the floor.
    let (position, axis) = (DVec3::new(0.2, 1.5, -0.1), DVec3::new(0.15, -1.0, 0.1).normalize());
    let (inner, outer, intensity) = (12.0, 30.0, 3.0);
    let text = FLOOR_AND_OCCLUDER.replace(
        "[[shapes]]\ntype = \"triangle\"\nvertices = [[-0.4, 0.6, -0.3], [-0.1, 0.7, 0.5], [0.5, 0.55, 0.0]]\nmaterial = \"grey\"\n",
        "",
    ) + &format!(
        "[[lights]]\ntype = \"spot\"\nposition = [{}, {}, {}]\ndirection = [{}, {}, {}]\nintensity = [{intensity}, {intensity}, {intensity}]\ninner_angle = {inner}\nouter_angle = {outer}\n",
        position.x, position.y, position.z, axis.x, axis.y, axis.z
    );
    let (_scratch, scene) = load("spot", &text);
    assert_eq!(scene.surfaces.len(), 1, "the floor alone");
    let Some(image) = common::render_direct(&scene, 64) else { return };
    let spot = |x: DVec3, n: DVec3| {
        let to = x - position;
        let r2 = to.length_squared();
        let w = to / r2.sqrt();
        (position, intensity * gltf_falloff(w.dot(axis), inner, outer) * n.dot(-w).max(0.0) / r2)
    };
    // The falloff is smooth but not linear across a pixel (and has a kink at the inner
    // cone): the pixel's 64-point mean against the GPU's 64 jittered samples leaves up to
    // 1.3e-3 of the peak in the steepest ring (measured).
    let peak = ALBEDO / PI * intensity / (position.y * position.y);
    compare_per_pixel(&image, &scene, &spot, 5e-3, 2e-3 * peak);
    // The profile: inside the inner cone, between the cones, beyond the outer one.
    let (mut inside, mut between, mut beyond) = (0, 0, 0);
    for py in 0..image.height {
        for px in 0..image.width {
            let (o, d) = camera_ray(&scene.camera, image.width, image.height, px as f64 + 0.5, py as f64 + 0.5);
            let x = o + d * (-o.y / d.y);
            let angle = (x - position).normalize().dot(axis).acos().to_degrees();
            let ours = image.at(px, py)[0];
            match angle {
                // 2 degrees: more than half a pixel, so the pixel's samples are on one side.
                a if a < inner - 2.0 => inside += 1,
                a if a > inner + 2.0 && a < outer - 2.0 => between += 1,
                a if a > outer + 2.0 => {
                    assert_eq!(ours, 0.0, "pixel ({px}, {py}) beyond the outer cone");
                    beyond += 1
                }
                _ => {}
            }
        }
    }
    eprintln!("{inside} pixels inside the inner cone, {between} between, {beyond} beyond the outer");
    assert!(inside > 20 && between > 200 && beyond > 200, "{inside} {between} {beyond}");
}

/// The mean of `f` over a triangle: the midpoints of its n^2 congruent sub-triangles.
fn triangle_mean(t: [DVec3; 3], n: u32, f: &dyn Fn(DVec3) -> f64) -> f64 {
    let cells = common::split(t, n);
    cells.iter().map(|c| f((c[0] + c[1] + c[2]) / 3.0)).sum::<f64>() / cells.len() as f64
}

#[test]
fn test03_first_shot_table_of_a_sun_is_cos_times_the_lit_share() {
    let Some(ctx) = common::gpu() else { return };
    let (d, theta) = sun_direction();
    // The floor of test 01 in 2 x 4^2 patches (facing up), and the occluder (facing down,
    // away from the sun: it receives nothing).
    let (a, b, c, e) = (
        DVec3::new(-1.5, 0.0, -1.5),
        DVec3::new(-1.5, 0.0, 1.5),
        DVec3::new(1.5, 0.0, 1.5),
        DVec3::new(1.5, 0.0, -1.5),
    );
    let mut tris: Vec<[DVec3; 3]> = [[a, b, c], [a, c, e]].iter().flat_map(|&t| common::split(t, 4)).collect();
    let occluder = [DVec3::new(-0.4, 0.6, -0.3), DVec3::new(0.5, 0.55, 0.0), DVec3::new(-0.1, 0.7, 0.5)];
    assert!((occluder[1] - occluder[0]).cross(occluder[2] - occluder[0]).y < 0.0);
    tris.push(occluder);
    let sample = LightSample {
        position: DVec3::ZERO,
        kind: SampleKind::Directional { direction: d },
        strength: [2.0; 3],
        weight: 1.0,
        light: 0,
    };
    let patches = common::patches_of(&tris, vec![sample]);
    let table = common::first_shot_table(&ctx, &patches, 512, LightWindow::Hemicube);
    // The oracle: cos(theta) times the share of the patch the caster finds in the light.
    let mut scene = common::bare_scene();
    scene.materials.push(firstshot::scene::Material {
        name: "grey".into(),
        kind: firstshot::scene::MaterialKind::Diffuse { albedo: [0.6; 3] },
    });
    scene.surfaces.push(firstshot::scene::Surface {
        origin: "test".into(),
        triangles: vec![firstshot::scene::Triangle { vertices: occluder, material: 0 }],
        emission: [0.0; 3],
        two_sided: false,
    });
    let caster = Caster::new(&scene);
    let (mut worst, mut partial, mut dark) = (0.0f64, 0, 0);
    for (j, t) in tris.iter().enumerate() {
        let measured: f64 = table[j].iter().map(|&(_, r)| r as f64).sum();
        let expected = if j == tris.len() - 1 {
            0.0
        } else {
            theta.cos() * triangle_mean(*t, 40, &|x| if caster.occluded(x, x - 100.0 * d) { 0.0 } else { 1.0 })
        };
        if expected > 0.0 && expected < 0.99 * theta.cos() {
            partial += 1;
        }
        if expected == 0.0 {
            dark += 1;
        }
        worst = worst.max((measured - expected).abs() / theta.cos());
        eprintln!("patch {j}: measured {measured:.5}, expected {expected:.5}");
    }
    eprintln!(
        "worst error of r_ij against cos(theta) x lit share: {worst:.5} of cos(theta); {partial} patches partly in the shadow"
    );
    // 512 pixels across the scene's bounding sphere: a patch covers thousands, its outline
    // and the shadow's edge cost a few of them.
    assert!(worst < 0.01, "worst {worst}");
    assert!(partial >= 3 && dark >= 1, "the shadow must cut some patches ({partial}) and the occluder stay dark");
}

#[test]
fn test04_first_shot_table_of_a_spot_is_its_falloff_integral() {
    let Some(ctx) = common::gpu() else { return };
    let (position, axis) = (DVec3::new(0.2, 1.5, -0.1), DVec3::new(0.15, -1.0, 0.1).normalize());
    let (inner, outer) = (12.0, 30.0);
    // The floor turned 17 degrees about the vertical: patch edges parallel to the cube's
    // pixel grid would each gain or lose up to half a row of pixels at once.
    let turn = glam::DQuat::from_rotation_y(17f64.to_radians());
    let [a, b, c, e] = [[-1.5, -1.5], [-1.5, 1.5], [1.5, 1.5], [1.5, -1.5]].map(|[x, z]| turn * DVec3::new(x, 0.0, z));
    let tris: Vec<[DVec3; 3]> = [[a, b, c], [a, c, e]].iter().flat_map(|&t| common::split(t, 6)).collect();
    let cone = SpotCone::new(inner, outer);
    let sample =
        LightSample { position, kind: SampleKind::Spot { axis, cone }, strength: [3.0; 3], weight: 1.0, light: 0 };
    let patches = common::patches_of(&tris, vec![sample]);
    let table = common::first_shot_table(&ctx, &patches, 512, LightWindow::Hemicube);
    // S_i r_ij is the patch's mean irradiance over intensity: the mean of
    // falloff(angle) cos_x / r^2 over the patch.
    let density = |x: DVec3| {
        let to = x - position;
        let r2 = to.length_squared();
        let w = to / r2.sqrt();
        gltf_falloff(w.dot(axis), inner, outer) * w.dot(-DVec3::Y).max(0.0) / r2
    };
    let expected: Vec<f64> = tris.iter().map(|&t| triangle_mean(t, 40, &density)).collect();
    let largest = expected.iter().copied().fold(0.0, f64::max);
    let (mut worst, mut lit, mut unlit) = (0.0f64, 0, 0);
    for (j, &e) in expected.iter().enumerate() {
        let measured: f64 = table[j].iter().map(|&(_, r)| r as f64).sum();
        if e > 0.0 {
            lit += 1;
        } else {
            unlit += 1;
            assert_eq!(measured, 0.0, "patch {j} lies beyond the outer cone");
        }
        worst = worst.max((measured - e).abs() / largest);
    }
    eprintln!(
        "worst error of r_ij against the falloff integral: {worst:.5} of the largest ({largest:.5}); {lit} lit, {unlit} beyond the cone"
    );
    // The floor's edges are not parallel to the cube's pixel grid: the pixel counts' errors
    // along them average out (3e-4 measured at 512).
    assert!(worst < 3e-3, "worst {worst}");
    assert!(lit >= 10 && unlit >= 10, "{lit} {unlit}");
}

fn source() -> &'static Path {
    Path::new("memory/lights.toml")
}

const SCENE: &str = r#"
format = 1
[camera]
position = [0.0, 1.0, -3.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
width = 8
height = 8
[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]
[[shapes]]
type = "quad"
vertices = [[-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]]
material = "white"
"#;

fn refused(light: &str, key: &str) -> String {
    match load_str(&format!("{SCENE}[[lights]]\n{light}"), source()) {
        Err(Error::Scene { file, key: k, message }) => {
            assert_eq!(file, source());
            assert_eq!(k, key, "refused with another key: {message}");
            message
        }
        Err(e) => panic!("refused, but not as a scene error: {e}"),
        Ok(_) => panic!("loaded, but should be refused with key {key}"),
    }
}

#[test]
fn test05_loader_reads_directional_and_spot_lights() {
    let text = format!(
        "{SCENE}[[lights]]\ntype = \"directional\"\ndirection = [0.0, -2.0, 0.0]\nirradiance = [1.0, 2.0, 3.0]\n\
         [[lights]]\ntype = \"spot\"\nposition = [0.0, 1.0, 0.0]\ndirection = [0.0, 0.0, -3.0]\nintensity = [4.0, 5.0, 6.0]\ninner_angle = 10\nouter_angle = 20.5\n\
         [[lights]]\ntype = \"spot\"\nposition = [0.0, 1.0, 0.0]\ndirection = [0.0, -1.0, 0.0]\nintensity = [1.0, 1.0, 1.0]\n"
    );
    let scene = load_str(&text, source()).unwrap();
    assert_eq!(scene.lights[0], Light::Directional { direction: DVec3::NEG_Y, irradiance: [1.0, 2.0, 3.0] });
    assert_eq!(
        scene.lights[1],
        Light::Spot {
            position: DVec3::Y,
            direction: DVec3::NEG_Z,
            intensity: [4.0, 5.0, 6.0],
            inner_angle: 10.0,
            outer_angle: 20.5
        }
    );
    // glTF's defaults: inner 0, outer 45 degrees.
    assert!(matches!(scene.lights[2], Light::Spot { inner_angle: 0.0, outer_angle: 45.0, .. }));
    // The cone as the scene module computes it, against the glTF formula written here.
    let cone = SpotCone::new(10.0, 20.5);
    for k in 0..=100 {
        let cd = (k as f64 / 100.0 * 30f64.to_radians()).cos();
        assert!((cone.falloff(cd) - gltf_falloff(cd, 10.0, 20.5)).abs() < 1e-12);
    }
    // A sun or spot alone is an emitter: the scene loads.
    let tessellated = scene::tessellate(&scene, f64::INFINITY).unwrap();
    assert_eq!(tessellated.samples.len(), 3);
    assert!(matches!(tessellated.samples[0].kind, SampleKind::Directional { direction } if direction == DVec3::NEG_Y));
    // The sun's sample has no place: the bounds are the floor's and the spots' alone.
    let (centre, radius) = firstshot::scene::tessellate::scene_bounds(&tessellated);
    assert!(centre.distance(DVec3::new(0.0, 0.5, 0.0)) < 1e-12 && (radius - 1.5).abs() < 1e-12);
}

#[test]
fn test06_loader_refuses_bad_lights_naming_file_and_key() {
    let m = refused(
        "type = \"directional\"\ndirection = [0.0, 0.0, 0.0]\nirradiance = [1.0, 1.0, 1.0]\n",
        "lights[0].direction",
    );
    assert!(m.contains("must not be zero"), "{m}");
    let m = refused(
        "type = \"directional\"\ndirection = [0.0, -1.0, 0.0]\nirradiance = [1.0, -1.0, 1.0]\n",
        "lights[0].irradiance",
    );
    assert!(m.contains(">= 0"), "{m}");
    refused("type = \"directional\"\ndirection = [0.0, -1.0, 0.0]\n", "lights[0].irradiance");
    let m = refused(
        "type = \"directional\"\ndirection = [0.0, -1.0, 0.0]\nirradiance = [1.0, 1.0, 1.0]\nposition = [0.0, 0.0, 0.0]\n",
        "lights[0].position",
    );
    assert!(m.contains("unknown key"), "{m}");
    let spot =
        "type = \"spot\"\nposition = [0.0, 1.0, 0.0]\ndirection = [0.0, -1.0, 0.0]\nintensity = [1.0, 1.0, 1.0]\n";
    let m = refused(&format!("{spot}power = [1.0, 1.0, 1.0]\n"), "lights[0].power");
    assert!(m.contains("unknown key") && m.contains("intensity"), "{m}");
    let m = refused(&format!("{spot}outer_angle = 95\n"), "lights[0].outer_angle");
    assert!(m.contains("from 0 to 90"), "{m}");
    refused(&format!("{spot}inner_angle = -1\n"), "lights[0].inner_angle");
    let m = refused(&format!("{spot}inner_angle = 30\nouter_angle = 30\n"), "lights[0].inner_angle");
    assert!(m.contains("less than outer_angle"), "{m}");
    let m = refused(&format!("{spot}inner_angle = 50\n"), "lights[0].inner_angle");
    assert!(m.contains("its default"), "{m}");
    refused(&spot.replace("direction = [0.0, -1.0, 0.0]", "direction = [0.0, 0.0, 0.0]"), "lights[0].direction");
    let m = refused("type = \"sun\"\n", "lights[0].type");
    assert!(m.contains("\"directional\" or \"spot\""), "{m}");
    // Black lights are no emitters.
    let m = refused("type = \"directional\"\ndirection = [0.0, -1.0, 0.0]\nirradiance = [0.0, 0.0, 0.0]\n", "lights");
    assert!(m.contains("no emitter"), "{m}");
}

#[test]
fn test07_no_first_shot_is_refused_for_suns_and_spots() {
    for (light, kind) in [
        ("type = \"directional\"\ndirection = [0.0, -1.0, 0.0]\nirradiance = [1.0, 1.0, 1.0]\n", "directional"),
        (
            "type = \"spot\"\nposition = [0.0, 1.0, 0.0]\ndirection = [0.0, -1.0, 0.0]\nintensity = [1.0, 1.0, 1.0]\n",
            "spot",
        ),
    ] {
        let scene = load_str(&format!("{SCENE}[[lights]]\n{light}"), source()).unwrap();
        let mut options = RenderOptions::from_scene(&scene);
        assert!(check_options(&scene, &options).is_ok());
        options.first_shot = false;
        let message = check_options(&scene, &options).unwrap_err().to_string();
        assert!(message.contains("--no-first-shot") && message.contains(&format!("{kind} light")), "{message}");
    }
}

#[test]
fn test08_sun_does_not_leak_through_a_tessellated_roof() {
    // A roof of small patches (seen from the sun by its back) over part of the floor: its
    // triangles' corners poke between the sun's texel centres at every mesh vertex. Per pixel,
    // the floor under it must be as dark as the caster says, and the rest lit.
    let (d, _) = sun_direction();
    let text = FLOOR_AND_OCCLUDER
        .replace("patch_size = 0.5", "patch_size = 0.1")
        .replace(
            "vertices = [[-0.4, 0.6, -0.3], [-0.1, 0.7, 0.5], [0.5, 0.55, 0.0]]",
            "vertices = [[-0.3, 0.5, -1.0], [1.0, 0.5, -1.0], [1.0, 0.5, 0.8], [-0.3, 0.5, 0.8]]",
        )
        .replace("type = \"triangle\"", "type = \"quad\"")
        + &format!(
            "[[lights]]\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = [2.0, 2.0, 2.0]\n",
            d.x, d.y, d.z
        );
    let (_scratch, scene) = load("roof", &text);
    let roof = &scene.surfaces[1].triangles[0];
    assert!((roof.vertices[1] - roof.vertices[0]).cross(roof.vertices[2] - roof.vertices[0]).y < 0.0, "faces down");
    let Some(image) = common::render_direct(&scene, 4) else { return };
    let sun = |x: DVec3, n: DVec3| (x - 100.0 * d, 2.0 * n.dot(-d).max(0.0));
    let (_, _, shadowed) = compare_per_pixel(&image, &scene, &sun, 5e-3, 1e-6);
    assert!(shadowed > 200, "the roof must shade the floor ({shadowed} pixels)");
}

#[test]
fn test09_sun_room_renders_with_its_sunlit_patch() {
    // The shipped example, small: the floor where the sun falls through the window, the
    // floor in the shade and the spot's pool on the block's top, direct light and a few
    // steps of the iteration.
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load(&common::scenes::shipped("sun_room")).unwrap();
    let mut options = RenderOptions::from_scene(&scene);
    (options.width, options.height) = (64, 48);
    (options.iterations, options.direct_passes, options.burn_in) = (8, 4, Some(2));
    (options.hemicube_resolution, options.bundle_resolution, options.shadow_resolution) =
        (Some(128), Some(64), Some(256));
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    let image = render(&ctx, &scene, &patches, &options).unwrap().image;
    // Finite; not necessarily >= 0 after 8 steps: the control variate's K_j can be negative
    // (docs/ALGORITHM.md 2), and so can a pixel's gather over 8 directions (unbiased, not
    // positive: 2 kd (|n . d| (L - Lbar) + Lbar / 2) is below 0 wherever a direction with
    // |n . d| > 1/2 sees less than Lbar).
    assert!(image.pixels.iter().flatten().all(|c| c.is_finite()));
    // So the sun and the shade are judged on the direct light, which the same options
    // estimate without the iteration (`iterations` 0: Le + D from 4 passes).
    let direct = RenderOptions { iterations: 0, ..options.clone() };
    let image = render(&ctx, &scene, &patches, &direct).unwrap().image;
    // Where the camera ray through a pixel centre meets the floor: in the sun (by the
    // caster) at albedo / pi E cos(theta), in the shade less.
    // The caster gives visibility only: materials made diffuse for it.
    let mut grey = scene.clone();
    for m in &mut grey.materials {
        m.kind = firstshot::scene::MaterialKind::Diffuse { albedo: [0.5; 3] };
    }
    let caster = Caster::new(&grey);
    let Light::Directional { direction: d, irradiance } = scene.lights[0] else { panic!("the sun comes first") };
    let floor_albedo = 0.55;
    let sunlit = floor_albedo / PI * irradiance[0] as f64 * d.dot(DVec3::NEG_Y);
    let (mut in_sun, mut in_shade) = (0, 0);
    for py in 0..image.height {
        for px in 0..image.width {
            let (o, dir) = camera_ray(&scene.camera, image.width, image.height, px as f64 + 0.5, py as f64 + 0.5);
            let Some((t, _)) = caster.hit(o, dir, 1e-9, f64::INFINITY) else { continue };
            let x = o + t * dir;
            if x.y.abs() > 1e-6 {
                continue; // not the floor
            }
            // Well inside or well outside the sunlit patch: the floor points seen through the
            // pixel's corners, and points 8 cm (3 of the sun's texels) around them, agree.
            let lit = |x: DVec3| !caster.occluded(x, x - 100.0 * d);
            let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)].map(|(sx, sy)| {
                let (o, dir) = camera_ray(&scene.camera, image.width, image.height, px as f64 + sx, py as f64 + sy);
                o + dir * (-o.y / dir.y)
            });
            let steps = [DVec3::ZERO, DVec3::X, DVec3::NEG_X, DVec3::Z, DVec3::NEG_Z];
            if corners.iter().flat_map(|&c| steps.map(|s| c + 0.08 * s)).any(|p| lit(p) != lit(x)) {
                continue;
            }
            let ours = image.at(px, py)[0] as f64;
            if lit(x) {
                in_sun += 1;
                assert!(ours >= sunlit * 0.995, "pixel ({px}, {py}) in the sun: {ours} < {sunlit}");
            } else {
                in_shade += 1;
                assert!(ours < 0.5 * sunlit, "pixel ({px}, {py}) in the shade: {ours}");
            }
        }
    }
    eprintln!("{in_sun} floor pixels in the sun (at least {sunlit:.4}), {in_shade} in the shade");
    assert!(in_sun > 50 && in_shade > 50, "{in_sun} {in_shade}");
}

#[test]
fn test10_sunlit_glossy_square_lights_a_receiver_through_the_iteration() {
    // A max-Phong square (two patches) lit by a sun at 75 degrees, and above it, facing it, a
    // small grey triangle the sun does not reach (its back faces the sun, and its shadow
    // falls beside the square). The triangle's pixels see only what the iteration carries
    // from the square: the first shot's S r_ij = E cos(theta) reflected by the square's
    // glossy BRDF toward each bundle direction. Oracle: the integral over the square of
    // E cos(theta) f(-d, w) cos_y cos_x / (pi r^2), averaged over the triangle.
    let Some(ctx) = common::gpu() else { return };
    let (h, theta, irradiance) = (0.4, 75f64.to_radians(), 2.0);
    let d = DVec3::new(theta.sin(), 0.0, -theta.cos());
    let (kd, ks, shininess) = (0.3, 0.5, 5.0);
    // The receiver's albedo: low, so that the light it sends back to the square and gets
    // again (which the oracle leaves out) is a small part of what it receives.
    let albedo = 0.25;
    let square = [
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(1.0, -1.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(-1.0, 1.0, 0.0),
    ];
    let receiver = [DVec3::new(-0.3, -0.2, h), DVec3::new(0.1, 0.35, h), DVec3::new(0.35, -0.25, h)];
    assert!((receiver[1] - receiver[0]).cross(receiver[2] - receiver[0]).z < 0.0, "the receiver faces the square");
    // Its shadow: the receiver's vertices pushed along d onto z = 0 all lie beyond x = 1.
    assert!(receiver.iter().all(|v| (*v + d * (v.z / d.z.abs())).x > 1.0));
    let mut scene = common::bare_scene();
    scene.camera.position = DVec3::new(0.02, 0.01, h / 2.0);
    scene.camera.look_at = DVec3::new(0.02, 0.01, h);
    scene.camera.fov_y = 60.0;
    (scene.camera.width, scene.camera.height) = (16, 16);
    scene.materials = vec![
        firstshot::scene::Material {
            name: "gloss".into(),
            kind: firstshot::scene::MaterialKind::Phong {
                diffuse: [kd as f32; 3],
                specular: [ks as f32; 3],
                shininess: shininess as f32,
            },
        },
        firstshot::scene::Material {
            name: "grey".into(),
            kind: firstshot::scene::MaterialKind::Diffuse { albedo: [albedo as f32; 3] },
        },
    ];
    let sun = LightSample {
        position: DVec3::ZERO,
        kind: SampleKind::Directional { direction: d },
        strength: [irradiance as f32; 3],
        weight: 1.0,
        light: 0,
    };
    let mut patches = common::patches_of(
        &[[square[0], square[1], square[2]], [square[0], square[2], square[3]], receiver],
        vec![sun],
    );
    for (p, m) in patches.patches.iter_mut().zip([0, 0, 1]) {
        p.material = Some(m);
    }
    // The oracle on a 48 x 48 grid of the square and the receiver's 8^2 sub-triangles.
    let (n_sq, n_r, cells) = (DVec3::Z, DVec3::NEG_Z, 48);
    let cell = 2.0 / cells as f64;
    let at_receiver = |x: DVec3| {
        let mut sum = 0.0;
        for i in 0..cells {
            for j in 0..cells {
                let y = DVec3::new(-1.0 + (i as f64 + 0.5) * cell, -1.0 + (j as f64 + 0.5) * cell, 0.0);
                let r = x - y;
                let w = r.normalize();
                let radiance = irradiance * theta.cos() * common::max_phong(kd, ks, shininess, n_sq, -d, w);
                sum += radiance * n_sq.dot(w) * n_r.dot(-w) / (PI * r.length_squared()) * cell * cell;
            }
        }
        sum
    };
    // The pixels measured are the centre 4 x 4 of the 16 x 16 image: the camera looks
    // straight up (its up is +y), so they see the square of the receiver's plane within a
    // quarter of the half-width of the view of the centre, where the radiance is averaged
    // (over the whole triangle it is the same to four digits here, but this is what the
    // pixels see).
    let half = 0.25 * (scene.camera.fov_y / 2.0).to_radians().tan() * (h - scene.camera.position.z);
    let grid = 8;
    let seen = |i: usize| -half + (i as f64 + 0.5) * 2.0 * half / grid as f64;
    let expected = albedo
        * (0..grid * grid)
            .map(|k| {
                let at =
                    DVec3::new(scene.camera.position.x + seen(k % grid), scene.camera.position.y + seen(k / grid), h);
                at_receiver(at)
            })
            .sum::<f64>()
        / (grid * grid) as f64;
    let runs: Vec<f64> = (0..8)
        .map(|seed| {
            let mut o = RenderOptions::from_scene(&scene);
            // A first shot of 1024: the sun sees the square at 75 degrees, about 46 texels
            // deep at 256, where a row of texels more or less is 2 % of its light (its mean
            // came out 2.5 % high there, 0.5 % at 1024).
            (o.iterations, o.seed, o.bundle_resolution, o.hemicube_resolution) =
                (250, 100 + seed, Some(48), Some(1024));
            let image = render(&ctx, &scene, &patches, &o).unwrap().image;
            let centre: Vec<f64> =
                (6..10).flat_map(|y| (6..10).map(move |x| (x, y))).map(|(x, y)| image.at(x, y)[0] as f64).collect();
            centre.iter().sum::<f64>() / centre.len() as f64
        })
        .collect();
    let mean = runs.iter().sum::<f64>() / runs.len() as f64;
    let var = runs.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (runs.len() - 1) as f64;
    let standard_error = (var / runs.len() as f64).sqrt();
    eprintln!("glossy square under the sun: oracle {expected:.5}, measured {mean:.5} +- {standard_error:.5}");
    assert!(standard_error < 0.05 * expected, "too noisy to judge: {standard_error}");
    // Four standard errors, and 1.5 % for what the oracle leaves out: the first shot's
    // texel counts (above), and the light the receiver sends back to the square and gets
    // again, about 2 % of its albedo (measured: a white receiver's mean was 1.6 % further
    // above the oracle than this grey one's), so 0.5 % here. (Before 2026-11-29 the receiver
    // was white and the first shot 256, and the mean was 3.6 % high over 32 seeds: this test
    // passed only while eight seeds spread wide enough.)
    assert!((mean - expected).abs() < 4.0 * standard_error + 0.015 * expected, "measured {mean} against {expected}");
}

/// The direct-light image of `scene` after `passes` passes, its lights' windows at `side`
/// texels whatever the lights (so that every render below sees through the same texels).
fn direct_with_windows(scene: &Scene, passes: u32, side: u32) -> Option<Image> {
    let ctx = common::gpu()?;
    let mut options = RenderOptions::from_scene(scene);
    options.iterations = 0;
    options.direct_passes = passes;
    options.shadow_resolution = Some(side);
    let patches = scene::tessellate(scene, options.patch_size).unwrap();
    Some(render(&ctx, scene, &patches, &options).unwrap().image)
}

#[test]
fn test11_a_sun_a_spot_and_a_point_light_together_light_as_the_sum_of_each_alone() {
    // The direct pass is compiled for the kinds of light the scene has (image_estimate's
    // LIGHT_KINDS and WINDOW_FACE_COUNTS): each light alone gets a kernel with its own kind's
    // code only, the three together one with all three. Light adds up, and each render
    // sees the same camera samples and window texels, so the sum of the three images must
    // be the image of the three, but for the order of a float sum per pixel.
    let (d, _) = sun_direction();
    let lights = [
        format!("[[lights]]\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = [2.0, 1.5, 1.0]\n", d.x, d.y, d.z),
        "[[lights]]\ntype = \"spot\"\nposition = [0.2, 1.5, -0.1]\ndirection = [0.15, -1.0, 0.1]\nintensity = [3.0, 3.0, 3.0]\ninner_angle = 12.0\nouter_angle = 30.0\n".to_string(),
        "[[lights]]\ntype = \"point\"\nposition = [-0.6, 1.2, 0.7]\npower = [20.0, 30.0, 40.0]\n".to_string(),
    ];
    // The sun's parallel view spans the scene's bounding sphere, which holds the lights'
    // positions too: a thin mast at the floor's corner, out of the camera's view, makes the
    // sphere the same with and without the spot and the point light.
    let base = format!(
        "{FLOOR_AND_OCCLUDER}\n[[shapes]]\ntype = \"triangle\"\nvertices = [[-1.5, 0.0, -1.5], [-1.5, 1.6, -1.5], [-1.45, 0.0, -1.5]]\nmaterial = \"grey\"\n"
    );
    let passes = 4;
    let mut alone = Vec::new();
    for (k, light) in lights.iter().enumerate() {
        let (_scratch, scene) = load(&format!("alone{k}"), &format!("{base}\n{light}"));
        let Some(image) = direct_with_windows(&scene, passes, 256) else { return };
        alone.push(image);
    }
    let (_scratch, scene) = load("together", &format!("{base}\n{}", lights.concat()));
    let Some(together) = direct_with_windows(&scene, passes, 256) else { return };
    let (mut lit, mut worst) = ([0usize; 3], 0f64);
    for py in 0..together.height {
        for px in 0..together.width {
            for c in 0..3 {
                let parts: Vec<f64> = alone.iter().map(|i| i.at(px, py)[c] as f64).collect();
                for (k, part) in parts.iter().enumerate() {
                    if *part > 0.0 {
                        lit[k] += 1;
                    }
                }
                let sum: f64 = parts.iter().sum();
                let ours = together.at(px, py)[c] as f64;
                let error = (ours - sum).abs() / sum.max(1e-3);
                worst = worst.max(error);
                assert!(
                    error <= 1e-5,
                    "pixel ({px}, {py}) channel {c}: {ours} together, {sum} as the sum of {parts:?}"
                );
            }
        }
    }
    eprintln!("pixels lit by each light alone (per channel): {lit:?}; worst relative difference {worst:.2e}");
    assert!(lit.iter().all(|&n| n > 500), "each light must light part of the floor: {lit:?}");
}

#[test]
fn test12_sun_behind_a_wall_does_not_light_the_crease_at_its_foot() {
    // A wall standing on a floor with the sun behind it: the floor in front lies in the
    // wall's shadow and the wall's front faces away from the sun, so the whole view of the
    // crease where they meet is black. A point of the floor within a few millimetres of the
    // wall lies that close to the wall's plane; taking every plane that near x for x's own
    // (a share of the segment to the sun's view, 1e-4 of it) let the sun through there: the
    // crease pixels of this close view came out lit.
    let text = r#"
format = 1
[camera]
position = [0.0, 0.05, -0.08]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 30.0
width = 32
height = 32
[settings]
patch_size = 0.5
[materials.grey]
type = "diffuse"
albedo = [0.6, 0.6, 0.6]
[[shapes]] # floor, in front of the wall
type = "quad"
vertices = [[-1.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, -1.0]]
material = "grey"
[[shapes]] # wall at z = 0, facing -z (the camera)
type = "quad"
vertices = [[-1.0, 0.0, 0.0], [-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]]
material = "grey"
[[lights]]
type = "directional"
direction = [0.0, -0.6, -0.8]
irradiance = [2.0, 2.0, 2.0]
"#;
    let (_scratch, scene) = load("crease", text);
    let Some(image) = common::render_direct(&scene, 16) else { return };
    // Sunlit, the floor would be 0.6 / pi * 2 * 0.6 = 0.23.
    let brightest = image.pixels.iter().map(|p| p[0]).fold(0.0f32, f32::max);
    let lit = image.pixels.iter().filter(|p| p[0] > 1e-4).count();
    assert!(brightest <= 1e-5, "{lit} of {} pixels lit, the brightest {brightest}", image.pixels.len());
}

#[test]
fn test13_sun_shadow_ends_at_the_occluders_outline_not_a_texel_past_it() {
    // A square roof of many patches (interior edges shared: the surface goes on across
    // them) over a floor, the camera close above its shadow's outline, where a texel of the
    // sun's view spans several pixels. A roof's plane crossed by the segment to the sun once
    // shaded every point within a texel of the outline (the plane reaches past the roof's
    // edge); now only a crossing inside the roof, or beyond an edge it shares with another
    // patch of its plane, shades. Per pixel against the caster, both sides of the outline.
    let (d, _) = sun_direction();
    // The roof spans x, z in [-0.3, 0.3] at y = 0.5; its edge x = 0.3 falls on the floor at
    // x = 0.3 + 0.5 d.x / -d.y, z shifted by 0.5 d.z / -d.y.
    let (ox, oz) = (0.3 + 0.5 * d.x / -d.y, 0.5 * d.z / -d.y);
    let text = FLOOR_AND_OCCLUDER
        .replace("patch_size = 0.5", "patch_size = 0.1")
        .replace("hemicube_resolution = 512", "hemicube_resolution = 64")
        .replace(
            "vertices = [[-0.4, 0.6, -0.3], [-0.1, 0.7, 0.5], [0.5, 0.55, 0.0]]",
            "vertices = [[-0.3, 0.5, -0.3], [0.3, 0.5, -0.3], [0.3, 0.5, 0.3], [-0.3, 0.5, 0.3]]",
        )
        .replace("type = \"triangle\"", "type = \"quad\"")
        .replace("position = [0.1, 3.0, 0.05]", &format!("position = [{ox}, 0.3, {oz}]"))
        .replace("look_at = [0.0, 0.0, 0.0]", &format!("look_at = [{ox}, 0.0, {oz}]"))
        .replace("fov_y = 60.0", "fov_y = 20.0")
        + &format!(
            "[[lights]]\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = [2.0, 2.0, 2.0]\n",
            d.x, d.y, d.z
        );
    let (_scratch, scene) = load("outline", &text);
    assert_eq!(scene.camera.up, DVec3::Z, "the camera looks straight down");
    let Some(image) = common::render_direct(&scene, 4) else { return };
    let sun = |x: DVec3, n: DVec3| (x - 100.0 * d, 2.0 * n.dot(-d).max(0.0));
    let caster = Caster::new(&scene);
    // Pixels whose 8 x 8 points the caster finds all lit or all in shadow: (count, wrong).
    let (mut lit, mut shaded) = ((0, 0), (0, 0));
    for py in 0..image.height {
        for px in 0..image.width {
            let points: Vec<(f64, bool)> = (0..64)
                .map(|k| {
                    let (sx, sy) = ((k % 8) as f64 + 0.5, (k / 8) as f64 + 0.5);
                    let (o, dir) = camera_ray(
                        &scene.camera,
                        image.width,
                        image.height,
                        px as f64 + sx / 8.0,
                        py as f64 + sy / 8.0,
                    );
                    let (value, _, is_lit) = seen_along(&caster, o, dir, &sun);
                    (value, is_lit)
                })
                .collect();
            let ours = image.at(px, py)[0] as f64;
            if points.iter().all(|p| p.1) {
                let expected = points.iter().map(|p| p.0).sum::<f64>() / 64.0;
                lit.0 += 1;
                lit.1 += usize::from((ours - expected).abs() > 5e-3 * expected);
            } else if points.iter().all(|p| !p.1) {
                shaded.0 += 1;
                shaded.1 += usize::from(ours > 1e-6);
            }
        }
    }
    eprintln!("lit pixels {lit:?}, shaded pixels {shaded:?} (count, wrong)");
    assert!(lit.0 > 300 && shaded.0 > 300, "the view holds both sides of the outline: {lit:?} {shaded:?}");
    // Nothing leaks into the shadow. On the lit side what is left is a wedge at the corner
    // of a roof triangle that touches the outline: the texels there show the triangle beside
    // the one on the outline, whose edge between them is smooth, so its plane is taken to go
    // on for a texel and a half (CONTINUATION_TEXELS). Measured: 57 of 1152 lit pixels wrong,
    // against 244 (the whole band along the outline) when every crossing of a plane shaded.
    assert_eq!(shaded.1, 0, "light leaked into the shadow: {shaded:?} (count, wrong)");
    assert!(lit.1 * 10 <= lit.0, "lit {lit:?} (count, wrong): the outline is shaded past the roof's edge");
}

/// A floor under a 16 x 16 grid of small tiles at several heights, lit by every kind of light
/// (an area light, a point light, a spot and a sun), with the camera above one corner of
/// the grid: 514 rasterised triangles, whose chunks of 64 consecutive ones are strips of the grid
/// that some window faces and the camera see and others do not.
fn tile_field() -> String {
    let mut text = String::from(
        r#"
format = 1
[camera]
position = [-3.4, 3.0, -3.6]
look_at = [-3.4, 0.0, -3.4]
up = [0.0, 1.0, 0.0]
fov_y = 30.0
width = 48
height = 40
[settings]
patch_size = 1.0
[materials.grey]
type = "diffuse"
albedo = [0.6, 0.6, 0.6]
[materials.gloss]
type = "phong"
diffuse = [0.2, 0.2, 0.2]
specular = [0.5, 0.5, 0.5]
shininess = 8.0
[[shapes]]
type = "quad"
vertices = [[5.0, 0.0, -5.0], [-5.0, 0.0, -5.0], [-5.0, 0.0, 5.0], [5.0, 0.0, 5.0]]
material = "grey"
[[lights]]
type = "area"
vertices = [[-2.0, 3.0, 2.0], [-2.5, 3.0, 2.0], [-2.5, 3.0, 2.5], [-2.0, 3.0, 2.5]]
radiance = [20.0, 20.0, 20.0]
[[lights]]
type = "point"
position = [-3.8, 1.2, -3.8]
power = [30.0, 30.0, 30.0]
[[lights]]
type = "spot"
position = [3.0, 2.5, 3.0]
direction = [-0.3, -1.0, -0.3]
intensity = [10.0, 10.0, 10.0]
inner_angle = 10.0
outer_angle = 20.0
[[lights]]
type = "directional"
direction = [0.4, -1.0, 0.2]
irradiance = [1.0, 1.0, 1.0]
"#,
    );
    for i in 0..16 {
        for j in 0..16 {
            let (x, z, h) = (-4.0 + 0.5 * i as f64, -4.0 + 0.5 * j as f64, 0.15);
            let y = 0.3 + 0.2 * ((7 * i + 3 * j) % 5) as f64;
            let material = if (i + j) % 2 == 0 { "grey" } else { "gloss" };
            text += &format!(
                "[[shapes]]\ntype = \"quad\"\nvertices = [[{}, {y}, {}], [{}, {y}, {}], [{}, {y}, {}], [{}, {y}, {}]]\nmaterial = \"{material}\"\n",
                x + h,
                z - h,
                x - h,
                z - h,
                x - h,
                z + h,
                x + h,
                z + h
            );
        }
    }
    text
}

#[test]
fn test14_culled_item_buffers_change_no_pixel() {
    // The item buffers draw only the chunks of triangles that can reach their view
    // (`gpu::frustum`). The oracle is the same render drawing every triangle: the first-shot
    // table, the lights' windows (a hemicube with half faces, a point light's cube, a spot's
    // face, a sun's parallel projection) and the camera's item buffer must be the same, so
    // the images too, to the bit.
    let Some(ctx) = common::gpu() else { return };
    let (_scratch, scene) = common::scenes::load_text("lights", "test14", &tile_field());
    let mut options = RenderOptions::from_scene(&scene);
    (options.iterations, options.direct_passes, options.burn_in) = (3, 2, Some(1));
    (options.hemicube_resolution, options.bundle_resolution, options.shadow_resolution) =
        (Some(96), Some(64), Some(128));
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    let run = |cull: bool, iterations: u32| {
        let o = RenderOptions { cull_raster: cull, iterations, ..options.clone() };
        render(&ctx, &scene, &patches, &o).unwrap()
    };
    for iterations in [0, 3] {
        let (culled, drawn) = (run(true, iterations), run(false, iterations));
        assert_eq!(culled.stats.first_shot_pairs, drawn.stats.first_shot_pairs);
        let differing = culled.image.pixels.iter().zip(&drawn.image.pixels).filter(|(a, b)| a != b).count();
        let lit = culled.image.pixels.iter().filter(|p| p.iter().any(|&c| c > 0.0)).count();
        eprintln!("{iterations} steps: {differing} of {} pixels differ, {lit} lit", culled.image.pixels.len());
        assert!(lit > culled.image.pixels.len() / 2, "the camera sees the lit tiles: {lit} pixels lit");
        assert_eq!(differing, 0, "culling changed {differing} pixels after {iterations} steps");
    }
    // The test means something only if the culling skips triangles here: the camera, above one
    // corner of the grid, leaves most strips of it out.
    let triangles = firstshot::gpu::scene_buffers::raster_triangles(&patches);
    let chunks = firstshot::gpu::frustum::ChunkBoxes::of(&triangles.vertices);
    let view = firstshot::stages::camera_item_buffer::gpu_camera(&scene.camera, 48, 40, 1e-3, [0.5, 0.5]);
    let kept: u32 = chunks.visible(&view, view.size[1]).iter().map(|r| r.end - r.start).sum();
    eprintln!("the camera draws {kept} of {} triangles", chunks.triangles);
    assert!(kept > 0 && 2 * kept < chunks.triangles, "kept {kept} of {} triangles", chunks.triangles);
}

#[test]
fn test15_a_scene_far_from_the_origin_renders_as_at_the_origin() {
    // Moving a scene, its camera and its lights together changes no light transport: the
    // image must be the same. Far from the origin every position the GPU holds in f32 would
    // be rounded more coarsely (about the offset times 6e-8, here 0.02 units in a box 560
    // wide), so the loader moves such a scene to its own origin (`Scene::recentre`): the
    // two images then differ by the rounding of two nearby frames, 0.13 % (0.45 % when the
    // GPU held the offset). Architectural models often come with such offsets (survey
    // coordinates). The box of cornell_point has a point light, glossy surfaces and, added
    // here, an area light; its walls light each other, so the gather matters (checked below).
    let Some(ctx) = common::gpu() else { return };
    let offset = DVec3::new(300_000.0, 100_000.0, -200_000.0);
    let text = std::fs::read_to_string(common::scenes::shipped("cornell_point")).unwrap()
        + "[[lights]]\ntype = \"area\"\nvertices = [[343.0, 548.7, 227.0], [343.0, 548.7, 332.0], [213.0, 548.7, 332.0], [213.0, 548.7, 227.0]]\nradiance = [4.0, 4.0, 4.0]\n";
    let render_at = |text: &str, name: &str, iterations: u32| {
        let (_scratch, scene) = common::scenes::load_text("lights", name, text);
        let mut options = RenderOptions::from_scene(&scene);
        (options.width, options.height) = (48, 48);
        (options.iterations, options.direct_passes) = (iterations, 4);
        (options.hemicube_resolution, options.bundle_resolution, options.shadow_resolution) =
            (Some(64), Some(64), Some(128));
        let patches = scene::tessellate(&scene, options.patch_size).unwrap();
        render(&ctx, &scene, &patches, &options).unwrap()
    };
    let (near, far) =
        (render_at(&text, "test15_near", 8), render_at(&common::scenes::moved(&text, offset), "test15_far", 8));
    // The burn-in's length comes from the walk's measured decay per bounce (src/burn_in.rs),
    // which cast its rays in world coordinates until 2026-11-29: there they fell back onto
    // the surface they left, and the moved box decayed faster and burned in for fewer steps.
    assert_eq!(far.stats.burn_in_steps, near.stats.burn_in_steps, "the burn-in");
    let (near, far) = (near.image, far.image);
    let error = firstshot::image::image_error(&far, &near).unwrap();
    eprintln!(
        "offset {offset}: error {:.5}, means {:?} against {:?}",
        error.relative_rmse, error.mean, error.reference_mean
    );
    // Rounding moves a few edge pixels' samples across an outline, not the image.
    assert!(error.relative_rmse < 0.005, "moved {offset}, the image is {:.4} off", error.relative_rmse);
    for c in 0..3 {
        let ratio = error.mean[c] / error.reference_mean[c];
        assert!((ratio - 1.0).abs() < 2e-3, "channel {c}: mean {ratio} of the one at the origin");
    }
    // The comparison covers the gather: without it (the direct light alone) the image is
    // darker by far more than the tolerance.
    let direct = render_at(&text, "test15_direct", 0).image;
    let share = firstshot::image::image_error(&direct, &near).unwrap();
    eprintln!("the direct light alone: {:?} against {:?}", share.mean, share.reference_mean);
    assert!(share.mean[0] < 0.8 * share.reference_mean[0], "the gather adds little here");
}
