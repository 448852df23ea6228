//! Shards and `firstshot merge` against docs/DISTRIBUTED.md and docs/CLI.md: one shard is
//! the unsharded run, merges are bit-identical in any order and grouping, mixed or repeated
//! parts are refused (exit 2, nothing written), missing shards are reported, and the Slurm
//! and Kubernetes variables give the shard `--shard` gives. Each test runs the built binary
//! in a temporary folder of its own.

mod common;

use common::bin::{stderr, stdout};
use common::scratch::{Scratch, listing};
use common::shards::{assert_same_pixels, ok_in, pixel_bits, run_in, small_cornell_args};
use firstshot::image::Image;
use firstshot::merge::Part;
use firstshot::shard::{Shard, ShardRun, Source};
use std::path::{Path, PathBuf};

fn args_with<'a>(base: &'a [String], more: &[&'a str]) -> Vec<&'a str> {
    base.iter().map(String::as_str).chain(more.iter().copied()).collect()
}

fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}\n{text}", path.display()))
}

/// A part made without a GPU: shard `index` of `count`, a `width` x 2 image after `samples`
/// estimates in each half of its image sum (direct light, then gathered: twice as bright).
fn fake_part(dir: &Path, name: &str, fingerprint: u64, index: u32, count: u32, width: u32, samples: f32) -> PathBuf {
    let run = ShardRun {
        shard: Shard { index, count, source: Source::Flag },
        run_seed: 1,
        seed: firstshot::shard::shard_seed(1, index, count),
        fingerprint,
    };
    let sums: Vec<[f32; 4]> = (0..2 * width * 2)
        .map(|i| {
            let v = 0.1 * (i % (width * 2) + 1) as f32 + index as f32;
            let v = if i < width * 2 { v } else { 2.0 * v };
            [v * samples, 2.0 * v * samples, 0.5 * v * samples + 1e-3, samples]
        })
        .collect();
    let part = Part::of_shard(&run, "scene.toml", width, 2, &sums, samples as u32).expect("a part");
    let path = dir.join(name);
    part.write(&path).expect("write the part");
    path
}

fn p(path: &Path) -> String {
    path.display().to_string()
}

/// Refused before anything is written: bad K/N, shard variables that do not give one, a
/// step count that leaves a shard without a step. No GPU is needed: the checks come first.
#[test]
fn test01_shard_refusals_exit_2_name_the_cause_and_write_nothing() {
    let scratch = Scratch::new("shards", "refusals");
    let base = small_cornell_args(16);
    type Case<'a> = (Vec<&'a str>, Vec<(&'a str, &'a str)>, &'a str);
    let cases: Vec<Case> = vec![
        (vec!["--shard", "4/4"], vec![], "--shard 4/4"),
        (vec!["--shard", "1"], vec![], "K/N"),
        (vec!["--shard", "0/0"], vec![], "--shard 0/0"),
        (vec!["--iterations", "3", "--shard", "0/4"], vec![], "--iterations 3"),
        (vec!["--shard-count", "4"], vec![], "JOB_COMPLETION_INDEX"),
        (vec!["--shard", "1/4", "--shard-count", "3"], vec![], "--shard-count 3"),
        (vec![], vec![("SLURM_ARRAY_TASK_ID", "2")], "SLURM_ARRAY_TASK_COUNT"),
        (vec![], vec![("SLURM_ARRAY_TASK_ID", "7"), ("SLURM_ARRAY_TASK_COUNT", "4")], "SLURM_ARRAY_TASK_ID=7"),
        (vec![], vec![("JOB_COMPLETION_INDEX", "1")], "FIRSTSHOT_SHARD_COUNT"),
        (vec![], vec![("JOB_COMPLETION_INDEX", "4"), ("FIRSTSHOT_SHARD_COUNT", "4")], "JOB_COMPLETION_INDEX=4"),
    ];
    for (more, env, part) in cases {
        let dir = scratch.dir("out");
        let out = p(&dir.join("x.exr"));
        let stats = p(&dir.join("s.json"));
        let args = args_with(&base, &[&more[..], &["--out", &out, "--stats", &stats]].concat());
        let o = run_in(&dir, &args, &env);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{more:?} {env:?}: stderr:\n{err}");
        assert!(err.contains(part), "{more:?} {env:?}: stderr lacks {part:?}:\n{err}");
        assert_eq!(err.lines().count(), 1, "{more:?} {env:?}: not one line:\n{err}");
        assert_eq!(listing(&dir), Vec::<String>::new(), "{more:?} {env:?} wrote files");
    }
}

