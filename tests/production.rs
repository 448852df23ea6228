//! Long runs: interruption and resume, checkpoints that do not belong, faults.

mod common;

use common::bin::firstshot;
use common::scratch::Scratch;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};

/// A small, quick run of the Cornell box with enough steps to be stopped in the middle. The
/// bundle resolution is the automatic one, which the checkpoint must not tell apart from the
/// options that chose it (a resume once was refused as "other flags" for that).
fn args(out: &Path) -> Vec<String> {
    let scene = common::scenes::shipped("cornell_box");
    format!(
        "{} --iterations 240 --width 48 --height 48 --bundle-resolution auto \
         --hemicube-resolution 64 --patch-size 80 --out {}",
        scene.display(),
        out.display()
    )
    .split_whitespace()
    .map(String::from)
    .collect()
}

#[test]
fn test01_interrupted_and_resumed_run_gives_the_same_bits() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("production", "resume");
    let full = dir.join("full.exr");
    let status = firstshot().args(args(&full)).arg("--quiet").status().unwrap();
    assert!(status.success());

    let run = dir.join("run.exr");
    let mut child = firstshot().args(args(&run)).stderr(Stdio::piped()).spawn().unwrap();
    // Wait until the iteration has begun (the first-shot phase is announced), then stop it
    // at a moment that changes from run to run.
    let stderr = BufReader::new(child.stderr.take().unwrap());
    let mut lines = stderr.lines();
    for line in lines.by_ref() {
        if line.unwrap().starts_with("first shot") {
            break;
        }
    }
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().subsec_nanos();
    std::thread::sleep(std::time::Duration::from_millis(50 + (nanos % 400) as u64));
    let kill = Command::new("kill").arg("-INT").arg(child.id().to_string()).status().unwrap();
    assert!(kill.success());
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    let status = child.wait().unwrap();
    if status.success() {
        // It finished before the signal landed: nothing was interrupted, nothing to resume.
        eprintln!("the run ended before SIGINT; the image must still match");
    } else {
        assert_eq!(status.code(), Some(130), "Ctrl-C exits with 130: {rest:?}");
        assert!(run.exists() && dir.join("run.checkpoint").exists(), "image and checkpoint written: {rest:?}");
        let resumed = firstshot().args(args(&run)).args(["--resume", "--quiet"]).output().unwrap();
        assert!(resumed.status.success(), "{}", String::from_utf8_lossy(&resumed.stderr));
    }
    let (a, b) = (std::fs::read(&full).unwrap(), std::fs::read(&run).unwrap());
    assert!(a == b, "the resumed EXR differs from the uninterrupted one ({})", dir.display());
}

#[test]
fn test02_checkpoints_that_do_not_belong_are_refused() {
    if common::gpu().is_none() {
        return;
    }
    let dir = Scratch::new("production", "refuse");
    let out = dir.join("run.exr");
    let ok = firstshot().args(args(&out)).args(["--quiet", "--checkpoint-every", "1000"]).status().unwrap();
    assert!(ok.success());
    let checkpoint = dir.join("run.checkpoint");
    assert!(checkpoint.exists(), "--checkpoint-every writes the final state");
    // Other flags.
    let other = firstshot().args(args(&out)).args(["--seed", "99", "--resume"]).output().unwrap();
    assert_eq!(other.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&other.stderr).contains("another scene or other flags"));
    // A damaged file.
    let mut bytes = std::fs::read(&checkpoint).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xff;
    std::fs::write(&checkpoint, &bytes).unwrap();
    let corrupt = firstshot().args(args(&out)).arg("--resume").output().unwrap();
    assert_eq!(corrupt.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&corrupt.stderr).contains("not a usable checkpoint"));
    // None at all.
    std::fs::remove_file(&checkpoint).unwrap();
    let missing = firstshot().args(args(&out)).arg("--resume").output().unwrap();
    assert_eq!(missing.status.code(), Some(2));
}

#[test]
fn test03_unwritable_output_fails_with_status_1_before_any_work() {
    let dir = Scratch::new("production", "unwritable");
    // A directory that cannot exist: its parent is a file.
    let blocker = dir.join("file");
    std::fs::write(&blocker, b"x").unwrap();
    let out = blocker.join("sub").join("x.exr");
    let result = firstshot().args(args(&out)).output().unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("file"), "the message names the path: {stderr}");
    assert!(!stderr.contains("adapter:"), "no GPU work before the check: {stderr}");
}

#[test]
fn test04_gpu_errors_become_errors_not_aborts() {
    let Some(ctx) = common::gpu() else { return };
    // A buffer both mappable for reading and a storage buffer is invalid: wgpu reports it
    // asynchronously; the context must hand it back as an error, not abort the process.
    let _bad = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("firstshot.test.invalid"),
        size: 16,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    let err = ctx.wait().expect_err("the invalid buffer must be reported");
    assert!(matches!(err, firstshot::Error::Gpu(_)), "{err}");
    assert!(err.to_string().contains("firstshot.test.invalid"), "the message names the resource: {err}");
    // Reported once: the context is usable again.
    ctx.wait().unwrap();
}
