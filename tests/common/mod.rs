//! Helpers shared by the integration tests: the GPU, temporary folders (`scratch`), scene
//! text (`scenes`), running the binary (`bin`), hand-made patches.
#![allow(dead_code)]

pub mod bin;
pub mod gltf_writer;
pub mod ray_caster;
pub mod scenes;
pub mod scratch;
pub mod shards;

use firstshot::gpu::{AdapterChoice, Context};
use std::path::PathBuf;

/// The mean of per-seed results and their sample standard deviation (n - 1): the spread
/// from which the seed-averaged tests take their tolerances.
pub fn mean_and_spread(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let spread = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    (mean, spread)
}

/// Form factor from a differential area at `x` with normal `n` to a polygon (Lambert's
/// contour formula), the tests' own oracle.
pub fn point_to_polygon(x: DVec3, n: DVec3, polygon: &[DVec3]) -> f64 {
    let mut sum = 0.0;
    for i in 0..polygon.len() {
        let a = (polygon[i] - x).normalize();
        let b = (polygon[(i + 1) % polygon.len()] - x).normalize();
        let angle = a.dot(b).clamp(-1.0, 1.0).acos();
        let c = a.cross(b);
        if c.length() > 0.0 {
            sum += angle * n.dot(c.normalize());
        }
    }
    (sum / (2.0 * std::f64::consts::PI)).abs()
}

/// max-Phong as SCENE_FORMAT.md writes it (one channel), the tests' own reading,
/// written apart from `scene::brdf`.
pub fn max_phong(kd: f64, ks: f64, shininess: f64, n: DVec3, w_in: DVec3, w_out: DVec3) -> f64 {
    let (cos_in, cos_out) = (n.dot(w_in), n.dot(w_out));
    if cos_in <= 0.0 || cos_out <= 0.0 {
        return 0.0;
    }
    let mirror = 2.0 * cos_in * n - w_in;
    kd / std::f64::consts::PI + ks * mirror.dot(w_out).max(0.0).powf(shininess) / cos_in.max(cos_out)
}

/// The adapter GPU tests open: `FIRSTSHOT_TEST_ADAPTER` (as `--adapter` takes it), else auto.
pub fn test_adapter() -> AdapterChoice {
    std::env::var("FIRSTSHOT_TEST_ADAPTER").map(|s| s.parse().unwrap()).unwrap_or(AdapterChoice::Auto)
}

/// The one way tests get a GPU. With `FIRSTSHOT_REQUIRE_GPU=1` (CI) a missing adapter is a
/// failure; with `FIRSTSHOT_REQUIRE_BACKEND=vulkan` so is an adapter of another backend.
/// Elsewhere a missing adapter is a visible skip.
pub fn gpu() -> Option<Context> {
    match Context::new(&test_adapter()) {
        Ok(ctx) => {
            if let Ok(backend) = std::env::var("FIRSTSHOT_REQUIRE_BACKEND") {
                assert!(
                    ctx.summary.backend.eq_ignore_ascii_case(&backend),
                    "FIRSTSHOT_REQUIRE_BACKEND={backend} but the test adapter is {}",
                    ctx.summary
                );
            }
            eprintln!("GPU test on adapter: {}", ctx.summary);
            Some(ctx)
        }
        Err(e) => {
            if std::env::var("FIRSTSHOT_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("FIRSTSHOT_REQUIRE_GPU=1 but no adapter: {e}");
            }
            eprintln!("SKIPPED (no GPU adapter): {e}");
            None
        }
    }
}

/// `target/test-output/<name>`, created; failing image tests write their images there.
pub fn output_dir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-output").join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `refs/` in the repository: the Mitsuba 3 reference images (how each was made: `refs/README.md`).
pub fn refs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("refs")
}

#[path = "../../benches/harness/mitsuba.rs"]
pub mod mitsuba;

