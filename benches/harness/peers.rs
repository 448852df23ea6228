//! Peers: how long firstshot takes to reach an image error, against the path tracer a user
//! would take instead (Mitsuba 3, through `tools/mitsuba/`), on the same machine, side by
//! side in one run.
//!
//! Both renderers run as whole processes, as a user runs them: a series of budgets (steps
//! for firstshot, samples per pixel for Mitsuba), each one process whose wall time is
//! measured from spawn to exit (start-up, scene loading, JIT compilation and writing the
//! EXR included), and whose image is measured against a long reference with the image
//! error of docs/ALGORITHM.md section 3. The budgets of the two alternate, so that a change
//! in the load of the (shared) machine falls on both alike. From each (time, error) curve,
//! the time to reach 10 %, 5 % and 2 % is interpolated in log-log (`stats::time_to_reach`).
//!
//! Pairing: on a CPU adapter firstshot runs on that adapter and Mitsuba's `llvm_ad_rgb`
//! variant on the same cores; on a GPU adapter, Mitsuba's `cuda_ad_rgb`.
//!
//! References: `refs/<scene>.full.exr` box-filtered down to the study's size where it
//! exists, else (or with `--reference`) a long Mitsuba render made once and kept in
//! `--out` (`peers_reference_<scene>_<w>x<h>_<spp>spp.exr`), with its own noise measured
//! from two independent halves.

use crate::mitsuba::{Python, SETUP, find_python};
use crate::stats::{CostModel, Reach, cost_model, time_to_reach};
use crate::svg::{Plot, Series};
use crate::{Config, Machine, Slot, print_table, write_json, write_text};
use firstshot::image::{Image, image_error};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// The error levels of the table (relative RMSE).
pub const LEVELS: [f64; 3] = [0.10, 0.05, 0.02];

/// Mitsuba's seeds for the reference start here, far from the series' seeds (0, 1, ...).
const REFERENCE_SEED: u32 = 1_000_000;

#[derive(Debug, Clone, Serialize)]
pub struct Run {
    pub renderer: &'static str,
    /// firstshot: steps; Mitsuba: samples per pixel.
    pub budget: u32,
    /// Wall time of the whole process, seconds.
    pub seconds: f64,
    pub relative_rmse: f64,
    pub mean_ratio: [f64; 3],
}

#[derive(Debug, Clone, Serialize)]
pub struct LevelResult {
    pub level: f64,
    pub firstshot: Option<Reach>,
    pub mitsuba: Option<Reach>,
    /// firstshot's time over Mitsuba's: > 1 means Mitsuba gets there first. A bound where a
    /// time is one (the string says which).
    pub ratio: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct SceneResult {
    pub scene: String,
    pub adapter: Slot,
    pub variant: String,
    pub image: [u32; 2],
    /// 128 in the quick mode, else `None` (the automatic one); the bundle resolution is always
    /// the automatic one.
    pub hemicube_resolution: Option<u32>,
    pub reference: String,
    /// The reference's own error, where it was measured here.
    pub reference_noise: Option<f64>,
    pub runs: Vec<Run>,
    pub levels: Vec<LevelResult>,
    /// What an error costs each renderer (`stats::cost_model` of its runs): start-up, time
    /// a sample, noise of one sample, floor. Where the ratios of `levels` come from.
    pub firstshot_cost: Option<CostModel>,
    pub mitsuba_cost: Option<CostModel>,
    pub plot: String,
}

#[derive(Serialize)]
struct Report<'a> {
    machine: &'a Machine,
    quick: bool,
    firstshot: String,
    python: Option<String>,
    mitsuba_version: Option<String>,
    skipped: Option<String>,
    commands: Vec<String>,
    results: &'a [SceneResult],
    failures: &'a [(String, String)],
}

/// `12.3 s`, `<= 1.2 s` (reached at the first budget), `> 40.0 s` (not within the series).
pub fn show_reach(r: &Option<Reach>) -> String {
    match r {
        Some(Reach::At(t)) => format!("{t:.1} s"),
        Some(Reach::NoLaterThan(t)) => format!("<= {t:.1} s"),
        Some(Reach::LaterThan(t)) => format!("> {t:.1} s"),
        None => "-".into(),
    }
}

