//! The `firstshot` command line (CLI.md): parse flags, call the library, report.

use anyhow::Context as _;
use clap::{Args, Parser, Subcommand};
use firstshot::first_shot::LightWindow;
use firstshot::gpu::context::{AdapterChoice, Context, list_adapters};
use firstshot::image::{Image, image_error};
use firstshot::render::{RenderOptions, render};
use firstshot::scene;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "firstshot",
    version,
    about = "GPU global illumination of glossy scenes: incoming first shot + ray-bundle stochastic iteration",
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    render: RenderArgs,
}

#[derive(Subcommand)]
enum Command {
    /// Image error of A against B (DESIGN.md 3): relative RMSE without the directly seen
    /// lights, ratio of the means, and per-channel means.
    Compare { a: PathBuf, b: PathBuf },
}

#[derive(Args)]
struct RenderArgs {
    /// The scene file (TOML, SCENE_FORMAT.md).
    #[arg(required_unless_present = "list_adapters")]
    scene: Option<PathBuf>,
    /// Image to write, PATH.exr (linear float RGB), and PATH.png (tonemapped sRGB) beside it.
    /// Default: the scene's file stem in the current directory.
    #[arg(long, value_name = "PATH")]
    out: Option<PathBuf>,
    /// Stochastic iterations (ray-bundle steps); 0 = emission and first shot only.
    #[arg(long, value_name = "N")]
    iterations: Option<u32>,
    /// Stop the iteration after this much wall time (whichever of --iterations and --time
    /// comes first).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    time: Option<f64>,
    /// Solve the area lights as emitters inside the iteration instead of first shot.
    #[arg(long)]
    no_first_shot: bool,
    /// Pixels along an edge of each parallel projection of the iteration.
    #[arg(long, value_name = "R")]
    bundle_resolution: Option<u32>,
    /// Random seed; the same seed, scene and flags give the same image.
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Longest patch edge after tessellation (scene units).
    // `allow_negative_numbers` (here and on --time): `-1` reaches run()'s range check and its
    // message, instead of clap's "unexpected argument '-1'".
    #[arg(long, value_name = "X", allow_negative_numbers = true)]
    patch_size: Option<f64>,
    /// Pixels along a full cube-face edge of the first shot's item buffers.
    #[arg(long, value_name = "R")]
    hemicube_resolution: Option<u32>,
    /// The window around area-light samples: hemicube | tetrahedron.
    #[arg(long, value_name = "W")]
    light_window: Option<LightWindow>,
    /// Image width in pixels.
    #[arg(long, value_name = "W")]
    width: Option<u32>,
    /// Image height in pixels.
    #[arg(long, value_name = "H")]
    height: Option<u32>,
    /// auto | cpu | gpu | a substring of the adapter's name.
    #[arg(long, value_name = "A", default_value = "auto")]
    adapter: AdapterChoice,
    /// Print the adapters found (name, backend, type) and exit.
    #[arg(long)]
    list_adapters: bool,
    /// Write run statistics as JSON.
    #[arg(long, value_name = "PATH")]
    stats: Option<PathBuf>,
    /// No progress output.
    #[arg(long)]
    quiet: bool,
}

/// A failure and the exit status it maps to (CLI.md: 2 usage or scene error, 1 run failure).
struct Failure {
    status: u8,
    error: anyhow::Error,
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(e: E) -> Self {
        let error = e.into();
        let status = match error.downcast_ref::<firstshot::Error>() {
            Some(e) if e.is_usage() => 2,
            _ => 1,
        };
        Failure { status, error }
    }
}

fn usage(message: String) -> Failure {
    Failure { status: 2, error: anyhow::anyhow!(message) }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Compare { a, b }) => compare(&a, &b),
        None => run(cli.render),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {:#}", f.error);
            ExitCode::from(f.status)
        }
    }
}

fn compare(a: &Path, b: &Path) -> Result<(), Failure> {
    let ia = Image::read_exr(a)?;
    let ib = Image::read_exr(b)?;
    let e = image_error(&ia, &ib)?;
    println!("relative RMSE      {:.5}", e.relative_rmse);
    println!(
        "ratio of means     {:.4} {:.4} {:.4}  (error of the mean {:+.2}% {:+.2}% {:+.2}%)",
        e.mean_ratio[0],
        e.mean_ratio[1],
        e.mean_ratio[2],
        (e.mean_ratio[0] - 1.0) * 100.0,
        (e.mean_ratio[1] - 1.0) * 100.0,
        (e.mean_ratio[2] - 1.0) * 100.0
    );
    println!("means of A         {:.5} {:.5} {:.5}", e.mean[0], e.mean[1], e.mean[2]);
    println!("means of B         {:.5} {:.5} {:.5}", e.reference_mean[0], e.reference_mean[1], e.reference_mean[2]);
    println!("pixels counted     {} (2x2 downsampled, lights left out)", e.pixels);
    Ok(())
}

