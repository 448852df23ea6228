//! Shards (docs/DISTRIBUTED.md): shard K of N is an independent chain of the same run, with
//! its own seed (derived from the run's seed and K), its own burn-in, and its share of the
//! steps, so that N machines render one image and `merge` adds their image sums exactly.
//!
//! K and N come from `--shard K/N`, else from a Slurm job array (`SLURM_ARRAY_TASK_ID`, ...),
//! else from a Kubernetes Indexed Job (`JOB_COMPLETION_INDEX` with `--shard-count N` or
//! `FIRSTSHOT_SHARD_COUNT`). Shard 0 of 1 is the unsharded run, bit for bit.

use crate::render::RenderOptions;
use crate::rng::splitmix64;
use crate::scene::Scene;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// The most shards of one run (a Slurm array's default MaxArraySize is 1001).
pub const MAX_SHARDS: u32 = 1 << 20;

/// Where a shard's K and N came from (named in messages and the stats).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// `--shard K/N`.
    Flag,
    /// `SLURM_ARRAY_TASK_ID` and its siblings.
    Slurm,
    /// `JOB_COMPLETION_INDEX` with `--shard-count` or `FIRSTSHOT_SHARD_COUNT`.
    Kubernetes,
}

/// Shard `index` of `count` (0 <= index < count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
    pub source: Source,
}

fn usage(message: String) -> Error {
    Error::Usage(message)
}

/// Parses `--shard K/N`.
pub fn parse_flag(text: &str) -> Result<Shard> {
    let bad = || {
        usage(format!(
            "--shard {text}: expected K/N, shard K of N counting from 0 (0 <= K < N, N at most {MAX_SHARDS}), e.g. --shard 0/4"
        ))
    };
    let (k, n) = text.split_once('/').ok_or_else(bad)?;
    let k: u32 = k.trim().parse().map_err(|_| bad())?;
    let n: u32 = n.trim().parse().map_err(|_| bad())?;
    if n == 0 || n > MAX_SHARDS || k >= n {
        return Err(bad());
    }
    Ok(Shard { index: k, count: n, source: Source::Flag })
}

/// Reads an environment variable as a whole number, naming it when it is not one.
fn env_number(env: &dyn Fn(&str) -> Option<String>, name: &str, fix: &str) -> Result<Option<u64>> {
    match env(name) {
        None => Ok(None),
        Some(v) => v
            .trim()
            .parse::<u64>()
            .map(Some)
            .map_err(|_| usage(format!("{name}={v}: expected a whole number >= 0; {fix}"))),
    }
}