/// Shard 0 of 1 is the unsharded run bit for bit (the same EXR bytes), and a merge of its
/// one part gives its pixels bit for bit.
#[test]
fn test02_one_shard_is_the_unsharded_run() {
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("shards", "one");
    let base = small_cornell_args(32);
    let dir = scratch.dir("run");
    ok_in(&dir, &args_with(&base, &["--iterations", "6", "--out", "plain.exr"]), &[]);
    ok_in(&dir, &args_with(&base, &["--iterations", "6", "--out", "one.exr", "--shard", "0/1"]), &[]);
    assert_eq!(listing(&dir), ["one.exr", "one.part", "one.png", "plain.exr", "plain.png"]);
    let (plain, one) = (std::fs::read(dir.join("plain.exr")).unwrap(), std::fs::read(dir.join("one.exr")).unwrap());
    assert!(plain == one, "shard 0/1 wrote other EXR bytes than the unsharded run");
    ok_in(&dir, &["merge", "merged.exr", "one.part", "--quiet"], &[]);
    assert_same_pixels(&dir.join("merged.exr"), &dir.join("plain.exr"));
    let stats = read_json(&dir.join("merged.stats.json"));
    assert_eq!(stats["iterations"], 6);
    assert_eq!(stats["shards"], serde_json::json!([0]));
    assert_eq!(stats["missing_shards"], serde_json::json!([]));
}

/// Three shards: their steps add up to --iterations, their seeds differ, and every order and
/// grouping of the merge gives the same bits, which are the steps-weighted mean of the
/// shards' images.
#[test]
fn test03_merges_are_bit_identical_in_any_order_and_grouping() {
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("shards", "order");
    let base = small_cornell_args(32);
    let dir = scratch.dir("run");
    for k in 0..3 {
        let shard = format!("{k}/3");
        ok_in(
            &dir,
            // A direct-light estimate every step, so that both halves of a shard's image
            // sum hold its steps and the merge is the steps-weighted mean of the images.
            &args_with(
                &base,
                &[
                    "--iterations",
                    "10",
                    "--window-steps",
                    "1",
                    "--out",
                    "cb.exr",
                    "--shard",
                    &shard,
                    "--stats",
                    "s.json",
                ],
            ),
            &[],
        );
    }
    let stats: Vec<serde_json::Value> =
        (0..3).map(|k| read_json(&dir.join(format!("s.shard-{k}-of-3.json")))).collect();
    let steps: Vec<u64> = stats.iter().map(|s| s["iterations"].as_u64().unwrap()).collect();
    assert_eq!(steps, [4, 3, 3], "10 steps over 3 shards");
    let seeds: std::collections::HashSet<u64> = stats.iter().map(|s| s["seed"].as_u64().unwrap()).collect();
    assert_eq!(seeds.len(), 3, "each shard has its own seed");
    for (k, s) in stats.iter().enumerate() {
        assert_eq!(s["shard"]["index"], k);
        assert_eq!(s["shard"]["count"], 3);
        assert_eq!(s["shard"]["run_seed"], 1);
        assert_eq!(s["shard"]["fingerprint"], stats[0]["shard"]["fingerprint"], "one run, one fingerprint");
    }
    let part = |k: u32| format!("cb.shard-{k}-of-3.part");
    let orders = [[0, 1, 2], [2, 1, 0], [1, 2, 0]];
    for (i, order) in orders.iter().enumerate() {
        let out = format!("m{i}.exr");
        let args: Vec<String> =
            ["merge".to_string(), out, "--quiet".into()].into_iter().chain(order.iter().map(|&k| part(k))).collect();
        ok_in(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>(), &[]);
    }
    let bytes = |name: &str| std::fs::read(dir.join(name)).unwrap();
    for (i, order) in orders.iter().enumerate().skip(1) {
        assert!(bytes(&format!("m{i}.exr")) == bytes("m0.exr"), "order {order:?}: other EXR bytes");
        assert!(bytes(&format!("m{i}.part")) == bytes("m0.part"), "order {order:?}: other part bytes");
    }
    // A merge of merges: (2 + 0) then 1, and the shards' own .exr names for their parts.
    ok_in(&dir, &["merge", "a.exr", &part(2), "cb.shard-0-of-3.exr", "--quiet"], &[]);
    ok_in(&dir, &["merge", "b.exr", "a.part", &part(1), "--quiet"], &[]);
    assert!(bytes("b.part") == bytes("m0.part"), "a merge of merges holds other sums");
    assert_same_pixels(&dir.join("b.exr"), &dir.join("m0.exr"));
    // The merged image is the steps-weighted mean of the shards' images (to f32 rounding),
    // and none of them.
    let merged = Image::read_exr(&dir.join("m0.exr")).unwrap();
    let shards: Vec<Image> =
        (0..3).map(|k| Image::read_exr(&dir.join(format!("cb.shard-{k}-of-3.exr"))).unwrap()).collect();
    let mut worst = 0.0f64;
    for (i, m) in merged.pixels.iter().enumerate() {
        for (c, &value) in m.iter().enumerate() {
            let mean: f64 =
                shards.iter().zip(&steps).map(|(s, &n)| s.pixels[i][c] as f64 * n as f64).sum::<f64>() / 10.0;
            worst = worst.max((value as f64 - mean).abs() / mean.abs().max(1e-3));
        }
    }
    assert!(worst < 1e-5, "merged pixels stray {worst:e} from the weighted mean of the shards");
    for k in 0..3 {
        assert_ne!(
            pixel_bits(&dir.join(format!("cb.shard-{k}-of-3.exr"))),
            pixel_bits(&dir.join("m0.exr")),
            "shard {k}"
        );
    }
    let m = read_json(&dir.join("m0.stats.json"));
    assert_eq!((m["iterations"].as_u64(), m["complete"].as_bool()), (Some(10), Some(true)));
}