/// The Python with Mitsuba 3 (`tools/mitsuba/setup.sh` makes it). With
/// `FIRSTSHOT_REQUIRE_MITSUBA=1` (CI) a missing one is a failure, elsewhere a visible skip.
pub fn mitsuba_python() -> Option<mitsuba::Python> {
    match mitsuba::find_python() {
        Ok(p) => {
            eprintln!("Mitsuba {} through {}", p.mitsuba_version, p.path.display());
            Some(p)
        }
        Err(e) => {
            if std::env::var("FIRSTSHOT_REQUIRE_MITSUBA").is_ok_and(|v| v == "1") {
                panic!("FIRSTSHOT_REQUIRE_MITSUBA=1 but {e}");
            }
            eprintln!("SKIPPED (no Mitsuba): {e}");
            None
        }
    }
}

/// `xvfb-run` (Debian's xvfb), which the viewer's tests (tests/viewer.rs) open their windows
/// under: a virtual X display. With `FIRSTSHOT_REQUIRE_DISPLAY=1` (CI) a missing one is a
/// failure, elsewhere a visible skip.
pub fn xvfb_run() -> Option<PathBuf> {
    let found = std::env::var_os("PATH")
        .map(|paths| std::env::split_paths(&paths).map(|p| p.join("xvfb-run")).find(|p| p.is_file()));
    match found.flatten() {
        Some(path) => Some(path),
        None => {
            if std::env::var("FIRSTSHOT_REQUIRE_DISPLAY").is_ok_and(|v| v == "1") {
                panic!("FIRSTSHOT_REQUIRE_DISPLAY=1 but no xvfb-run on PATH: apt-get install xvfb xauth");
            }
            eprintln!("SKIPPED (no xvfb-run on PATH; apt-get install xvfb xauth)");
            None
        }
    }
}

use firstshot::scene::{LightSample, Patch, PatchKind, Patches};
use glam::DVec3;

/// A one-sided black patch from three vertices (counter-clockwise from the front).
pub fn patch(v: [DVec3; 3]) -> Patch {
    let c = (v[1] - v[0]).cross(v[2] - v[0]);
    Patch {
        vertices: v,
        normal: c.normalize(),
        area: 0.5 * c.length(),
        material: None,
        emission: [0.0; 3],
        kind: PatchKind::Surface { surface: 0 },
        twin: false,
    }
}

/// Splits a triangle into k^2 congruent ones (the test's own tessellation).
pub fn split(v: [DVec3; 3], k: u32) -> Vec<[DVec3; 3]> {
    let p = |i: u32, j: u32| v[0] + (v[1] - v[0]) * (i as f64 / k as f64) + (v[2] - v[0]) * (j as f64 / k as f64);
    let mut out = Vec::new();
    for i in 0..k {
        for j in 0..k - i {
            out.push([p(i, j), p(i + 1, j), p(i, j + 1)]);
            if i + j + 1 < k {
                out.push([p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
    }
    out
}

/// The 12 triangles of an axis-aligned box, fronts facing inward (a closed room).
pub fn room(lo: DVec3, hi: DVec3) -> Vec<[DVec3; 3]> {
    let c = |x: usize, y: usize, z: usize| DVec3::new([lo.x, hi.x][x], [lo.y, hi.y][y], [lo.z, hi.z][z]);
    let quads = [
        [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], // floor, normal +y
        [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)], // ceiling, -y
        [c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], // x = lo, +x
        [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)], // x = hi, -x
        [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], // z = lo, +z
        [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)], // z = hi, -z
    ];
    let centre = (lo + hi) * 0.5;
    let mut out = Vec::new();
    for q in quads {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            out.push(if n.dot(centre - t[0]) > 0.0 { t } else { [t[0], t[2], t[1]] });
        }
    }
    out
}

pub fn point_sample(position: DVec3) -> LightSample {
    LightSample { position, kind: firstshot::scene::SampleKind::Point, strength: [1.0; 3], weight: 1.0, light: 0 }
}

