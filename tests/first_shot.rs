//! First-shot factors against oracles that share no code with them: the exact solid angle
//! of a triangle, closed rooms (every direction hits something), and a CPU ray caster.

mod common;

use common::*;
use firstshot::first_shot::LightWindow;
use glam::DVec3;
use std::f64::consts::PI;

/// r_ij of a point light times 4 pi A_j: the solid angle the patch covers, as measured.
fn measured_solid_angle(table: &[Vec<(u32, f32)>], patches: &firstshot::scene::Patches, j: usize) -> f64 {
    table[j].iter().map(|&(_, r)| r as f64).sum::<f64>() * 4.0 * PI * patches.patches[j].area
}

#[test]
fn test01_unoccluded_triangle_matches_its_solid_angle() {
    let Some(ctx) = gpu() else { return };
    let light = DVec3::new(0.1, -0.2, 0.3);
    // One triangle inside a face, one across the seam of two faces and one across a
    // corner of three; each covers a few thousand pixels at 512.
    let tris = [
        [DVec3::new(0.9, 0.1, 0.0), DVec3::new(1.0, 0.0, 0.3), DVec3::new(1.1, -0.25, -0.05)],
        [DVec3::new(0.35, 0.9, 0.5), DVec3::new(0.6, 0.95, 0.75), DVec3::new(0.75, 0.8, 0.3)],
        [DVec3::new(-0.95, -0.75, 0.75), DVec3::new(-0.7, -1.0, 0.8), DVec3::new(-0.8, -0.9, 1.1)],
    ]
    .map(|t| t.map(|v| v + light));
    // Turn each to face the light.
    let tris: Vec<[DVec3; 3]> = tris
        .iter()
        .map(|t| {
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            if n.dot(light - t[0]) > 0.0 { *t } else { [t[0], t[2], t[1]] }
        })
        .collect();
    let patches = patches_of(&tris, vec![point_sample(light)]);
    let mut errors = Vec::new();
    for resolution in [64, 128, 256, 512, 1024] {
        let table = first_shot_table(&ctx, &patches, resolution, LightWindow::Hemicube);
        let worst = (0..tris.len())
            .map(|j| {
                let exact = solid_angle(light, tris[j]);
                eprintln!("  triangle {j}: exact {exact:.6} measured {:.6}", measured_solid_angle(&table, &patches, j));
                (measured_solid_angle(&table, &patches, j) - exact).abs() / exact
            })
            .fold(0.0, f64::max);
        eprintln!("resolution {resolution}: worst relative error of the solid angle {worst:.5}");
        errors.push(worst);
    }
    // docs/ALGORITHM.md 1: 1% at 512 for triangles of a few hundred pixels, error of order 1/R.
    assert!(errors[3] < 0.01, "error at 512: {}", errors[3]);
    assert!(errors[4] < errors[1] / 2.0, "error does not shrink with resolution: {errors:?}");
}

#[test]
fn test02_point_light_in_a_closed_room_sees_every_direction() {
    let Some(ctx) = gpu() else { return };
    let tris: Vec<_> =
        room(DVec3::new(-1.0, -0.7, -1.3), DVec3::new(1.5, 1.1, 0.9)).into_iter().flat_map(|t| split(t, 4)).collect();
    let patches = patches_of(&tris, vec![point_sample(DVec3::new(0.2, 0.1, -0.3))]);
    let table = first_shot_table(&ctx, &patches, 256, LightWindow::Hemicube);
    let total: f64 = (0..tris.len()).map(|j| measured_solid_angle(&table, &patches, j)).sum();
    // The sum of (4 / R^2) cos^3 over a face is its solid angle up to the midpoint rule's
    // O(1/R^2) error, far below 1e-4 at R = 256.
    assert!((total / (4.0 * PI) - 1.0).abs() < 1e-4, "4 pi sum r A = {total}, expected 4 pi");
}

