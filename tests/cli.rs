//! The `firstshot` binary against CLI.md: exit statuses, what is (and is not) written, the
//! `--stats` keys, `--list-adapters` and `compare`. Each test runs the built binary in a
//! temporary folder of its own.

mod common;

use common::bin::{firstshot_in, stderr, stdout};
use common::scenes::{MINIMAL, edited};
use common::scratch::{Scratch, listing};
use firstshot::image::Image;
use std::path::Path;
use std::process::Output;

fn firstshot(args: &[&str]) -> Output {
    firstshot_in(&std::env::temp_dir(), args)
}

fn cornell_box() -> String {
    common::scenes::shipped("cornell_box").display().to_string()
}

/// Runs `args` with `--out <empty folder>/<out> --stats <empty folder>/s.json`, in that
/// folder, and checks a refusal: exit status 2, nothing written, nothing on stdout. Returns
/// stderr.
fn refused_render(scratch: &Scratch, args: &[&str], out: &str) -> String {
    let dir = scratch.dir("out");
    let exr = dir.join(out).display().to_string();
    let stats = dir.join("s.json").display().to_string();
    let mut all = args.to_vec();
    all.extend_from_slice(&["--out", &exr, "--stats", &stats]);
    let o = firstshot_in(&dir, &all);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{all:?}: expected exit status 2; stderr:\n{err}");
    assert_eq!(listing(&dir), Vec::<String>::new(), "{all:?} wrote files; stderr:\n{err}");
    assert_eq!(stdout(&o), "", "{all:?} printed to stdout");
    err
}

/// Asserts that `err` is one line that names `file` and `key`.
fn one_line_naming(err: &str, file: &Path, key: &str) {
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "stderr is not one line:\n{err}");
    assert!(err.contains(&file.display().to_string()), "stderr does not name {}: {err}", file.display());
    assert!(err.contains(key), "stderr does not name the key {key:?}: {err}");
}

#[test]
fn test01_scene_refusals_exit_2_name_file_and_key_and_write_nothing() {
    let scratch = Scratch::new("cli", "scene-refusals");
    let area_light = "[[lights]]\ntype = \"area\"\nvertices = [[0, 2, 0], [1, 2, 0], [1, 2.5, 1], [0, 2, 1]]\n\
                      radiance = [1, 1, 1]\n";
    let sierpinski = "[[shapes]]\ntype = \"sierpinski\"\ncenter = [0, 0, 0]\nsize = 1\nlevel = 50\n\
                      material = \"white\"\n";
    let hot = "[materials.hot]\ntype = \"phong\"\ndiffuse = [0, 0, 0]\nspecular = [1, 1, 1]\nshininess = 3\n";
    let mesh = "[[shapes]]\ntype = \"mesh\"\nfile = \"meshes/nowhere.obj\"\nmaterial = \"white\"\n\n[[shapes]]";
    let no_lights = MINIMAL.split("[[lights]]").next().expect("MINIMAL has lights").to_string();
    let no_shapes = MINIMAL.split("[[shapes]]").next().expect("MINIMAL has shapes").to_string()
        + "[[lights]]\ntype = \"point\"\nposition = [0, 3, 0]\npower = [10, 10, 10]\n";
    let no_camera = {
        let (head, rest) = MINIMAL.split_once("[camera]").expect("MINIMAL has a camera");
        head.to_string() + &rest[rest.find("[materials").expect("materials follow the camera")..]
    };
    // (what, scene text, key, a part of the message)
    let cases: Vec<(&str, String, &str, &str)> = vec![
        ("unknown key", format!("colour = 1\n{MINIMAL}"), "colour", "unknown key"),
        ("missing [camera]", no_camera, "camera", "required"),
        (
            "negative colour",
            edited(&[("albedo = [0.5, 0.5, 0.5]", "albedo = [0.5, -0.5, 0.5]")]),
            "materials.white.albedo",
            ">= 0",
        ),
        ("nan", edited(&[("position = [0, 1, -5]", "position = [0, nan, -5]")]), "camera.position[1]", "finite"),
        ("inf", edited(&[("power = [10, 10, 10]", "power = [inf, 10, 10]")]), "lights[0].power[0]", "finite"),
        ("unknown material", edited(&[("material = \"white\"", "material = \"whte\"")]), "shapes[0].material", "whte"),
        ("missing mesh file", edited(&[("[[shapes]]", mesh)]), "shapes[0].file", "nowhere.obj"),
        (
            "degenerate quad",
            edited(&[("[1, 0, 1], [1, 0, -1]]", "[1, 0, 1], [1, 0, 1]]")]),
            "shapes[0].vertices",
            "zero area",
        ),
        ("non-planar area light", format!("{MINIMAL}\n{area_light}"), "lights[1].vertices", "not planar"),
        ("no emitter", no_lights, "lights", "no emitter"),
        ("no surfaces", no_shapes, "shapes", "no surfaces"),
        ("sierpinski level 50", format!("{MINIMAL}\n{sierpinski}"), "shapes[1].level", "50"),
        // ks = 1, n = 3 reflects 2 pi / 5 = 1.2566 at normal incidence (brdf.rs test09).
        ("energy-gaining phong", format!("{MINIMAL}\n{hot}"), "materials.hot", "1.256"),
    ];
    for (what, text, key, part) in cases {
        let scene = scratch.dir("scene").join(format!("{}.toml", what.replace(' ', "_")));
        std::fs::write(&scene, text).expect("write the scene");
        let err = refused_render(&scratch, &[&scene.display().to_string()], "x.exr");
        one_line_naming(&err, &scene, key);
        assert!(err.contains(part), "{what}: stderr lacks {part:?}: {err}");
    }
}