/// `--out` as the EXR path and the PNG path beside it.
fn output_paths(args: &RenderArgs, scene_path: &Path) -> Result<(PathBuf, PathBuf), Failure> {
    let exr = match &args.out {
        Some(out) => match out.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("exr") => out.clone(),
            None => out.with_extension("exr"),
            Some(e) => {
                return Err(usage(format!(
                    "--out {}: expected a .exr path (or no extension), not .{e}",
                    out.display()
                )));
            }
        },
        None => {
            let stem = scene_path.file_stem().unwrap_or_default();
            PathBuf::from(stem).with_extension("exr")
        }
    };
    let png = exr.with_extension("png");
    Ok((exr, png))
}

fn run(args: RenderArgs) -> Result<(), Failure> {
    if args.list_adapters {
        let adapters = list_adapters();
        if adapters.is_empty() {
            println!("no adapters found");
        }
        for a in adapters {
            println!("{}\t{}\t{}\t{}", a.name, a.backend, a.device_type, a.driver);
        }
        return Ok(());
    }
    let Some(scene_path) = args.scene.clone() else {
        return Err(usage("a scene file is required".into()));
    };
    let say = |s: String| {
        if !args.quiet {
            eprintln!("{s}");
        }
    };
    let start = Instant::now();
    let scene = scene::load(&scene_path)?;
    let mut options = RenderOptions::from_scene(&scene);
    if let Some(v) = args.iterations {
        options.iterations = v;
    }
    if let Some(v) = args.seed {
        options.seed = v;
    }
    if let Some(v) = args.patch_size {
        if !(v.is_finite() && v > 0.0) {
            return Err(usage(format!("--patch-size {v}: expected a finite number > 0")));
        }
        options.patch_size = v;
    }
    if let Some(t) = args.time {
        if !(t.is_finite() && t > 0.0) {
            return Err(usage(format!("--time {t}: expected a number of seconds > 0")));
        }
        options.time_limit = Some(std::time::Duration::from_secs_f64(t));
        if args.iterations.is_none() {
            options.iterations = u32::MAX;
        }
    }
    options.first_shot = !args.no_first_shot;
    if let Some(v) = args.light_window {
        options.light_window = v;
    }
    for (flag, v) in [
        ("--width", args.width),
        ("--height", args.height),
        ("--hemicube-resolution", args.hemicube_resolution),
        ("--bundle-resolution", args.bundle_resolution),
    ] {
        if let Some(v) = v
            && !(1..=16384).contains(&v)
        {
            return Err(usage(format!("{flag} {v}: expected 1 to 16384 pixels")));
        }
    }
    options.width = args.width.unwrap_or(options.width);
    options.height = args.height.unwrap_or(options.height);
    options.hemicube_resolution = args.hemicube_resolution.unwrap_or(options.hemicube_resolution);
    options.bundle_resolution = args.bundle_resolution.unwrap_or(options.bundle_resolution);
    let (exr_path, png_path) = output_paths(&args, &scene_path)?;
    firstshot::render::check_options(&scene, &options)?;
    say(format!("loaded {} in {:.0} ms", scene_path.display(), start.elapsed().as_secs_f64() * 1e3));

    let t = Instant::now();
    let patches = scene::tessellate(&scene, options.patch_size)?;
    let tessellation_ms = t.elapsed().as_secs_f64() * 1e3;
    say(format!(
        "tessellated into {} patches and {} light samples in {tessellation_ms:.0} ms",
        patches.patches.len(),
        patches.samples.len()
    ));

    let ctx = Context::new(&args.adapter)?;
    say(format!("adapter: {}", ctx.summary));
    firstshot::render::check_limits(&ctx.limits(), &patches, &options)?;

    let mut rendered = render(&ctx, &scene, &patches, &options)?;
    if rendered.stats.first_shot {
        say(format!(
            "first shot: {} light samples, {} faces of {r}x{r}, {} pairs, {:.0} ms",
            rendered.stats.light_samples,
            rendered.stats.first_shot_faces,
            rendered.stats.first_shot_pairs,
            rendered.stats.first_shot_ms,
            r = options.hemicube_resolution
        ));
    }
    rendered.stats.tessellation_ms = tessellation_ms;
    rendered.stats.total_ms = start.elapsed().as_secs_f64() * 1e3;

    if let Some(dir) = exr_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let attributes = [
        ("firstshot.scene", scene_path.display().to_string()),
        ("firstshot.seed", options.seed.to_string()),
        ("firstshot.iterations", options.iterations.to_string()),
        ("firstshot.adapter", ctx.summary.to_string()),
    ];
    rendered.image.write_exr(&exr_path, &attributes)?;
    rendered.image.write_png(&png_path, rendered.image.auto_exposure())?;
    if let Some(stats) = &args.stats {
        let json = serde_json::to_string_pretty(&rendered.stats).context("encoding the stats")?;
        firstshot::image::write_atomically(stats, json.as_bytes())?;
    }
    if rendered.stats.iterations > 0 {
        say(format!(
            "iteration: {} steps of {r}x{r} bundles, median {:.1} ms per step ({:.1} steps/s)",
            rendered.stats.iterations,
            rendered.stats.iteration_ms_median,
            1e3 / rendered.stats.iteration_ms_median.max(1e-9),
            r = options.bundle_resolution
        ));
    }
    say(format!(
        "wrote {} and {} ({:.0} ms in all)",
        exr_path.display(),
        png_path.display(),
        start.elapsed().as_secs_f64() * 1e3
    ));
    Ok(())
}
