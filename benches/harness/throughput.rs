//! Throughput: for every scene and adapter, the first-shot time and the step time of the
//! product's `render` (warm-up first, then repeats), the fragments of a step, each stage's
//! time, the bytes it moves against the adapter's copy rate, and ratios between adapters.

use crate::session::{IDLE, Session, copy_bandwidth, merge_repeated_stages, own_time, stage_bytes};
use crate::stats::{Summary, summary};
use crate::{Config, LoadedScene, Machine, Slot, guarded, load_scene, print_table, spread, write_json};
use firstshot::gpu::profile::StageTimer;
use firstshot::render::render;
use serde::Serialize;

/// One stage over the profiled steps.
#[derive(Debug, Clone, Serialize)]
pub struct StageRow {
    pub name: String,
    /// Submitted alone and waited for: the stage plus one round trip.
    pub wall_ms: Summary,
    /// Between timestamps around the stage, where the device has them.
    pub gpu_ms: Option<Summary>,
    /// Whether the timestamps agree with the wall time less the idle round trip (within a
    /// factor 2): lavapipe puts some compute dispatches outside their timestamps.
    pub gpu_plausible: Option<bool>,
    /// The stage's own time: the timestamps where plausible, else wall less the round trip.
    pub ms: f64,
    /// Share of the step (of the sum of `ms` over stages).
    pub share: f64,
    /// Bytes the stage must at least move (session::stage_bytes).
    pub bytes: f64,
    /// bytes / time, and that as a fraction of the adapter's copy rate.
    pub gb_per_s: f64,
    pub of_copy_rate: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Measured {
    pub patches: usize,
    pub light_samples: usize,
    pub first_shot_pairs: u32,
    pub first_shot_faces: usize,
    pub image: [u32; 2],
    pub hemicube_resolution: u32,
    pub bundle_resolution: u32,
    /// Bundles a step draws, each at `bundle_resolution` (four where the image sets the
    /// resolution: `iteration::auto_bundles_per_step`), so steps of runs that drew a
    /// different number are not the same work.
    pub bundles_per_step: u32,
    /// Fine lines along a wide line's edge outside the glossy patches' window (1: one level).
    pub wide_lines: u32,
    pub steps_per_run: u32,
    pub repeats: usize,
    /// `render`'s first-shot time, over the repeats.
    pub first_shot_ms: Summary,
    /// `render`'s median step time (over its batches of 8 steps), over the repeats.
    pub step_ms: Summary,
    pub steps_per_second: f64,
    pub render_total_ms: Summary,
    /// The same steps timed in the session, per batch of 8 (cross-check, finer spread).
    pub batch_step_ms: Summary,
    /// Of a step in those batches, the host's time to write its uniforms and record it
    /// (submit excluded): a floor under the step time on any adapter.
    pub host_step_ms: Summary,
    /// Whether the area lights were first shot (`--no-first-shot` turns it off).
    pub first_shot: bool,
    pub fragments_per_step: Summary,
    /// Fragments per second at the median step time.
    pub fragments_per_second: f64,
    pub fragment_capacity: u32,
    pub timestamps: bool,
    pub stages: Vec<StageRow>,
    /// Sum of the stages' medians (wall) against the step time: the submit-and-wait round
    /// trips a profiled step pays and a real step does not.
    pub stage_wall_sum_ms: f64,
    pub stage_sum_ms: f64,
    /// An empty submission's round trip (the `idle` stage).
    pub idle_ms: f64,
    /// Process CPU time over wall time during the timed renders: the cores kept busy.
    pub cores_busy: Option<f64>,
    pub load_average: Option<[f64; 3]>,
    pub copy_gb_per_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Case {
    pub scene: String,
    pub adapter: Slot,
    pub error: Option<String>,
    pub measured: Option<Measured>,
    /// Against the first CPU adapter that measured this scene: > 1 is faster.
    pub ratio_to: Option<String>,
    pub steps_per_second_ratio: Option<f64>,
    pub first_shot_speed_ratio: Option<f64>,
}

#[derive(Serialize)]
struct Report<'a> {
    machine: &'a Machine,
    quick: bool,
    cases: &'a [Case],
}

const PROFILED_STEPS: usize = 5;
const BATCH: u32 = 8;

fn measure(config: &Config, slot: &Slot, s: &LoadedScene) -> Result<Measured, String> {
    let ctx = slot.open(config.timestamps)?;
    let mut options = config.options(&s.scene);
    let steps = config.steps;
    // Warm-up: pipelines are created (and on lavapipe compiled) inside `render`.
    options.iterations = 2.min(steps);
    render(&ctx, &s.scene, &s.patches, &options).map_err(|e| e.to_string())?;
    options.iterations = steps;
    let load_average = crate::load_average();
    let (cpu0, wall0) = (crate::process_cpu_seconds(), std::time::Instant::now());
    let mut runs = Vec::new();
    for r in 0..config.repeats {
        let out = render(&ctx, &s.scene, &s.patches, &options).map_err(|e| e.to_string())?;
        eprintln!(
            "  run {}/{}: first shot {:.0} ms, step {:.1} ms",
            r + 1,
            config.repeats,
            out.stats.first_shot_ms,
            out.stats.iteration_ms_median
        );
        runs.push(out.stats);
    }
    let cores_busy = cpu0.zip(crate::process_cpu_seconds()).map(|(a, b)| (b - a) / wall0.elapsed().as_secs_f64());
    let first = &runs[0];
    let first_shot_ms = summary(&runs.iter().map(|r| r.first_shot_ms).collect::<Vec<_>>());
    let step_ms = summary(&runs.iter().map(|r| r.iteration_ms_median).collect::<Vec<_>>());
    let render_total_ms = summary(&runs.iter().map(|r| r.total_ms).collect::<Vec<_>>());

    let mut session = Session::new(&ctx, &s.scene, &s.patches, &options).map_err(|e| e.to_string())?;
    session.time_batches(1, 2).map_err(|e| e.to_string())?;
    let batches = if config.quick { 2 } else { 2 * config.repeats.max(3) };
    let timed = session.time_batches(batches, BATCH).map_err(|e| e.to_string())?;
    let (batch_step_ms, host_step_ms) = (summary(&timed.step_ms), summary(&timed.host_ms));
    // Room for every stage of a step of four bundles and several views.
    let timer = StageTimer::new(&ctx, 128);
    let mut profiles = Vec::new();
    let mut fragments = Vec::new();
    for _ in 0..if config.quick { 2 } else { PROFILED_STEPS } {
        let (times, f) = session.profile_step(&timer).map_err(|e| e.to_string())?;
        profiles.push(merge_repeated_stages(times));
        fragments.push(f as f64);
    }
    let copy = copy_bandwidth(&ctx).map_err(|e| e.to_string())?;
    let fragments_per_step = summary(&fragments);
    let sizes = session.sizes(fragments_per_step.median as u64);
    let names: Vec<&str> = profiles[0].iter().map(|t| t.0.name).collect();
    let idle_ms = summary(&profiles.iter().map(|p| p[0].0.wall_ms).collect::<Vec<_>>()).median;
    let mut stages: Vec<StageRow> = names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let wall = summary(&profiles.iter().map(|p| p[i].0.wall_ms).collect::<Vec<_>>());
            let gpu: Vec<f64> = profiles.iter().filter_map(|p| p[i].0.gpu_ms).collect();
            let gpu = (gpu.len() == profiles.len()).then(|| summary(&gpu));
            let runs = profiles[0][i].1 as f64;
            let (ms, gpu_plausible) = own_time(wall.median, gpu.map(|g| g.median), runs * idle_ms);
            let bytes = runs * stage_bytes(name, sizes);
            let gb_per_s = bytes / (ms.max(1e-6) * 1e-3) / 1e9;
            StageRow {
                name: name.to_string(),
                wall_ms: wall,
                gpu_ms: gpu,
                gpu_plausible,
                ms,
                share: 0.0,
                bytes,
                gb_per_s,
                of_copy_rate: gb_per_s / copy,
            }
        })
        .collect();
    let work = |r: &&StageRow| r.name != IDLE;
    let stage_wall_sum_ms: f64 = stages.iter().filter(work).map(|r| r.wall_ms.median).sum();
    let stage_sum_ms: f64 = stages.iter().filter(work).map(|r| r.ms).sum();
    for row in &mut stages {
        row.share = if row.name == IDLE { 0.0 } else { row.ms / stage_sum_ms };
    }
    Ok(Measured {
        patches: first.patches,
        light_samples: first.light_samples,
        first_shot_pairs: first.first_shot_pairs,
        first_shot_faces: first.first_shot_faces,
        image: first.image,
        hemicube_resolution: first.hemicube_resolution,
        bundle_resolution: first.bundle_resolution,
        bundles_per_step: first.bundles_per_step,
        wide_lines: first.wide_lines,
        steps_per_run: steps,
        repeats: config.repeats,
        first_shot_ms,
        steps_per_second: 1e3 / step_ms.median,
        step_ms,
        render_total_ms,
        batch_step_ms,
        host_step_ms,
        first_shot: options.first_shot,
        fragments_per_second: fragments_per_step.median / (step_ms.median * 1e-3),
        fragments_per_step,
        fragment_capacity: session.capacity(),
        timestamps: timer.has_timestamps(),
        stages,
        stage_wall_sum_ms,
        stage_sum_ms,
        idle_ms,
        cores_busy,
        load_average,
        copy_gb_per_s: copy,
    })
}

