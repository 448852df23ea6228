//! The environment around the scene, attacked as a careless or hostile user would: flag
//! values of every magnitude, file names in any script, failing standard streams, FIFOs,
//! devices and folders where files belong, outputs that are folders or each other, stop
//! signals. Whatever comes, the binary keeps the contract of docs/CLI.md: exit 0; 2 with
//! nothing written; 1 with the work kept; 128 + the signal after a stop signal; never a
//! panic, never a hang. Each test runs the built binary in a temporary folder of its own.

mod common;

use common::bin::{BIN, stderr, stdout};
use common::scenes::MINIMAL;
use common::scratch::{Scratch, listing};
use firstshot::checkpoint::Checkpoint;
use firstshot::image::Image;
use std::io::{BufRead, BufReader, Read};
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// A tiny, quick render of MINIMAL (a point light over a floor, two patches).
const TINY: [&str; 8] = ["--width", "16", "--height", "16", "--hemicube-resolution", "16", "--bundle-resolution", "32"];

/// Longer than any run of these tests takes; a run still going then is a hang.
const DEADLINE: Duration = Duration::from_secs(90);

fn command(cwd: &Path, args: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args(args).current_dir(cwd).stdin(Stdio::null());
    c
}

/// Waits for `child` (its stdout and stderr piped), killing it and failing past `DEADLINE`.
fn wait_within(mut child: Child, what: &str) -> Output {
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut bytes);
            }
            bytes
        })
    };
    let out = drain(child.stdout.take().map(|p| Box::new(p) as Box<dyn Read + Send>));
    let err = drain(child.stderr.take().map(|p| Box::new(p) as Box<dyn Read + Send>));
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("waiting for firstshot") {
            break status;
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what}: still running after {DEADLINE:?} (a hang)");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output { status, stdout: out.join().expect("stdout"), stderr: err.join().expect("stderr") }
}

/// Runs `args` in `cwd` with a deadline.
fn run(cwd: &Path, args: &[&str]) -> Output {
    let child = command(cwd, args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("spawn firstshot");
    wait_within(child, &format!("{args:?}"))
}

/// The contract on every run: an allowed status, no panic, no temporary file left behind.
fn assert_contract(o: &Output, dir: &Path, what: &str) {
    let err = stderr(o);
    let code = o.status.code();
    assert!(matches!(code, Some(0 | 1 | 2 | 130)), "{what}: exit {code:?} (a crash?); stderr:\n{err}");
    assert!(!err.contains("panicked"), "{what}: a panic:\n{err}");
    let left: Vec<String> = listing(dir).into_iter().filter(|p| p.ends_with(".tmp")).collect();
    assert!(left.is_empty(), "{what}: temporary files left behind: {left:?}");
}

/// Runs `args` in `dir` and checks a refusal: exit status 2, no panic, the folder exactly
/// as before (nothing written, no folder made). Returns stderr.
fn refused(dir: &Path, args: &[&str]) -> String {
    let before = listing(dir);
    let o = run(dir, args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: expected exit status 2; stderr:\n{err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert_eq!(listing(dir), before, "{args:?} wrote something; stderr:\n{err}");
    err
}

/// Writes MINIMAL as `name` in `dir`; returns its path as a string.
fn minimal_scene(dir: &Path, name: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, MINIMAL).expect("write the scene");
    path.display().to_string()
}

fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).expect("no NUL in the path");
    // SAFETY: a NUL-terminated path that outlives the call.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo {}", path.display());
}

fn symlink(target: impl AsRef<Path>, link: &Path) {
    std::os::unix::fs::symlink(target, link).expect("symlink");
}

fn stats_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}:\n{text}", path.display()))
}

/// An EXR that reads back, of finite, non-negative radiance, not black.
fn assert_image(path: &Path, size: u32) -> Image {
    let image = Image::read_exr(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!((image.width, image.height), (size, size), "{}", path.display());
    assert!(image.pixels.iter().flatten().all(|v| v.is_finite() && *v >= 0.0), "{}", path.display());
    assert!(image.mean().iter().any(|&m| m > 0.0), "{} is black", path.display());
    image
}

// ---------------------------------------------------------------------------------------
// 1. Panics from values and environments.

#[test]
fn test01_durations_of_every_magnitude_are_checked() {
    let dir = Scratch::new("hardening", "durations");
    let scene = minimal_scene(&dir, "s.toml");
    for flag in ["--time", "--checkpoint-every"] {
        for value in ["1e300", "1e10", "1.8446744073709552e19", "inf", "-inf", "nan", "0", "-0", "-1", "1e-400"] {
            // `--flag=value`: `-inf` must reach the check, not be taken for a flag by clap.
            let err = refused(&dir, &[&scene, &format!("{flag}={value}"), "--out", "o/x"]);
            assert!(err.contains(flag) && err.contains("seconds"), "{flag} {value}: {err}");
            assert_eq!(err.lines().count(), 1, "{flag} {value}: one line: {err}");
            assert!(err.len() < 300, "{flag} {value}: the number is written short: {err}");
        }
    }
}

/// EXR text holds Latin-1 only; the attributes are escaped, whatever script they are in.
#[test]
fn test02_exr_attributes_in_any_script_are_written() {
    let image = Image::new(2, 1, vec![[0.5, 0.25, 1.0]; 2]);
    for value in ["日本/シーン.toml", "😀 emoji.toml", "line\nbreak", "back\\slash", "Ünïcödé é", "\u{fffd}"]
    {
        let bytes = image.exr_bytes(&[("firstshot.scene", value.to_string())]).expect(value);
        assert!(!bytes.is_empty());
    }
    assert_eq!(
        firstshot::image::exr_text("a\\b\n日é~"),
        "a\\\\b\\u{a}\\u{65e5}\\u{e9}~",
        "printable ASCII stays, the rest is escaped"
    );
}

#[test]
fn test03_scene_and_output_names_in_any_script_render() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "unicode-names");
    let folder = dir.join("données/日本");
    std::fs::create_dir_all(&folder).unwrap();
    let scene = minimal_scene(&folder, "😀 ñ 場面.toml");
    // A name that is not UTF-8 at all (Unix file names are bytes).
    let raw = folder.join(std::ffi::OsStr::from_bytes(b"x\xff\xfe.toml"));
    std::fs::write(&raw, MINIMAL).unwrap();
    // Each scene renders, and its EXR carries the escaped path.
    let cases: Vec<(std::ffi::OsString, PathBuf)> =
        vec![(scene.clone().into(), dir.join("出力/画像.exr")), (raw.clone().into_os_string(), dir.join("raw/x.exr"))];
    for (scene, exr) in cases {
        let o = Command::new(BIN)
            .arg(&scene)
            .args(TINY)
            .args(["--iterations", "0", "--quiet", "--out"])
            .arg(&exr)
            .current_dir(&*dir)
            .output()
            .unwrap();
        assert_contract(&o, &dir, &format!("{scene:?}"));
        assert_eq!(o.status.code(), Some(0), "{scene:?}: {}", stderr(&o));
        assert_image(&exr, 16);
        assert!(exr.with_extension("png").is_file());
        let bytes = std::fs::read(&exr).unwrap();
        let has = |s: &str| bytes.windows(s.len()).any(|w| w == s.as_bytes());
        assert!(has("firstshot.scene="), "the scene is recorded");
        if has("1f600") {
            assert!(has("\\u{1f600}"), "the emoji is escaped");
        } else {
            assert!(has("\\u{fffd}"), "the bytes that are not UTF-8 are recorded as U+FFFD");
        }
    }
}

