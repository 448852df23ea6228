//! Convergence (the paper's figure 6): the image error (docs/ALGORITHM.md 3) against time, with and
//! without first shot, and the equal-error speed-up of first shot.
//!
//! Step k's random numbers depend only on (seed, k), so a run of N steps is exactly the mean
//! of the first N estimates of any longer run with that seed: each point of a curve is one
//! `render` with `iterations = N`, and its time is that run's whole time (first shot
//! included). The long runs that stand for the converged image use another seed, so that
//! the short runs' estimates are not part of the image they are measured against (which
//! would hide a share N / long of their error).

use crate::stats::{SpeedUp, equal_error_speedups};
use crate::svg::{Plot, Series};
use crate::{Config, LoadedScene, Machine, Slot, guarded, load_scene, print_table, write_json, write_text};
use firstshot::gpu::Context;
use firstshot::image::{Image, image_error};
use firstshot::render::{RenderOptions, render};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The long runs' seed is the scene's plus this.
const LONG_SEED_OFFSET: u64 = 1_000_003;

#[derive(Debug, Clone, Serialize)]
pub struct Point {
    pub first_shot: bool,
    pub steps: u32,
    /// The long no-first-shot run (another seed), measured against the long first-shot
    /// run: the no-first-shot curve's last point there.
    pub long: bool,
    /// The render's whole time (first shot, steps, image read-back), seconds.
    pub seconds: f64,
    pub first_shot_ms: f64,
    /// Relative RMSE against the long first-shot run.
    pub rmse_long_first_shot: f64,
    /// Against the long run of the same method (NaN for that run itself).
    pub rmse_long_same_method: f64,
    /// Against the external reference, if one was given.
    pub rmse_reference: Option<f64>,
    /// Ratio of the means (green) against the external reference: shows a bias that the
    /// RMSE mixes with noise.
    pub mean_ratio_reference: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SpeedUps {
    /// Measured against: long_first_shot | long_same_method | reference.
    pub against: String,
    pub points: Vec<SpeedUp>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SceneResult {
    pub scene: String,
    pub adapter: Slot,
    pub patches: usize,
    pub image: [u32; 2],
    pub bundle_resolution: u32,
    pub hemicube_resolution: u32,
    pub seed: u64,
    pub long_seed: u64,
    pub long_steps: u32,
    pub reference: Option<String>,
    /// The long no-first-shot run against the long first-shot run: where the two methods'
    /// limits (and the long runs' own noise) put a floor under the curves.
    pub long_runs_rmse: f64,
    pub points: Vec<Point>,
    pub speedups: Vec<SpeedUps>,
    pub plot: String,
}

#[derive(Serialize)]
struct Report<'a> {
    machine: &'a Machine,
    quick: bool,
    results: &'a [SceneResult],
    failures: &'a [(String, String)],
}

/// `dir/long_<scene>_<method>_<sizes>_n<steps>_s<seed>.exr`: every parameter in the name, so
/// `--reuse-long` can trust a file it finds.
fn long_path(dir: &Path, scene: &str, o: &RenderOptions) -> PathBuf {
    dir.join(format!(
        "long_{scene}_{}_{}x{}_b{}_h{}_p{}_n{}_s{}.exr",
        if o.first_shot { "fs" } else { "nofs" },
        o.width,
        o.height,
        o.bundle_resolution.unwrap_or_default(),
        o.hemicube_resolution.unwrap_or_default(),
        o.patch_size,
        o.iterations,
        o.seed
    ))
}

/// A long run and its time in seconds (NaN when reused without a record of it), written
/// beside the other outputs (EXR, and its time in a `.json` of the same stem).
fn long_run(config: &Config, ctx: &Context, s: &LoadedScene, o: &RenderOptions) -> Result<(Image, f64), String> {
    let path = long_path(&config.out, &s.name, o);
    let timing = path.with_extension("json");
    if config.reuse_long && path.exists() {
        eprintln!("  reusing {}", path.display());
        let seconds = std::fs::read_to_string(&timing)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| v["seconds"].as_f64())
            .unwrap_or(f64::NAN);
        return Ok((Image::read_exr(&path).map_err(|e| e.to_string())?, seconds));
    }
    eprintln!("  long run: {} steps, first shot {}", o.iterations, o.first_shot);
    let out = render(ctx, &s.scene, &s.patches, o).map_err(|e| e.to_string())?;
    let seconds = out.stats.total_ms / 1e3;
    eprintln!("    {seconds:.1} s");
    out.image.write_exr(&path, &[("firstshot.seed", o.seed.to_string())]).map_err(|e| e.to_string())?;
    let record = serde_json::json!({ "seconds": seconds, "stats": out.stats });
    firstshot::image::write_atomically(&timing, record.to_string().as_bytes()).map_err(|e| e.to_string())?;
    Ok((out.image, seconds))
}