#[test]
fn test03_area_light_vertex_in_a_closed_room_integrates_the_cosine() {
    let Some(ctx) = gpu() else { return };
    let tris: Vec<_> =
        room(DVec3::new(-1.0, -0.7, -1.3), DVec3::new(1.5, 1.1, 0.9)).into_iter().flat_map(|t| split(t, 3)).collect();
    let normal = DVec3::new(0.3, -1.0, 0.2).normalize();
    let weight = 0.37;
    let sample = firstshot::scene::LightSample {
        position: DVec3::new(0.1, 0.6, -0.2),
        kind: firstshot::scene::SampleKind::AreaVertex { normal },
        strength: [1.0; 3],
        weight,
        light: 0,
    };
    let patches = patches_of(&tris, vec![sample]);
    for window in [LightWindow::Hemicube, LightWindow::Tetrahedron] {
        let table = first_shot_table(&ctx, &patches, 256, window);
        let total: f64 = (0..tris.len())
            .map(|j| table[j].iter().map(|&(_, r)| r as f64).sum::<f64>() * patches.patches[j].area / weight)
            .sum();
        assert!((total / PI - 1.0).abs() < 1e-3, "{window:?}: sum of cos dOmega = {total}, expected pi");
    }
}

/// Whether the segment from `a` to `b` crosses triangle `t` (Moller-Trumbore), the CPU ray
/// caster of the tests.
fn blocked(a: DVec3, b: DVec3, t: [DVec3; 3]) -> bool {
    let d = b - a;
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-14 {
        return false;
    }
    let s = a - t[0];
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let h = e2.dot(q) / det;
    u >= 0.0 && v >= 0.0 && u + v <= 1.0 && h > 1e-9 && h < 1.0 - 1e-9
}

#[test]
fn test04_partly_shadowed_receiver_matches_a_cpu_ray_caster() {
    let Some(ctx) = gpu() else { return };
    let light = DVec3::new(0.0, 2.0, 0.0);
    // A floor facing up, split into patches, and a tilted occluder between it and the light.
    let floor = [
        [DVec3::new(-1.0, 0.0, -1.0), DVec3::new(-1.0, 0.0, 1.0), DVec3::new(1.0, 0.0, 1.0)],
        [DVec3::new(-1.0, 0.0, -1.0), DVec3::new(1.0, 0.0, 1.0), DVec3::new(1.0, 0.0, -1.0)],
    ];
    let occluder = [DVec3::new(-0.5, 1.0, -0.3), DVec3::new(0.6, 1.1, 0.1), DVec3::new(-0.1, 0.9, 0.7)];
    let occluder = if (occluder[1] - occluder[0]).cross(occluder[2] - occluder[0]).y < 0.0 {
        occluder
    } else {
        [occluder[0], occluder[2], occluder[1]]
    };
    let mut tris: Vec<_> = floor.iter().flat_map(|&t| split(t, 4)).collect();
    let receivers = tris.len();
    tris.push(occluder);
    let patches = patches_of(&tris, vec![point_sample(light)]);
    let table = first_shot_table(&ctx, &patches, 512, LightWindow::Hemicube);
    let mut checked = 0;
    for (j, t) in tris.iter().take(receivers).enumerate() {
        // Oracle: solid angle of the visible part = integral over the patch of
        // V cos / r^2, by a 64 x 64 stratified grid of points in barycentric coordinates.
        let (mut visible, mut total) = (0.0, 0.0);
        let k = 64;
        for sub in split(*t, k) {
            let x = (sub[0] + sub[1] + sub[2]) / 3.0;
            let area = 0.5 * (sub[1] - sub[0]).cross(sub[2] - sub[0]).length();
            let to_light = light - x;
            let g = area * to_light.normalize().y / to_light.length_squared();
            total += g;
            if !blocked(x, light, occluder) {
                visible += g;
            }
        }
        let measured = measured_solid_angle(&table, &patches, j);
        let unoccluded = solid_angle(light, *t);
        // The grid's own error is ~1/k of the shadow edge's share; the item buffer's is a
        // few pixels along the edge. 2% of the unoccluded solid angle covers both.
        let tolerance = 0.02 * unoccluded;
        assert!(
            (measured - visible).abs() < tolerance,
            "patch {j}: measured {measured:.6}, ray caster {visible:.6} (unoccluded {total:.6})"
        );
        if visible < 0.9 * total && visible > 0.1 * total {
            checked += 1;
        }
    }
    assert!(checked >= 2, "the occluder must put some patches in partial shadow, got {checked}");
}

