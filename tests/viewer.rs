//! The interactive viewer (`firstshot view`, docs/CLI.md "Viewer"), run without a person: a
//! script moves the camera, runs some steps and takes a screenshot of the window, under a
//! virtual X display (xvfb-run). The screenshot must be the PNG that `firstshot SCENE`
//! renders from the camera the viewer printed, with the same steps: the viewer shares the
//! renderer's steps, and shows the PNG's bytes.

mod common;

use common::bin::{BIN, firstshot_in, stderr, stdout};
use common::scratch::Scratch;
use std::path::Path;
use std::process::Command;

/// Small enough for two CPU cores (as tests/views.rs).
const SMALL: [&str; 13] = [
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
    "--seed=5",
];

/// The image steps of the scripted session and of the render it is compared with.
const STEPS: u32 = 6;

/// The PNG's size and RGB bytes.
fn png_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
    let mut data = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut data).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    data.truncate(info.buffer_size());
    (info.width, info.height, data)
}

/// The `[camera]` table the viewer printed (its `print-camera`), up to the blank line.
fn printed_camera(out: &str) -> String {
    let start = out.find("[camera]").unwrap_or_else(|| panic!("no [camera] table printed: {out}"));
    out[start..].split("\n\n").next().unwrap().to_string() + "\n"
}

/// The scene text with its `[camera]` table replaced by `camera`.
fn with_camera(scene: &str, camera: &str) -> String {
    let start = scene.find("[camera]").unwrap();
    let end = start + scene[start..].find("\n[").unwrap() + 1;
    format!("{}{camera}\n{}", &scene[..start], &scene[end..])
}

/// `xvfb-run` starting the viewer on a virtual display of its own. `-a` takes the first free
/// display number from `-n` on; tests running at once start from numbers of their own
/// (`slot`), so that two never race for the same free number.
fn under_xvfb(xvfb_run: &Path, slot: u32) -> Command {
    let first = 100 + (std::process::id() % 1000) * 4 + slot;
    let mut c = Command::new(xvfb_run);
    c.args(["-a", "-n", &first.to_string(), "-s", "-screen 0 320x240x24", BIN, "view"]);
    // No Wayland session here: winit need not look for one (nor warn about its folder).
    c.env_remove("WAYLAND_DISPLAY");
    c
}

