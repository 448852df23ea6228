//! One solution, many views (docs/CLI.md, "Several cameras"): `--all-cameras` renders every
//! camera of a scene from one iteration, each image the same bits as a run with that camera
//! alone.

mod common;

use common::bin::{firstshot_in, stderr};
use common::scratch::{Scratch, listing};
use firstshot::image::Image;
use std::path::Path;

/// The Cornell box with three cameras besides `[camera]`, of other sizes than it.
fn cornell_with_cameras(dir: &Path) -> String {
    let mut text = std::fs::read_to_string(common::scenes::shipped("cornell_box")).unwrap();
    text = text.replace("width = 512\nheight = 512", "width = 24\nheight = 24");
    text.push_str(
        r#"
[[cameras]]
name = "left"
position = [100.0, 300.0, -500.0]
look_at = [278.0, 250.0, 280.0]
up = [0.0, 1.0, 0.0]
fov_y = 45.0
width = 20
height = 16

[[cameras]]
name = "right-low"
position = [450.0, 200.0, -500.0]
look_at = [278.0, 273.0, 280.0]
up = [0.0, 1.0, 0.0]
fov_y = 45.0
width = 16
height = 24

[[cameras]]
name = "top.view"
position = [278.0, 500.0, -300.0]
look_at = [278.0, 0.0, 280.0]
up = [0.0, 1.0, 0.0]
fov_y = 50.0
width = 24
height = 24
"#,
    );
    let path = dir.join("cb.toml");
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// Small enough for two CPU cores: a coarse tessellation, small windows and bundles, the
/// direct light estimated on the first steps and then every other step.
const SMALL: [&str; 14] = [
    "--patch-size",
    "120",
    "--hemicube-resolution",
    "32",
    "--bundle-resolution",
    "64",
    "--burn-in",
    "2",
    "--direct-passes",
    "3",
    "--window-steps",
    "2",
    "--quiet",
    "--seed=5",
];

const NAMES: [&str; 4] = ["camera", "left", "right-low", "top.view"];

fn run(dir: &Path, args: &[&str]) {
    let o = firstshot_in(dir, args);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
}

fn pixel_bits(path: &Path) -> (u32, u32, Vec<u32>) {
    let image = Image::read_exr(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (image.width, image.height, image.pixels.iter().flatten().map(|v| v.to_bits()).collect())
}

#[test]
fn test01_all_cameras_give_each_camera_the_bits_of_its_own_run() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("views", "all-cameras");
    let scene = cornell_with_cameras(&dir);
    let out = dir.dir("all");
    let all_out = out.join("cb.exr").display().to_string();
    run(&dir, &[&[scene.as_str(), "--iterations", "7", "--all-cameras", "--out", &all_out][..], &SMALL].concat());
    let mut expected: Vec<String> = NAMES.iter().flat_map(|n| [format!("cb_{n}.exr"), format!("cb_{n}.png")]).collect();
    expected.sort();
    assert_eq!(listing(&out), expected, "one EXR and one PNG per camera, named after it");
    for (name, size) in NAMES.iter().zip([(24, 24), (20, 16), (16, 24), (24, 24)]) {
        let one = dir.join(format!("one_{name}.exr")).display().to_string();
        run(&dir, &[&[scene.as_str(), "--iterations", "7", "--camera", name, "--out", &one][..], &SMALL].concat());
        let (w, h, all_bits) = pixel_bits(&out.join(format!("cb_{name}.exr")));
        assert_eq!((w, h), size, "camera {name} keeps its own size");
        let (_, _, one_bits) = pixel_bits(Path::new(&one));
        assert!(all_bits == one_bits, "camera {name}: the image of --all-cameras differs from its own run");
        assert!(all_bits.iter().any(|&b| b != 0), "camera {name}: a black image");
    }
    // The views differ (each camera sees its own image, not the first one's).
    assert_ne!(pixel_bits(&out.join("cb_camera.exr")).2, pixel_bits(&out.join("cb_top.view.exr")).2);
}

#[test]
fn test02_all_cameras_resume_bit_for_bit_and_keep_their_sizes_under_width() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("views", "all-cameras-resume");
    let scene = cornell_with_cameras(&dir);
    let size = ["--width", "12", "--height", "10"];
    let go = |out: &str, extra: &[&str]| {
        run(&dir, &[&[scene.as_str(), "--all-cameras", "--out", out][..], &size, &SMALL, extra].concat());
    };
    // Stopped after 5 steps with a checkpoint (the final one of --checkpoint-every), resumed to 9.
    go("part", &["--iterations", "5", "--checkpoint-every", "1000"]);
    assert!(dir.join("part.checkpoint").is_file(), "one checkpoint, beside OUT, for all the cameras");
    go("part", &["--iterations", "9", "--resume"]);
    go("whole", &["--iterations", "9"]);
    for name in NAMES {
        let (w, h, resumed) = pixel_bits(&dir.join(format!("part_{name}.exr")));
        assert_eq!((w, h), (12, 10), "--width and --height size every camera");
        assert!(resumed == pixel_bits(&dir.join(format!("whole_{name}.exr"))).2, "camera {name}: resumed differs");
    }
    // A checkpoint of one camera does not resume all of them.
    run(
        &dir,
        &[&[scene.as_str(), "--out", "single", "--iterations", "5", "--checkpoint-every", "1000"][..], &size, &SMALL]
            .concat(),
    );
    std::fs::copy(dir.join("single.checkpoint"), dir.join("part.checkpoint")).unwrap();
    let o = firstshot_in(
        &dir,
        &[&[scene.as_str(), "--all-cameras", "--out", "part", "--iterations", "9", "--resume"][..], &size, &SMALL]
            .concat(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("part.checkpoint"), "{}", stderr(&o));
}

#[test]
fn test03_all_cameras_refusals_exit_2_and_write_nothing() {
    let dir = Scratch::new("views", "all-cameras-refusals");
    let scene = cornell_with_cameras(&dir);
    let bad_name = dir.join("bad.toml");
    let text = std::fs::read_to_string(&scene).unwrap().replace("name = \"left\"", "name = \"a/b\"");
    std::fs::write(&bad_name, text).unwrap();
    let bad_name = bad_name.display().to_string();
    for (args, says) in [
        (vec![scene.as_str(), "--all-cameras", "--camera", "left"], "--camera"),
        (vec![scene.as_str(), "--all-cameras", "--shard", "0/2"], "--all-cameras"),
        (vec![bad_name.as_str(), "--all-cameras"], "\"a/b\""),
    ] {
        let out = dir.dir("out");
        let mut all = args.clone();
        let exr = out.join("x.exr").display().to_string();
        all.extend(["--out", &exr, "--iterations", "3", "--quiet"]);
        let o = firstshot_in(&dir, &all);
        assert_eq!(o.status.code(), Some(2), "{all:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{all:?}: {}", stderr(&o));
        assert_eq!(listing(&out), Vec::<String>::new(), "{all:?} wrote files");
    }
}