#[test]
fn test05_automatic_resolution_makes_the_median_patch_its_pixels_across() {
    use firstshot::first_shot::{AUTO_RESOLUTION_MAX, AUTO_RESOLUTION_MIN, PIXELS_PER_PATCH, auto_resolution};
    use firstshot::scene::SampleKind;
    // A quad of side 2 at y = 0, cut into two triangles of area 2, and a light straight
    // above its centre at height h: each triangle's centroid lies at (1/3, 0, -1/3) or
    // (-1/3, 0, 1/3), so q = sqrt(h^2 + 2/9) / sqrt(2) for both, and a face of R pixels
    // shows a patch R / (2 q) pixels across: R = 2 * 1.5 * q, up to a multiple of 16.
    let quad = |s: f64| {
        [
            [DVec3::new(-1.0, 0.0, -1.0), DVec3::new(-1.0, 0.0, 1.0), DVec3::new(1.0, 0.0, 1.0)],
            [DVec3::new(-1.0, 0.0, -1.0), DVec3::new(1.0, 0.0, 1.0), DVec3::new(1.0, 0.0, -1.0)],
        ]
        .map(|t| t.map(|v| v * s))
    };
    let at = |h: f64, s: f64| auto_resolution(&patches_of(&quad(s), vec![point_sample(DVec3::new(0.0, h, 0.0) * s)]));
    assert_eq!(PIXELS_PER_PATCH, 1.5, "the figures below are for 1.5 pixels");
    // h = 100: q = 70.712, 2 * 1.5 * q = 212.1 -> 224.
    assert_eq!(at(100.0, 1.0), 224);
    // Only the ratio of distance to patch size counts: the same scene 7 times larger.
    assert_eq!(at(100.0, 7.0), 224);
    // Twice as far: q = 141.42, 424.3 -> 432.
    assert_eq!(at(200.0, 1.0), 432);
    // Near (q = 7.08, 21.2) and far (q = 707, 2121): the bounds.
    assert_eq!(at(10.0, 1.0), AUTO_RESOLUTION_MIN);
    assert_eq!(at(1000.0, 1.0), AUTO_RESOLUTION_MAX);
    // The sample that needs most sets it: the far light of the two.
    let both = vec![point_sample(DVec3::new(0.0, 100.0, 0.0)), point_sample(DVec3::new(0.0, 200.0, 0.0))];
    assert_eq!(auto_resolution(&patches_of(&quad(1.0), both)), 432);
    // An area-light sample counts only the patches in front of it: facing up, away from
    // the quad, it sees none and asks for the least; facing down, as the point light.
    let area = |normal: DVec3| {
        let mut s = point_sample(DVec3::new(0.0, 100.0, 0.0));
        s.kind = SampleKind::AreaVertex { normal };
        auto_resolution(&patches_of(&quad(1.0), vec![s]))
    };
    assert_eq!(area(DVec3::Y), AUTO_RESOLUTION_MIN);
    assert_eq!(area(-DVec3::Y), 224);
    // A sun's parallel view of 4 R pixels spans the bounding sphere's diameter, 2 sqrt(2)
    // here (the quad's corners): a triangle of the quad cut into 256^2, area 2 / 65536,
    // is sqrt(2) / 256 across, 4 R / (2 sqrt(2)) * sqrt(2) / 256 = R / 128 pixels: 1.5
    // pixels at R = 192.
    let fine: Vec<[DVec3; 3]> = quad(1.0).iter().flat_map(|&t| split(t, 256)).collect();
    let mut sun = point_sample(DVec3::ZERO);
    sun.kind = SampleKind::Directional { direction: -DVec3::Y };
    assert_eq!(auto_resolution(&patches_of(&fine, vec![sun])), 192);
}