/// The interval a reach stands for: [t, t], (0, t] or (t, inf).
fn interval(r: &Reach) -> (f64, f64) {
    match *r {
        Reach::At(t) => (t, t),
        Reach::NoLaterThan(t) => (0.0, t),
        Reach::LaterThan(t) => (t, f64::INFINITY),
    }
}

/// firstshot time / Mitsuba time, or the bound the two intervals allow.
pub fn ratio(firstshot: &Option<Reach>, mitsuba: &Option<Reach>) -> String {
    let (Some(f), Some(m)) = (firstshot, mitsuba) else { return "-".into() };
    let ((f_lo, f_hi), (m_lo, m_hi)) = (interval(f), interval(m));
    let lo = f_lo / m_hi;
    let hi = if m_lo > 0.0 { f_hi / m_lo } else { f64::INFINITY };
    match (lo > 0.0 && lo.is_finite(), hi.is_finite()) {
        (true, true) if (hi - lo).abs() <= 1e-9 * hi => format!("{lo:.2}"),
        (true, true) => format!("{lo:.2}-{hi:.2}"),
        (true, false) => format!("> {lo:.2}"),
        (false, true) => format!("<= {hi:.2}"),
        (false, false) => "?".into(),
    }
}

pub fn firstshot_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_firstshot"))
}

/// Runs `cmd`, timing the whole process; an error carries its stderr's tail.
pub fn timed(cmd: &mut Command) -> Result<f64, String> {
    let start = Instant::now();
    let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
    let seconds = start.elapsed().as_secs_f64();
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err.lines().rev().take(6).collect();
        return Err(format!(
            "{cmd:?} exited with {}: {}",
            out.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        ));
    }
    Ok(seconds)
}

/// The `--stats` JSON a `firstshot` process wrote to `path`; an error names the file.
pub fn read_stats(path: &Path) -> Result<serde_json::Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// The adapter spec to give `firstshot --adapter` for this slot: a CPU adapter by its
/// backend (lavapipe and llvmpipe share a name), a GPU by its name.
pub fn adapter_arg(slot: &Slot) -> String {
    if slot.adapter.is_cpu() { slot.adapter.backend.to_lowercase() } else { slot.adapter.name.clone() }
}

struct Study<'a> {
    config: &'a Config,
    python: &'a Python,
    dir: PathBuf,
}