/// `image` box-filtered down to `width` x `height` when it is that size times a power of
/// two (a pixel of the renders is the mean over its area, which the box filter keeps).
pub(crate) fn fit_reference(mut image: Image, width: u32, height: u32) -> Option<Image> {
    while image.width > width && image.width == 2 * (image.width / 2) && image.height == 2 * (image.height / 2) {
        image = image.downsample2();
    }
    ((image.width, image.height) == (width, height)).then_some(image)
}

/// The external reference for this scene: the one whose file name starts with the scene's
/// stem, else the only one when there is one scene.
pub(crate) fn reference_for(config: &Config, scene: &str) -> Option<PathBuf> {
    let named = config.references.iter().find(|p| {
        p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(&format!("{scene}.")) || n == scene)
    });
    named
        .cloned()
        .or_else(|| (config.scenes.len() == 1 && config.references.len() == 1).then(|| config.references[0].clone()))
}

fn measure(config: &Config, slot: &Slot, s: &LoadedScene) -> Result<SceneResult, String> {
    let ctx = slot.open(config.timestamps)?;
    let mut base = config.options(&s.scene);
    // The resolution the renders will take, in the long runs' file names and the results.
    base.bundle_resolution = Some(base.bundle_resolution_for(&s.scene, &s.patches));
    let mut warm = base.clone();
    warm.iterations = 2;
    render(&ctx, &s.scene, &s.patches, &warm).map_err(|e| e.to_string())?;

    let long_seed = base.seed.wrapping_add(LONG_SEED_OFFSET);
    let long = |first_shot: bool| {
        let mut o = base.clone();
        (o.first_shot, o.iterations, o.seed) = (first_shot, config.long_steps, long_seed);
        long_run(config, &ctx, s, &o)
    };
    let (long_fs, _) = long(true)?;
    let (long_nofs, long_nofs_seconds) = long(false)?;
    let long_runs_rmse = image_error(&long_nofs, &long_fs).map_err(|e| e.to_string())?.relative_rmse;

    let reference_path = reference_for(config, &s.name);
    let reference = match &reference_path {
        Some(p) => {
            let img = Image::read_exr(p).map_err(|e| e.to_string())?;
            let (w, h) = (img.width, img.height);
            let fitted = fit_reference(img, base.width, base.height);
            if fitted.is_none() {
                eprintln!("  {} is {w}x{h}, the renders {}x{}: left out", p.display(), base.width, base.height);
            }
            fitted
        }
        None => None,
    };

    let mut points = Vec::new();
    // The two methods alternate, so that a change in the machine's load (it is shared)
    // falls on both curves alike rather than on one of them.
    for &n in &config.series {
        for first_shot in [true, false] {
            let mut o = base.clone();
            (o.first_shot, o.iterations) = (first_shot, n);
            let out = render(&ctx, &s.scene, &s.patches, &o).map_err(|e| e.to_string())?;
            let err = |r: &Image| image_error(&out.image, r).map_err(|e| e.to_string());
            let vs_ref = reference.as_ref().map(err).transpose()?;
            let point = Point {
                first_shot,
                steps: n,
                long: false,
                seconds: out.stats.total_ms / 1e3,
                first_shot_ms: out.stats.first_shot_ms,
                rmse_long_first_shot: err(&long_fs)?.relative_rmse,
                rmse_long_same_method: err(if first_shot { &long_fs } else { &long_nofs })?.relative_rmse,
                rmse_reference: vs_ref.map(|e| e.relative_rmse),
                mean_ratio_reference: vs_ref.map(|e| e.mean_ratio[1]),
            };
            eprintln!(
                "  {} N={n}: {:.2} s, rmse {:.4} (same method {:.4}){}",
                if first_shot { "first shot   " } else { "no first shot" },
                point.seconds,
                point.rmse_long_first_shot,
                point.rmse_long_same_method,
                point.rmse_reference.map_or(String::new(), |r| format!(", reference {r:.4}"))
            );
            points.push(point);
        }
    }

    points.sort_by_key(|p| (!p.first_shot, p.steps));
    // The long no-first-shot run has its own seed, so against the long first-shot run it
    // is one more (independent) point of the no-first-shot curve, far beyond the series.
    let long_vs_ref = reference.as_ref().map(|r| image_error(&long_nofs, r)).transpose().map_err(|e| e.to_string())?;
    points.push(Point {
        first_shot: false,
        steps: config.long_steps,
        long: true,
        seconds: long_nofs_seconds,
        first_shot_ms: 0.0,
        rmse_long_first_shot: long_runs_rmse,
        rmse_long_same_method: f64::NAN,
        rmse_reference: long_vs_ref.map(|e| e.relative_rmse),
        mean_ratio_reference: long_vs_ref.map(|e| e.mean_ratio[1]),
    });
    let curve = |fs: bool, key: &dyn Fn(&Point) -> Option<f64>| -> Vec<(f64, f64)> {
        let mut c: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.first_shot == fs)
            .filter_map(|p| Some((p.seconds, key(p)?)))
            .filter(|(t, e)| t.is_finite() && e.is_finite())
            .collect();
        c.sort_by(|a, b| a.0.total_cmp(&b.0));
        c
    };
    type Key = fn(&Point) -> Option<f64>;
    let keys: Vec<(&str, &str, Key)> = {
        let mut k: Vec<(&str, &str, Key)> = vec![
            ("long_first_shot", "vs long first-shot run", |p| Some(p.rmse_long_first_shot)),
            ("long_same_method", "vs long run of the same method", |p| Some(p.rmse_long_same_method)),
        ];
        if reference.is_some() {
            k.push(("reference", "vs external reference", |p| p.rmse_reference));
        }
        k
    };
    let speedups: Vec<SpeedUps> = keys
        .iter()
        .map(|(against, _, key)| SpeedUps {
            against: against.to_string(),
            points: equal_error_speedups(&curve(true, key), &curve(false, key)),
        })
        .collect();

    let mut series = Vec::new();
    for (i, (against, label, key)) in keys.iter().enumerate() {
        for fs in [true, false] {
            // The first-shot curve against its own method's long run is the same as
            // against the long first-shot run: drawn once.
            if fs && *against == "long_same_method" {
                continue;
            }
            series.push(Series {
                label: format!("{} {label}", if fs { "first shot" } else { "no first shot" }),
                points: curve(fs, key),
                dashed: i > 0,
            });
        }
    }
    let hemicube_resolution = base.hemicube_resolution_for(&s.patches);
    let plot = Plot {
        title: format!("{}: relative RMSE against time, with and without first shot", s.name),
        subtitle: format!(
            "{} ({}); {} patches, image {}x{}, bundles {}, hemicube {}; long runs {} steps",
            slot.adapter.name,
            slot.adapter.backend,
            s.patches.patches.len(),
            base.width,
            base.height,
            base.bundle_resolution.unwrap_or_default(),
            hemicube_resolution,
            config.long_steps
        ),
        x_label: "seconds (whole render, first shot included)".into(),
        y_label: "relative RMSE".into(),
        log_x: true,
        log_y: true,
        series,
    };
    let plot_name = format!("convergence_{}.svg", s.name);
    write_text(&config.out, &plot_name, &crate::svg::render(&plot))?;
    Ok(SceneResult {
        scene: s.name.clone(),
        adapter: slot.clone(),
        patches: s.patches.patches.len(),
        image: [base.width, base.height],
        bundle_resolution: base.bundle_resolution.unwrap_or_default(),
        hemicube_resolution,
        seed: base.seed,
        long_seed,
        long_steps: config.long_steps,
        reference: reference_path.filter(|_| reference.is_some()).map(|p| p.display().to_string()),
        long_runs_rmse,
        points,
        speedups,
        plot: plot_name,
    })
}