#[test]
fn test02_usage_errors_exit_2_and_write_nothing() {
    let scratch = Scratch::new("cli", "usage");
    let cb = cornell_box();
    let png = refused_render(&scratch, &[&cb], "x.png");
    assert!(png.contains("--out") && png.contains(".exr"), "{png}");
    for (args, part) in [
        (vec!["--width", "0"], "--width"),
        (vec!["--height", "16385"], "--height"),
        (vec!["--patch-size", "-1"], "--patch-size -1: expected a finite number > 0"),
        (vec!["--patch-size", "nan"], "--patch-size"),
        (vec!["--time", "0"], "--time"),
        (vec!["--time", "-3"], "--time"),
        (vec!["--light-window", "cube"], "--light-window"),
        (vec!["--shadow-resolution", "0"], "--shadow-resolution"),
        (vec!["--direct-passes", "0"], "--direct-passes 0"),
        (vec!["--window-steps", "0"], "--window-steps 0"),
        (vec!["--burn-in", "-1"], "--burn-in"),
        (vec!["--bundle-resolution", "0"], "--bundle-resolution 0: expected 4 to 16384"),
        (vec!["--bundle-resolution", "-5"], "expected a number of pixels or \"auto\", got \"-5\""),
        (vec!["--bundle-resolution", "fine"], "expected a number of pixels or \"auto\""),
        (vec!["--hemicube-resolution", "0"], "--hemicube-resolution 0: expected 1 to 16384"),
        (vec!["--hemicube-resolution", "fine"], "expected a number of pixels or \"auto\""),
        (vec!["--wide-lines", "3"], "expected 1, 2, 4 or \"auto\", got \"3\""),
        (vec!["--camera", "side"], "--camera side: the scene has no camera \"side\"; its cameras are \"camera\""),
    ] {
        let err = refused_render(&scratch, &[&[cb.as_str()], &args[..]].concat(), "x.exr");
        assert!(err.contains(part), "{args:?}: stderr lacks {part:?}: {err}");
        // Flags are checked before the (default, non-quiet) progress output begins.
        assert!(!err.contains("loaded"), "{args:?}: progress before the refusal: {err}");
    }
    let unknown = refused_render(&scratch, &[&cb, "--bogus"], "x.exr");
    assert!(unknown.contains("--bogus"), "{unknown}");
    let missing = refused_render(&scratch, &[], "x.exr");
    assert!(missing.to_lowercase().contains("scene"), "{missing}");
}