/// A standard stream that fails (stderr or stdout to `/dev/full`, a closed pipe) never
/// panics; only a result that cannot reach stdout is a failure (1).
#[test]
fn test04_failing_standard_streams() {
    let dir = Scratch::new("hardening", "streams");
    let scene = minimal_scene(&dir, "s.toml");
    let full = || Stdio::from(std::fs::OpenOptions::new().write(true).open("/dev/full").expect("/dev/full"));

    // A refusal whose message cannot be written still refuses.
    let child = command(&dir, &[&scene, "--width", "0"]).stdout(Stdio::piped()).stderr(full()).spawn().unwrap();
    let o = wait_within(child, "refusal with stderr to /dev/full");
    assert_eq!(o.status.code(), Some(2));

    // --list-adapters to a full disk: a failure, said on stderr.
    let child = command(&dir, &["--list-adapters"]).stdout(full()).stderr(Stdio::piped()).spawn().unwrap();
    let o = wait_within(child, "--list-adapters to /dev/full");
    assert_contract(&o, &dir, "--list-adapters to /dev/full");
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("standard output"), "{}", stderr(&o));

    // compare to a full disk: a failure; to a reader that closed the pipe: its choice.
    let (a, b) = (dir.join("a.exr"), dir.join("b.exr"));
    Image::new(4, 4, vec![[1.0; 3]; 16]).write_exr(&a, &[]).unwrap();
    Image::new(4, 4, vec![[0.5; 3]; 16]).write_exr(&b, &[]).unwrap();
    let (a, b) = (a.display().to_string(), b.display().to_string());
    let child = command(&dir, &["compare", &a, &b]).stdout(full()).stderr(Stdio::piped()).spawn().unwrap();
    let o = wait_within(child, "compare to /dev/full");
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let mut child = command(&dir, &["compare", &a, &b]).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    drop(child.stdout.take());
    let o = wait_within(child, "compare to a closed pipe");
    assert_contract(&o, &dir, "compare to a closed pipe");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));

    // A whole render, its progress lines going nowhere.
    if common::gpu().is_none() {
        return;
    }
    let child = command(&dir, &[&scene, "--iterations", "3", "--out", "r/x", "--stats", "r/s.json"])
        .args(TINY)
        .stdout(Stdio::piped())
        .stderr(full())
        .spawn()
        .unwrap();
    let o = wait_within(child, "render with stderr to /dev/full");
    assert_eq!(o.status.code(), Some(0));
    assert_image(&dir.join("r/x.exr"), 16);
    assert_eq!(stats_json(&dir.join("r/s.json"))["iterations"], 3);
}

// ---------------------------------------------------------------------------------------
// 2. Hangs: FIFOs, devices and folders where an input file belongs.

#[test]
fn test05_inputs_that_are_not_files_are_refused_without_hanging() {
    let dir = Scratch::new("hardening", "inputs");
    let fifo = dir.join("fifo.toml");
    mkfifo(&fifo);
    std::fs::create_dir(dir.join("folder.toml")).unwrap();
    let fifo_s = fifo.display().to_string();
    let folder_s = dir.join("folder.toml").display().to_string();
    for (scene, what) in
        [(fifo_s.as_str(), "FIFO"), ("/dev/zero", "device"), ("/dev/null", "device"), (folder_s.as_str(), "folder")]
    {
        let err = refused(&dir, &[scene, "--out", "o/x"]);
        assert!(err.contains(scene) && err.contains(what), "{scene}: {err}");
    }

    // A mesh file of the scene.
    mkfifo(&dir.join("fifo.obj"));
    std::fs::create_dir(dir.join("folder.obj")).unwrap();
    for (mesh, what) in [("fifo.obj", "FIFO"), ("folder.obj", "folder"), ("/dev/zero", "device")] {
        let text = MINIMAL.replacen(
            "[[shapes]]",
            &format!("[[shapes]]\ntype = \"mesh\"\nfile = \"{mesh}\"\nmaterial = \"white\"\n\n[[shapes]]"),
            1,
        );
        let scene = dir.join(format!("mesh-{what}.toml"));
        std::fs::write(&scene, text).unwrap();
        let err = refused(&dir, &[&scene.display().to_string(), "--out", "o/x"]);
        assert!(err.contains("shapes[0].file") && err.contains(what), "{mesh}: {err}");
    }

    // The checkpoint of --resume, and the images of compare.
    let scene = minimal_scene(&dir, "s.toml");
    mkfifo(&dir.join("run.checkpoint"));
    let err = refused(&dir, &[&scene, "--resume", "--out", "run"]);
    assert!(err.contains("run.checkpoint") && err.contains("FIFO"), "{err}");
    Image::new(2, 2, vec![[1.0; 3]; 4]).write_exr(&dir.join("a.exr"), &[]).unwrap();
    let a = dir.join("a.exr").display().to_string();
    std::fs::write(dir.join("text.exr"), b"not an image").unwrap();
    let text = dir.join("text.exr").display().to_string();
    for other in [fifo_s.as_str(), "/dev/zero", folder_s.as_str(), text.as_str(), "missing.exr"] {
        let err = refused(&dir, &["compare", &a, other]);
        assert!(err.contains(other), "compare {other}: {err}");
    }
}