impl Study<'_> {
    fn size(&self, scene: &firstshot::scene::Scene) -> (u32, u32) {
        let s = self.config.peer_size;
        // The scene's aspect ratio at the study's height.
        let w = ((s as f64) * scene.camera.width as f64 / scene.camera.height as f64).round() as u32;
        (w.max(1), s)
    }

    fn firstshot(
        &self,
        path: &Path,
        name: &str,
        slot: &Slot,
        size: (u32, u32),
        steps: u32,
    ) -> Result<(f64, Image), String> {
        let out = self.dir.join(format!("{name}_firstshot_{steps}.exr"));
        let mut cmd = Command::new(firstshot_bin());
        cmd.arg(path).arg("--out").arg(&out).arg("--quiet");
        cmd.args(["--iterations", &steps.to_string(), "--adapter", &adapter_arg(slot)]);
        cmd.args(["--width", &size.0.to_string(), "--height", &size.1.to_string()]);
        // Quick: a coarser first shot only. The bundle resolution stays the automatic one, which
        // crosses the median glossy patch with a line a step; a forced coarse one (128 on the
        // Sierpinski scene, a twentieth of a line) makes the glossy fractal's J spikes that
        // take the image's error up again after 64 steps (docs/PERFORMANCE.md).
        if self.config.quick {
            cmd.args(["--hemicube-resolution", "128"]);
        }
        let seconds = timed(&mut cmd)?;
        Ok((seconds, Image::read_exr(&out).map_err(|e| e.to_string())?))
    }

    fn mitsuba_cmd(&self, path: &Path, variant: &str, size: (u32, u32), spp: u32, seed: u32, out: &Path) -> Command {
        let mut cmd = self.python.script("render.py");
        cmd.arg(path).arg("--out").arg(out).arg("--quiet");
        cmd.args(["--variant", variant, "--spp", &spp.to_string(), "--seed", &seed.to_string()]);
        cmd.args(["--width", &size.0.to_string(), "--height", &size.1.to_string()]);
        cmd
    }

    fn mitsuba(
        &self,
        path: &Path,
        name: &str,
        variant: &str,
        size: (u32, u32),
        spp: u32,
        seed: u32,
    ) -> Result<(f64, Image), String> {
        let out = self.dir.join(format!("{name}_mitsuba_{spp}.exr"));
        let seconds = timed(&mut self.mitsuba_cmd(path, variant, size, spp, seed, &out))?;
        Ok((seconds, Image::read_exr(&out).map_err(|e| e.to_string())?))
    }

    /// The stored reference, or a long Mitsuba render (kept for the next run).
    fn reference(
        &self,
        path: &Path,
        name: &str,
        variant: &str,
        size: (u32, u32),
    ) -> Result<(Image, String, Option<f64>), String> {
        let stored = crate::convergence::reference_for(self.config, name)
            .or_else(|| Some(Path::new(env!("CARGO_MANIFEST_DIR")).join("refs").join(format!("{name}.full.exr"))))
            .filter(|p| p.exists());
        if let Some(p) = stored {
            let image = Image::read_exr(&p).map_err(|e| e.to_string())?;
            if let Some(fitted) = crate::convergence::fit_reference(image, size.0, size.1) {
                // Relative to the repository where it lies in it (refs/...): the JSON is
                // committed to docs/perf/.
                let shown = p.strip_prefix(env!("CARGO_MANIFEST_DIR")).unwrap_or(&p).display().to_string();
                return Ok((fitted, shown, None));
            }
            eprintln!("  {} does not box-filter down to {}x{}: rendering a reference", p.display(), size.0, size.1);
        }
        let spp = self.config.peer_reference_spp;
        let out = self.config.out.join(format!("peers_reference_{name}_{}x{}_{spp}spp.exr", size.0, size.1));
        let noise_file = out.with_extension("json");
        if !out.exists() {
            eprintln!("  reference: Mitsuba {variant}, {spp} samples per pixel (kept as {})", out.display());
            let mut cmd = self.mitsuba_cmd(path, variant, size, spp.div_ceil(4), REFERENCE_SEED, &out);
            cmd.args(["--passes", "4", "--halves"]);
            let seconds = timed(&mut cmd)?;
            let half = |h: &str| Image::read_exr(&out.with_extension(format!("{h}.exr"))).map_err(|e| e.to_string());
            let noise = 0.5 * image_error(&half("even")?, &half("odd")?).map_err(|e| e.to_string())?.relative_rmse;
            eprintln!("    {seconds:.0} s, noise {noise:.4}");
            let record = serde_json::json!({ "seconds": seconds, "spp": spp, "variant": variant, "noise": noise });
            std::fs::write(&noise_file, record.to_string()).map_err(|e| e.to_string())?;
        }
        let noise = std::fs::read_to_string(&noise_file)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| v["noise"].as_f64());
        Ok((Image::read_exr(&out).map_err(|e| e.to_string())?, out.display().to_string(), noise))
    }

    fn measure(&self, path: &Path, slot: &Slot) -> Result<SceneResult, String> {
        let scene = firstshot::scene::load(path).map_err(|e| e.to_string())?;
        let name = path.file_stem().unwrap_or_default().to_string_lossy().into_owned();
        let size = self.size(&scene);
        let variant = if slot.adapter.is_cpu() { "llvm_ad_rgb" } else { "cuda_ad_rgb" };
        if !self.python.variants.iter().any(|v| v == variant) {
            return Err(format!(
                "this Mitsuba has no {variant} variant that runs here (llvm_ad_rgb needs libLLVM 19; cuda_ad_rgb a CUDA build)"
            ));
        }
        let (reference, reference_name, reference_noise) = self.reference(path, &name, variant, size)?;

        // Warm-up: both renderers keep caches on disk (Mesa's shader cache, Dr.Jit's kernel
        // cache); the series measures what a user sees from the second run on.
        self.firstshot(path, &name, slot, size, 1)?;
        self.mitsuba(path, &name, variant, size, 1, 0)?;

        let mut runs = Vec::new();
        let (steps, spps) = (&self.config.peer_steps, &self.config.peer_spp);
        for i in 0..steps.len().max(spps.len()) {
            let mut record = |renderer: &'static str,
                              budget: u32,
                              (seconds, image): (f64, Image)|
             -> Result<(), String> {
                let e = image_error(&image, &reference).map_err(|e| e.to_string())?;
                eprintln!("  {renderer:<9} {budget:>5}: {seconds:6.2} s, error {:.4}", e.relative_rmse);
                runs.push(Run { renderer, budget, seconds, relative_rmse: e.relative_rmse, mean_ratio: e.mean_ratio });
                Ok(())
            };
            if let Some(&n) = steps.get(i) {
                record("firstshot", n, self.firstshot(path, &name, slot, size, n)?)?;
            }
            if let Some(&spp) = spps.get(i) {
                record("mitsuba", spp, self.mitsuba(path, &name, variant, size, spp, i as u32 + 1)?)?;
            }
        }
        let curve = |renderer: &str| -> Vec<(f64, f64)> {
            let mut c: Vec<(f64, f64)> = runs
                .iter()
                .filter(|r| r.renderer == renderer && r.relative_rmse.is_finite())
                .map(|r| (r.seconds, r.relative_rmse))
                .collect();
            c.sort_by(|a, b| a.0.total_cmp(&b.0));
            c
        };
        let (fs_curve, mi_curve) = (curve("firstshot"), curve("mitsuba"));
        let cost = |renderer: &str| {
            let runs: Vec<(f64, f64, f64)> = runs
                .iter()
                .filter(|r| r.renderer == renderer)
                .map(|r| (r.budget as f64, r.seconds, r.relative_rmse))
                .collect();
            cost_model(&runs)
        };
        let levels = LEVELS
            .iter()
            .map(|&level| {
                let firstshot = time_to_reach(&fs_curve, level);
                let mitsuba = time_to_reach(&mi_curve, level);
                LevelResult { level, ratio: ratio(&firstshot, &mitsuba), firstshot, mitsuba }
            })
            .collect();
        let plot = Plot {
            title: format!("{name}: image error against wall time, firstshot and Mitsuba 3"),
            subtitle: format!(
                "{}x{}; firstshot on {} ({}), Mitsuba {} {variant}; whole processes; reference {}",
                size.0,
                size.1,
                slot.adapter.name,
                slot.adapter.backend,
                self.python.mitsuba_version,
                Path::new(&reference_name).file_name().unwrap_or_default().to_string_lossy()
            ),
            x_label: "seconds (whole process)".into(),
            y_label: "relative RMSE".into(),
            log_x: true,
            log_y: true,
            series: vec![
                Series { label: format!("firstshot (steps {})", join(steps)), points: fs_curve, dashed: false },
                Series { label: format!("Mitsuba {variant} (spp {})", join(spps)), points: mi_curve, dashed: false },
            ],
        };
        let plot_name = format!("peers_{name}.svg");
        write_text(&self.config.out, &plot_name, &crate::svg::render(&plot))?;
        Ok(SceneResult {
            scene: name,
            adapter: slot.clone(),
            variant: variant.into(),
            image: [size.0, size.1],
            hemicube_resolution: self.config.quick.then_some(128),
            reference: reference_name,
            reference_noise,
            firstshot_cost: cost("firstshot"),
            mitsuba_cost: cost("mitsuba"),
            runs,
            levels,
            plot: plot_name,
        })
    }
}

