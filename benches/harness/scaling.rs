//! Scaling: step time against patch count (the Sierpinski scene at levels 3 to 7, built in
//! memory from scenes/sierpinski.toml) and against bundle resolution, with the fragments of
//! a step and each stage's time, so the growth can be read per stage; then, as whole
//! `firstshot` processes, the large series: the Sierpinski scene cut finer (`--patch-sizes`,
//! up to 10 M patches) and the Cornell box at large images (`--images`, up to 8K), with the
//! memory predicted and the process's peak.

use crate::session::{IDLE, Session, merge_repeated_stages, own_time};
use crate::stats::{Summary, median, summary};
use crate::svg::{Plot, Series};
use crate::{Config, LoadedScene, Machine, Slot, guarded, print_table, scene_path, write_json, write_text};
use firstshot::gpu::Context;
use firstshot::gpu::profile::StageTimer;
use serde::Serialize;
use std::collections::BTreeMap;

#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub study: &'static str,
    pub level: u32,
    pub bundle_resolution: u32,
    pub patches: usize,
    pub first_shot_ms: f64,
    /// Per-repeat medians of the time per step (batches of `BATCH`).
    pub step_ms: Summary,
    pub fragments_per_step: f64,
    /// Median time of each stage (timestamps where the device has them, else wall).
    pub stage_ms: BTreeMap<String, f64>,
    pub error: Option<String>,
}

#[derive(Serialize)]
struct Report<'a> {
    machine: &'a Machine,
    quick: bool,
    adapter: &'a Slot,
    steps: u32,
    repeats: usize,
    rows: &'a [Row],
    /// The whole-process runs: patch sizes and image sizes.
    process_rows: &'a [ProcessRow],
}

const BATCH: u32 = 4;

/// The Sierpinski scene at `level`: its text with the fractal's level replaced.
fn sierpinski(level: u32) -> Result<LoadedScene, String> {
    let path = scene_path("sierpinski");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let marker = "level = 6";
    if !text.contains(marker) {
        return Err(format!("{}: no `{marker}` to change", path.display()));
    }
    let scene = firstshot::scene::load::load_str(&text.replacen(marker, &format!("level = {level}"), 1), &path)
        .map_err(|e| e.to_string())?;
    let patches = firstshot::scene::tessellate(&scene, scene.settings.patch_size).map_err(|e| e.to_string())?;
    Ok(LoadedScene { name: format!("sierpinski level {level}"), scene, patches })
}

fn measure(
    config: &Config,
    ctx: &Context,
    study: &'static str,
    level: u32,
    resolution: Option<u32>,
) -> Result<Row, String> {
    let s = sierpinski(level)?;
    let mut options = config.options(&s.scene);
    if let Some(r) = resolution {
        options.bundle_resolution = Some(r);
    }
    let mut session = Session::new(ctx, &s.scene, &s.patches, &options).map_err(|e| e.to_string())?;
    let first_shot_ms = session.first_shot.as_ref().map_or(0.0, |f| f.ms);
    session.time_batches(1, 2).map_err(|e| e.to_string())?;
    let batches = config.scaling_steps.div_ceil(BATCH) as usize;
    let mut per_repeat = Vec::new();
    let mut fragments = Vec::new();
    for _ in 0..config.repeats {
        per_repeat.push(median(&session.time_batches(batches, BATCH).map_err(|e| e.to_string())?.step_ms));
        fragments.push(session.fragments().map_err(|e| e.to_string())? as f64);
    }
    let timer = StageTimer::new(ctx, 128);
    let mut stage_times: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for _ in 0..2 {
        let (times, f) = session.profile_step(&timer).map_err(|e| e.to_string())?;
        fragments.push(f as f64);
        let idle = times.iter().find(|t| t.name == IDLE).map_or(0.0, |t| t.wall_ms);
        // A stage that runs several times a step (one per bundle) counts with its sum.
        for (t, runs) in merge_repeated_stages(times).iter().filter(|(t, _)| t.name != IDLE) {
            let ms = own_time(t.wall_ms, t.gpu_ms, *runs as f64 * idle).0;
            stage_times.entry(t.name.to_string()).or_default().push(ms);
        }
    }
    Ok(Row {
        study,
        level,
        bundle_resolution: options.bundle_resolution_for(&s.scene, &s.patches),
        patches: s.patches.patches.len(),
        first_shot_ms,
        step_ms: summary(&per_repeat),
        fragments_per_step: median(&fragments),
        stage_ms: stage_times.into_iter().map(|(k, v)| (k, median(&v))).collect(),
        error: None,
    })
}

