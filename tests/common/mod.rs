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