#[test]
fn test06_a_render_without_a_hemicube_resolution_takes_the_automatic_one() {
    use firstshot::render::{RenderOptions, render};
    let Some(ctx) = gpu() else { return };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.toml");
    let scene = firstshot::scene::load(&path).unwrap();
    assert_eq!(scene.settings.hemicube_resolution, None, "the Cornell box leaves it to the rule");
    let mut options = RenderOptions::from_scene(&scene);
    (options.iterations, options.width, options.height, options.direct_passes) = (0, 16, 16, 1);
    let patches = firstshot::scene::tessellate(&scene, options.patch_size).unwrap();
    let auto = firstshot::first_shot::auto_resolution(&patches);
    assert!(auto.is_multiple_of(16) && (64..=1024).contains(&auto), "{auto}");
    let stats = render(&ctx, &scene, &patches, &options).unwrap().stats;
    assert_eq!(stats.hemicube_resolution, auto);
    // Asked for, it is taken as given.
    options.hemicube_resolution = Some(48);
    assert_eq!(render(&ctx, &scene, &patches, &options).unwrap().stats.hemicube_resolution, 48);
}

/// The rasterising stages draw a source triangle cut into a k x k lattice once per side and
/// find each fragment's patch on the lattice (`scene_buffers::raster_triangles`,
/// `lattice_patch`). Measured through the first shot's item buffers, every patch of a
/// tessellated two-sided quad must get its own exact solid angle, and its back twin, which
/// faces away from the light, none: a patch index off by one row, one step or one side would
/// give a neighbour's solid angle, or the twin's.
#[test]
fn test07_lattice_patches_each_get_their_own_solid_angle() {
    let Some(ctx) = gpu() else { return };
    let text = r#"
format = 1
[materials.grey]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]
[[shapes]]
type = "quad"
vertices = [[-1.0, -0.8, 1.4], [1.2, -1.0, 1.6], [1.0, 1.1, 1.2], [-1.2, 1.3, 1.0]]
material = "grey"
two_sided = true
[[lights]]
type = "point"
position = [0.1, 0.05, -0.2]
power = [1.0, 1.0, 1.0]
[camera]
position = [0.0, 0.0, -3.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
width = 16
height = 16
"#;
    let scene = firstshot::scene::load::load_str(text, std::path::Path::new("lattice.toml")).unwrap();
    let patches = firstshot::scene::tessellate(&scene, 0.45).unwrap();
    assert!(
        !patches.lattices.is_empty() && patches.lattices.iter().all(|l| l.k >= 5 && l.sides == 2),
        "the quad's triangles should be lattices with twins: {:?}",
        patches.lattices.iter().map(|l| (l.k, l.sides)).collect::<Vec<_>>()
    );
    let raster = firstshot::gpu::scene_buffers::raster_triangles(&patches);
    assert_eq!(raster.triangle_count() as usize, 2 * patches.lattices.len(), "one triangle a lattice and side");
    let light = patches.samples[0].position;
    let table = first_shot_table(&ctx, &patches, 512, LightWindow::Hemicube);
    let (mut worst, mut total, mut exact_total) = (0.0f64, 0.0, 0.0);
    for (j, p) in patches.patches.iter().enumerate() {
        let measured = measured_solid_angle(&table, &patches, j);
        if p.normal.dot(light - p.vertices[0]) < 0.0 {
            assert_eq!(measured, 0.0, "patch {j} faces away from the light but got {measured}");
            continue;
        }
        let exact = solid_angle(light, p.vertices);
        worst = worst.max((measured - exact).abs() / exact);
        (total, exact_total) = (total + measured, exact_total + exact);
    }
    eprintln!("{} patches: worst relative error {worst:.4}, sum {total:.5} of {exact_total:.5}", patches.patches.len());
    // Each patch covers 1 500-4 000 pixels at 512; test01's 1 % for whole triangles of a few
    // hundred pixels, and 3 % for the pixels along the edges the patches share.
    assert!(worst < 0.03, "worst relative error of a patch's solid angle: {worst}");
    assert!((total / exact_total - 1.0).abs() < 2e-3, "sum {total} against {exact_total}");
}