pub fn run(config: &Config, machine: &Machine, slots: &[Slot]) -> Result<(), String> {
    println!("\n== scaling");
    let slot = slots.first().ok_or("no adapter")?;
    if slots.len() > 1 {
        eprintln!("scaling runs on the first selected adapter only: {}", slot.label());
    }
    let ctx = slot.open(config.timestamps)?;
    let level3 = sierpinski(3)?;
    let default_resolution = config.options(&level3.scene).bundle_resolution_for(&level3.scene, &level3.patches);
    let mut plan: Vec<(&'static str, u32, Option<u32>)> = config.levels.iter().map(|&l| ("patches", l, None)).collect();
    plan.extend(config.resolutions.iter().map(|&r| ("resolution", 6, Some(r))));
    let mut rows = Vec::new();
    for (study, level, resolution) in plan {
        let r = resolution.unwrap_or(default_resolution);
        eprintln!("{study}: level {level}, bundle resolution {r}");
        let row = guarded(|| measure(config, &ctx, study, level, resolution)).unwrap_or_else(|e| {
            eprintln!("  FAILED: {e}");
            Row {
                study,
                level,
                bundle_resolution: r,
                patches: 0,
                first_shot_ms: f64::NAN,
                step_ms: summary(&[]),
                fragments_per_step: f64::NAN,
                stage_ms: BTreeMap::new(),
                error: Some(e),
            }
        });
        if row.error.is_none() {
            eprintln!(
                "  {} patches, {:.1} ms per step, {:.0} fragments",
                row.patches, row.step_ms.median, row.fragments_per_step
            );
        }
        rows.push(row);
    }
    print_rows(&rows);
    let process_rows = process_rows(config, slot);
    print_process_rows(&process_rows);
    let path = write_json(
        &config.out,
        "scaling.json",
        &Report {
            machine,
            quick: config.quick,
            adapter: slot,
            steps: config.scaling_steps,
            repeats: config.repeats,
            rows: &rows,
            process_rows: &process_rows,
        },
    )?;
    write_plots(config, slot, &rows)?;
    println!("wrote {} and scaling_patches.svg, scaling_resolution.svg", path.display());
    if rows.iter().all(|r| r.error.is_some()) && process_rows.iter().all(|r| r.error.is_some()) {
        return Err("nothing measured".into());
    }
    Ok(())
}

fn print_rows(rows: &[Row]) {
    let stages: Vec<String> = rows.iter().find(|r| r.error.is_none()).map_or(vec![], |r| {
        // Product order, not alphabetical.
        let order = [
            "clear",
            "reflect",
            "visibility",
            "transfer",
            "finalize",
            "camera",
            "light_windows",
            "direct",
            "gather",
            "gather_edges",
            "gather_first_bounce",
        ];
        order.iter().filter(|s| r.stage_ms.contains_key(**s)).map(|s| s.to_string()).collect()
    });
    let mut headers = vec!["study", "level", "bundle", "patches", "first shot ms", "step ms", "frags/step", "ns/frag"];
    headers.extend(stages.iter().map(String::as_str));
    let table: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let mut row = vec![r.study.to_string(), r.level.to_string(), r.bundle_resolution.to_string()];
            if let Some(e) = &r.error {
                row.push(format!("FAILED: {e}"));
                return row;
            }
            row.extend([
                r.patches.to_string(),
                format!("{:.0}", r.first_shot_ms),
                crate::spread(&r.step_ms, 1),
                format!("{:.2}M", r.fragments_per_step / 1e6),
                format!("{:.0}", r.step_ms.median * 1e6 / r.fragments_per_step),
            ]);
            row.extend(stages.iter().map(|s| r.stage_ms.get(s).map_or("-".into(), |v| format!("{v:.1}"))));
            row
        })
        .collect();
    println!("(stage columns: ms per stage of one step, each submitted alone)");
    print_table(&headers, &table);
}

