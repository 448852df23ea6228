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

/// A walkthrough of the Cornell box: from `[camera]` (its `up` and `fov_y` by default) to
/// two other views and back.
const WALK: &str = r#"
format = 1

[[keyframes]]
position = [278.0, 273.0, -800.0]
look_at = [278.0, 273.0, 0.0]

[[keyframes]]
position = [150.0, 300.0, -500.0]
look_at = [300.0, 250.0, 280.0]

[[keyframes]]
position = [400.0, 350.0, -400.0]
look_at = [250.0, 150.0, 280.0]
fov_y = 50.0

[[keyframes]]
position = [278.0, 273.0, -700.0]
look_at = [278.0, 273.0, 0.0]
"#;

const FRAME_SIZE: [&str; 4] = ["--width", "16", "--height", "16"];

fn frame_names(stem: &str, frames: u32) -> Vec<String> {
    let mut names: Vec<String> =
        (0..frames).flat_map(|f| [format!("{stem}_{f:04}.exr"), format!("{stem}_{f:04}.png")]).collect();
    names.push(format!("{stem}.checkpoint"));
    names.sort();
    names
}

#[test]
fn test04_a_path_writes_every_frame_and_its_first_is_a_run_of_k_steps() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("views", "path");
    let scene = cornell_with_cameras(&dir);
    std::fs::write(dir.join("walk.toml"), WALK).unwrap();
    let out = dir.dir("frames");
    let walk_out = out.join("w").display().to_string();
    let path_args = ["--path", "walk.toml", "--frames", "5", "--steps-per-frame", "3"];
    run(&dir, &[&[scene.as_str(), "--out", &walk_out][..], &path_args, &FRAME_SIZE, &SMALL].concat());
    assert_eq!(listing(&out), frame_names("w", 5), "OUT_NNNN.exr and .png per frame, and the checkpoint");
    // Frame 0 is the scene camera after the burn-in, averaged over its 3 steps: the very
    // image of a 3-step run.
    let plain = dir.join("plain.exr").display().to_string();
    run(&dir, &[&[scene.as_str(), "--out", &plain, "--iterations", "3"][..], &FRAME_SIZE, &SMALL].concat());
    assert!(pixel_bits(&out.join("w_0000.exr")).2 == pixel_bits(Path::new(&plain)).2, "frame 0 differs from its run");
    // Every frame sees its own view; the last keyframe is close to the first one, not equal.
    let frames: Vec<Vec<u32>> = (0..5).map(|f| pixel_bits(&out.join(format!("w_{f:04}.exr"))).2).collect();
    for f in 1..5 {
        assert_ne!(frames[f], frames[f - 1], "frames {} and {f} are the same", f - 1);
    }
    // A second run with --resume finds every frame written and does nothing.
    let o = firstshot_in(
        &dir,
        &[&[scene.as_str(), "--out", &walk_out, "--resume"][..], &path_args, &FRAME_SIZE, &SMALL].concat(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(pixel_bits(&out.join("w_0004.exr")).2 == frames[4]);
}

#[test]
fn test05_an_interrupted_path_resumes_after_its_last_frame_bit_for_bit() {
    if common::gpu().is_none() {
        return;
    }
    use std::io::BufRead as _;
    let dir = Scratch::new("views", "path-resume");
    let scene = cornell_with_cameras(&dir);
    std::fs::write(dir.join("walk.toml"), WALK).unwrap();
    let path_args = ["--path", "walk.toml", "--frames", "6", "--steps-per-frame", "3"];
    let args = |out: &str| -> Vec<String> {
        [&[scene.as_str(), "--out", out][..], &path_args, &FRAME_SIZE, &SMALL]
            .concat()
            .iter()
            .filter(|s| **s != "--quiet")
            .map(|s| s.to_string())
            .collect()
    };
    // Stopped by SIGTERM once frame 2 is written (the frame in progress is dropped).
    let mut child = common::bin::firstshot()
        .args(args("cut"))
        .current_dir(&*dir)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let mut log = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        log.push_str(&line);
        log.push('\n');
        if line.starts_with("frame 2/6") {
            unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
            break;
        }
    }
    log.extend(lines.map(|l| l.unwrap() + "\n"));
    let status = child.wait().unwrap();
    let written = (0..6).filter(|f| dir.join(format!("cut_{f:04}.exr")).is_file()).count();
    if status.code() == Some(143) {
        assert!(log.contains("--resume"), "{log}");
        assert!((2..6).contains(&written), "{written} frames written before the stop:\n{log}");
    } else {
        // The last frames were done before the signal landed: nothing to resume, still a pass.
        assert_eq!(status.code(), Some(0), "{log}");
    }
    let resumed: Vec<String> =
        args("cut").into_iter().chain(["--resume".into(), "--stats".into(), "cut.json".into()]).collect();
    let refs: Vec<&str> = resumed.iter().map(String::as_str).collect();
    run(&dir, &refs);
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cut.json")).unwrap()).unwrap();
    assert_eq!(stats["frames_rendered"], serde_json::json!([written, 6]), "the resumed run renders the frames left");
    let whole = args("whole");
    let refs: Vec<&str> = whole.iter().map(String::as_str).collect();
    run(&dir, &refs);
    for f in 0..6 {
        let (a, b) =
            (pixel_bits(&dir.join(format!("cut_{f:04}.exr"))), pixel_bits(&dir.join(format!("whole_{f:04}.exr"))));
        assert!(a == b, "frame {f}: the resumed walkthrough differs from the uninterrupted one");
    }
}