/// The shard of this run: `--shard` (`flag`) wins; else a Slurm array task; else a
/// Kubernetes Indexed Job's completion index, with its count from `count_flag`
/// (`--shard-count`) or `FIRSTSHOT_SHARD_COUNT`; else none (an unsharded run). `env` reads
/// the environment (a parameter, so that tests need not change the process's).
pub fn resolve(
    flag: Option<&str>,
    count_flag: Option<u32>,
    env: &dyn Fn(&str) -> Option<String>,
) -> Result<Option<Shard>> {
    if let Some(text) = flag {
        let shard = parse_flag(text)?;
        if let Some(n) = count_flag
            && n != shard.count
        {
            return Err(usage(format!("--shard-count {n} contradicts --shard {text}; give one of them")));
        }
        return Ok(Some(shard));
    }
    let fix = "or give the shard explicitly with --shard K/N (--shard 0/1: not sharded)";
    if let Some(id) = env_number(env, "SLURM_ARRAY_TASK_ID", fix)? {
        let count = env_number(env, "SLURM_ARRAY_TASK_COUNT", fix)?.ok_or_else(|| {
            usage(format!("SLURM_ARRAY_TASK_ID={id} is set but SLURM_ARRAY_TASK_COUNT is not; {fix}"))
        })?;
        let min = env_number(env, "SLURM_ARRAY_TASK_MIN", fix)?.unwrap_or(0);
        let step = env_number(env, "SLURM_ARRAY_TASK_STEP", fix)?.unwrap_or(1).max(1);
        let offset = id.checked_sub(min).filter(|o| o % step == 0);
        let k = offset.map(|o| o / step).filter(|&k| k < count);
        let (Some(k), true) = (k, (1..=MAX_SHARDS as u64).contains(&count)) else {
            return Err(usage(format!(
                "SLURM_ARRAY_TASK_ID={id} (SLURM_ARRAY_TASK_MIN={min}, SLURM_ARRAY_TASK_STEP={step}, SLURM_ARRAY_TASK_COUNT={count}) is not shard K of N: shards need an array of evenly spaced indices such as --array=0-{}; {fix}",
                count.clamp(1, MAX_SHARDS as u64) - 1
            )));
        };
        if let Some(n) = count_flag
            && n as u64 != count
        {
            return Err(usage(format!(
                "--shard-count {n} contradicts SLURM_ARRAY_TASK_COUNT={count}; drop --shard-count"
            )));
        }
        return Ok(Some(Shard { index: k as u32, count: count as u32, source: Source::Slurm }));
    }
    if let Some(index) = env_number(env, "JOB_COMPLETION_INDEX", fix)? {
        let count = match count_flag {
            Some(n) => Some(n as u64),
            None => env_number(env, "FIRSTSHOT_SHARD_COUNT", fix)?,
        };
        let Some(count) = count else {
            return Err(usage(format!(
                "JOB_COMPLETION_INDEX={index} is set (a Kubernetes Indexed Job) but not the number of shards: pass --shard-count N or set FIRSTSHOT_SHARD_COUNT=N (the Job's spec.completions), {fix}"
            )));
        };
        let via = if count_flag.is_some() { "--shard-count" } else { "FIRSTSHOT_SHARD_COUNT" };
        if count == 0 || count > MAX_SHARDS as u64 || index >= count {
            return Err(usage(format!(
                "JOB_COMPLETION_INDEX={index} with {via} {count}: expected 0 <= index < count (count 1 to {MAX_SHARDS}); set {via} to the Job's spec.completions"
            )));
        }
        return Ok(Some(Shard { index: index as u32, count: count as u32, source: Source::Kubernetes }));
    }
    if let Some(n) = count_flag {
        return Err(usage(format!(
            "--shard-count {n}: only used with JOB_COMPLETION_INDEX (a Kubernetes Indexed Job), which is not set; use --shard K/N"
        )));
    }
    // FIRSTSHOT_SHARD_COUNT alone is harmless (a Job's environment outside the Job): no shard.
    Ok(None)
}

/// `resolve` with the process's environment.
pub fn from_cli(flag: Option<&str>, count_flag: Option<u32>) -> Result<Option<Shard>> {
    resolve(flag, count_flag, &|name| std::env::var(name).ok())
}

/// A constant that sets the shards' seed streams apart from the runs' seeds.
const SHARD_STREAM: u64 = 0x5348_4152_4453_0001;

/// The seed of shard `index` of `count` of a run seeded `seed`: the run's own seed for one
/// shard (shard 0 of 1 is the unsharded run), otherwise a SplitMix64 mix of the seed and the
/// index, so that shards are independent chains.
pub fn shard_seed(seed: u64, index: u32, count: u32) -> u64 {
    if count <= 1 { seed } else { splitmix64(seed ^ splitmix64(SHARD_STREAM ^ index as u64)) }
}

/// Shard `index`'s share of `total` steps: the first `total % count` shards take one more,
/// so that the shares add up to `total` exactly.
pub fn share(total: u32, index: u32, count: u32) -> u32 {
    total / count + u32::from(index < total % count)
}

/// What a shard's render needs beyond its options: what its part records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardRun {
    pub shard: Shard,
    /// The run's seed (before the shard's derivation).
    pub run_seed: u64,
    /// The shard's own seed.
    pub seed: u64,
    /// The fingerprint of the whole run (the scene and every image-changing option, with the
    /// run's seed): every shard of one run has the same, and `merge` refuses others.
    pub fingerprint: u64,
}

impl Shard {
    /// Turns the run's `options` into this shard's: its seed and its share of the steps
    /// (all shards run for the whole of a time limit). Refuses a split that leaves a shard
    /// no step (it would render another kind of image, the direct light only).
    pub fn apply(&self, scene: &Scene, options: &mut RenderOptions) -> Result<ShardRun> {
        let fingerprint = crate::render::fingerprint(scene, options);
        let run_seed = options.seed;
        if options.iterations != u32::MAX && options.iterations > 0 {
            if options.iterations < self.count {
                return Err(usage(format!(
                    "--iterations {} over {} shards leaves shard {} without a step: give at least {} iterations or fewer shards",
                    options.iterations,
                    self.count,
                    self.count - 1,
                    self.count
                )));
            }
            options.iterations = share(options.iterations, self.index, self.count);
        }
        options.seed = shard_seed(run_seed, self.index, self.count);
        Ok(ShardRun { shard: *self, run_seed, seed: options.seed, fingerprint })
    }