fn write_plots(config: &Config, slot: &Slot, rows: &[Row]) -> Result<(), String> {
    let subtitle = format!(
        "{} ({}, {}); median of {} repeats of {} steps; stages timed alone",
        slot.adapter.name, slot.adapter.backend, slot.adapter.device_type, config.repeats, config.scaling_steps
    );
    let ok = |study: &'static str| rows.iter().filter(move |r| r.study == study && r.error.is_none());
    let stage_series = |study: &'static str, x: &dyn Fn(&Row) -> f64| -> Vec<Series> {
        let mut out = vec![Series {
            label: "whole step".into(),
            points: ok(study).map(|r| (x(r), r.step_ms.median)).collect(),
            dashed: false,
        }];
        for stage in ["transfer", "visibility", "direct", "gather", "reflect"] {
            out.push(Series {
                label: format!("{stage} (alone)"),
                points: ok(study).filter_map(|r| Some((x(r), *r.stage_ms.get(stage)?))).collect(),
                dashed: true,
            });
        }
        out
    };
    let patches = Plot {
        title: "Step time against patch count (Sierpinski levels)".into(),
        subtitle: subtitle.clone(),
        x_label: "patches".into(),
        y_label: "ms".into(),
        log_x: false,
        log_y: false,
        series: stage_series("patches", &|r| r.patches as f64),
    };
    let resolution = Plot {
        title: "Step time against bundle resolution (Sierpinski level 6)".into(),
        subtitle,
        x_label: "bundle resolution (pixels per edge)".into(),
        y_label: "ms".into(),
        log_x: true,
        log_y: true,
        series: stage_series("resolution", &|r| r.bundle_resolution as f64),
    };
    write_text(&config.out, "scaling_patches.svg", &crate::svg::render(&patches))?;
    write_text(&config.out, "scaling_resolution.svg", &crate::svg::render(&resolution))?;
    Ok(())
}

/// One whole-process run of the scaling study's large series: a scene at a patch size
/// (`patch_size`) or an image size (`image`), two image steps and no burn-in, as
/// `firstshot SCENE ... --iterations 2 --burn-in 0 --stats` reports it; repeated, medians.
#[derive(Debug, Clone, Serialize)]
pub struct ProcessRow {
    pub study: &'static str,
    pub scene: String,
    pub patch_size: Option<f64>,
    pub width: u32,
    pub height: u32,
    pub patches: u64,
    pub first_shot_ms: f64,
    pub first_shot_pairs: u64,
    /// The run's median step (`iteration_ms_median`), per repeat.
    pub step_ms: Summary,
    pub upload_ms: f64,
    /// The image sums brought back and averaged: `image_ms` less the steps.
    pub read_back_ms: f64,
    /// Predicted GPU bytes (`memory.device_bytes`).
    pub device_bytes: u64,
    /// Predicted host bytes, with the GPU's where it is the host's (`total_host_bytes`).
    pub total_host_bytes: u64,
    /// The process's resident peak (`memory.peak_rss_bytes`), the largest of the repeats.
    pub peak_rss_bytes: Option<u64>,
    /// Wall time of the whole process, per repeat.
    pub wall_s: Summary,
    pub error: Option<String>,
}

/// Runs `firstshot` on `scene` with `extra` flags `repeats` times and reads its stats.
fn process_row(
    config: &Config,
    slot: &Slot,
    study: &'static str,
    scene: &str,
    patch_size: Option<f64>,
    size: (u32, u32),
) -> Result<ProcessRow, String> {
    use crate::peers::{adapter_arg, firstshot_bin, read_stats, timed};
    let dir = config.out.join("scaling_runs");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let tag = match patch_size {
        Some(p) => format!("{scene}_patch_{p}"),
        None => format!("{scene}_{}x{}", size.0, size.1),
    };
    let (stats_path, out) = (dir.join(format!("{tag}.json")), dir.join(format!("{tag}.exr")));
    let (mut steps, mut walls, mut peak) = (Vec::new(), Vec::new(), None::<u64>);
    let mut stats = serde_json::Value::Null;
    for _ in 0..config.repeats {
        let mut cmd = std::process::Command::new(firstshot_bin());
        cmd.arg(scene_path(scene)).arg("--out").arg(&out).arg("--stats").arg(&stats_path).arg("--quiet");
        cmd.args(["--iterations", "2", "--burn-in", "0", "--adapter", &adapter_arg(slot)]);
        cmd.args(["--width", &size.0.to_string(), "--height", &size.1.to_string()]);
        if let Some(p) = patch_size {
            cmd.args(["--patch-size", &p.to_string()]);
        }
        walls.push(timed(&mut cmd)?);
        stats = read_stats(&stats_path)?;
        steps.push(stats["iteration_ms_median"].as_f64().ok_or("no iteration_ms_median in the stats")?);
        if let Some(p) = stats["memory"]["peak_rss_bytes"].as_u64() {
            peak = Some(peak.map_or(p, |q| q.max(p)));
        }
    }
    let f = |key: &str| stats[key].as_f64().unwrap_or(f64::NAN);
    // `iteration_ms`: all steps of the run; `image_ms` holds them and the read-back.
    let steps_total = f("iteration_ms");
    Ok(ProcessRow {
        study,
        scene: scene.to_string(),
        patch_size,
        width: size.0,
        height: size.1,
        patches: stats["patches"].as_u64().unwrap_or(0),
        first_shot_ms: f("first_shot_ms"),
        first_shot_pairs: stats["first_shot_pairs"].as_u64().unwrap_or(0),
        step_ms: summary(&steps),
        upload_ms: f("upload_ms"),
        read_back_ms: f("image_ms") - steps_total,
        device_bytes: stats["memory"]["device_bytes"].as_u64().unwrap_or(0),
        total_host_bytes: stats["memory"]["total_host_bytes"].as_u64().unwrap_or(0),
        peak_rss_bytes: peak,
        wall_s: summary(&walls),
        error: None,
    })
}

