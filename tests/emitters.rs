//! Emitting shapes as first-shot lights (docs/ALGORITHM.md 1, "Emitting shapes"), against
//! oracles that share no code with them: the direct light of a non-planar emitter from the
//! CPU ray caster's integral over its faces, and a closed room lit by an emitting quad
//! against the same room lit by the same quad declared as an area light.

mod common;

use common::ray_caster::{Caster, camera_ray};
use common::scratch::Scratch;
use firstshot::image::{Image, image_error};
use firstshot::render::{RenderOptions, render};
use firstshot::scene::{self, Scene};
use glam::DVec3;

fn load(test: &str, text: &str) -> (Scratch, Scene) {
    common::scenes::load_text("emitters", test, text)
}

/// A floor, a triangle above it and, above both, an emitting pyramid pointing down: four
/// faces that face four different ways, so every point on the emitter has its own normal.
/// The camera does not see the emitter: the oracle's 3 x 3 rays per pixel are too few for
/// the edge of something 50 times brighter than the floor.
const PYRAMID: &str = r#"
format = 1
[camera]
position = [0.0, 2.2, -2.4]
look_at = [0.0, 0.0, 0.2]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
width = 40
height = 40
[settings]
patch_size = 0.5
hemicube_resolution = 512
[materials.grey]
type = "diffuse"
albedo = [0.6, 0.6, 0.6]
[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]
[[shapes]]
type = "quad"
vertices = [[-1.5, 0.0, -1.5], [-1.5, 0.0, 1.5], [1.5, 0.0, 1.5], [1.5, 0.0, -1.5]]
material = "grey"
[[shapes]]
type = "triangle"
vertices = [[-0.4, 0.6, -0.3], [-0.1, 0.7, 0.5], [0.5, 0.55, 0.0]]
material = "grey"
[[shapes]] # apex (0, 1.4, 0), base corners at y = 1.6; each face counter-clockwise from below
type = "triangle"
vertices = [[0.0, 1.4, 0.0], [-0.3, 1.6, -0.3], [0.3, 1.6, -0.3]]
material = "black"
emission = [5.0, 5.0, 5.0]
[[shapes]]
type = "triangle"
vertices = [[0.0, 1.4, 0.0], [0.3, 1.6, -0.3], [0.3, 1.6, 0.3]]
material = "black"
emission = [5.0, 5.0, 5.0]
[[shapes]]
type = "triangle"
vertices = [[0.0, 1.4, 0.0], [0.3, 1.6, 0.3], [-0.3, 1.6, 0.3]]
material = "black"
emission = [5.0, 5.0, 5.0]
[[shapes]]
type = "triangle"
vertices = [[0.0, 1.4, 0.0], [-0.3, 1.6, 0.3], [-0.3, 1.6, -0.3]]
material = "black"
emission = [5.0, 5.0, 5.0]
"#;

/// Direct light toward the camera along one camera ray: the emission of an emitter seen
/// head-on, or the light of `points` (position, normal, radiance times the area it stands
/// for) reflected by a diffuse surface, with the caster's visibility.
fn direct_along(caster: &Caster, scene: &Scene, origin: DVec3, dir: DVec3, points: &[(DVec3, DVec3, f64)]) -> f64 {
    let Some((t, i)) = caster.hit(origin, dir, 1e-9, f64::INFINITY) else { return 0.0 };
    let tri = &caster.tris[i];
    if tri.n.dot(-dir) <= 0.0 {
        return 0.0;
    }
    // The caster's triangles are the surfaces' in order: find the surface for its emission.
    let mut index = i;
    let surface = scene
        .surfaces
        .iter()
        .find(|s| {
            let here = index < s.triangles.len();
            if !here {
                index -= s.triangles.len();
            }
            here
        })
        .unwrap();
    let x = origin + t * dir;
    let mut sum = surface.emission[0] as f64;
    for &(y, normal, weight) in points {
        let to_light = y - x;
        let r2 = to_light.length_squared();
        let w = to_light / r2.sqrt();
        let (cos_x, cos_l) = (tri.n.dot(w), normal.dot(-w));
        if cos_x > 0.0 && cos_l > 0.0 && !caster.occluded(x, y) {
            sum += weight * tri.albedo / std::f64::consts::PI * cos_x * cos_l / r2;
        }
    }
    sum
}