#[test]
fn test01_the_screenshot_of_a_scripted_session_is_the_render_of_its_camera() {
    if common::gpu().is_none() {
        return;
    }
    let Some(xvfb_run) = common::xvfb_run() else { return };
    let dir = Scratch::new("viewer", "screenshot");
    let scene_text = std::fs::read_to_string(common::scenes::shipped("cornell_box")).unwrap();
    let scene = dir.join("cb.toml");
    std::fs::write(&scene, &scene_text).unwrap();
    let output = common::output_dir("viewer");
    let screenshot = output.join("screenshot.png");
    let _ = std::fs::remove_file(&screenshot);
    // Moves and turns before the steps: the image then averages exactly the steps after the
    // burn-in, as a render's does.
    let script = dir.join("session.txt");
    std::fs::write(
        &script,
        format!(
            "# tests/viewer.rs\nmove forward 120\nmove left 30\nturn 6.5 -4\nsteps {STEPS}\nscreenshot {}\nprint-camera\nsave\nquit\n",
            screenshot.display()
        ),
    )
    .unwrap();
    let adapter = std::env::var("FIRSTSHOT_TEST_ADAPTER").unwrap_or_else(|_| "auto".into());
    let viewer = under_xvfb(&xvfb_run, 0)
        .arg(&scene)
        .args(["--width", "128", "--height", "128", "--adapter", &adapter, "--script"])
        .arg(&script)
        .args(["--out", "saved/view.exr"])
        .args(SMALL)
        .current_dir(&*dir)
        .env("XDG_RUNTIME_DIR", &*dir)
        .output()
        .expect("running xvfb-run");
    let log = stderr(&viewer);
    eprintln!("{log}");
    assert_eq!(viewer.status.code(), Some(0), "the viewer under xvfb-run failed: {log}");
    if let Ok(backend) = std::env::var("FIRSTSHOT_REQUIRE_BACKEND") {
        let line = log.lines().find(|l| l.starts_with("adapter: ")).unwrap_or_default();
        assert!(line.to_lowercase().contains(&backend.to_lowercase()), "FIRSTSHOT_REQUIRE_BACKEND={backend}: {line}");
    }
    assert!(log.contains(&format!("screenshot 128x128: {}", screenshot.display())), "{log}");
    // The saved image (the P key's) is the image shown, with its PNG beside it.
    assert!(dir.join("saved/view_0001.exr").is_file() && dir.join("saved/view_0001.png").is_file(), "{log}");

    // The same camera and steps, rendered.
    let camera = printed_camera(&stdout(&viewer));
    assert!(camera.contains("width = 128\nheight = 128"), "{camera}");
    std::fs::write(dir.join("cb_view.toml"), with_camera(&scene_text, &camera)).unwrap();
    let render_png = output.join("render.png");
    let steps = STEPS.to_string();
    let args = [&["cb_view.toml", "--iterations", &steps, "--quiet", "--adapter", &adapter][..], &SMALL].concat();
    let o = firstshot_in(&dir, &[&args[..], &["--out", &output.join("render.exr").display().to_string()]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));

    let (w, h, shown) = png_rgb(&screenshot);
    let (rw, rh, rendered) = png_rgb(&render_png);
    assert_eq!((w, h), (rw, rh), "the screenshot is the image's size");
    let differing = shown.chunks(3).zip(rendered.chunks(3)).filter(|(a, b)| a != b).count();
    let largest = shown.iter().zip(&rendered).map(|(a, b)| a.abs_diff(*b)).max().unwrap_or(0);
    eprintln!(
        "screenshot {} against render {}: {differing} of {} pixels differ, by at most {largest} of 255",
        screenshot.display(),
        render_png.display(),
        w * h
    );
    assert!(
        differing == 0,
        "the window showed another image than the render of its camera: {differing} pixels differ, by up to {largest}"
    );
    // Not a black or flat window: the Cornell box has its red and green walls.
    let red = shown.chunks(3).filter(|p| p[0] > 2 * p[1] && p[0] > 40).count();
    let green = shown.chunks(3).filter(|p| p[1] > 2 * p[0] && p[1] > 40).count();
    assert!(red > 50 && green > 50, "red {red}, green {green} pixels: not the Cornell box");
    // The saved PNG is the image shown (same exposure), byte for byte.
    assert_eq!(png_rgb(&dir.join("saved/view_0001.png")).2, shown, "the saved PNG differs from the window");
}

/// The keyframe lines (position, look_at) of a printed `[camera]` table.
fn keyframe_of(camera: &str) -> String {
    let keep: Vec<&str> = camera.lines().filter(|l| l.starts_with("position") || l.starts_with("look_at")).collect();
    format!("[[keyframes]]\n{}\n", keep.join("\n"))
}