// ---------------------------------------------------------------------------------------
// 3. Outputs checked before any work.

#[test]
fn test06_outputs_that_are_folders_or_each_other_are_refused_before_any_work() {
    let dir = Scratch::new("hardening", "outputs");
    let scene = minimal_scene(&dir, "s.toml");
    let tiny: Vec<&str> = TINY.to_vec();
    let with = |extra: &[&'static str]| -> Vec<String> {
        [&[scene.as_str()], extra, &tiny[..]].concat().into_iter().map(String::from).collect()
    };
    let refused = |dir: &Path, args: &[String]| refused(dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let run = |dir: &Path, args: &[String]| run(dir, &args.iter().map(String::as_str).collect::<Vec<_>>());

    // A folder at each output's name.
    for (folder, args) in [
        ("x.exr", vec!["--out", "x"]),
        ("x.png", vec!["--out", "x"]),
        ("x.checkpoint", vec!["--out", "x", "--checkpoint-every", "5"]),
        ("s.json", vec!["--out", "x", "--stats", "s.json"]),
    ] {
        std::fs::create_dir(dir.join(folder)).unwrap();
        let err = refused(&dir, &with(&args));
        assert!(err.contains(folder) && err.contains("folder"), "{folder}: {err}");
        std::fs::remove_dir(dir.join(folder)).unwrap();
    }

    // Two outputs that are one file, or an output that is the scene; by any spelling.
    std::fs::write(dir.join("old.exr"), b"an earlier image").unwrap();
    symlink("old.exr", &dir.join("link.json"));
    for (args, part) in [
        (vec!["--out", "x", "--stats", "x.exr"], "the image"),
        (vec!["--out", "x", "--stats", "x.png"], "the PNG"),
        (vec!["--out", "x", "--stats", "x.checkpoint"], "the checkpoint"),
        (vec!["--out", "x", "--stats", "s.toml"], "the scene"),
        (vec!["--out", "sub/../x", "--stats", "./x.exr"], "the image"),
        (vec!["--out", "old", "--stats", "link.json"], "the image"),
    ] {
        let err = refused(&dir, &with(&args));
        assert!(err.contains("same file") && err.contains(part), "{args:?}: {err}");
    }
    // A scene whose name is the default output's.
    std::fs::write(dir.join("scene.exr"), MINIMAL).unwrap();
    let err = refused(&dir, &["scene.exr".to_string()]);
    assert!(err.contains("same file") && err.contains("the scene"), "{err}");

    // Devices and links to nothing at an image's name.
    symlink("/dev/null", &dir.join("dev.exr"));
    let err = refused(&dir, &with(&["--out", "dev"]));
    assert!(err.contains("dev.exr") && err.contains("device"), "{err}");
    symlink("nowhere.png", &dir.join("dangling.png"));
    let err = refused(&dir, &with(&["--out", "dangling"]));
    assert!(err.contains("dangling.png") && err.contains("link to nothing"), "{err}");

    // Outputs that cannot be written: a failure (1), found before the adapter is opened,
    // with nothing written.
    std::fs::write(dir.join("file"), b"x").unwrap();
    for args in [vec!["--out", "x", "--stats", "file/s.json"], vec!["--out", "file/sub/x"]] {
        let before = listing(&dir);
        let o = run(&dir, &with(&args));
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains("file") && !err.contains("adapter:"), "{args:?}: {err}");
        assert_eq!(listing(&dir), before, "{args:?} wrote something");
    }
    // A FIFO that no one reads: a failure at once, not a hang at the end.
    mkfifo(&dir.join("nobody.json"));
    let before = listing(&dir);
    let o = run(&dir, &with(&["--out", "x", "--stats", "nobody.json"]));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("no one reads"), "{}", stderr(&o));
    assert_eq!(listing(&dir), before);
}