    /// `path` with `.shard-K-of-N` before its extension (K zero-padded to N's digits, so
    /// that the files sort in shard order), unchanged for one shard.
    pub fn path(&self, path: &Path) -> PathBuf {
        if self.count <= 1 {
            return path.to_path_buf();
        }
        let digits = (self.count - 1).to_string().len();
        let tag = format!("shard-{:0digits$}-of-{}", self.index, self.count);
        let stem = path.file_stem().unwrap_or_default().to_string_lossy();
        let name = match path.extension() {
            Some(ext) => format!("{stem}.{tag}.{}", ext.to_string_lossy()),
            None => format!("{stem}.{tag}"),
        };
        path.with_file_name(name)
    }
}

/// The `shard` object of a shard's `--stats` (docs/CLI.md).
pub fn stats_json(run: &ShardRun) -> serde_json::Value {
    serde_json::json!({
        "index": run.shard.index,
        "count": run.shard.count,
        "source": run.shard.source,
        "run_seed": run.run_seed,
        "seed": run.seed,
        "fingerprint": format!("{:016x}", run.fingerprint),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn env_of(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let map: HashMap<String, String> = pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        move |name| map.get(name).cloned()
    }

    fn resolved(flag: Option<&str>, count: Option<u32>, env: &[(&str, &str)]) -> Result<Option<Shard>> {
        resolve(flag, count, &env_of(env))
    }

    fn message(r: Result<Option<Shard>>) -> String {
        match r {
            Err(e @ Error::Usage(_)) => e.to_string(),
            other => panic!("expected a usage error, got {other:?}"),
        }
    }

    #[test]
    fn shard_flag_parses_and_refuses_what_is_not_k_of_n() {
        assert_eq!(parse_flag("2/4").unwrap(), Shard { index: 2, count: 4, source: Source::Flag });
        assert_eq!(parse_flag("0/1").unwrap(), Shard { index: 0, count: 1, source: Source::Flag });
        for bad in ["4/4", "5/4", "0/0", "-1/4", "1", "a/b", "1/2/3", "", "/4", "1/", "1/2000000"] {
            let e = parse_flag(bad).unwrap_err().to_string();
            assert!(e.contains("--shard") && e.contains("K/N"), "{bad}: {e}");
        }
    }

    #[test]
    fn environment_defaults_slurm_then_kubernetes_and_the_flag_wins() {
        let slurm = [("SLURM_ARRAY_TASK_ID", "6"), ("SLURM_ARRAY_TASK_COUNT", "4"), ("SLURM_ARRAY_TASK_MIN", "5")];
        assert_eq!(resolved(None, None, &slurm).unwrap(), Some(Shard { index: 1, count: 4, source: Source::Slurm }));
        // No MIN: the array starts at 0.
        let plain = [("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_COUNT", "4")];
        assert_eq!(resolved(None, None, &plain).unwrap().map(|s| s.index), Some(3));
        // --array=1-7:2 (1, 3, 5, 7): task 5 is shard 2.
        let stepped = [
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ];
        assert_eq!(resolved(None, None, &stepped).unwrap().map(|s| (s.index, s.count)), Some((2, 4)));
        let k8s = [("JOB_COMPLETION_INDEX", "2"), ("FIRSTSHOT_SHARD_COUNT", "3")];
        assert_eq!(resolved(None, None, &k8s).unwrap(), Some(Shard { index: 2, count: 3, source: Source::Kubernetes }));
        assert_eq!(
            resolved(None, Some(5), &[("JOB_COMPLETION_INDEX", "4")]).unwrap(),
            Some(Shard { index: 4, count: 5, source: Source::Kubernetes })
        );
        // The flag wins over both; nothing set: no shard.
        assert_eq!(
            resolved(Some("0/1"), None, &slurm).unwrap().map(|s| (s.index, s.count, s.source)),
            Some((0, 1, Source::Flag))
        );
        assert_eq!(resolved(None, None, &[]).unwrap(), None);
        assert_eq!(resolved(None, None, &[("FIRSTSHOT_SHARD_COUNT", "4")]).unwrap(), None);
    }

    #[test]
    fn environment_errors_name_the_variable_and_the_fix() {
        let e = message(resolved(None, None, &[("SLURM_ARRAY_TASK_ID", "1")]));
        assert!(e.contains("SLURM_ARRAY_TASK_COUNT") && e.contains("--shard K/N"), "{e}");
        let e = message(resolved(None, None, &[("SLURM_ARRAY_TASK_ID", "x1"), ("SLURM_ARRAY_TASK_COUNT", "4")]));
        assert!(e.contains("SLURM_ARRAY_TASK_ID=x1"), "{e}");
        // --array=0,1,9: not evenly spaced, task 9 is beyond the count.
        let e = message(resolved(None, None, &[("SLURM_ARRAY_TASK_ID", "9"), ("SLURM_ARRAY_TASK_COUNT", "3")]));
        assert!(e.contains("SLURM_ARRAY_TASK_ID=9") && e.contains("--array=0-2"), "{e}");
        let e = message(resolved(None, None, &[("JOB_COMPLETION_INDEX", "1")]));
        assert!(
            e.contains("JOB_COMPLETION_INDEX=1") && e.contains("FIRSTSHOT_SHARD_COUNT") && e.contains("--shard-count"),
            "{e}"
        );
        let e = message(resolved(None, None, &[("JOB_COMPLETION_INDEX", "3"), ("FIRSTSHOT_SHARD_COUNT", "3")]));
        assert!(e.contains("FIRSTSHOT_SHARD_COUNT 3"), "{e}");
        let e = message(resolved(None, Some(0), &[("JOB_COMPLETION_INDEX", "0")]));
        assert!(e.contains("--shard-count 0"), "{e}");
        let e = message(resolved(None, Some(4), &[]));
        assert!(e.contains("--shard-count 4") && e.contains("JOB_COMPLETION_INDEX"), "{e}");
        let e = message(resolved(Some("1/4"), Some(3), &[]));
        assert!(e.contains("--shard-count 3") && e.contains("--shard 1/4"), "{e}");
    }

    #[test]
    fn shard_seeds_keep_one_shard_unchanged_and_differ_between_shards_and_runs() {
        assert_eq!(shard_seed(1, 0, 1), 1);
        assert_eq!(shard_seed(u64::MAX, 0, 1), u64::MAX);
        let mut seen = std::collections::HashSet::new();
        for seed in [0u64, 1, 2, 3, 1 << 40] {
            seen.insert(seed);
        }
        for seed in [0u64, 1, 2, 3, 1 << 40] {
            for k in 0..64 {
                let s = shard_seed(seed, k, 64);
                assert!(seen.insert(s), "seed {seed} shard {k}: {s} repeats another seed");
                // The same shard of the same run, the same seed, whatever else ran.
                assert_eq!(s, shard_seed(seed, k, 64));
            }
        }
        // Shard k's seed depends on k, not on how many shards there are (beyond one).
        assert_eq!(shard_seed(7, 2, 4), shard_seed(7, 2, 8));
    }

    #[test]
    fn shares_add_up_and_differ_by_at_most_one() {
        for total in [1u32, 3, 4, 7, 1000, 1001, 65_537] {
            for count in 1..=12u32.min(total) {
                let shares: Vec<u32> = (0..count).map(|k| share(total, k, count)).collect();
                assert_eq!(shares.iter().map(|&s| s as u64).sum::<u64>(), total as u64, "{total} over {count}");
                let (lo, hi) = (shares.iter().min().unwrap(), shares.iter().max().unwrap());
                assert!(hi - lo <= 1 && *lo > 0, "{total} over {count}: {shares:?}");
            }
        }
        assert_eq!((0..4).map(|k| share(1000, k, 4)).collect::<Vec<_>>(), [250; 4]);
        assert_eq!((0..3).map(|k| share(10, k, 3)).collect::<Vec<_>>(), [4, 3, 3]);
    }

    #[test]
    fn shard_paths_carry_k_of_n_before_the_extension() {
        let s = |index, count| Shard { index, count, source: Source::Flag };
        assert_eq!(s(2, 4).path(Path::new("out/cb.exr")), PathBuf::from("out/cb.shard-2-of-4.exr"));
        assert_eq!(s(3, 12).path(Path::new("s.json")), PathBuf::from("s.shard-03-of-12.json"));
        assert_eq!(s(0, 1).path(Path::new("out/cb.exr")), PathBuf::from("out/cb.exr"));
        assert_eq!(s(1, 2).path(Path::new("noext")), PathBuf::from("noext.shard-1-of-2"));
    }
}