fn exr_bits(path: &Path) -> Vec<u32> {
    let image = firstshot::image::Image::read_exr(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    image.pixels.iter().flatten().map(|v| v.to_bits()).collect()
}

#[test]
fn test04_a_move_restarts_the_image_but_not_the_state_as_a_walkthrough_frame() {
    if common::gpu().is_none() {
        return;
    }
    let Some(xvfb_run) = common::xvfb_run() else { return };
    let dir = Scratch::new("viewer", "move");
    let scene = common::scenes::shipped("cornell_box");
    // K image steps at the scene's camera, a move, K more: the second image must be frame 1
    // of a walkthrough from the scene's camera to the moved one (K steps a frame), whose
    // state carries on from frame 0. Restarting the state at the move would differ.
    let script = dir.join("session.txt");
    std::fs::write(
        &script,
        format!("steps {STEPS}\nsave\nmove forward 150\nturn -8 3\nsteps {STEPS}\nsave\nprint-camera\n"),
    )
    .unwrap();
    let adapter = std::env::var("FIRSTSHOT_TEST_ADAPTER").unwrap_or_else(|_| "auto".into());
    let viewer = under_xvfb(&xvfb_run, 1)
        .arg(&scene)
        .args(["--width", "64", "--height", "48", "--adapter", &adapter, "--script"])
        .arg(&script)
        .args(["--out", "view.exr"])
        .args(SMALL)
        .current_dir(&*dir)
        .env("XDG_RUNTIME_DIR", &*dir)
        .output()
        .expect("running xvfb-run");
    assert_eq!(viewer.status.code(), Some(0), "the viewer under xvfb-run failed: {}", stderr(&viewer));
    let moved = printed_camera(&stdout(&viewer));
    // The path: the scene's camera, then the moved one twice, so that frame 1 (at keyframe 1,
    // the start of the last segment) is the moved camera exactly.
    let scene_camera = printed_camera(&std::fs::read_to_string(&scene).unwrap());
    let path =
        format!("format = 1\n\n{}\n{}\n{}", keyframe_of(&scene_camera), keyframe_of(&moved), keyframe_of(&moved));
    std::fs::write(dir.join("path.toml"), path).unwrap();
    let steps = STEPS.to_string();
    let scene_arg = scene.display().to_string();
    let args = [
        &[scene_arg.as_str(), "--path", "path.toml", "--frames", "3", "--steps-per-frame", &steps][..],
        &["--width", "64", "--height", "48", "--out", "walk", "--quiet", "--adapter", &adapter],
        &SMALL,
    ]
    .concat();
    let o = firstshot_in(&dir, &args);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for (view, frame) in [("view_0001.exr", "walk_0000.exr"), ("view_0002.exr", "walk_0001.exr")] {
        let (a, b) = (exr_bits(&dir.join(view)), exr_bits(&dir.join(frame)));
        let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(differing == 0, "{view} against {frame}: {differing} of {} values differ", a.len());
    }
    assert_ne!(exr_bits(&dir.join("view_0001.exr")), exr_bits(&dir.join("view_0002.exr")), "the move changed the view");
}

#[test]
fn test02_a_bad_script_is_refused_before_any_window_naming_its_line() {
    let dir = Scratch::new("viewer", "bad-script");
    std::fs::write(dir.join("s.txt"), "steps 4\nmove sideways 3\n").unwrap();
    let scene = common::scenes::shipped("cornell_box").display().to_string();
    let o = firstshot_in(&dir, &["view", &scene, "--script", "s.txt"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("s.txt:2: \"sideways\": expected forward, back, left, right, up or down"),
        "{}",
        stderr(&o)
    );
    // The environment variable names a script as --script does.
    let o = common::bin::firstshot()
        .args(["view", &scene])
        .env("FIRSTSHOT_VIEW_SCRIPT", dir.join("s.txt"))
        .current_dir(&*dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("s.txt:2:"), "{}", stderr(&o));
}

#[test]
fn test03_render_only_flags_are_refused_and_no_display_is_a_clear_failure() {
    let dir = Scratch::new("viewer", "refusals");
    let scene = common::scenes::shipped("cornell_box").display().to_string();
    for flag in [&["--iterations", "5"][..], &["--all-cameras"], &["--resume"]] {
        let o = firstshot_in(&dir, &[&["view", &scene][..], flag].concat());
        assert_eq!(o.status.code(), Some(2), "{flag:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("view: {} belongs to a render", flag[0])), "{}", stderr(&o));
    }
    let o = firstshot_in(&dir, &["view", &scene, "--frame-ms", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // Without a display the viewer fails (1) and says what it needs.
    let o = common::bin::firstshot()
        .args(["view", &scene, "--width", "16", "--height", "16"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .current_dir(&*dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("the viewer needs a display"), "{}", stderr(&o));
}