/// `--stats` into a device, a pipe or through a link: written in place, never replacing
/// the link or the device by a file.
#[test]
fn test07_stats_into_devices_pipes_and_links() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "stats-targets");
    let scene = minimal_scene(&dir, "s.toml");
    let render = |stats: &str, out: &str| {
        let o = run(
            &dir,
            &[&[scene.as_str()], &TINY[..], &["--iterations", "2", "--quiet", "--out", out, "--stats", stats]].concat(),
        );
        assert_contract(&o, &dir, stats);
        assert_eq!(o.status.code(), Some(0), "--stats {stats}: {}", stderr(&o));
        o
    };
    // This process's stdout, as /dev/stdout is (a link to /proc/self/fd/1); a link of our
    // own, so that a regression replaces it and not the system's.
    symlink("/proc/self/fd/1", &dir.join("stdout.json"));
    let o = render("stdout.json", "a");
    let json: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("the stats on stdout");
    assert_eq!(json["iterations"], 2);
    // Stdout redirected to a file that holds more than the stats (as `> log 2>&1` does):
    // the JSON is added where the stream stands, the file is not replaced.
    let log = dir.join("log.txt");
    let mut handle = std::fs::File::create(&log).unwrap();
    std::io::Write::write_all(&mut handle, b"before\n").unwrap();
    let inode = std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(&log).unwrap());
    let args =
        [&[scene.as_str()], &TINY[..], &["--iterations", "2", "--quiet", "--out", "e", "--stats", "stdout.json"]]
            .concat();
    let child = command(&dir, &args).stdout(Stdio::from(handle)).stderr(Stdio::piped()).spawn().unwrap();
    let o = wait_within(child, "--stats to stdout redirected to a file");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(&log).unwrap();
    let json = text.strip_prefix("before\n").unwrap_or_else(|| panic!("the file was replaced:\n{text}"));
    assert_eq!(serde_json::from_str::<serde_json::Value>(json).expect("the stats after the line")["iterations"], 2);
    assert_eq!(std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(&log).unwrap()), inode, "the same file");
    // A device.
    symlink("/dev/null", &dir.join("null.json"));
    render("null.json", "b");
    // A link to a file: the file is replaced, the link stays.
    std::fs::write(dir.join("real.json"), b"old").unwrap();
    symlink("real.json", &dir.join("link.json"));
    render("link.json", "c");
    assert_eq!(stats_json(&dir.join("real.json"))["iterations"], 2);
    for link in ["stdout.json", "null.json", "link.json"] {
        let m = std::fs::symlink_metadata(dir.join(link)).unwrap();
        assert!(m.file_type().is_symlink(), "{link} was replaced");
    }
    assert!(!std::fs::metadata("/dev/null").unwrap().is_file(), "/dev/null is still a device");
    // A FIFO whose reader is there: the reader gets the JSON.
    let fifo = dir.join("pipe.json");
    mkfifo(&fifo);
    let reader = {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(&fifo).unwrap()
    };
    render("pipe.json", "d");
    let mut text = String::new();
    (&reader).read_to_string(&mut text).unwrap();
    assert_eq!(serde_json::from_str::<serde_json::Value>(&text).expect("JSON through the FIFO")["iterations"], 2);
}

// ---------------------------------------------------------------------------------------
// 4. "Nothing written": a refusal makes no folder, however late it comes.

#[test]
fn test08_refusals_make_no_folder() {
    let dir = Scratch::new("hardening", "no-folders");
    let scene = minimal_scene(&dir, "s.toml");
    let unknown_key = dir.join("bad.toml");
    std::fs::write(&unknown_key, format!("colour = 1\n{MINIMAL}")).unwrap();
    let unknown_key = unknown_key.display().to_string();
    let outputs = ["--out", "new/a/x", "--stats", "new2/b/s.json"];
    let mut cases: Vec<Vec<&str>> = vec![
        vec![&scene, "--width", "0"],
        vec![&unknown_key],
        vec![&scene, "--no-first-shot"],
        vec![&scene, "--resume"],
        vec![&scene, "--resume", "--iterations", "0"],
        vec![&scene, "--time", "1e300"],
        vec![&scene, "--direct-passes", "4294967295"],
    ];
    let gpu = common::gpu().is_some();
    if gpu {
        // Refusals that need the adapter: a choice that fits none, a device limit.
        cases.push(vec![&scene, "--adapter", "no-such-adapter-anywhere"]);
        cases.push(vec![&scene, "--iterations", "1", "--bundle-resolution", "16384"]);
    }
    for case in cases {
        let args = [&case[..], &TINY[..], &outputs[..]].concat();
        refused(&dir, &args);
    }
    // The same outputs, aliased: refused before the folders are made.
    refused(&dir, &[&scene, "--out", "new/a/x", "--stats", "new/a/x.png"]);
}

// ---------------------------------------------------------------------------------------
// 5. Exit statuses and messages.

#[test]
fn test09_missing_or_unreadable_scene_is_a_usage_error_said_once() {
    let dir = Scratch::new("hardening", "missing-scene");
    std::fs::write(dir.join("file"), b"x").unwrap();
    for (scene, os_error) in [("nowhere.toml", "No such file"), ("file/scene.toml", "Not a directory")] {
        let err = refused(&dir, &[scene, "--out", "o/x"]);
        assert!(err.contains(scene), "{err}");
        assert_eq!(err.matches(os_error).count(), 1, "the OS error once: {err}");
    }
    // Unreadable: only without root's privileges, which read anything.
    if unsafe { libc::geteuid() } != 0 {
        let scene = minimal_scene(&dir, "locked.toml");
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&scene, std::fs::Permissions::from_mode(0o000)).unwrap();
        let err = refused(&dir, &[&scene, "--out", "o/x"]);
        assert_eq!(err.matches("Permission denied").count(), 1, "{err}");
    }
}

