//! The Kubernetes manifests of docs/DISTRIBUTED.md (`tools/k8s/*.yaml`) against the schemas of
//! Kubernetes itself, offline: `kubernetes-validate --strict` (tools/k8s/setup.sh installs it
//! into .venv/), which must also reject broken copies, so that a validator that passes
//! everything cannot pass this test. Then the manifests must agree with each other and with
//! firstshot: an Indexed Job whose completions are the shard count the pods read, writing on
//! a ReadWriteMany volume that the merge Job mounts and globs with the shards' file names.
//!
//! Without kubernetes-validate the test is skipped visibly; with
//! `FIRSTSHOT_REQUIRE_KUBERNETES=1` (CI) that is a failure.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// kubernetes-validate: FIRSTSHOT_KUBERNETES_VALIDATE, else .venv/bin, else PATH.
fn validator() -> Option<PathBuf> {
    let candidates = [
        std::env::var_os("FIRSTSHOT_KUBERNETES_VALIDATE").map(PathBuf::from),
        Some(repo(".venv/bin/kubernetes-validate")),
        Some(PathBuf::from("kubernetes-validate")),
    ];
    candidates
        .into_iter()
        .flatten()
        .find(|c| Command::new(c).arg("--version").output().is_ok_and(|o| o.status.success()))
}

/// Runs the validator on `files` in strict mode: (passed, its output).
fn validate(validator: &Path, files: &[&Path]) -> (bool, String) {
    let o = Command::new(validator).arg("--strict").args(files).output().expect("running kubernetes-validate");
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    (o.status.success(), text)
}

/// The YAML documents of `file` as JSON, through the validator's own Python (it has PyYAML).
fn documents(validator: &Path, file: &Path) -> Vec<Value> {
    let script = std::fs::read_to_string(validator).unwrap_or_default();
    let python = script
        .lines()
        .next()
        .and_then(|l| l.strip_prefix("#!"))
        .map(|p| p.trim().to_string())
        .filter(|p| Path::new(p).exists())
        .unwrap_or_else(|| "python3".into());
    let code = "import sys, json, yaml; print(json.dumps([d for d in yaml.safe_load_all(open(sys.argv[1])) if d]))";
    let o = Command::new(&python).args(["-c", code]).arg(file).output().expect("running Python");
    assert!(o.status.success(), "{python}: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("the documents as JSON")
}

fn find<'a>(docs: &'a [Value], kind: &str, name: &str) -> &'a Value {
    docs.iter()
        .find(|d| d["kind"] == kind && d["metadata"]["name"] == name)
        .unwrap_or_else(|| panic!("no {kind} {name} in {docs:?}"))
}

/// The one container of a Job's pod.
fn container(job: &Value) -> &Value {
    let containers = job["spec"]["template"]["spec"]["containers"].as_array().expect("containers");
    assert_eq!(containers.len(), 1, "{job}");
    &containers[0]
}

fn strings(v: &Value) -> Vec<&str> {
    v.as_array().map(|a| a.iter().filter_map(Value::as_str).collect()).unwrap_or_default()
}

/// The claim behind the volume mounted at `dir` (a prefix of `path`).
fn claim_of<'a>(job: &'a Value, path: &str) -> &'a str {
    let mounts = container(job)["volumeMounts"].as_array().expect("volumeMounts");
    let mount = mounts
        .iter()
        .find(|m| m["mountPath"].as_str().is_some_and(|d| path.starts_with(&format!("{}/", d.trim_end_matches('/')))))
        .unwrap_or_else(|| panic!("{path} is on no mounted volume: {mounts:?}"));
    let volumes = job["spec"]["template"]["spec"]["volumes"].as_array().expect("volumes");
    let volume = volumes.iter().find(|v| v["name"] == mount["name"]).expect("the mounted volume");
    volume["persistentVolumeClaim"]["claimName"].as_str().expect("a persistentVolumeClaim")
}

/// Whether `text` matches `pattern`, whose `*` stand for any characters (a shell glob's).
fn glob_match(pattern: &str, text: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == text,
        Some((head, rest)) => text.starts_with(head) && (head.len()..=text.len()).any(|i| glob_match(rest, &text[i..])),
    }
}