fn join(v: &[u32]) -> String {
    v.iter().map(u32::to_string).collect::<Vec<_>>().join(",")
}

fn firstshot_version() -> String {
    Command::new(firstshot_bin())
        .arg("--version")
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "?".into())
}

pub fn run(config: &Config, machine: &Machine, slots: &[Slot]) -> Result<(), String> {
    println!("\n== peers (firstshot against Mitsuba 3)");
    let python = match find_python() {
        Ok(p) => p,
        Err(e) => {
            println!("peers: SKIPPED: {e}");
            let report = Report {
                machine,
                quick: config.quick,
                firstshot: firstshot_version(),
                python: None,
                mitsuba_version: None,
                skipped: Some(e.clone()),
                commands: vec![],
                results: &[],
                failures: &[],
            };
            write_json(&config.out, "peers.json", &report)?;
            if std::env::var("FIRSTSHOT_REQUIRE_MITSUBA").is_ok_and(|v| v == "1") {
                return Err(format!("FIRSTSHOT_REQUIRE_MITSUBA=1 but {e}"));
            }
            println!("peers: set up the Python environment with `{SETUP}` and run again");
            return Ok(());
        }
    };
    println!("Mitsuba {} through {}", python.mitsuba_version, python.path.display());
    let dir = config.out.join("peers");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let study = Study { config, python: &python, dir };
    let mut results = Vec::new();
    let mut failures = Vec::new();
    for path in &config.scenes {
        for slot in slots {
            let what = format!("{} on {}", path.file_stem().unwrap_or_default().to_string_lossy(), slot.label());
            eprintln!("{what}");
            match study.measure(path, slot) {
                Ok(r) => results.push(r),
                Err(e) => {
                    eprintln!("  FAILED: {e}");
                    failures.push((what, e));
                }
            }
        }
    }
    print_results(&results);
    for (what, e) in &failures {
        println!("{what}: FAILED: {e}");
    }
    let commands = vec![
        format!(
            "{} SCENE --iterations N --width W --height H --adapter A --quiet --out OUT.exr{}",
            firstshot_bin().display(),
            if config.quick { " --hemicube-resolution 128" } else { "" }
        ),
        format!(
            "{} tools/mitsuba/render.py SCENE --spp N --width W --height H --variant V --seed S --quiet --out OUT.exr",
            python.path.display()
        ),
    ];
    let report = Report {
        machine,
        quick: config.quick,
        firstshot: firstshot_version(),
        python: Some(python.path.display().to_string()),
        mitsuba_version: Some(python.mitsuba_version.clone()),
        skipped: None,
        commands,
        results: &results,
        failures: &failures,
    };
    let path = write_json(&config.out, "peers.json", &report)?;
    println!("wrote {} and the plots beside it", path.display());
    if results.is_empty() {
        return Err("nothing measured".into());
    }
    Ok(())
}