/// One whole-process run of the large series: (study, scene, --patch-size, image size).
type PlannedRun<'a> = (&'static str, &'a str, Option<f64>, (u32, u32));

/// The large series, whole processes: the Sierpinski scene at `config.patch_sizes` and the
/// Cornell box at `config.images`, smallest first (a failure, e.g. out of memory, is a
/// row of its own).
fn process_rows(config: &Config, slot: &Slot) -> Vec<ProcessRow> {
    let mut plan: Vec<PlannedRun> =
        config.patch_sizes.iter().map(|&p| ("patch_size", "sierpinski", Some(p), (128, 128))).collect();
    plan.extend(config.images.iter().map(|&s| ("image", "cornell_box", None, s)));
    plan.into_iter()
        .map(|(study, scene, patch_size, size)| {
            eprintln!(
                "{study}: {scene}, {}x{}{}",
                size.0,
                size.1,
                patch_size.map_or(String::new(), |p| format!(", --patch-size {p}"))
            );
            guarded(|| process_row(config, slot, study, scene, patch_size, size)).unwrap_or_else(|e| {
                eprintln!("  FAILED: {e}");
                ProcessRow {
                    study,
                    scene: scene.to_string(),
                    patch_size,
                    width: size.0,
                    height: size.1,
                    patches: 0,
                    first_shot_ms: f64::NAN,
                    first_shot_pairs: 0,
                    step_ms: summary(&[]),
                    upload_ms: f64::NAN,
                    read_back_ms: f64::NAN,
                    device_bytes: 0,
                    total_host_bytes: 0,
                    peak_rss_bytes: None,
                    wall_s: summary(&[]),
                    error: Some(e),
                }
            })
        })
        .collect()
}

fn print_process_rows(rows: &[ProcessRow]) {
    let mib = |b: u64| format!("{:.0}", b as f64 / (1u64 << 20) as f64);
    let headers = [
        "study",
        "scene",
        "patch size",
        "image",
        "patches",
        "first shot s (pairs)",
        "step ms",
        "upload ms",
        "read-back ms",
        "device MiB",
        "host MiB (all)",
        "peak RSS MiB",
        "wall s",
    ];
    let table: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let mut row = vec![
                r.study.to_string(),
                r.scene.clone(),
                r.patch_size.map_or("-".into(), |p| p.to_string()),
                format!("{}x{}", r.width, r.height),
            ];
            if let Some(e) = &r.error {
                row.push(format!("FAILED: {e}"));
                return row;
            }
            row.extend([
                r.patches.to_string(),
                format!("{:.2} ({:.2} M)", r.first_shot_ms / 1e3, r.first_shot_pairs as f64 / 1e6),
                crate::spread(&r.step_ms, 1),
                format!("{:.0}", r.upload_ms),
                format!("{:.0}", r.read_back_ms),
                mib(r.device_bytes),
                mib(r.total_host_bytes),
                r.peak_rss_bytes.map_or("?".into(), mib),
                crate::spread(&r.wall_s, 2),
            ]);
            row
        })
        .collect();
    println!("(whole processes: two image steps, no burn-in; memory predicted, and the peak of the repeats)");
    print_table(&headers, &table);
}
