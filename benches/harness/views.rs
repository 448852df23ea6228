//! Views: what the extra cameras of a scene cost. For every scene with `[[cameras]]`, pairs
//! of whole `firstshot` processes at the same steps, one rendering the scene's first camera
//! and one rendering all of them (`--all-cameras`), each pair in alternating order so that
//! a drift in the (shared) machine's load falls on both alike. The ratio of each pair's wall
//! times is the figure of issue 13 (four cameras at most 1.5 times one); their difference
//! over the extra views' steps is what one more view adds to an image step.
//!
//! The views share the first shot, the burn-in and every bundle step; each view adds only its
//! image estimate (camera item buffer, direct light, gather), so the ratio is
//! 1 + (n - 1) I / (B + I) for n views, image stages I and shared stages B a step
//! (docs/PERFORMANCE.md, "Several cameras").

use crate::peers::{adapter_arg, firstshot_bin, read_stats, timed};
use crate::stats::{Summary, pair_ratios, summary};
use crate::{Config, Machine, Slot, load_scene, print_table, spread, write_json};
use serde::Serialize;
use std::path::Path;
use std::process::Command;

/// One process of a pair.
#[derive(Debug, Clone, Serialize)]
pub struct ViewRun {
    /// Whether it rendered every camera.
    pub all_cameras: bool,
    /// Spawn to exit.
    pub seconds: f64,
    /// `iteration_ms_median` of its `--stats`: the median step, burn-in steps (which render no
    /// view) included.
    pub step_ms: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SceneViews {
    pub scene: String,
    pub adapter: Slot,
    pub cameras: usize,
    pub image: [u32; 2],
    pub steps: u32,
    /// In the order they ran.
    pub runs: Vec<ViewRun>,
    pub one_camera_seconds: Summary,
    pub all_cameras_seconds: Summary,
    /// Each pair's all-cameras wall time over its one-camera wall time.
    pub ratio: Summary,
    /// What one more view adds to an image step on average, per pair: (all-cameras time -
    /// one-camera time) / ((cameras - 1) steps), its direct passes and camera item buffers
    /// included.
    pub ms_per_extra_view_step: Summary,
}

#[derive(Debug, Clone, Serialize)]
pub struct ViewsReport {
    pub machine: Machine,
    pub quick: bool,
    pub command: String,
    pub results: Vec<SceneViews>,
}

/// One process: the scene's first camera, or all of them, every camera at the study's image
/// size (`--view-size`), its image and `--stats` written to `dir`.
fn run_one(
    config: &Config,
    path: &Path,
    slot: &Slot,
    all_cameras: bool,
    dir: &Path,
    name: &str,
) -> Result<ViewRun, String> {
    let label = if all_cameras { "all" } else { "one" };
    let out = dir.join(format!("{name}_{label}.exr"));
    let stats = dir.join(format!("{name}_{label}.json"));
    let (w, h) = config.view_size;
    let mut cmd = Command::new(firstshot_bin());
    cmd.arg(path).arg("--out").arg(&out).arg("--stats").arg(&stats).arg("--quiet");
    cmd.args(["--iterations", &config.view_steps.to_string(), "--adapter", &adapter_arg(slot)]);
    cmd.args(["--width", &w.to_string(), "--height", &h.to_string(), "--seed", "1"]);
    if all_cameras {
        cmd.arg("--all-cameras");
    }
    if config.quick {
        cmd.args(["--hemicube-resolution", "128", "--bundle-resolution", "128"]);
    }
    let seconds = timed(&mut cmd)?;
    let json = read_stats(&stats)?;
    let step_ms =
        json["iteration_ms_median"].as_f64().ok_or_else(|| format!("{}: no iteration_ms_median", stats.display()))?;
    Ok(ViewRun { all_cameras, seconds, step_ms })
}

pub fn run(config: &Config, machine: &Machine, slots: &[Slot]) -> Result<(), String> {
    println!("\n== views (one camera against all cameras, whole processes)");
    let dir = config.out.join("views");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut results = Vec::new();
    let mut table = Vec::new();
    for path in &config.scenes {
        let loaded = load_scene(path)?;
        // `[camera]` and its `[[cameras]]`, as `--all-cameras` renders them.
        let cameras = loaded.scene.cameras.len().max(1);
        if cameras < 2 {
            return Err(format!(
                "{}: the scene has one camera; the views study needs a scene with [[cameras]] \
                 (benches/scenes/*_4cameras.toml)",
                path.display()
            ));
        }
        for slot in slots {
            println!("{} on {}", loaded.name, slot.label());
            let mut runs = Vec::new();
            for pair in 0..config.repeats {
                // Alternate which of the two goes first.
                let order = if pair % 2 == 0 { [false, true] } else { [true, false] };
                for all in order {
                    let r = run_one(config, path, slot, all, &dir, &loaded.name)?;
                    println!(
                        "  pair {}/{}: {} {:.2} s (median step {:.1} ms)",
                        pair + 1,
                        config.repeats,
                        if all { "all cameras" } else { "one camera " },
                        r.seconds,
                        r.step_ms
                    );
                    runs.push(r);
                }
            }
            let seconds =
                |all: bool| -> Vec<f64> { runs.iter().filter(|r| r.all_cameras == all).map(|r| r.seconds).collect() };
            let (one_s, all_s) = (seconds(false), seconds(true));
            let ratio = summary(&pair_ratios(&one_s, &all_s));
            let extra_view_steps = ((cameras - 1) as u64 * config.view_steps as u64) as f64;
            let per_view: Vec<f64> = one_s.iter().zip(&all_s).map(|(o, a)| 1e3 * (a - o) / extra_view_steps).collect();
            let row = SceneViews {
                scene: loaded.name.clone(),
                adapter: slot.clone(),
                cameras,
                image: [config.view_size.0, config.view_size.1],
                steps: config.view_steps,
                one_camera_seconds: summary(&one_s),
                all_cameras_seconds: summary(&all_s),
                ratio,
                ms_per_extra_view_step: summary(&per_view),
                runs,
            };
            table.push(vec![
                row.scene.clone(),
                slot.label(),
                row.cameras.to_string(),
                format!("{}x{}", row.image[0], row.image[1]),
                row.steps.to_string(),
                spread(&row.one_camera_seconds, 2),
                spread(&row.all_cameras_seconds, 2),
                spread(&row.ratio, 2),
                spread(&row.ms_per_extra_view_step, 1),
            ]);
            results.push(row);
        }
    }
    println!();
    print_table(
        &[
            "scene",
            "adapter",
            "cameras",
            "image",
            "steps",
            "one camera s",
            "all cameras s",
            "ratio",
            "ms a view a step",
        ],
        &table,
    );
    println!("(ratio: median [min-max] over the pairs of each pair's wall times, all cameras / one)");
    let report = ViewsReport {
        machine: machine.clone(),
        quick: config.quick,
        command: "firstshot SCENE [--all-cameras] --iterations N --width W --height H --seed 1 --adapter A --quiet \
                  --out OUT.exr --stats OUT.json"
            .into(),
        results,
    };
    let path = write_json(&config.out, "views.json", &report)?;
    println!("wrote {}", path.display());
    Ok(())
}
