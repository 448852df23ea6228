//! Hostile input: each a clear refusal or a working render, never a panic or an abort.

mod common;

use common::bin::firstshot;
use common::scratch::Scratch;
use firstshot::scene;

const HEAD: &str = r#"format = 1
[camera]
position = [0.5, 0.5, 3.0]
look_at = [0.5, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 50.0
width = 24
height = 24
[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]
"#;

#[test]
fn test01_million_vertex_mesh_loads_and_tessellates() {
    let dir = Scratch::new("hostile", "mesh");
    // A 1000 x 1000 vertex grid: a million vertices, two million triangles.
    let n = 1000;
    let mut obj = String::with_capacity(40 * n * n);
    for j in 0..n {
        for i in 0..n {
            obj.push_str(&format!("v {} {} 0\n", i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64));
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i + 1;
            obj.push_str(&format!("f {} {} {} {}\n", a, a + 1, a + n + 1, a + n));
        }
    }
    std::fs::write(dir.join("grid.obj"), obj).unwrap();
    let text = format!(
        "{HEAD}[[shapes]]\ntype = \"mesh\"\nfile = \"grid.obj\"\nmaterial = \"white\"\nemission = [1.0, 1.0, 1.0]\n"
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = scene::load(&path).unwrap();
    let patches = scene::tessellate(&scene, 1.0).unwrap();
    assert_eq!(patches.patches.len(), 2 * (n - 1) * (n - 1));
}

/// Runs the binary on a scene; it must exit 0 (rendered) or 2 (refused), never crash.
fn survives(name: &str, shapes: &str, extra: &[&str]) -> (i32, String) {
    let dir = Scratch::new("hostile", name);
    let path = dir.join("scene.toml");
    std::fs::write(&path, format!("{HEAD}{shapes}")).unwrap();
    let out = firstshot()
        .arg(&path)
        .args(["--quiet", "--iterations", "3", "--bundle-resolution", "32", "--hemicube-resolution", "32"])
        .args(extra)
        .arg("--out")
        .arg(dir.join("x.exr"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    let code = out.status.code().unwrap_or(-1);
    assert!(code == 0 || code == 2, "{name}: exit {code} (a crash?): {stderr}");
    assert!(!stderr.contains("panicked"), "{name}: {stderr}");
    (code, stderr)
}

#[test]
fn test02_extreme_numbers_render_or_are_refused() {
    if common::gpu().is_none() {
        return;
    }
    let quad = |scale: &str| {
        format!(
            "[[shapes]]\ntype = \"quad\"\nvertices = [[0,0,0],[{s},0,0],[{s},{s},0],[0,{s},0]]\nmaterial = \"white\"\nemission = [1,1,1]\n",
            s = scale
        )
    };
    survives("huge", &quad("1e30"), &[]);
    survives("tiny", &quad("1e-30"), &[]);
    survives("huge-emission", &quad("1").replace("emission = [1,1,1]", "emission = [3e38, 3e38, 3e38]"), &[]);
    let (code, _) = survives(
        "level50",
        "[[shapes]]\ntype = \"sierpinski\"\nlevel = 50\nmaterial = \"white\"\nemission = [1,1,1]\n",
        &[],
    );
    assert_eq!(code, 2);
    let (code, _) = survives("zero-width", &quad("1"), &["--width", "0"]);
    assert_eq!(code, 2);
    let (code, stderr) = survives("too-many-patches", &quad("1"), &["--patch-size", "1e-5"]);
    assert_eq!(code, 2, "{stderr}");
}

/// A camera a tenth of a unit from a glowing unit square in a scene 100 000 units across (a far
/// backdrop): 2e-6 of the scene's radius, which the camera's near distance (1e-5 radii before
/// 2026-11-30) cut off, rendering the square black. Now it is in the image; and nearer than
/// the near distance, 2^-20 radii (where single-precision positions cannot tell the square from
/// the eye), the render says so instead of dropping it without a word.
#[test]
fn test03_a_surface_near_the_camera_in_a_large_scene_is_seen_or_named() {
    if common::gpu().is_none() {
        return;
    }
    let render = |distance: f64| {
        let dir = Scratch::new("hostile", &format!("near-{}", (distance * 1000.0) as u32));
        let camera = HEAD.replace("position = [0.5, 0.5, 3.0]", &format!("position = [0.5, 0.5, {distance}]"));
        assert_ne!(camera, HEAD);
        let text = format!(
            "{camera}[[shapes]]\ntype = \"quad\"\nvertices = [[0,0,0],[1,0,0],[1,1,0],[0,1,0]]\nmaterial = \"white\"\n\
             emission = [1,1,1]\n[[shapes]]\ntype = \"quad\"\nvertices = [[0,0,-1e5],[0,1,-1e5],[1,1,-1e5],[1,0,-1e5]]\n\
             material = \"white\"\n"
        );
        let path = dir.join("scene.toml");
        std::fs::write(&path, text).unwrap();
        let (exr, stats) = (dir.join("x.exr"), dir.join("x.json"));
        let out = firstshot()
            .arg(&path)
            .args(["--quiet", "--iterations", "2", "--out"])
            .arg(&exr)
            .arg("--stats")
            .arg(&stats)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        let notes: Vec<String> =
            stats["notes"].as_array().unwrap().iter().map(|n| n.as_str().unwrap().to_string()).collect();
        (firstshot::image::Image::read_exr(&exr).unwrap().mean()[0], notes)
    };
    // The square fills the view (tan 25 degrees * 0.1 < 0.5), so every pixel sees its
    // emission: 1, plus nothing it could reflect.
    let (seen, notes) = render(0.1);
    assert!((seen - 1.0).abs() < 1e-3, "mean {seen}, expected the square's emission 1");
    assert!(notes.iter().all(|n| !n.contains("nearer than")), "{notes:?}");
    // 0.01 is under 2^-20 of the radius (0.048): cut off, and said.
    let (_, notes) = render(0.01);
    assert!(notes.iter().any(|n| n.contains("camera \"camera\"") && n.contains("nearer than")), "{notes:?}");
}

/// Light transport has no length scale: the same scene in units 2^k times smaller (every
/// length times 2^k, a point light's power times 4^k) is the same image, and with powers of two
/// the same to the bit. That holds across the sizes the loader accepts
/// (`scene::EXTENT_RANGE`); beyond them f32 products of lengths overflow or vanish, and the
/// loader refuses the scene, naming the range and the fix, instead of rendering it black or
/// with NaN pixels (a glowing quad 1e30 across did, 2026-11-30).
#[test]
fn test04_a_scene_in_other_units_is_the_same_image_or_refused() {
    let text = std::fs::read_to_string(common::scenes::shipped("cornell_point")).unwrap();
    let dir = Scratch::new("hostile", "units");
    let load = |factor: f64| {
        let path = dir.join(format!("scene_{}.toml", factor.log2()));
        std::fs::write(&path, common::scenes::scaled(&text, factor)).unwrap();
        scene::load(&path)
    };
    let message = |factor: f64| load(factor).map(|_| ()).unwrap_err().to_string();
    // cornell_point's radius is about 500: 2^-34 of it is 2.9e-8, 2^25 1.7e10.
    for factor in [2f64.powi(-34), 2f64.powi(25)] {
        let e = message(factor);
        assert!(e.contains("shapes, lights") && e.contains("radius 1e-7 to 1e10") && e.contains("power"), "{e}");
    }
    let far = text.replace("position = [278.0, 273.0, -800.0]", "position = [278.0, 273.0, -2e10]");
    assert_ne!(far, text, "the test's camera line");
    std::fs::write(dir.join("far.toml"), &far).unwrap();
    let e = scene::load(&dir.join("far.toml")).map(|_| ()).unwrap_err().to_string();
    assert!(e.contains("camera.position") && e.contains("1e10"), "{e}");

    let Some(ctx) = common::gpu() else { return };
    let render = |factor: f64| {
        let scene = load(factor).unwrap();
        let mut options = firstshot::render::RenderOptions::from_scene(&scene);
        (options.width, options.height, options.iterations, options.direct_passes) = (32, 32, 4, 2);
        (options.hemicube_resolution, options.bundle_resolution, options.shadow_resolution) =
            (Some(64), Some(64), Some(128));
        let patches = scene::tessellate(&scene, options.patch_size).unwrap();
        firstshot::render::render(&ctx, &scene, &patches, &options).unwrap().image
    };
    let reference = render(1.0);
    assert!(reference.mean()[0] > 0.0);
    // Near both ends of the range: radius 1.2e-7, and 4.2e9 with the camera 9e9 from it.
    for k in [-22, 23] {
        let image = render(2f64.powi(k));
        let error = firstshot::image::image_error(&image, &reference).unwrap();
        assert!(error.relative_rmse < 1e-6, "in units 2^{k} smaller: {:.2e} off", error.relative_rmse);
    }
}