/// A point light cannot be an emitter inside the iteration (SCENE_FORMAT.md, area lights):
/// refused as a usage error before any adapter is opened, so the refusal is the same on a
/// machine without a GPU.
#[test]
fn test03_no_first_shot_with_a_point_light_is_a_usage_error() {
    let scratch = Scratch::new("cli", "no-first-shot");
    let scene = scratch.dir("scene").join("point.toml");
    std::fs::write(&scene, MINIMAL).expect("write the scene");
    let err = refused_render(&scratch, &[&scene.display().to_string(), "--no-first-shot"], "x.exr");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "stderr is not one line (did an adapter get opened?):\n{err}");
    assert!(err.contains("--no-first-shot") && err.contains("point light"), "{err}");
}

/// The stats keys of CLI.md.
const STATS_KEYS: [&str; 21] = [
    "adapter",
    "patches",
    "memory",
    "light_samples",
    "image",
    "hemicube_resolution",
    "bundle_resolution",
    "bundles_per_step",
    "wide_lines",
    "bundle_lines",
    "gather",
    "light_visibility",
    "unshadowed_patches",
    "unshadowed_ms",
    "first_shot",
    "first_shot_ms",
    "iterations",
    "iteration_ms_median",
    "total_ms",
    "seed",
    "notes",
];