pub fn patches_of(triangles: &[[DVec3; 3]], samples: Vec<LightSample>) -> Patches {
    Patches { patches: triangles.iter().map(|&t| patch(t)).collect(), samples, ..Default::default() }
}

/// Solid angle of a triangle seen from `p` (Van Oosterom and Strackee, 1983).
pub fn solid_angle(p: DVec3, t: [DVec3; 3]) -> f64 {
    let (a, b, c) = (t[0] - p, t[1] - p, t[2] - p);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c)).abs();
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// A scene with a default camera and nothing else, for tests that bring their own patches.
pub fn bare_scene() -> firstshot::scene::Scene {
    let camera = firstshot::scene::Camera {
        position: DVec3::new(0.0, 0.0, -5.0),
        look_at: DVec3::ZERO,
        up: DVec3::Y,
        fov_y: 40.0,
        width: 32,
        height: 32,
    };
    firstshot::scene::Scene {
        source: "test".into(),
        camera,
        cameras: vec![firstshot::scene::NamedCamera { name: "camera".into(), camera }],
        environment: [0.0; 3],
        settings: firstshot::scene::Settings::default(),
        materials: vec![],
        surfaces: vec![],
        lights: vec![],
        notes: vec![],
        file_origin: glam::DVec3::ZERO,
    }
}

/// Runs the first shot over hand-made patches and returns the table by patch.
pub fn first_shot_table(
    ctx: &firstshot::gpu::Context,
    patches: &Patches,
    resolution: u32,
    window: firstshot::first_shot::LightWindow,
) -> Vec<Vec<(u32, f32)>> {
    let scene = bare_scene();
    let mut buffers = firstshot::gpu::scene_buffers::SceneBuffers::new(&ctx.device, &scene, patches, true);
    firstshot::first_shot::run(ctx, &mut buffers, patches, resolution, window).unwrap();
    firstshot::first_shot::read_table(ctx, &buffers).unwrap()
}

/// The direct-light image of `scene` (`--iterations 0`) after `passes` passes, at the
/// scene's own settings; `None` without a GPU (see `gpu`).
pub fn render_direct(scene: &firstshot::scene::Scene, passes: u32) -> Option<firstshot::image::Image> {
    let ctx = gpu()?;
    let mut options = firstshot::render::RenderOptions::from_scene(scene);
    options.iterations = 0;
    options.direct_passes = passes;
    let patches = firstshot::scene::tessellate(scene, options.patch_size).unwrap();
    Some(firstshot::render::render(&ctx, scene, &patches, &options).unwrap().image)
}

/// The form-factor scene of tests/iteration.rs test02: an emitting square (radiance 1, black)
/// in z = 0 and, facing it at z = 0.4, one white receiving triangle (albedo 1), seen from
/// halfway by a 16 x 16 camera whose centre 4 x 4 pixels show the receiver alone; and the
/// oracle they converge to, the point-to-square form factor averaged over 8 x 8 points of
/// each of those pixels (their camera samples are uniform in the pixel), where their camera
/// rays meet the receiver's plane. `extra`: more triangles, each with its material, which
/// the scene's materials get after black and white.
pub struct FormFactorScene {
    pub scene: firstshot::scene::Scene,
    pub patches: Patches,
    pub form_factor: f64,
}

