//! A real Slurm cluster runs docs/DISTRIBUTED.md's job array: `tools/slurm/render.sbatch` as
//! an array of 4 shards, then `tools/slurm/merge.sbatch` as a job that depends on it. The
//! merged image must be bit-identical to a merge of the same 4 shards rendered here with
//! `--shard K/4`, and its error against a long reference must be well below one shard's, as
//! 4 times the steps make it.
//!
//! It needs a cluster that takes jobs: `tools/slurm/local-cluster.sh` starts one on this
//! machine (CI does). Without one the test is skipped visibly; with
//! `FIRSTSHOT_REQUIRE_SLURM=1` (CI) that is a failure.

mod common;

use common::bin::BIN;
use common::scratch::Scratch;
use common::shards::{assert_same_pixels, ok_in, small_cornell_args};
use firstshot::image::{Image, image_error};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const SHARDS: u32 = 4;
/// Steps of the whole run (32 per shard) and of the reference.
const STEPS: u32 = 128;
const REFERENCE_STEPS: u32 = 1024;
/// How long the array and the merge may take on a loaded 2-core machine.
const DEADLINE: Duration = Duration::from_secs(240);

fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// Whether a Slurm cluster takes jobs here; `Err` says why not.
fn cluster() -> Result<String, String> {
    let version = Command::new("sbatch").arg("--version").output().map_err(|e| format!("no sbatch: {e}"))?;
    let state = Command::new("sinfo").args(["-h", "-o", "%T"]).output().map_err(|e| format!("no sinfo: {e}"))?;
    let states = String::from_utf8_lossy(&state.stdout).into_owned();
    if !states.lines().any(|s| ["idle", "mixed", "allocated", "completing"].iter().any(|t| s.starts_with(t))) {
        return Err(format!(
            "no node takes jobs (sinfo: {:?} {})",
            states.trim(),
            String::from_utf8_lossy(&state.stderr).trim()
        ));
    }
    Ok(String::from_utf8_lossy(&version.stdout).trim().to_string())
}

fn logs(dir: &Path) -> String {
    let mut out = String::new();
    let mut entries: Vec<PathBuf> =
        std::fs::read_dir(dir).map(|d| d.flatten().map(|e| e.path()).collect()).unwrap_or_default();
    entries.sort();
    for p in entries.iter().filter(|p| p.extension().is_some_and(|e| e == "log")) {
        out += &format!("== {}\n{}\n", p.display(), std::fs::read_to_string(p).unwrap_or_default());
    }
    out
}

/// `sbatch --parsable ARGS`: the job id.
fn submit(args: &[&str]) -> String {
    let o = Command::new("sbatch").arg("--parsable").args(args).output().expect("running sbatch");
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "sbatch {args:?} failed: {}{}", out, String::from_utf8_lossy(&o.stderr));
    out.trim().split(';').next().unwrap_or_default().to_string()
}