#[test]
fn test04_tiny_render_writes_exr_png_and_stats() {
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("cli", "render");
    let exr = scratch.join("sub/dir/cb.exr");
    let stats = scratch.join("s.json");
    let o = firstshot(&[
        &cornell_box(),
        "--iterations",
        "0",
        "--width",
        "32",
        "--height",
        "32",
        "--hemicube-resolution",
        "64",
        "--out",
        &exr.display().to_string(),
        "--stats",
        &stats.display().to_string(),
        "--quiet",
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(0), "stderr:\n{err}");
    assert_eq!(stdout(&o), "", "--quiet prints nothing");
    // Exactly the outputs: the missing folders made, no temporary file left beside them.
    assert_eq!(listing(&scratch), ["s.json", "sub", "sub/dir", "sub/dir/cb.exr", "sub/dir/cb.png"]);

    let image = Image::read_exr(&exr).expect("cb.exr reads back");
    assert_eq!((image.width, image.height), (32, 32));
    assert!(image.pixels.iter().flatten().all(|v| v.is_finite() && *v >= 0.0), "finite, non-negative radiance");
    assert!(image.mean().iter().all(|&m| m > 0.0), "the lit box is not black: {:?}", image.mean());

    let png = std::fs::File::open(exr.with_extension("png")).expect("cb.png");
    let reader = png::Decoder::new(std::io::BufReader::new(png)).read_info().expect("cb.png decodes");
    assert_eq!((reader.info().width, reader.info().height), (32, 32));

    let text = std::fs::read_to_string(&stats).expect("s.json");
    let json: serde_json::Value = serde_json::from_str(&text).expect("s.json is JSON");
    for key in STATS_KEYS {
        assert!(json.get(key).is_some(), "stats lack {key:?}:\n{text}");
    }
    for key in ["name", "backend", "device_type"] {
        assert!(json["adapter"][key].as_str().is_some_and(|s| !s.is_empty()), "adapter.{key}:\n{text}");
    }
    assert_eq!(json["image"], serde_json::json!([32, 32]));
    assert_eq!(json["hemicube_resolution"], 64);
    // --gather auto: the split passes on a CPU adapter, one fused pass on a GPU.
    let cpu = json["adapter"]["device_type"] == "Cpu";
    assert_eq!(json["gather"], if cpu { "split" } else { "fused" }, "{text}");
    // From the scene's [settings]: seed 1; 2 x 2 light cells give 9 samples. No
    // bundle_resolution there, so the automatic one: the Cornell box is diffuse, so its
    // patches ask for no lines (iteration::is_glossy), and the 32 x 32 image asks for less
    // than the smallest, 64; one bundle a step, as its 6065 patches outnumber the 1024
    // pixels (iteration::auto_bundles_per_step).
    assert_eq!(json["bundle_resolution"], 64);
    assert_eq!(json["bundles_per_step"], 1);
    assert_eq!(json["seed"], 1);
    assert_eq!(json["light_samples"], 9);
    assert_eq!(json["first_shot"], true);
    // The Cornell box's area light takes shadow rays (the default), so it has no window.
    assert_eq!(json["light_visibility"], "rays");
    assert_eq!(json["shadow_atlas_texels"], 0, "{text}");
    // A 32 x 32 image has fewer pixels than twice the 6065 patches: no search for the
    // patches that see the whole light (direct_light::SHAFT_PIXELS_PER_PATCH).
    assert!(json["unshadowed_patches"].is_null() && json["unshadowed_ms"].is_null(), "{text}");
    assert_eq!(json["iterations"], 0);
    assert_eq!(json["notes"], serde_json::json!([]), "the Cornell box has nothing to note");
    assert!(json["patches"].as_u64().is_some_and(|n| n > 0), "{text}");
    for key in ["first_shot_ms", "iteration_ms_median", "total_ms"] {
        assert!(json[key].as_f64().is_some_and(|ms| ms >= 0.0), "{key}:\n{text}");
    }
    // The memory predicted before any GPU work, and the peak the run reached.
    let memory = &json["memory"];
    assert_eq!(memory["patches"], json["patches"], "{text}");
    assert_eq!(memory["pixels"], 32 * 32, "{text}");
    assert_eq!(memory["lines"], 0, "no iteration: {text}");
    let bytes = |key: &str| memory[key].as_u64().unwrap_or_else(|| panic!("memory.{key}:\n{text}"));
    assert!(bytes("device_bytes_per_patch") >= 300 && bytes("device_bytes") > 0, "{text}");
    assert!(bytes("total_host_bytes") >= bytes("host_bytes"), "{text}");
    assert!(bytes("peak_rss_bytes") > 0 && bytes("available_bytes") > 0, "{text}");
}

#[test]
fn test04b_a_run_predicted_not_to_fit_is_refused_before_any_work() {
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("cli", "memory-refusals");
    let cb = cornell_box();
    // Whatever dominates, the message gives the figures and the flag to change.
    let err = refused_render(&scratch, &[&cb, "--memory-limit", "1", "--iterations", "0"], "cb.exr");
    for part in ["host memory", "1 MiB are available", "patches (", "pixels (", "--memory-limit"] {
        assert!(err.contains(part), "{err:?} lacks {part:?}");
    }
    // An image far larger than the limit names the image size.
    // 512 MiB: on a CPU adapter the GPU's memory counts too, on a discrete GPU only the host's
    // (about 900 MiB for this image, so 1024 let it run on an H200), and either exceeds it.
    let big = ["--width", "4096", "--height", "4096", "--memory-limit", "512", "--iterations", "0"];
    let err = refused_render(&scratch, &[&[cb.as_str()][..], &big[..]].concat(), "cb.exr");
    assert!(err.contains("16777216 pixels") && err.contains("--width/--height"), "{err}");
    // A fine tessellation names the patch size.
    let fine = ["--patch-size", "2", "--width", "32", "--height", "32", "--memory-limit", "512", "--iterations", "0"];
    let err = refused_render(&scratch, &[&[cb.as_str()][..], &fine[..]].concat(), "cb.exr");
    assert!(err.contains("--patch-size"), "{err}");
}

/// wgpu's names of its backends (`wgpu::Backend`'s Debug form).
const BACKENDS: [&str; 6] = ["Vulkan", "Metal", "Dx12", "Gl", "BrowserWebGpu", "Noop"];

#[test]
fn test05_list_adapters() {
    let o = firstshot(&["--list-adapters"]);
    assert_eq!(o.status.code(), Some(0), "stderr:\n{}", stderr(&o));
    let out = stdout(&o);
    // One adapter per line: name, backend, type, driver, separated by tabs.
    let backends: Vec<&str> = out.lines().filter_map(|l| l.split('\t').nth(1)).collect();
    let required = std::env::var("FIRSTSHOT_REQUIRE_GPU").is_ok_and(|v| v == "1");
    if backends.is_empty() && !required {
        eprintln!("SKIPPED (no GPU adapter): --list-adapters printed {out:?}");
        return;
    }
    assert!(backends.iter().any(|b| BACKENDS.contains(b)), "no line names a backend:\n{out}");
    if required {
        // CI (README) runs on lavapipe: Vulkan unless FIRSTSHOT_REQUIRE_BACKEND says otherwise.
        let backend = std::env::var("FIRSTSHOT_REQUIRE_BACKEND").unwrap_or_else(|_| "vulkan".into());
        assert!(backends.iter().any(|b| b.eq_ignore_ascii_case(&backend)), "no {backend} adapter listed:\n{out}");
    }
}

fn write_exr(path: &Path, width: u32, height: u32, value: [f32; 3]) {
    Image::new(width, height, vec![value; (width * height) as usize]).write_exr(path, &[]).expect("write an EXR");
}

#[test]
fn test06_compare() {
    let scratch = Scratch::new("cli", "compare");
    let path = |name: &str| scratch.join(name).display().to_string();
    write_exr(&scratch.join("a.exr"), 8, 6, [0.55, 0.22, 1.1]);
    write_exr(&scratch.join("b.exr"), 8, 6, [0.5, 0.2, 1.0]);
    write_exr(&scratch.join("small.exr"), 4, 6, [0.5, 0.2, 1.0]);

    let o = firstshot(&["compare", &path("a.exr"), &path("b.exr")]);
    assert_eq!(o.status.code(), Some(0), "stderr:\n{}", stderr(&o));
    let out = stdout(&o);
    let rmse: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("relative RMSE"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no relative RMSE line:\n{out}"));
    // A is B times 1.1 everywhere: the relative RMSE is 0.1, printed to 5 decimals.
    assert!((rmse - 0.1).abs() <= 0.5e-5, "{rmse}");

    let o = firstshot(&["compare", &path("a.exr"), &path("small.exr")]);
    assert_ne!(o.status.code(), Some(0));
    let err = stderr(&o);
    assert!(err.contains("differ in size") && err.contains("8x6") && err.contains("4x6"), "{err}");

    let o = firstshot(&["compare", &path("a.exr"), &path("missing.exr")]);
    assert_ne!(o.status.code(), Some(0));
    assert!(stderr(&o).contains("missing.exr"), "{}", stderr(&o));
    assert_eq!(listing(&scratch), ["a.exr", "b.exr", "small.exr"], "compare writes nothing");
}

/// A bundle projection whose line table no buffer of the device holds: refused by
/// `check_limits` (exit 2), where it used to reach wgpu as a validation panic (exit 101) on
/// scenes small enough to pass the fragment bound.
#[test]
fn test07_bundle_resolution_beyond_the_buffers_is_a_limits_error() {
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("cli", "bundle-limit");
    let scene = scratch.dir("scene").join("small.toml");
    std::fs::write(&scene, MINIMAL).expect("write the scene");
    let path = scene.display().to_string();
    let args = [path.as_str(), "--iterations", "1", "--bundle-resolution", "16384", "--quiet"];
    let err = refused_render(&scratch, &args, "x.exr");
    // The hint names the largest resolution whose table fits what the device allows: the
    // table is line_table_bytes(r), the same bytes for every line.
    let number_after = |key: &str| -> u64 {
        let rest = &err[err.find(key).unwrap_or_else(|| panic!("{key:?} in {err}")) + key.len()..];
        rest.split(|c: char| !c.is_ascii_digit()).next().unwrap().parse().unwrap()
    };
    let (allowed, largest) = (number_after("the device allows "), number_after("use --bundle-resolution "));
    let table = |r: u64| firstshot::iteration::line_table_bytes(r as u32);
    assert!(table(largest) <= allowed && table(largest + 1) > allowed, "{err}");
}

/// `--hemicube-resolution auto` overrides a scene's fixed resolution with the automatic
/// choice (`first_shot::auto_resolution`), which `--stats` reports; without the flag the
/// scene's own stands.
#[test]
fn test08_hemicube_resolution_auto_overrides_the_scene() {
    let scratch = Scratch::new("cli", "hemicube_auto");
    let text = std::fs::read_to_string(cornell_box()).unwrap();
    assert!(!text.contains("hemicube_resolution"), "the shipped Cornell box leaves it to the rule");
    let scene = scratch.join("fixed.toml");
    std::fs::write(&scene, text.replacen("[settings]", "[settings]\nhemicube_resolution = 512", 1)).unwrap();
    let loaded = firstshot::scene::load(&scene).unwrap();
    assert_eq!(loaded.settings.hemicube_resolution, Some(512));
    let patches = firstshot::scene::tessellate(&loaded, loaded.settings.patch_size).unwrap();
    let auto = firstshot::first_shot::auto_resolution(&patches);
    assert_ne!(auto, 512);
    let (stats, out) = (scratch.join("s.json"), scratch.join("x.exr"));
    for (flag, expected) in [(None, 512), (Some("auto"), auto), (Some("80"), 80)] {
        let mut args = vec![scene.to_str().unwrap(), "--iterations", "0", "--width", "16", "--height", "16"];
        args.extend(["--direct-passes", "1", "--quiet", "--out", out.to_str().unwrap()]);
        args.extend(["--stats", stats.to_str().unwrap()]);
        if let Some(value) = flag {
            args.extend(["--hemicube-resolution", value]);
        }
        let o = firstshot(&args);
        assert_eq!(o.status.code(), Some(0), "{flag:?}: {}", stderr(&o));
        let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        assert_eq!(json["hemicube_resolution"], expected, "{flag:?}");
    }
}

/// wgpu's GL backend on llvmpipe, the fallback where no Vulkan driver exists (docs/CLI.md,
/// "Adapters"), renders the Cornell box as lavapipe's Vulkan does. It allows 16 storage
/// buffers a shader stage, fewer than the kernels' pages: a scene whose per-patch arrays
/// fit one binding binds only their first pages (the check once counted every page and
/// refused every scene on GL). With `FIRSTSHOT_REQUIRE_GL=1` (CI) a missing GL adapter is a
/// failure, elsewhere a visible skip.
#[test]
fn test09_gl_adapter_renders_what_vulkan_renders() {
    let listed = stdout(&firstshot(&["--list-adapters"]));
    if !listed.lines().any(|l| l.split('\t').nth(1) == Some("Gl")) {
        assert!(
            std::env::var("FIRSTSHOT_REQUIRE_GL").map_or(true, |v| v != "1"),
            "FIRSTSHOT_REQUIRE_GL=1 but no GL adapter: {listed}"
        );
        eprintln!("SKIPPED (no GL adapter): {listed}");
        return;
    }
    let scratch = Scratch::new("cli", "gl_adapter");
    let dir = scratch.dir("out");
    let scene = cornell_box();
    // An OpenGL driver older than 4.3 has no compute shaders (NVIDIA's EGL adapter, which
    // wgpu opens as OpenGL 3.3): --list-adapters marks it, and a run on it is refused with
    // the reason before any GPU work, writing nothing (llvmpipe, CI's, has OpenGL 4.5).
    let gl_lines: Vec<&str> = listed.lines().filter(|l| l.split('\t').nth(1) == Some("Gl")).collect();
    if gl_lines.iter().all(|l| l.contains("\tunusable: ")) {
        for line in &gl_lines {
            assert!(line.contains("compute shaders") && line.contains("--adapter vulkan"), "{line}");
        }
        let err = refused_render(&scratch, &[&scene, "--adapter", "gl", "--iterations", "2"], "gl.exr");
        assert!(err.contains("lacks compute shaders") && err.contains("--adapter vulkan"), "{err}");
        eprintln!("the GL adapters lack compute shaders; --adapter gl refused: {err}");
        return;
    }
    let mut images = Vec::new();
    for adapter in ["gl", "vulkan"] {
        let out = dir.join(format!("{adapter}.exr"));
        let stats = dir.join(format!("{adapter}.json"));
        let run = firstshot(&[
            &scene,
            "--iterations",
            "8",
            "--width",
            "32",
            "--height",
            "32",
            "--seed",
            "3",
            "--adapter",
            adapter,
            "--quiet",
            "--out",
            &out.display().to_string(),
            "--stats",
            &stats.display().to_string(),
        ]);
        assert!(run.status.success(), "--adapter {adapter}: {}", stderr(&run));
        let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        let backend = stats["adapter"]["backend"].as_str().unwrap().to_lowercase();
        assert_eq!(backend, adapter, "--adapter {adapter} ran on {}", stats["adapter"]);
        images.push(Image::read_exr(&out).unwrap());
    }
    // The same scene, seed and steps: only rounding and the rasterisers' tie rules differ.
    let error = firstshot::image::image_error(&images[0], &images[1]).unwrap();
    assert!(error.relative_rmse < 0.01, "GL against Vulkan: {error:?}");
}

#[test]
fn test10_a_sharp_glossy_lobe_is_noted_on_stderr_and_in_the_stats() {
    // A max-Phong floor of shininess 2000 reflecting about half the light
    // (SCENE_FORMAT.md, max-Phong): the run goes on, with one `note:` line naming the scene
    // and the material, and the same note in the statistics; --quiet hides the line only.
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("cli", "sharp-lobe");
    let scene = scratch.dir("scene").join("mirror.toml");
    let floor = "[materials.white]\ntype = \"phong\"\ndiffuse = [0.1, 0.1, 0.1]\nspecular = [160.0, 160.0, 160.0]\nshininess = 2000.0";
    std::fs::write(&scene, edited(&[("[materials.white]\ntype = \"diffuse\"\nalbedo = [0.5, 0.5, 0.5]", floor)]))
        .expect("write the scene");
    for quiet in [false, true] {
        let dir = scratch.dir(if quiet { "quiet" } else { "loud" });
        let (exr, stats) = (dir.join("m.exr").display().to_string(), dir.join("s.json"));
        let mut args = vec![scene.to_str().unwrap(), "--iterations", "0", "--width", "16", "--height", "16"];
        args.extend(["--hemicube-resolution", "64", "--out", &exr, "--stats", stats.to_str().unwrap()]);
        if quiet {
            args.push("--quiet");
        }
        let o = firstshot(&args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(0), "stderr:\n{err}");
        let noted: Vec<&str> = err.lines().filter(|l| l.starts_with("note: ")).collect();
        assert_eq!(noted.len(), usize::from(!quiet), "stderr:\n{err}");
        let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        let notes = json["notes"].as_array().expect("notes");
        assert_eq!(notes.len(), 1, "{notes:?}");
        let note = notes[0].as_str().unwrap();
        for part in ["mirror.toml", "material \"white\"", "shininess 2000", "Sharp lobes"] {
            assert!(note.contains(part), "{note}");
        }
        if !quiet {
            assert_eq!(noted[0], format!("note: {note}"));
        }
    }
}

#[test]
fn test11_the_cpu_adapters_get_four_worker_threads_a_core_unless_the_environment_says() {
    // Mesa's CPU adapters read LP_NUM_THREADS when the adapter opens; the command line sets
    // it to four a core where it is unset (gpu::context::set_cpu_adapter_threads, CLI.md) and
    // leaves a user's own value alone. The stats say what the run had, and the image is the
    // same either way: every sum the kernels make is exact in any order.
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("cli", "lp-threads");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut images = Vec::new();
    for (given, expected) in [(None, (4 * cores).to_string()), (Some("3"), "3".to_string())] {
        let dir = scratch.dir(given.unwrap_or("unset"));
        let (exr, stats) = (dir.join("cb.exr"), dir.join("s.json"));
        let mut command = common::bin::firstshot();
        command.current_dir(&dir).env_remove("LP_NUM_THREADS");
        if let Some(value) = given {
            command.env("LP_NUM_THREADS", value);
        }
        let (exr_arg, stats_arg) = (exr.display().to_string(), stats.display().to_string());
        let args = [&cornell_box(), "--iterations", "4", "--width", "24", "--height", "24", "--out", &exr_arg];
        let o = command.args(args).args(["--stats", &stats_arg, "--quiet"]).output().expect("running firstshot");
        assert_eq!(o.status.code(), Some(0), "stderr:\n{}", stderr(&o));
        let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        assert_eq!(json["lp_num_threads"], expected.as_str(), "LP_NUM_THREADS {given:?}");
        images.push(std::fs::read(&exr).expect("the image"));
    }
    assert!(images[0] == images[1], "the image depends on the CPU adapter's thread count");
}

#[test]
fn test12_a_bundle_resolution_too_coarse_for_the_glossy_patches_is_noted() {
    // The Sierpinski fractal's glossy triangles (edge 2 / 64) want about 700 lines across a
    // bundle for one line a step; --bundle-resolution 128 crosses them with 0.04, and the
    // image would reflect their spikes (render::RenderOptions::coarse_bundle_note). The run
    // goes on, with the note on stderr and in the stats; the automatic resolution has none.
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("cli", "coarse-bundles");
    let scene = common::scenes::shipped("sierpinski").display().to_string();
    for coarse in [true, false] {
        let dir = scratch.dir(if coarse { "coarse" } else { "automatic" });
        let (exr, stats) = (dir.join("s.exr").display().to_string(), dir.join("s.json"));
        let mut args = vec![scene.as_str(), "--iterations", "1", "--burn-in", "0", "--width", "16", "--height", "16"];
        args.extend(["--hemicube-resolution", "64", "--out", &exr, "--stats", stats.to_str().unwrap()]);
        if coarse {
            args.extend(["--bundle-resolution", "128", "--bundles-per-step", "1"]);
        }
        let o = firstshot(&args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(0), "stderr:\n{err}");
        let noted: Vec<&str> = err.lines().filter(|l| l.starts_with("note: ")).collect();
        let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        let notes: Vec<&str> = json["notes"].as_array().expect("notes").iter().filter_map(|n| n.as_str()).collect();
        if coarse {
            assert_eq!(noted.len(), 1, "stderr:\n{err}");
            for part in ["bundle resolution 128", "0.04 lines a step", "automatic resolution"] {
                assert!(noted[0].contains(part), "{}", noted[0]);
            }
            assert_eq!(notes, [noted[0].trim_start_matches("note: ")]);
        } else {
            assert!(noted.is_empty() && notes.is_empty(), "stderr:\n{err}\nstats: {notes:?}");
        }
    }
}