#[test]
fn kubernetes_manifests_pass_the_schemas_and_agree_with_firstshot() {
    let Some(validator) = validator() else {
        if std::env::var("FIRSTSHOT_REQUIRE_KUBERNETES").is_ok_and(|v| v == "1") {
            panic!("FIRSTSHOT_REQUIRE_KUBERNETES=1 but no kubernetes-validate: run tools/k8s/setup.sh");
        }
        eprintln!("SKIPPED (no kubernetes-validate: tools/k8s/setup.sh installs it)");
        return;
    };
    let (shards_file, merge_file) = (repo("tools/k8s/firstshot-shards.yaml"), repo("tools/k8s/firstshot-merge.yaml"));
    let (ok, out) = validate(&validator, &[&shards_file, &merge_file]);
    assert!(ok, "the manifests fail the Kubernetes schemas:\n{out}");
    for resource in ["persistentvolumeclaim/firstshot-parts", "job/firstshot-shards", "job/firstshot-merge"] {
        assert!(out.contains(&format!("passed for resource {resource}")), "{resource} was not validated:\n{out}");
    }

    // Broken copies must fail: a misspelt field, a wrong type, an unknown completion mode.
    let text = std::fs::read_to_string(&shards_file).unwrap();
    let dir = std::env::temp_dir().join(format!("firstshot-kubernetes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (what, from, to) in [
        ("misspelt field", "completionMode: Indexed", "completionMod: Indexed"),
        ("wrong type", "completions: 4", "completions: four"),
        ("misplaced field", "      restartPolicy: Never", "      restartPolicy: Never\n      completions: 4"),
    ] {
        assert!(text.contains(from), "{from:?} is not in {}", shards_file.display());
        let broken = dir.join(format!("{}.yaml", what.replace(' ', "-")));
        std::fs::write(&broken, text.replacen(from, to, 1)).unwrap();
        let (ok, out) = validate(&validator, &[&broken]);
        assert!(!ok, "{what}: a broken manifest passed:\n{out}");
    }
    let _ = std::fs::remove_dir_all(&dir);

    // The shards: an Indexed Job of N completions whose pods read N, writing to shared storage.
    let docs = documents(&validator, &shards_file);
    let job = find(&docs, "Job", "firstshot-shards");
    assert_eq!(job["apiVersion"], "batch/v1");
    assert_eq!(job["spec"]["completionMode"], "Indexed");
    let n = job["spec"]["completions"].as_u64().expect("completions");
    assert!(n >= 2, "completions {n}");
    let shard = container(job);
    let count = shard["env"]
        .as_array()
        .and_then(|e| e.iter().find(|v| v["name"] == "FIRSTSHOT_SHARD_COUNT"))
        .and_then(|v| v["value"].as_str())
        .expect("FIRSTSHOT_SHARD_COUNT");
    assert_eq!(count, n.to_string(), "FIRSTSHOT_SHARD_COUNT is not spec.completions");
    let command = strings(&shard["command"]);
    assert_eq!(command.first(), Some(&"firstshot"), "{command:?}");
    assert!(
        !command.iter().any(|a| a.starts_with("--shard")),
        "the index must come from JOB_COMPLETION_INDEX: {command:?}"
    );
    let out = command.iter().position(|&a| a == "--out").and_then(|i| command.get(i + 1)).expect("--out");
    assert!(out.ends_with(".exr"), "{out}");
    let claim = claim_of(job, out);
    let pvc = find(&docs, "PersistentVolumeClaim", claim);
    assert!(strings(&pvc["spec"]["accessModes"]).contains(&"ReadWriteMany"), "pods on many nodes share {claim}");
    // The names a pod writes, as firstshot makes them.
    let run = firstshot::shard::resolve(None, None, &|v| match v {
        "JOB_COMPLETION_INDEX" => Some((n - 1).to_string()),
        "FIRSTSHOT_SHARD_COUNT" => Some(count.to_string()),
        _ => None,
    })
    .expect("the pods' variables give a shard")
    .expect("a shard");
    assert_eq!((run.index as u64, run.count as u64), (n - 1, n));
    let parts: Vec<String> = (0..run.count)
        .map(|k| {
            let shard = firstshot::shard::Shard { index: k, ..run };
            shard.path(Path::new(out)).with_extension("part").display().to_string()
        })
        .collect();

    // The merge: the same volume, every shard's part (and not its own output), the whole run.
    let docs = documents(&validator, &merge_file);
    let merge = find(&docs, "Job", "firstshot-merge");
    let script = strings(&container(merge)["command"]).join(" ");
    assert!(script.contains(&format!("firstshot merge --complete {out} ")), "{script}");
    let glob = script.split_whitespace().last().expect("the parts");
    for part in &parts {
        assert!(glob_match(glob, part), "{glob} misses {part}");
    }
    let merged = Path::new(out).with_extension("part").display().to_string();
    assert!(!glob_match(glob, &merged), "{glob} takes the merge's own {merged}");
    assert_eq!(claim_of(merge, out), claim, "the merge mounts another volume");
}