pub fn form_factor_scene(extra: &[([DVec3; 3], firstshot::scene::Material)]) -> FormFactorScene {
    use firstshot::scene::{Material, MaterialKind};
    let h = 0.4;
    let square = [
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(1.0, -1.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(-1.0, 1.0, 0.0),
    ];
    let receiver = [DVec3::new(-0.3, -0.2, h), DVec3::new(0.1, 0.35, h), DVec3::new(0.35, -0.25, h)];
    let mut scene = bare_scene();
    scene.camera.position = DVec3::new(0.02, 0.01, h / 2.0);
    scene.camera.look_at = DVec3::new(0.02, 0.01, h);
    scene.camera.fov_y = 60.0;
    scene.camera.width = 16;
    scene.camera.height = 16;
    scene.materials = vec![
        Material { name: "black".into(), kind: MaterialKind::Diffuse { albedo: [0.0; 3] } },
        Material { name: "white".into(), kind: MaterialKind::Diffuse { albedo: [1.0; 3] } },
    ];
    scene.materials.extend(extra.iter().map(|(_, m)| m.clone()));
    let facing = |t: [DVec3; 3], towards: DVec3| {
        if (t[1] - t[0]).cross(t[2] - t[0]).dot(towards) > 0.0 { t } else { [t[0], t[2], t[1]] }
    };
    let mut triangles = vec![
        facing([square[0], square[1], square[2]], DVec3::Z),
        facing([square[0], square[2], square[3]], DVec3::Z),
        facing(receiver, -DVec3::Z),
    ];
    triangles.extend(extra.iter().map(|(t, _)| *t));
    let mut patches = patches_of(&triangles, vec![]);
    for p in &mut patches.patches[..2] {
        p.material = Some(0);
        p.emission = [1.0; 3];
    }
    for (i, p) in patches.patches[2..].iter_mut().enumerate() {
        p.material = Some(1 + i as u32);
    }
    let points: Vec<DVec3> = (6..10)
        .flat_map(|y| (6..10).flat_map(move |x| ray_caster::pixel_grid(x, y, 8)))
        .map(|(px, py)| {
            let (o, d) = ray_caster::camera_ray(&scene.camera, 16, 16, px, py);
            o + d * ((h - o.z) / d.z)
        })
        .collect();
    // Inside the receiver: on the same side of each of its edges (in its plane z = h).
    let inside = |p: DVec3| {
        let side = |a: DVec3, b: DVec3| (b - a).truncate().perp_dot((p - a).truncate());
        let s = [side(receiver[0], receiver[1]), side(receiver[1], receiver[2]), side(receiver[2], receiver[0])];
        (p.z - h).abs() < 1e-9 && (s.iter().all(|&v| v > 0.0) || s.iter().all(|&v| v < 0.0))
    };
    assert!(points.iter().all(|&p| inside(p)), "the centre pixels see the receiver");
    let form_factor =
        points.iter().map(|&p| point_to_polygon(p, -DVec3::Z, &square)).sum::<f64>() / points.len() as f64;
    FormFactorScene { scene, patches, form_factor }
}

/// The mean of the first channel over the centre 4 x 4 pixels of a 16 x 16 image (what
/// `form_factor_scene`'s oracle is for).
pub fn centre_mean(image: &firstshot::image::Image) -> f64 {
    let centre: Vec<f64> =
        (6..10).flat_map(|y| (6..10).map(move |x| (x, y))).map(|(x, y)| image.at(x, y)[0] as f64).collect();
    centre.iter().sum::<f64>() / centre.len() as f64
}

/// How image `a` differs from image `b` of the same size, pixel by pixel over every channel:
/// the relative RMSE (the RMS of a - b over the RMS of b), the ratio of their means, and b's
/// mean.
pub struct Difference {
    pub relative_rmse: f64,
    pub ratio_of_means: f64,
    pub reference_mean: f64,
}

pub fn difference(a: &firstshot::image::Image, b: &firstshot::image::Image) -> Difference {
    assert_eq!((a.width, a.height), (b.width, b.height), "images of different sizes");
    let (mut num, mut den, mut sum_a, mut sum_b) = (0.0, 0.0, 0.0, 0.0);
    for (x, y) in a.pixels.iter().flatten().zip(b.pixels.iter().flatten()) {
        let (x, y) = (*x as f64, *y as f64);
        num += (x - y).powi(2);
        den += y * y;
        sum_a += x;
        sum_b += y;
    }
    let count = (3 * b.pixels.len()).max(1) as f64;
    Difference { relative_rmse: (num / den).sqrt(), ratio_of_means: sum_a / sum_b, reference_mean: sum_b / count }
}