/// Ratios against the first CPU adapter (or else the first adapter) that measured the scene.
fn add_ratios(cases: &mut [Case]) {
    let scenes: Vec<String> = cases.iter().map(|c| c.scene.clone()).collect();
    for scene in scenes {
        let base = cases
            .iter()
            .filter(|c| c.scene == scene)
            .filter_map(|c| Some((c, c.measured.clone()?)))
            .max_by_key(|(c, _)| (c.adapter.adapter.is_cpu(), std::cmp::Reverse(c.adapter.index)))
            .map(|(c, m)| (c.adapter.label(), m));
        let Some((label, b)) = base else { continue };
        for c in cases.iter_mut().filter(|c| c.scene == scene) {
            if let Some(m) = &c.measured {
                c.ratio_to = Some(label.clone());
                c.steps_per_second_ratio = Some(m.steps_per_second / b.steps_per_second);
                c.first_shot_speed_ratio =
                    (m.first_shot && b.first_shot).then(|| b.first_shot_ms.median / m.first_shot_ms.median);
            }
        }
    }
}

pub fn run(config: &Config, machine: &Machine, slots: &[Slot]) -> Result<(), String> {
    println!("\n== throughput");
    let mut cases = Vec::new();
    for path in &config.scenes {
        let loaded = load_scene(path)?;
        for slot in slots {
            eprintln!("{} on {}", loaded.name, slot.label());
            let result = guarded(|| measure(config, slot, &loaded));
            if let Err(e) = &result {
                eprintln!("  FAILED: {e}");
            }
            let (measured, error) = match result {
                Ok(m) => (Some(m), None),
                Err(e) => (None, Some(e)),
            };
            cases.push(Case {
                scene: loaded.name.clone(),
                adapter: slot.clone(),
                error,
                measured,
                ratio_to: None,
                steps_per_second_ratio: None,
                first_shot_speed_ratio: None,
            });
        }
    }
    add_ratios(&mut cases);
    print_summary(&cases);
    let path = write_json(&config.out, "throughput.json", &Report { machine, quick: config.quick, cases: &cases })?;
    println!("wrote {}", path.display());
    if cases.iter().all(|c| c.measured.is_none()) {
        return Err("no adapter measured anything".into());
    }
    Ok(())
}