#[test]
fn test01_non_planar_emitter_direct_light_converges_to_the_integral_over_its_faces() {
    let (_scratch, scene) = load("pyramid", PYRAMID);
    let Some(ctx) = common::gpu() else { return };
    let patches = scene::tessellate(&scene, scene.settings.patch_size).unwrap();
    assert_eq!(patches.emitters.len(), 4, "every emitting triangle is a first-shot light");
    let render_direct = |passes: u32| {
        let mut options = RenderOptions::from_scene(&scene);
        options.iterations = 0;
        options.direct_passes = passes;
        render(&ctx, &scene, &patches, &options).unwrap().image
    };
    let (coarse, fine) = (render_direct(4), render_direct(64));
    // Each emitting face as a midpoint rule of 24^2 congruent triangles.
    let caster = Caster::new(&scene);
    let mut points = Vec::new();
    for surface in scene.surfaces.iter().filter(|s| s.emission[0] > 0.0) {
        for t in &surface.triangles {
            let [a, b, c] = t.vertices;
            let normal = (b - a).cross(c - a).normalize();
            for piece in common::split(t.vertices, 24) {
                let [p, q, r] = piece;
                let area = 0.5 * (q - p).cross(r - p).length();
                points.push(((p + q + r) / 3.0, normal, surface.emission[0] as f64 * area));
            }
        }
    }
    let (w, h) = (coarse.width, coarse.height);
    let mut expected = Vec::new();
    for py in 0..h {
        for px in 0..w {
            const N: u32 = 3;
            let mut sum = 0.0;
            for k in 0..N * N {
                let (sx, sy) = (((k % N) as f64 + 0.5) / N as f64, ((k / N) as f64 + 0.5) / N as f64);
                let (o, dir) = camera_ray(&scene.camera, w, h, px as f64 + sx, py as f64 + sy);
                sum += direct_along(&caster, &scene, o, dir, &points);
            }
            expected.push([(sum / (N * N) as f64) as f32; 3]);
        }
    }
    let expected = Image::new(w, h, expected);
    let (e4, e64) =
        (image_error(&coarse, &expected).unwrap().relative_rmse, image_error(&fine, &expected).unwrap().relative_rmse);
    eprintln!("emitting pyramid, relative RMSE against the integral: {e4:.4} after 4 passes, {e64:.4} after 64");
    // The error falls with the passes, to a few per cent (as an area light's, per_pixel test02).
    assert!(e64 < e4 / 2.0 && e64 < 0.03, "{e4} after 4 passes, {e64} after 64");
}

/// A closed room of grey walls lit by a ceiling quad: `LIGHT` is either an area light or an
/// emitting shape with a black material.
fn room(light: &str) -> String {
    format!(
        r#"
format = 1
[camera]
position = [0.5, 0.5, 0.05]
look_at = [0.5, 0.45, 1.0]
up = [0.0, 1.0, 0.0]
fov_y = 80.0
width = 32
height = 32
[settings]
patch_size = 0.25
hemicube_resolution = 64
bundle_resolution = 64
[materials.grey]
type = "diffuse"
albedo = [0.7, 0.5, 0.3]
[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]
[[shapes]]
type = "box"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
material = "grey"
two_sided = true
[[shapes]]
type = "box"
min = [0.55, 0.0, 0.45]
max = [0.8, 0.35, 0.7]
material = "grey"
{light}
"#
    )
}

/// The light quad, facing down, 1e-3 below the ceiling; its diagonal is 0.25 * sqrt(2), so
/// the patch size 0.25 gives the emitting quad's grid 2 x 2, as the area light's.
const QUAD: &str =
    "vertices = [[0.375, 0.999, 0.375], [0.625, 0.999, 0.375], [0.625, 0.999, 0.625], [0.375, 0.999, 0.625]]";