fn print_results(results: &[SceneResult]) {
    for r in results {
        println!(
            "\n{} on {} against Mitsuba {}: {}x{}, reference {}{}",
            r.scene,
            r.adapter.label(),
            r.variant,
            r.image[0],
            r.image[1],
            r.reference,
            r.reference_noise.map_or(String::new(), |n| format!(" (noise {n:.4})"))
        );
        let rows: Vec<Vec<String>> = r
            .runs
            .iter()
            .map(|p| {
                vec![
                    p.renderer.to_string(),
                    format!("{} {}", p.budget, if p.renderer == "firstshot" { "steps" } else { "spp" }),
                    format!("{:.2}", p.seconds),
                    format!("{:.4}", p.relative_rmse),
                    format!("{:.3}", p.mean_ratio[1]),
                ]
            })
            .collect();
        print_table(&["renderer", "budget", "seconds", "error", "mean ratio (G)"], &rows);
    }
    println!("\nTime to reach an image error (whole processes, wall time; ratio = firstshot / Mitsuba):");
    let rows: Vec<Vec<String>> = results
        .iter()
        .flat_map(|r| {
            r.levels.iter().map(move |l| {
                vec![
                    r.scene.clone(),
                    format!("{:.0}%", l.level * 100.0),
                    show_reach(&l.firstshot),
                    show_reach(&l.mitsuba),
                    l.ratio.clone(),
                ]
            })
        })
        .collect();
    print_table(&["scene", "error", "firstshot", "Mitsuba", "ratio"], &rows);
    println!(
        "\nWhat an error costs (fitted to the runs of at least a fiftieth of the largest budget: seconds = start + N t, error^2 = s^2 / N + b^2; s^2 t in ms, the lower the faster):"
    );
    let rows: Vec<Vec<String>> = results
        .iter()
        .flat_map(|r| {
            [("firstshot", &r.firstshot_cost), ("Mitsuba", &r.mitsuba_cost)].map(|(who, c)| {
                let mut row = vec![r.scene.clone(), who.to_string()];
                row.extend(match c {
                    Some(c) => vec![
                        format!("{:.2} s", c.start),
                        format!("{:.1} ms", c.per_sample * 1e3),
                        format!("{:.3}", c.noise),
                        format!("{:.4}", c.floor),
                        format!("{:.2}", c.noise_time()),
                    ],
                    None => vec!["-".into(); 5],
                });
                row
            })
        })
        .collect();
    print_table(&["scene", "renderer", "start", "t a sample", "s", "floor b", "s^2 t"], &rows);
}