/// Parts of another run (scene or flags), shard count or image size, a shard given twice, a
/// damaged or missing file: exit 2, naming the part, and nothing written.
#[test]
fn test04_mismatched_parts_are_refused_naming_the_part() {
    let scratch = Scratch::new("shards", "mismatch");
    let parts = scratch.dir("parts");
    let a = fake_part(&parts, "a.part", 7, 0, 4, 3, 5.0);
    let cases: Vec<(PathBuf, &str)> = vec![
        (fake_part(&parts, "other-run.part", 8, 1, 4, 3, 5.0), "another run"),
        (fake_part(&parts, "other-count.part", 7, 1, 3, 3, 5.0), "shard count"),
        (fake_part(&parts, "other-size.part", 7, 1, 4, 4, 5.0), "image size"),
        (fake_part(&parts, "again.part", 7, 0, 4, 3, 9.0), "both hold shard 0"),
        (parts.join("missing.part"), "missing.part"),
        (parts.join("junk.part"), "not a usable firstshot part"),
    ];
    std::fs::write(parts.join("junk.part"), b"FSPART01 but nothing else of one").unwrap();
    for (bad, part) in &cases {
        let out = scratch.dir("out");
        let o = run_in(&out, &["merge", "m.exr", &p(&a), &p(bad)], &[]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{}: stderr:\n{err}", bad.display());
        assert!(
            err.contains(&p(bad)) && err.contains(part),
            "{}: stderr lacks the part or {part:?}:\n{err}",
            bad.display()
        );
        assert_eq!(listing(&out), Vec::<String>::new(), "{}: something was written", bad.display());
        assert_eq!(stdout(&o), "");
    }
    // A merged part that already holds a shard given again.
    let out = scratch.dir("out");
    let b = fake_part(&parts, "b.part", 7, 1, 4, 3, 5.0);
    ok_in(&out, &["merge", "ab.exr", &p(&a), &p(&b), "--quiet"], &[]);
    let before = listing(&out);
    let o = run_in(&out, &["merge", "again.exr", "ab.part", &p(&b)], &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("ab.part") && stderr(&o).contains("both hold shard 1"), "{}", stderr(&o));
    assert_eq!(listing(&out), before, "a refused merge wrote something");
    // Not an EXR to write.
    let o = run_in(&out, &["merge", "m.png", &p(&a)], &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("m.png"), "{}", stderr(&o));
    assert_eq!(listing(&out), before);
}

/// Missing shards are a warning (stderr and stats) and the partial merge is valid: the rest
/// merged in later gives the bits of one merge of all. `--complete` refuses it instead.
#[test]
fn test05_missing_shards_are_reported_and_can_be_merged_in_later() {
    let scratch = Scratch::new("shards", "missing");
    let parts = scratch.dir("parts");
    let shard: Vec<PathBuf> =
        (0..4).map(|k| fake_part(&parts, &format!("s{k}.part"), 7, k, 4, 3, 5.0 + k as f32)).collect();
    let out = scratch.dir("out");
    let o = run_in(&out, &["merge", "--complete", "m.exr", &p(&shard[0]), &p(&shard[2])], &[]);
    assert_eq!(o.status.code(), Some(2), "--complete with missing shards: {}", stderr(&o));
    assert!(stderr(&o).contains("1, 3 of 4"), "{}", stderr(&o));
    assert_eq!(listing(&out), Vec::<String>::new());

    let o = ok_in(&out, &["merge", "m.exr", &p(&shard[2]), &p(&shard[0])], &[]);
    let err = stderr(&o);
    assert!(err.contains("warning") && err.contains("shards 1, 3 of 4 are missing"), "{err}");
    assert_eq!(listing(&out), ["m.exr", "m.part", "m.png", "m.stats.json"]);
    let stats = read_json(&out.join("m.stats.json"));
    assert_eq!(stats["missing_shards"], serde_json::json!([1, 3]));
    assert_eq!(stats["shards"], serde_json::json!([0, 2]));
    assert_eq!(stats["complete"], false);
    assert_eq!(stats["iterations"], 5 + 7);

    ok_in(&out, &["merge", "later.exr", "m.part", &p(&shard[3]), &p(&shard[1]), "--complete", "--quiet"], &[]);
    ok_in(
        &out,
        &["merge", "all.exr", &p(&shard[1]), &p(&shard[3]), &p(&shard[0]), &p(&shard[2]), "--stats", "all.json"],
        &[],
    );
    let bytes = |name: &str| std::fs::read(out.join(name)).unwrap();
    assert!(bytes("later.part") == bytes("all.part"), "a merge in two goes holds other sums");
    assert_same_pixels(&out.join("later.exr"), &out.join("all.exr"));
    let all = read_json(&out.join("all.json"));
    assert_eq!((all["complete"].as_bool(), all["samples"].as_u64()), (Some(true), Some(5 + 6 + 7 + 8)));
    // The image is the sum over the estimates: pixel 0, red, is sum_k (0.1 + k) n_k / sum n_k
    // in the direct half and twice that in the gathered half.
    let image = Image::read_exr(&out.join("all.exr")).unwrap();
    let expected: f64 = 3.0 * (0..4).map(|k| ((0.1f32 + k as f32) * (5.0 + k as f32)) as f64).sum::<f64>() / 26.0;
    assert!(
        (image.pixels[0][0] as f64 - expected).abs() < 1e-6 * expected,
        "{} against {expected}",
        image.pixels[0][0]
    );
}

/// A Slurm array task and a Kubernetes Indexed Job's pod render the shard that `--shard`
/// names, under the same file names; `--shard` wins over the variables.
#[test]
fn test06_slurm_and_kubernetes_variables_give_the_shard() {
    if common::gpu().is_none() {
        return;
    }
    let scratch = Scratch::new("shards", "environment");
    let base = small_cornell_args(16);
    let run = |name: &str, more: &[&str], env: &[(&str, &str)]| {
        let dir = scratch.dir(name);
        ok_in(&dir, &args_with(&base, &[&["--iterations", "6", "--out", "cb.exr"], more].concat()), env);
        dir
    };
    let flag = run("flag", &["--shard", "1/2"], &[]);
    let slurm = run(
        "slurm",
        &[],
        &[("SLURM_ARRAY_TASK_ID", "4"), ("SLURM_ARRAY_TASK_MIN", "3"), ("SLURM_ARRAY_TASK_COUNT", "2")],
    );
    let k8s = run("k8s", &[], &[("JOB_COMPLETION_INDEX", "1"), ("FIRSTSHOT_SHARD_COUNT", "2")]);
    let k8s_flag = run("k8s-flag", &["--shard-count", "2"], &[("JOB_COMPLETION_INDEX", "1")]);
    let wins = run("wins", &["--shard", "1/2"], &[("SLURM_ARRAY_TASK_ID", "0"), ("SLURM_ARRAY_TASK_COUNT", "2")]);
    let files = ["cb.shard-1-of-2.exr", "cb.shard-1-of-2.part", "cb.shard-1-of-2.png"];
    for dir in [&flag, &slurm, &k8s, &k8s_flag, &wins] {
        assert_eq!(listing(dir), files, "{}", dir.display());
        let same = std::fs::read(dir.join(files[1])).unwrap() == std::fs::read(flag.join(files[1])).unwrap();
        assert!(same, "{}: another part than --shard 1/2", dir.display());
        assert_same_pixels(&dir.join(files[0]), &flag.join(files[0]));
    }
    // And shard 0 is another chain.
    let other = run("other", &["--shard", "0/2"], &[]);
    assert_ne!(pixel_bits(&other.join("cb.shard-0-of-2.exr")), pixel_bits(&flag.join(files[0])));
}
