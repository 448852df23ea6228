//! Running shards and merges of the binary (tests/shards.rs, tests/slurm.rs).

use super::bin::{firstshot, stderr};
use firstshot::image::Image;
use std::path::Path;
use std::process::{Command, Output};

/// The variables a shard reads its K and N from (docs/DISTRIBUTED.md).
pub const SHARD_VARIABLES: [&str; 6] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_STEP",
    "JOB_COMPLETION_INDEX",
    "FIRSTSHOT_SHARD_COUNT",
];

/// The binary with none of the shard variables (a test run inside a Slurm job or a
/// Kubernetes pod must not shard every render), in `cwd`.
pub fn command_in(cwd: &Path) -> Command {
    let mut c = firstshot();
    for v in SHARD_VARIABLES {
        c.env_remove(v);
    }
    c.current_dir(cwd);
    c
}

/// Runs `args` in `cwd` with `env` set, shard variables otherwise cleared.
pub fn run_in(cwd: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = command_in(cwd);
    c.args(args);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("running the firstshot binary")
}

/// As `run_in`, and asserts exit status 0.
pub fn ok_in(cwd: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    let o = run_in(cwd, args, env);
    assert_eq!(o.status.code(), Some(0), "{args:?} {env:?}: stderr:\n{}", stderr(&o));
    o
}

/// The Cornell box, small and quick: 32 x 32 (or `size`), coarse first shot and bundles.
pub fn small_cornell_args(size: u32) -> Vec<String> {
    let scene = super::scenes::shipped("cornell_box").display().to_string();
    let s = size.to_string();
    [
        scene.as_str(),
        "--width",
        &s,
        "--height",
        &s,
        "--hemicube-resolution",
        "64",
        "--bundle-resolution",
        "64",
        "--quiet",
    ]
    .iter()
    .map(|a| a.to_string())
    .collect()
}

/// The pixels of an EXR as bits, for bit-for-bit comparisons.
pub fn pixel_bits(path: &Path) -> (u32, u32, Vec<[u32; 3]>) {
    let image = Image::read_exr(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (image.width, image.height, image.pixels.iter().map(|p| p.map(f32::to_bits)).collect())
}

/// Asserts that two EXRs hold the same pixels, bit for bit.
pub fn assert_same_pixels(a: &Path, b: &Path) {
    let (pa, pb) = (pixel_bits(a), pixel_bits(b));
    assert_eq!((pa.0, pa.1), (pb.0, pb.1), "{} and {} differ in size", a.display(), b.display());
    let differing = pa.2.iter().zip(&pb.2).filter(|(x, y)| x != y).count();
    assert_eq!(differing, 0, "{} and {}: {differing} pixels differ", a.display(), b.display());
}