fn print_summary(cases: &[Case]) {
    let mut rows = Vec::new();
    for c in cases {
        let fs = c.measured.as_ref().is_none_or(|m| m.first_shot);
        let mut row = vec![format!("{}{}", c.scene, if fs { "" } else { " (no first shot)" }), c.adapter.label()];
        match &c.measured {
            Some(m) => row.extend([
                m.patches.to_string(),
                format!("{}x{}/{}", m.bundles_per_step, m.bundle_resolution, m.hemicube_resolution),
                if m.first_shot { spread(&m.first_shot_ms, 0) } else { "-".into() },
                spread(&m.step_ms, 1),
                format!("{:.1}", m.steps_per_second),
                format!("{:.2}M", m.fragments_per_step.median / 1e6),
                c.steps_per_second_ratio.map_or("-".into(), |r| format!("{r:.2}")),
                c.first_shot_speed_ratio.map_or("-".into(), |r| format!("{r:.2}")),
            ]),
            None => row.push(format!("FAILED: {}", c.error.as_deref().unwrap_or("?"))),
        }
        rows.push(row);
    }
    print_table(
        &[
            "scene",
            "adapter",
            "patches",
            "bundles/hemi",
            "first shot ms",
            "step ms",
            "steps/s",
            "frags/step",
            "x steps/s",
            "x first shot",
        ],
        &rows,
    );
    for c in cases {
        let Some(m) = &c.measured else { continue };
        println!(
            "\n{} on {}: one step stage by stage ({:.0} fragments, adapter copy rate {:.1} GB/s, timestamps: {})",
            c.scene,
            c.adapter.label(),
            m.fragments_per_step.median,
            m.copy_gb_per_s,
            if m.timestamps { "yes" } else { "no" },
        );
        println!(
            "step {} ms in render, {} ms in batches of 8 (host: {} ms to record); cores busy {}; load average {}",
            spread(&m.step_ms, 1),
            spread(&m.batch_step_ms, 1),
            spread(&m.host_step_ms, 2),
            m.cores_busy.map_or("?".into(), |c| format!("{c:.2}")),
            m.load_average.map_or("?".into(), |l| format!("{:.2}", l[0]))
        );
        let rows: Vec<Vec<String>> = m
            .stages
            .iter()
            .map(|s| {
                vec![
                    s.name.clone(),
                    format!("{:.2}", s.wall_ms.median),
                    s.gpu_ms.map_or("-".into(), |g| {
                        format!("{:.2}{}", g.median, if s.gpu_plausible == Some(false) { "?" } else { "" })
                    }),
                    format!("{:.2}", s.ms),
                    format!("{:.0}%", 100.0 * s.share),
                    format!("{:.1}", s.bytes / 1e6),
                    // Under 0.1 ms a stage's time is mostly noise: no rate from it.
                    if s.ms < 0.1 { "-".into() } else { format!("{:.2}", s.gb_per_s) },
                    if s.ms < 0.1 { "-".into() } else { format!("{:.0}%", 100.0 * s.of_copy_rate) },
                ]
            })
            .collect();
        print_table(&["stage", "wall ms", "gpu ms", "own ms", "share", "MB", "GB/s", "of copy"], &rows);
        println!(
            "sum over stages: wall {:.1} ms, own {:.1} ms (gpu ms marked ? disagree with wall less idle: own = wall - idle)",
            m.stage_wall_sum_ms, m.stage_sum_ms
        );
    }
}