#[test]
fn slurm_array_and_dependent_merge_match_a_local_merge_and_beat_one_shard() {
    let version = match cluster() {
        Ok(v) => v,
        Err(why) => {
            if std::env::var("FIRSTSHOT_REQUIRE_SLURM").is_ok_and(|v| v == "1") {
                panic!("FIRSTSHOT_REQUIRE_SLURM=1 but {why}; start one with tools/slurm/local-cluster.sh");
            }
            eprintln!("SKIPPED (no Slurm cluster: {why}; tools/slurm/local-cluster.sh starts one)");
            return;
        }
    };
    if common::gpu().is_none() {
        return;
    }
    eprintln!("Slurm: {version}");
    let scratch = Scratch::new("slurm", "array");
    let slurm = scratch.dir("slurm");
    let local = scratch.dir("local");
    let base = small_cornell_args(64);
    let steps = STEPS.to_string();
    let mut flags: Vec<&str> = base.iter().map(String::as_str).collect();
    flags.extend(["--iterations", &steps]);

    // The array and the merge that depends on it, as docs/DISTRIBUTED.md submits them.
    let out = slurm.join("cb.exr").display().to_string();
    let (dir, export) = (slurm.display().to_string(), format!("--export=ALL,FIRSTSHOT={BIN}"));
    let array = format!("--array=0-{}", SHARDS - 1);
    let chdir = format!("--chdir={dir}");
    let shard_log = format!("--output={dir}/shard-%a.log");
    let render = repo("tools/slurm/render.sbatch").display().to_string();
    let mut args = vec![array.as_str(), chdir.as_str(), shard_log.as_str(), export.as_str(), render.as_str()];
    args.extend(&flags);
    args.extend(["--out", out.as_str()]);
    let start = Instant::now();
    let array_job = submit(&args);
    let merge_script = repo("tools/slurm/merge.sbatch").display().to_string();
    let dependency = format!("--dependency=afterok:{array_job}");
    let merge_log = format!("--output={dir}/merge.log");
    let mut merge = Command::new("sbatch")
        .args(["--parsable", "--wait", "--kill-on-invalid-dep=yes", &dependency, &chdir, &merge_log, &export])
        .args([merge_script.as_str(), out.as_str()])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("running sbatch --wait");
    let status = loop {
        if let Some(status) = merge.try_wait().expect("waiting for sbatch") {
            break status;
        }
        if start.elapsed() > DEADLINE {
            let _ = merge.kill();
            let _ = Command::new("scancel").arg(&array_job).status();
            let queue = Command::new("squeue").output().map(|o| String::from_utf8_lossy(&o.stdout).into_owned());
            panic!("the array and merge did not finish in {DEADLINE:?}; squeue:\n{queue:?}\n{}", logs(&slurm));
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let wall = start.elapsed();
    let mut merge_job = String::new();
    if let Some(mut stdout) = merge.stdout.take() {
        let _ = std::io::Read::read_to_string(&mut stdout, &mut merge_job);
    }
    let merge_job = merge_job.trim().split(';').next().unwrap_or_default().to_string();
    // `sbatch --wait` exits 0 for a job cancelled because a shard failed: ask for its state.
    let state = Command::new("scontrol").args(["show", "job", &merge_job]).output().expect("running scontrol");
    let state = String::from_utf8_lossy(&state.stdout).into_owned();
    assert!(
        status.success() && state.contains("JobState=COMPLETED"),
        "the merge job {merge_job} did not complete ({status}):\n{state}\n{}",
        logs(&slurm)
    );
    eprintln!(
        "Slurm array of {SHARDS} shards x {} steps + merge: {:.1} s from submission",
        STEPS / SHARDS,
        wall.as_secs_f64()
    );
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(slurm.join("cb.stats.json")).expect("the merge's stats"))
            .unwrap();
    assert_eq!(stats["shards"], serde_json::json!([0, 1, 2, 3]), "{stats}");
    assert_eq!((stats["iterations"].as_u64(), stats["complete"].as_bool()), (Some(STEPS as u64), Some(true)));

    // The same shards here, merged here (in another order).
    for k in 0..SHARDS {
        let shard = format!("{k}/{SHARDS}");
        let mut a = flags.clone();
        a.extend(["--shard", &shard, "--out", "cb.exr"]);
        ok_in(&local, &a, &[]);
    }
    let parts: Vec<String> = (0..SHARDS).rev().map(|k| format!("cb.shard-{k}-of-{SHARDS}.part")).collect();
    let mut a = vec!["merge", "merged.exr", "--quiet"];
    a.extend(parts.iter().map(String::as_str));
    ok_in(&local, &a, &[]);
    assert_same_pixels(&slurm.join("cb.exr"), &local.join("merged.exr"));
    let same = std::fs::read(slurm.join("cb.part")).unwrap() == std::fs::read(local.join("merged.part")).unwrap();
    assert!(same, "the Slurm merge's part holds other sums than the local merge's");

    // Against a long reference (another seed): the merge's error is about half a shard's.
    let reference_steps = REFERENCE_STEPS.to_string();
    let mut a: Vec<&str> = base.iter().map(String::as_str).collect();
    a.extend(["--iterations", &reference_steps, "--seed", "99", "--out", "reference.exr"]);
    ok_in(&local, &a, &[]);
    let reference = Image::read_exr(&local.join("reference.exr")).unwrap();
    let error = |path: &Path| image_error(&Image::read_exr(path).unwrap(), &reference).unwrap().relative_rmse;
    let merged = error(&slurm.join("cb.exr"));
    let shards: Vec<f64> = (0..SHARDS).map(|k| error(&local.join(format!("cb.shard-{k}-of-{SHARDS}.exr")))).collect();
    let mean = shards.iter().sum::<f64>() / shards.len() as f64;
    eprintln!(
        "relative RMSE against {REFERENCE_STEPS} steps: merged {merged:.4}, shards {shards:.4?} (mean {mean:.4})"
    );
    // In squared error, 4 times the steps leave a quarter of the noise; the reference's own
    // noise, which every image is measured against, adds the same to each (measured: 0.50
    // and 0.56 of the shards' mean squared error). A merge that added no steps would stay
    // near 1.
    let shard_mse = shards.iter().map(|e| e * e).sum::<f64>() / shards.len() as f64;
    assert!(
        merged * merged < 0.7 * shard_mse,
        "merged {merged:.4} is not well below the shards' RMS error {:.4}: {shards:?}",
        shard_mse.sqrt()
    );
    // Single shards' errors scatter by a factor 2 (one bundle direction per step moves the
    // whole image: 0.13-0.30 measured), so the luckiest of four can beat the merge; the
    // median cannot, unless merging did not add steps.
    let mut sorted = shards.clone();
    sorted.sort_by(f64::total_cmp);
    let median = 0.5 * (sorted[1] + sorted[2]);
    assert!(merged < median, "merged {merged:.4} against the shards' median {median:.4}: {shards:?}");
}