#[test]
fn test06_path_refusals_name_the_file_and_key_exit_2_and_write_nothing() {
    let dir = Scratch::new("views", "path-refusals");
    let scene = cornell_with_cameras(&dir);
    std::fs::write(dir.join("walk.toml"), WALK).unwrap();
    let broken = |name: &str, text: String| {
        std::fs::write(dir.join(name), text).unwrap();
        name.to_string()
    };
    let no_look_at = broken("no_look_at.toml", WALK.replacen("look_at = [300.0, 250.0, 280.0]\n", "", 1));
    let bad_fov = broken("bad_fov.toml", WALK.replace("fov_y = 50.0", "fov_y = 200.0"));
    let unknown = broken("unknown.toml", WALK.replace("fov_y = 50.0", "roll = 5.0"));
    let k = ["--frames", "4", "--steps-per-frame", "2"];
    for (args, says) in [
        (vec!["--path", &no_look_at, k[0], k[1], k[2], k[3]], format!("{no_look_at}: keyframes[1].look_at")),
        (vec!["--path", &bad_fov, k[0], k[1], k[2], k[3]], format!("{bad_fov}: keyframes[2].fov_y")),
        (vec!["--path", &unknown, k[0], k[1], k[2], k[3]], format!("{unknown}: keyframes[2].roll")),
        (vec!["--path", "missing.toml", k[0], k[1], k[2], k[3]], "missing.toml".into()),
        (vec!["--path", "walk.toml", k[0], k[1]], "--steps-per-frame".into()),
        (vec!["--path", "walk.toml", k[0], "0", k[2], k[3]], "--frames 0".into()),
        (vec!["--path", "walk.toml", k[0], k[1], k[2], "0"], "--steps-per-frame 0".into()),
        (vec!["--path", "walk.toml", k[0], k[1], k[2], k[3], "--all-cameras"], "--all-cameras".into()),
        (vec!["--path", "walk.toml", k[0], k[1], k[2], k[3], "--iterations", "5"], "--iterations".into()),
        (vec!["--path", "walk.toml", k[0], k[1], k[2], k[3], "--resume"], "no checkpoint".into()),
        (vec!["--frames", "4"], "--path".into()),
    ] {
        let out = dir.dir("out");
        let exr = out.join("x.exr").display().to_string();
        let mut all = vec![scene.as_str()];
        all.extend(args.iter().copied());
        all.extend(["--out", &exr, "--quiet"]);
        let o = firstshot_in(&dir, &all);
        assert_eq!(o.status.code(), Some(2), "{all:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(&says), "{all:?}: expected {says:?} in: {}", stderr(&o));
        assert_eq!(listing(&out), Vec::<String>::new(), "{all:?} wrote files");
    }
}

#[test]
fn test07_a_path_through_a_scene_far_from_the_origin_sees_what_it_sees_at_it() {
    // The loader moves a scene far from the origin of its file to its own (`Scene::recentre`);
    // the path's keyframes are in the file's coordinates and move with it. Forgetting that
    // puts every frame's camera a million millimetres from the box.
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("views", "path_far");
    let text = std::fs::read_to_string(common::scenes::shipped("cornell_box")).unwrap();
    let by = glam::DVec3::new(1.0e6, 0.0, 3.0e5);
    std::fs::write(dir.join("near.toml"), &text).unwrap();
    std::fs::write(dir.join("far.toml"), common::scenes::moved(&text, by)).unwrap();
    std::fs::write(dir.join("walk_near.toml"), WALK).unwrap();
    std::fs::write(dir.join("walk_far.toml"), common::scenes::moved(WALK, by)).unwrap();
    for place in ["near", "far"] {
        let (scene, walk, out) = (format!("{place}.toml"), format!("walk_{place}.toml"), format!("{place}/w"));
        let path_args = ["--path", &walk, "--frames", "3", "--steps-per-frame", "2"];
        run(&dir, &[&[scene.as_str(), "--out", &out][..], &path_args, &FRAME_SIZE, &SMALL].concat());
    }
    for f in 0..3 {
        let read = |place: &str| Image::read_exr(&dir.join(format!("{place}/w_{f:04}.exr"))).unwrap();
        let (near, far) = (read("near"), read("far"));
        let difference = common::difference(&far, &near);
        let rmse = difference.relative_rmse;
        eprintln!("frame {f}: relative RMSE {rmse:.5} against the frame at the origin");
        assert!(difference.reference_mean > 0.0 && rmse < 0.002, "frame {f}: relative RMSE {rmse}");
    }
}