/// A time limit shorter than the first shot (or the burn-in) gives the direct-light image,
/// not a failure; with --iterations 0 it bounds the direct passes.
#[test]
fn test10_a_time_limit_too_short_for_one_step_gives_the_direct_image() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "short-time");
    let scene = minimal_scene(&dir, "s.toml");
    for (i, extra) in [vec!["--time", "1e-6"], vec!["--time", "1e-300", "--iterations", "3", "--burn-in", "100000"]]
        .into_iter()
        .enumerate()
    {
        let (out, stats) = (format!("o{i}/x"), format!("o{i}/s.json"));
        let o = run(&dir, &[&[scene.as_str()], &TINY[..], &extra[..], &["--out", &out, "--stats", &stats]].concat());
        assert_contract(&o, &dir, &format!("{extra:?}"));
        assert_eq!(o.status.code(), Some(0), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains("direct light"), "the image is said to be the direct light: {}", stderr(&o));
        let json = stats_json(&dir.join(&stats));
        assert_eq!(json["iterations"], 0, "{json}");
        assert!(json["camera_samples"].as_u64().is_some_and(|n| n >= 1), "{json}");
        assert_image(&dir.join(format!("o{i}/x.exr")), 16);
    }
    // The largest direct image, bounded by the time.
    let started = Instant::now();
    let o = run(
        &dir,
        &[
            &[scene.as_str()],
            &TINY[..],
            &["--iterations", "0", "--direct-passes", "1048576", "--time", "0.5", "--stats", "d.json", "--quiet"],
        ]
        .concat(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(started.elapsed() < Duration::from_secs(60), "the time limit bounds the passes");
    let passes = stats_json(&dir.join("d.json"))["camera_samples"].as_u64().unwrap();
    assert!((1..1048576).contains(&passes), "{passes}");
}

/// A checkpoint whose checksum was recomputed over numbers no run writes: refused, naming
/// the file, not blamed on the GPU. The checkpoint a run wrote resumes.
#[test]
fn test11_checkpoints_with_numbers_no_run_writes_are_refused() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "forged-checkpoint");
    let scene = minimal_scene(&dir, "s.toml");
    let args = |extra: &[&str]| -> Vec<String> {
        [&[scene.as_str()], &TINY[..], &["--burn-in", "3", "--out", "run", "--quiet"], extra]
            .concat()
            .iter()
            .map(|s| s.to_string())
            .collect()
    };
    let go = |extra: &[&str]| {
        let a = args(extra);
        run(&dir, &a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let o = go(&["--iterations", "12", "--checkpoint-every", "1000"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let path = dir.join("run.checkpoint");
    let good = Checkpoint::read(&path).expect("the run's checkpoint");
    let f32_at = |bytes: &mut Vec<u8>, i: usize, v: f32| bytes[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    type Forge = Box<dyn Fn(&mut Checkpoint)>;
    let forgeries: Vec<(&str, Forge)> = vec![
        ("NaN in the state", Box::new(move |c| f32_at(&mut c.state, 1, f32::NAN))),
        ("infinity in the image", Box::new(move |c| f32_at(&mut c.image_sum, 0, f32::INFINITY))),
        ("NaN weight", Box::new(move |c| f32_at(&mut c.image_sum, 3, f32::NAN))),
        ("zero weight", Box::new(move |c| f32_at(&mut c.image_sum, 7, 0.0))),
        ("a step inside the burn-in", Box::new(|c| c.step = 2)),
    ];
    for (what, forge) in forgeries {
        let mut c = good.clone();
        forge(&mut c);
        std::fs::write(&path, c.to_bytes()).unwrap();
        let o = go(&["--iterations", "12", "--resume"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert!(err.contains("run.checkpoint") && err.contains("not a usable checkpoint"), "{what}: {err}");
        assert!(!err.contains("GPU"), "{what}: blamed on the GPU: {err}");
    }
    std::fs::write(&path, good.to_bytes()).unwrap();
    let o = go(&["--resume", "--iterations", "20"]);
    assert_eq!(o.status.code(), Some(0), "the run's own checkpoint resumes: {}", stderr(&o));
}

#[test]
fn test12_adapter_errors_in_plain_words() {
    let dir = Scratch::new("hardening", "adapter");
    let scene = minimal_scene(&dir, "s.toml");
    let listed = run(&dir, &["--list-adapters"]);
    let any_adapter = stdout(&listed).lines().any(|l| l.contains('\t'));
    let before = listing(&dir);
    let o = run(&dir, &[&scene, "--adapter", "no such adapter", "--out", "o/x"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(if any_adapter { 2 } else { 1 }), "{err}");
    assert!(err.contains("--adapter no such adapter"), "{err}");
    assert!(!err.contains("Name(") && !err.contains("\"no such adapter\""), "Rust debug syntax: {err}");
    assert!(!any_adapter || err.contains("--list-adapters"), "says how to see the choices: {err}");
    assert_eq!(listing(&dir), before);
}

// ---------------------------------------------------------------------------------------
// 6. Stop signals.

/// Spawns a render (progress on stderr) and returns once its first shot is done.
fn spawn_until_first_shot(dir: &Path, args: &[&str]) -> (Child, mpsc::Receiver<String>) {
    let mut child = command(dir, args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let (tx, rx) = mpsc::channel();
    let lines = BufReader::new(child.stderr.take().unwrap()).lines();
    std::thread::spawn(move || {
        for line in lines.map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let start = Instant::now();
    loop {
        match rx.recv_timeout(DEADLINE.saturating_sub(start.elapsed())) {
            Ok(line) if line.starts_with("first shot") => return (child, rx),
            Ok(_) => {}
            Err(e) => {
                let _ = child.kill();
                panic!("{args:?}: no first shot ({e})");
            }
        }
    }
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: a signal to our own child.
    assert_eq!(unsafe { libc::kill(child.id() as i32, sig) }, 0);
}

/// Waits for a signalled child; returns its status code and the rest of its stderr.
fn finish(mut child: Child, rx: mpsc::Receiver<String>) -> (Option<i32>, String) {
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            panic!("still running {DEADLINE:?} after the signal");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    std::thread::sleep(Duration::from_millis(50));
    (status.code(), rx.try_iter().collect::<Vec<_>>().join("\n"))
}

#[test]
fn test13_stop_signals_write_image_stats_and_checkpoint() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "signals");
    let scene = minimal_scene(&dir, "s.toml");
    let base = |out: &str| -> Vec<String> {
        [&[scene.as_str()], &TINY[..], &["--burn-in", "2", "--out", out]]
            .concat()
            .iter()
            .map(|s| s.to_string())
            .collect()
    };
    for (sig, name, status) in
        [(libc::SIGTERM, "SIGTERM", 143), (libc::SIGHUP, "SIGHUP", 129), (libc::SIGINT, "SIGINT", 130)]
    {
        let out = name.to_lowercase();
        let mut args = base(&out);
        args.extend(["--iterations", "1000000", "--stats", &format!("{out}.json")].map(String::from));
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let (child, rx) = spawn_until_first_shot(&dir, &refs);
        std::thread::sleep(Duration::from_millis(300));
        signal(&child, sig);
        let (code, err) = finish(child, rx);
        assert_eq!(code, Some(status), "{name}: {err}");
        assert!(err.contains(name) && err.contains("--resume"), "{name}: {err}");
        assert_image(&dir.join(format!("{out}.exr")), 16);
        assert!(dir.join(format!("{out}.png")).is_file());
        let steps = stats_json(&dir.join(format!("{out}.json")))["iterations"].as_u64().unwrap();
        assert!((1..1000000).contains(&steps), "{name}: {steps} steps");
        let checkpoint = Checkpoint::read(&dir.join(format!("{out}.checkpoint"))).expect("a checkpoint");
        assert_eq!(checkpoint.step as u64, steps + 2, "{name}: the checkpoint is the image's state");

        if sig == libc::SIGTERM {
            // It continues bit for bit: resumed to a few more steps, as an uninterrupted run.
            let total = (steps + 5).to_string();
            let mut resumed = base(&out);
            resumed.extend(["--iterations", &total, "--resume", "--quiet"].map(String::from));
            let refs: Vec<&str> = resumed.iter().map(String::as_str).collect();
            let o = run(&dir, &refs);
            assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
            let mut whole = base("whole");
            whole.extend(["--iterations", &total, "--quiet"].map(String::from));
            let refs: Vec<&str> = whole.iter().map(String::as_str).collect();
            assert_eq!(run(&dir, &refs).status.code(), Some(0));
            let (a, b) =
                (std::fs::read(dir.join(format!("{out}.exr"))).unwrap(), std::fs::read(dir.join("whole.exr")).unwrap());
            assert!(a == b, "the resumed image differs from the uninterrupted one");
        }
    }
}

/// A direct-light image (--iterations 0) stops at a signal too: after its current pass.
#[test]
fn test14_stop_signals_end_a_direct_light_image() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "signals-direct");
    let scene = minimal_scene(&dir, "s.toml");
    for (sig, status) in [(libc::SIGINT, 130), (libc::SIGTERM, 143)] {
        let out = format!("d{status}");
        let stats = format!("{out}.json");
        let args = [
            &[scene.as_str()],
            &TINY[..],
            &["--iterations", "0", "--direct-passes", "1048576", "--out", &out, "--stats", &stats],
        ]
        .concat();
        let (child, rx) = spawn_until_first_shot(&dir, &args);
        std::thread::sleep(Duration::from_millis(300));
        signal(&child, sig);
        let (code, err) = finish(child, rx);
        assert_eq!(code, Some(status), "{err}");
        assert_image(&dir.join(format!("{out}.exr")), 16);
        let passes = stats_json(&dir.join(&stats))["camera_samples"].as_u64().unwrap();
        assert!((1..1048576).contains(&passes), "{passes} passes");
        assert!(!dir.join(format!("{out}.checkpoint")).exists(), "a direct image has no checkpoint");
    }
}

/// A second signal ends the process at once, even while the first waits for a long burn-in.
#[test]
fn test15_a_second_signal_ends_at_once() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("hardening", "second-signal");
    let scene = minimal_scene(&dir, "s.toml");
    let args = [&[scene.as_str()], &TINY[..], &["--iterations", "10", "--burn-in", "100000000", "--out", "x"]].concat();
    let (mut child, rx) = spawn_until_first_shot(&dir, &args);
    signal(&child, libc::SIGTERM);
    std::thread::sleep(Duration::from_millis(500));
    assert!(child.try_wait().unwrap().is_none(), "the first signal waits for the burn-in");
    let second = Instant::now();
    signal(&child, libc::SIGTERM);
    let (code, err) = finish(child, rx);
    assert_eq!(code, Some(143), "{err}");
    assert!(second.elapsed() < Duration::from_secs(10), "ended at once");
}

// ---------------------------------------------------------------------------------------
// 7. --out FOLDER.

#[test]
fn test16_out_folder_writes_inside_it() {
    let dir = Scratch::new("hardening", "out-folder");
    let scene = minimal_scene(&dir, "room.toml");
    // Without a GPU too: the refusal names the file inside the folder.
    std::fs::create_dir_all(dir.join("renders/room.png")).unwrap();
    let err = refused(&dir, &[&scene, "--out", "renders"]);
    assert!(err.contains("renders/room.png"), "{err}");
    std::fs::remove_dir(dir.join("renders/room.png")).unwrap();
    if common::gpu().is_none() {
        return;
    }
    std::fs::create_dir(dir.join("target-folder")).unwrap();
    symlink("target-folder", &dir.join("link-folder"));
    for (out, exr) in [
        ("renders", "renders/room.exr"),
        ("fresh/", "fresh/room.exr"),
        ("link-folder", "target-folder/room.exr"),
        (".", "room.exr"),
    ] {
        let o = run(&dir, &[&[scene.as_str()], &TINY[..], &["--iterations", "0", "--quiet", "--out", out]].concat());
        assert_eq!(o.status.code(), Some(0), "--out {out}: {}", stderr(&o));
        assert_image(&dir.join(exr), 16);
        assert!(dir.join(exr).with_extension("png").is_file(), "--out {out}");
        assert!(std::fs::symlink_metadata(dir.join("link-folder")).unwrap().file_type().is_symlink());
    }
}

// ---------------------------------------------------------------------------------------
// 8. Devices opened and closed by several threads at once.

/// A program (a test suite run by `cargo test`, a tool rendering views in threads) may open
/// and close devices from several threads at once. NVIDIA's Linux driver deadlocked when
/// they did (an H100 hung the views tests of four threads every time), so `Context` opens
/// and releases devices one at a time. Eight threads each open, use and close three: all
/// must finish, and a hang fails the test after two minutes instead of eating CI's time.
/// The threads are joined before the test returns. Left running past it, a thread's exit
/// (the driver's per-thread state torn down) could race the process's own (its global state
/// torn down): once in CI on lavapipe the test process aborted after the test had passed
/// ("double free or corruption"), and so did 2 of 140 runs of it alone, four at a time, on
/// this 2-core machine; joined, none of 300.
#[test]
fn test18_threads_open_and_close_devices_at_once() {
    if common::gpu().is_none() {
        return;
    }
    let choice = common::test_adapter();
    let (done, finished) = mpsc::channel();
    let start = std::sync::Arc::new(std::sync::Barrier::new(8));
    let mut threads = Vec::new();
    for thread in 0..8u32 {
        let (done, start, choice) = (done.clone(), start.clone(), choice.clone());
        threads.push(std::thread::spawn(move || {
            start.wait();
            for round in 0..3u32 {
                let ctx = firstshot::gpu::Context::new(&choice).expect("opening a device");
                let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("test18"),
                    size: 16,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::STORAGE,
                    mapped_at_creation: false,
                });
                ctx.queue.write_buffer(&buffer, 0, &[thread as u8, round as u8, 0, 0]);
                ctx.queue.submit([]);
                ctx.wait().expect("waiting for the device");
            }
            done.send(thread).unwrap();
        }));
    }
    let mut seen = Vec::new();
    for _ in 0..8 {
        match finished.recv_timeout(Duration::from_secs(120)) {
            Ok(thread) => seen.push(thread),
            Err(e) => panic!("threads {seen:?} finished; the others did not within 2 minutes ({e}): a deadlock"),
        }
    }
    seen.sort_unstable();
    assert_eq!(seen, (0..8).collect::<Vec<_>>());
    // Each has sent its number, so each is past its work: joining waits only for its exit.
    for thread in threads {
        thread.join().expect("a device thread panicked");
    }
}

/// The command line opens its device on a second thread while it tessellates the scene
/// (`Context::open_while`), then renders on the first. The work's result comes back with
/// the device, and that device renders the image a device opened here renders, bit for bit.
#[test]
fn test19_a_device_opened_while_tessellating_renders_as_one_opened_here() {
    let Some(here) = common::gpu() else {
        return;
    };
    let scene = firstshot::scene::load::load_str(MINIMAL, Path::new("minimal.toml")).unwrap();
    let mut options = firstshot::render::RenderOptions::from_scene(&scene);
    (options.iterations, options.width, options.height, options.seed) = (4, 32, 32, 3);
    let (opened, patches) = firstshot::gpu::Context::open_while(&common::test_adapter(), || {
        firstshot::scene::tessellate(&scene, options.patch_size)
    });
    let (opened, patches) = (opened.expect("opening a device beside the tessellation"), patches.unwrap());
    assert_eq!(opened.summary.to_string(), here.summary.to_string());
    let beside = firstshot::render::render(&opened, &scene, &patches, &options).unwrap().image;
    let own = firstshot::render::render(&here, &scene, &patches, &options).unwrap().image;
    assert!(beside.pixels.iter().any(|p| p.iter().any(|&c| c > 0.0)), "a black image proves nothing");
    assert_eq!(beside.pixels, own.pixels);
}

// ---------------------------------------------------------------------------------------
// The contract under random flag values.

use proptest::prelude::*;

/// A value for a numeric flag: every magnitude and sign, NaN and the infinities, integers
/// past every width, and text that is no number at all. Small valid values are there too,
/// so that some runs reach the GPU; valid values of the middle magnitudes (a 10000-pixel
/// image, a patch size that makes millions of patches) are left to the range tests, as
/// they would make a case cost minutes.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        1 => any::<f64>().prop_map(|v| format!("{v}")),
        1 => any::<f64>().prop_map(|v| format!("{v:e}")),
        1 => any::<i64>().prop_map(|v| v.to_string()),
        1 => any::<u64>().prop_map(|v| v.to_string()),
        1 => (-400i32..400, any::<bool>()).prop_map(|(e, negative)| format!("{}1e{e}", if negative { "-" } else { "" })),
        1 => ("[-+]?", "[1-9][0-9]{19,60}").prop_map(|(sign, digits)| format!("{sign}{digits}")),
        3 => (0u32..=32).prop_map(|v| v.to_string()),
        2 => (50u32..3000).prop_map(|v| format!("{}", v as f64 / 1000.0)),
        2 => prop::sample::select(vec![
            "nan", "NaN", "inf", "-inf", "infinity", "-0", "0", "+1", "1e", "", "  ", "0x10", "1_000", "١٢", "½",
            "4294967295", "4294967296", "18446744073709551616", "-2147483649", "1e-400", "5e-324",
        ])
        .prop_map(String::from),
        1 => "\\PC{0,8}",
    ]
}

/// A file name: "o" and then arbitrary Unicode (controls and long names included; not `/`
/// or NUL, which no file name holds).
fn name() -> impl Strategy<Value = String> {
    any::<String>().prop_map(|s| format!("o{}", s.replace(['/', '\0'], "_")))
}

/// The flags that take values, and what else each may get besides a number.
const VALUE_FLAGS: [&str; 15] = [
    "--iterations",
    "--time",
    "--seed",
    "--patch-size",
    "--hemicube-resolution",
    "--shadow-resolution",
    "--bundle-resolution",
    "--width",
    "--height",
    "--direct-passes",
    "--burn-in",
    "--window-steps",
    "--checkpoint-every",
    "--light-window",
    "--adapter",
];

fn flag_value(flag: &'static str) -> BoxedStrategy<String> {
    match flag {
        "--light-window" => {
            prop_oneof![Just("hemicube".to_string()), Just("tetrahedron".to_string()), number()].boxed()
        }
        "--adapter" => prop_oneof![
            prop::sample::select(vec!["auto", "cpu", "gpu", "vulkan", "gl", "llvmpipe"]).prop_map(String::from),
            number()
        ]
        .boxed(),
        _ => number().boxed(),
    }
}

/// Inputs each case's folder holds before the run: folders, links to devices, FIFOs.
fn prepare_inputs(dir: &Path) {
    std::fs::create_dir(dir.join("dir")).unwrap();
    std::fs::write(dir.join("file"), b"a file where a folder might be expected").unwrap();
    symlink("/dev/null", &dir.join("dev.exr"));
    symlink("/dev/null", &dir.join("null.json"));
    symlink("/dev/full", &dir.join("full.json"));
    symlink("/proc/self/fd/1", &dir.join("stdout.json"));
    mkfifo(&dir.join("fifo.json"));
    mkfifo(&dir.join("fifo.toml"));
    std::fs::write(dir.join("empty.toml"), b"").unwrap();
}

#[derive(Debug, Clone)]
enum SceneChoice {
    /// MINIMAL under this name.
    Named(String),
    /// One of the prepared inputs, or a device or a missing path.
    Other(&'static str),
}

fn scene_choice() -> impl Strategy<Value = SceneChoice> {
    prop_oneof![
        6 => name().prop_map(|n| SceneChoice::Named(format!("{n}.toml"))),
        2 => name().prop_map(SceneChoice::Named),
        1 => prop::sample::select(vec!["fifo.toml", "dir", "/dev/zero", "/dev/null", "missing.toml", "empty.toml", "file/x.toml"])
            .prop_map(SceneChoice::Other),
    ]
}

fn out_choice() -> impl Strategy<Value = Option<String>> {
    prop_oneof![
        3 => Just(None),
        3 => name().prop_map(Some),
        1 => name().prop_map(|n| Some(format!("{n}.exr"))),
        1 => name().prop_map(|n| Some(format!("{n}.png"))),
        1 => name().prop_map(|n| Some(format!("new/{n}/"))),
        1 => prop::sample::select(vec!["dir", "dir/", "dev", "", "file/x", "fifo.json", "null.json"]).prop_map(|s| Some(s.to_string())),
    ]
}

fn stats_choice() -> impl Strategy<Value = Option<String>> {
    prop_oneof![
        3 => Just(None),
        2 => name().prop_map(Some),
        2 => prop::sample::select(vec![
            "dir", "null.json", "full.json", "stdout.json", "fifo.json", "", "file/s.json", "fifo.toml", "dev.exr",
            "s.json",
        ])
        .prop_map(|s| Some(s.to_string())),
    ]
}

#[derive(Debug, Clone)]
struct Case {
    scene: SceneChoice,
    flags: Vec<(&'static str, String)>,
    out: Option<String>,
    stats: Option<String>,
    switches: Vec<&'static str>,
}

fn case() -> impl Strategy<Value = Case> {
    let flags = prop::collection::vec(prop::sample::select(VALUE_FLAGS.to_vec()), 0..3)
        .prop_flat_map(|names| names.into_iter().map(|f| (Just(f), flag_value(f))).collect::<Vec<_>>());
    let switches = prop::collection::vec(
        prop::sample::select(vec!["--quiet", "--quiet", "--no-first-shot", "--resume", "--list-adapters"]),
        0..2,
    );
    (scene_choice(), flags, out_choice(), stats_choice(), switches)
        .prop_map(|(scene, flags, out, stats, switches)| Case { scene, flags, out, stats, switches })
}

/// Fast defaults, each replaced by the case's own value of that flag: a case that passes
/// every check renders a 16 x 16 image in a fraction of a second.
const DEFAULTS: [(&str, &str); 6] = [
    ("--width", "16"),
    ("--height", "16"),
    ("--hemicube-resolution", "16"),
    ("--bundle-resolution", "32"),
    ("--iterations", "2"),
    ("--time", "20"),
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(150))]

    /// Random flag values, names and inputs: exit 0, 1, 2 (or 130), never a panic or a
    /// hang, nothing written with 2, no temporary file left, an image with 0.
    #[test]
    fn test17_random_flags_keep_the_contract(case in case()) {
        static COUNT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = Scratch::new("hardening", &format!("contract-{n}"));
        prepare_inputs(&dir);
        let scene = match &case.scene {
            SceneChoice::Named(name) => {
                std::fs::write(dir.join(name), MINIMAL).ok();
                name.clone()
            }
            SceneChoice::Other(path) => path.to_string(),
        };
        let mut args: Vec<String> = vec![scene];
        for (flag, default) in DEFAULTS {
            if !case.flags.iter().any(|(f, _)| *f == flag) {
                args.extend([flag.to_string(), default.to_string()]);
            }
        }
        let mut seen = std::collections::HashSet::new();
        for (flag, value) in &case.flags {
            // `--flag=value`, so that a value starting with `-` is a value; twice the same
            // flag is clap's refusal, which the contract covers too, but rarely worth a case.
            if seen.insert(*flag) {
                args.push(format!("{flag}={value}"));
            }
        }
        if let Some(out) = &case.out {
            args.push(format!("--out={out}"));
        }
        if let Some(stats) = &case.stats {
            args.push(format!("--stats={stats}"));
        }
        args.extend(case.switches.iter().map(|s| s.to_string()));

        let before = listing(&dir);
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&dir, &refs);
        let what = format!("{args:?}");
        assert_contract(&o, &dir, &what);
        let after = listing(&dir);
        match o.status.code() {
            Some(2) => prop_assert_eq!(&after, &before, "{} wrote on a refusal; stderr:\n{}", what, stderr(&o)),
            Some(0) if !case.switches.contains(&"--list-adapters") => {
                let new: Vec<&String> = after.iter().filter(|p| !before.contains(p)).collect();
                prop_assert!(new.iter().any(|p| p.ends_with(".exr")) && new.iter().any(|p| p.ends_with(".png")),
                    "{} succeeded without an image: {:?}", what, new);
            }
            _ => {}
        }
    }
}