pub fn run(config: &Config, machine: &Machine, slots: &[Slot]) -> Result<(), String> {
    println!("\n== convergence");
    let mut results = Vec::new();
    let mut failures = Vec::new();
    for path in &config.scenes {
        let loaded = load_scene(path)?;
        for slot in slots {
            eprintln!("{} on {}", loaded.name, slot.label());
            match guarded(|| measure(config, slot, &loaded)) {
                Ok(r) => results.push(r),
                Err(e) => {
                    eprintln!("  FAILED: {e}");
                    failures.push((format!("{} on {}", loaded.name, slot.label()), e));
                }
            }
        }
    }
    for r in &results {
        print_result(r);
    }
    for (what, e) in &failures {
        println!("{what}: FAILED: {e}");
    }
    let report = Report { machine, quick: config.quick, results: &results, failures: &failures };
    let path = write_json(&config.out, "convergence.json", &report)?;
    println!("wrote {} and the plots beside it", path.display());
    if results.is_empty() {
        return Err("nothing measured".into());
    }
    Ok(())
}

fn print_result(r: &SceneResult) {
    println!(
        "\n{} on {}: {} patches, image {}x{}, bundles {}, long runs {} steps (seed {}); long no-first-shot vs long first-shot run: {:.4}",
        r.scene,
        r.adapter.label(),
        r.patches,
        r.image[0],
        r.image[1],
        r.bundle_resolution,
        r.long_steps,
        r.long_seed,
        r.long_runs_rmse
    );
    let with_ref = r.reference.is_some();
    let rows: Vec<Vec<String>> = r
        .points
        .iter()
        .map(|p| {
            let mut row = vec![
                match (p.first_shot, p.long) {
                    (true, _) => "first shot".into(),
                    (false, false) => "none".into(),
                    (false, true) => "none (long)".into(),
                },
                p.steps.to_string(),
                format!("{:.2}", p.seconds),
                format!("{:.4}", p.rmse_long_first_shot),
                if p.long { "-".into() } else { format!("{:.4}", p.rmse_long_same_method) },
            ];
            if with_ref {
                row.push(p.rmse_reference.map_or("-".into(), |v| format!("{v:.4}")));
                row.push(p.mean_ratio_reference.map_or("-".into(), |v| format!("{v:.3}")));
            }
            row
        })
        .collect();
    let mut headers = vec!["method", "steps", "seconds", "rmse vs long fs", "vs long same"];
    if with_ref {
        headers.extend(["vs reference", "mean ratio"]);
    }
    print_table(&headers, &rows);
    for s in &r.speedups {
        let cells: Vec<String> =
            s.points.iter().map(|p| format!("{:.4}@{:.2}s: {}", p.level, p.time_fast, p.display())).collect();
        println!("equal-error speed-up ({}): {}", s.against, cells.join(", "));
    }
}