#[test]
fn test02_room_lit_by_an_emitting_quad_converges_like_the_same_area_light() {
    let area = room(&format!("[[lights]]\ntype = \"area\"\n{QUAD}\nradiance = [20.0, 20.0, 20.0]\nsubdivisions = 2\n"));
    let shape =
        room(&format!("[[shapes]]\ntype = \"quad\"\n{QUAD}\nmaterial = \"black\"\nemission = [20.0, 20.0, 20.0]\n"));
    let (_a, area) = load("room_area", &area);
    let (_s, shape) = load("room_shape", &shape);
    let Some(ctx) = common::gpu() else { return };
    let run = |scene: &Scene, first_shot: bool, iterations: u32, seed: u64| {
        let mut options = RenderOptions::from_scene(scene);
        options.first_shot = first_shot;
        options.iterations = iterations;
        options.seed = seed;
        // The area light with the patch-level first bounce that a scene with an emitting
        // shape keeps (docs/ALGORITHM.md 6, "Near senders' first bounce per point"), so that
        // the runs differ only in how the light is represented.
        options.patch_first_bounce = true;
        let patches = scene::tessellate(scene, options.patch_size).unwrap();
        render(&ctx, scene, &patches, &options).unwrap().image
    };
    // The reference: the area light, long, with a seed of its own.
    let reference = run(&area, true, 800, 7);
    let error = |image: &Image| image_error(image, &reference).unwrap();
    let steps = 100;
    let by_area = error(&run(&area, true, steps, 1));
    let by_shape = error(&run(&shape, true, steps, 1));
    let without = error(&run(&shape, false, steps, 1));
    eprintln!(
        "after {steps} steps, against the area light's 800: area light {:.4}, emitting quad {:.4}, emitting quad without first shot {:.4}; means {:?} {:?} {:?}",
        by_area.relative_rmse,
        by_shape.relative_rmse,
        without.relative_rmse,
        by_area.mean_ratio,
        by_shape.mean_ratio,
        without.mean_ratio
    );
    // The emitting quad is as close to the answer as the area light after as many steps...
    assert!(
        by_shape.relative_rmse <= 1.25 * by_area.relative_rmse + 0.005,
        "emitting quad {} against area light {}",
        by_shape.relative_rmse,
        by_area.relative_rmse
    );
    // Both runs draw the same directions (one seed): their means agree far more closely than
    // either agrees with the reference.
    for c in 0..3 {
        assert!((by_shape.mean_ratio[c] - by_area.mean_ratio[c]).abs() < 0.01, "{by_shape:?} {by_area:?}");
    }
    // ...and far closer than without its first shot, what the shape was before.
    assert!(
        without.relative_rmse > 2.0 * by_shape.relative_rmse,
        "without first shot {} against {}",
        without.relative_rmse,
        by_shape.relative_rmse
    );
}

#[test]
fn test03_closed_furnace_of_first_shot_emitters_stays_exact_on_average() {
    // per_pixel test03's furnace (every surface emits 1 and reflects half: the radiance is 2
    // everywhere), now with every surface a first-shot light: the first shot carries the
    // first reflection, the per-pixel direct light the emitters' light at every pixel.
    let text = common::scenes::half_furnace(true);
    let (_scratch, scene) = load("furnace", &text);
    let Some(ctx) = common::gpu() else { return };
    let mut options = RenderOptions::from_scene(&scene);
    options.iterations = 800;
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    assert_eq!(patches.emitters.len(), 2);
    let image = render(&ctx, &scene, &patches, &options).unwrap().image;
    let mean = image.mean();
    let mut errors: Vec<f64> = image.pixels.iter().map(|p| (p[0] as f64 - 2.0).abs()).collect();
    errors.sort_by(f64::total_cmp);
    let (median, p90, worst) = (errors[errors.len() / 2], errors[errors.len() * 9 / 10], errors[errors.len() - 1]);
    eprintln!(
        "furnace of first-shot emitters: mean {mean:?}, pixels off by {median:.3} (median), {p90:.3} (90 %), {worst:.3} (worst)"
    );
    assert!((mean[0] - 2.0).abs() < 0.02, "mean {mean:?}");
    // Near a wall's edge, points on the neighbouring wall are close to x, and 1 / r^2 would
    // make rare points very bright (a pixel was 10 off before the light was shared). The
    // gather and D share the emitting shapes' light (multiple importance sampling), which
    // bounds D's value per pass by 2 pi f Le cos_x <= 2 albedo Le = 1 here.
    assert!(p90 < 0.1, "90 % of the pixels within {p90}");
    assert!(worst < 1.0, "a pixel is off by {worst}");
}
