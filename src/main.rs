//! The `firstshot` command line (docs/CLI.md): parse flags, call the library, report.

mod cli;
mod viewer;

use anyhow::Context as _;
use clap::{Args, Parser, Subcommand};
use cli::io::say;
use cli::outputs::OutputPlan;
use cli::signals::StopSignals;
use firstshot::checkpoint::Checkpoint;
use firstshot::direct_light::LightVisibility;
use firstshot::first_shot::LightWindow;
use firstshot::gpu::context::{AdapterChoice, Context, list_adapters};
use firstshot::image::Image as RenderedImage;
use firstshot::image::{Image, image_error};
use firstshot::render::{Hooks, RenderOptions, render_with};
use firstshot::scene;
use firstshot::stages::image_estimate::GatherChoice;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

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
    /// Image error of A against B (docs/ALGORITHM.md 3): relative RMSE without the directly seen
    /// lights, ratio of the means, and per-channel means.
    Compare { a: PathBuf, b: PathBuf },
    /// Adds the parts of a sharded run exactly (docs/DISTRIBUTED.md): writes OUT.exr, OUT.png,
    /// OUT.part (itself mergeable) and the stats; reports missing shards.
    Merge(MergeArgs),
    /// Opens a window on the scene (docs/CLI.md, "Viewer"): the image refines while it is
    /// shown; the mouse and keys move the camera.
    View(Box<viewer::ViewArgs>),
}

#[derive(Args)]
struct MergeArgs {
    /// The merged image, OUT.exr; OUT.png and OUT.part beside it.
    out: PathBuf,
    /// Part files of shards or of earlier merges (SHARD.exr stands for the SHARD.part beside it).
    #[arg(required = true, value_name = "PARTS")]
    parts: Vec<PathBuf>,
    /// Statistics JSON (default: OUT.stats.json).
    #[arg(long, value_name = "PATH")]
    stats: Option<PathBuf>,
    /// Refuse (exit 2) if any shard of the run is missing.
    #[arg(long)]
    complete: bool,
    /// No summary line.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
pub(crate) struct RenderArgs {
    /// The scene file: TOML, or glTF 2.0 (.gltf, .glb) by its extension (docs/SCENE_FORMAT.md).
    #[arg(required_unless_present = "list_adapters")]
    scene: Option<PathBuf>,
    /// Image to write, PATH.exr (linear float RGB), and PATH.png (tonemapped sRGB) beside it;
    /// an existing folder takes SCENE-STEM.exr inside. Default: the scene's file stem in the
    /// current directory.
    #[arg(long, value_name = "PATH")]
    out: Option<PathBuf>,
    /// Stochastic iterations (ray-bundle steps); 0 = emission and first shot only.
    #[arg(long, value_name = "N")]
    iterations: Option<u32>,
    /// Stop the iteration after this much wall time (whichever of --iterations and --time
    /// comes first).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    time: Option<f64>,
    /// Solve the area lights and emitting shapes as emitters inside the iteration instead of
    /// first shot (refused with point, spot or directional lights).
    #[arg(long)]
    no_first_shot: bool,
    /// Pixels along an edge of each parallel projection of the iteration, or "auto": from
    /// the glossy patches' sizes and the image (the default unless the scene's [settings]
    /// set one).
    #[arg(long, value_name = "R|auto", value_parser = parse_resolution, allow_negative_numbers = true)]
    bundle_resolution: Option<Resolution>,
    /// Random seed; the same seed, scene and flags give the same image.
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Longest patch edge after tessellation (scene units).
    // `allow_negative_numbers` (here and on --time): `-1` reaches run()'s range check and its
    // message, instead of clap's "unexpected argument '-1'".
    #[arg(long, value_name = "X", allow_negative_numbers = true)]
    patch_size: Option<f64>,
    /// Pixels along a full cube-face edge of the first shot's item buffers, or "auto": from
    /// the patches the light samples see (the default unless the scene's [settings] set one).
    #[arg(long, value_name = "R|auto", value_parser = parse_resolution, allow_negative_numbers = true)]
    hemicube_resolution: Option<Resolution>,
    /// The window around area-light samples: hemicube | tetrahedron.
    #[arg(long, value_name = "W")]
    light_window: Option<LightWindow>,
    /// Pixels along a full face edge of the lights' windows for the per-pixel direct light
    /// (default: enough for a typical patch to be 8 texels across as the lights see it, at
    /// least the hemicube resolution, at most 2048).
    #[arg(long, allow_negative_numbers = true, value_name = "R")]
    shadow_resolution: Option<u32>,
    /// Passes of a direct-light image (--iterations 0), each a new camera sample per pixel
    /// and new points on the area lights.
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    direct_passes: Option<u32>,
    /// Steps that advance the iteration state before any is averaged into the image
    /// (default: from the light's measured decay per bounce, docs/ALGORITHM.md 6).
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    burn_in: Option<u32>,
    /// After the first --direct-passes image steps, at most 16 with area lights or emitting
    /// shapes and 4 without (each of which estimates the direct light), steps of the
    /// iteration per estimate of the direct light, each with new points on the area lights and
    /// their windows (default 8; the indirect light every step).
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    window_steps: Option<u32>,
    /// Bundles each step of the iteration draws: 1, 4, or "auto" (the default unless the
    /// scene sets it: 4 where the image needs at least the lines the patches do and the
    /// patches are fewer than the largest view's pixels, else 1). With 4, each pixel of
    /// a 2 x 2 block gathers through its own bundle, so that neighbouring pixels' errors are
    /// independent; the automatic --bundle-resolution is halved for them (as many lines a
    /// step).
    #[arg(long, allow_negative_numbers = true, value_name = "N|auto", value_parser = |v: &str| parse_choice(v, &firstshot::iteration::BUNDLES_PER_STEP_CHOICES))]
    bundles_per_step: Option<Choice>,
    /// Lines of two widths in each bundle: fine lines (the --bundle-resolution) only in a
    /// window around the projection of the glossy patches, and outside it lines N fine lines
    /// wide: 1 (one level), 2, 4, or "auto" (the default: where glossy patches ask for lines,
    /// the widest that is at most twice the line width the image asks of a bundle and
    /// crosses the median patch that is not glossy once a step, else 1; docs/ALGORITHM.md 6,
    /// "Two levels of lines")
    #[arg(long, allow_negative_numbers = true, value_name = "N|auto", value_parser = |v: &str| parse_choice(v, &firstshot::iteration::WIDE_LINES_CHOICES))]
    wide_lines: Option<Choice>,
    /// Take each surface's first reflection of the lights, as the image gathers it from that
    /// surface, at the patch level (the paper's method) instead of at the point the gather
    /// meets it (the default, unless a light is an emitting shape).
    #[arg(long)]
    patch_first_bounce: bool,
    /// How the image's gather finishes the pixels near a patch's edge or beside a near
    /// surface: `fused` in its one pass, `split` in passes of their own, `auto` by the
    /// adapter (split on a CPU adapter, fused on a GPU). The image is the same.
    #[arg(long, value_name = "auto|fused|split", value_parser = parse_gather, default_value = "auto")]
    gather: GatherChoice,
    /// How the per-pixel direct light of area lights and emitting shapes, whose point moves
    /// every pass, finds what it sees: `rays`, a shadow ray per pixel through a BVH of the
    /// scene's triangles (exact), or `windows`, item buffers rendered at every pass's point
    /// (the paper's; exact where an occluder covers a texel centre). Point, spot and
    /// directional lights keep their windows, rendered once. With rays, where the scene has
    /// an environment, each pixel's gather also finds what it receives by its own ray
    /// through the BVH (the environment where the ray leaves the scene)
    #[arg(long, value_name = "rays|windows", value_parser = |v: &str| v.parse::<LightVisibility>(), default_value = "rays")]
    light_visibility: LightVisibility,
    /// The camera to render, by name: "camera" for the [camera] table, or a [[cameras]]
    /// entry's name (default: the first of the scene's cameras).
    #[arg(long, value_name = "NAME")]
    camera: Option<String>,
    /// Render every camera of the scene ([camera], then each [[cameras]] entry) from the
    /// same iteration: one image per camera, OUT_NAME.exr and OUT_NAME.png.
    #[arg(long, conflicts_with = "camera")]
    all_cameras: bool,
    /// A camera path (TOML keyframes, docs/CAMERA_PATH.md): render a walkthrough of
    /// --frames frames, OUT_0000.exr ... each with its PNG, from one iteration.
    #[arg(
        long,
        value_name = "PATH",
        requires_all = ["frames", "steps_per_frame"],
        conflicts_with_all = ["all_cameras", "iterations", "time", "checkpoint_every", "shard"]
    )]
    path: Option<PathBuf>,
    /// Frames of the walkthrough (--path).
    #[arg(long, value_name = "N", requires = "path")]
    frames: Option<u32>,
    /// Steps of the iteration each frame of the walkthrough averages (--path).
    #[arg(long, value_name = "K", requires = "path")]
    steps_per_frame: Option<u32>,
    /// Image width in pixels.
    #[arg(long, value_name = "W")]
    width: Option<u32>,
    /// Image height in pixels.
    #[arg(long, value_name = "H")]
    height: Option<u32>,
    /// auto | cpu | gpu | a substring of the adapter's name.
    #[arg(long, value_name = "A", default_value = "auto")]
    adapter: AdapterChoice,
    /// Print the adapters found (name, backend, type, driver; "unusable: ..." where firstshot
    /// cannot run on one) and exit.
    #[arg(long)]
    list_adapters: bool,
    /// Write run statistics as JSON.
    #[arg(long, value_name = "PATH")]
    stats: Option<PathBuf>,
    /// Refuse, before any GPU work, a run predicted to need more host memory than this many
    /// MiB (GPU memory included on a CPU adapter). Default: the host's available memory.
    #[arg(long, value_name = "MIB")]
    memory_limit: Option<u64>,
    /// No progress output.
    #[arg(long)]
    quiet: bool,
    /// Write the running image and the iteration state every this many seconds.
    #[arg(long, value_name = "S")]
    checkpoint_every: Option<f64>,
    /// Continue the run whose checkpoint belongs to --out.
    #[arg(long)]
    resume: bool,
    /// Render shard K of N (counting from 0) of the run (docs/DISTRIBUTED.md). Default: from
    /// a Slurm array (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX).
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// The number of shards with JOB_COMPLETION_INDEX (else FIRSTSHOT_SHARD_COUNT).
    #[arg(long, value_name = "N")]
    shard_count: Option<u32>,
}

/// A failure and the exit status it maps to (docs/CLI.md: 2 usage or scene error, 1 run failure).
pub(crate) struct Failure {
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

/// Progress (a bar on a terminal, a line every few seconds elsewhere, nothing with
/// --quiet), stop signals (Ctrl-C, SIGTERM, SIGHUP) and checkpoints, for `render_with`.
struct CliHooks<'a> {
    quiet: bool,
    bar: Option<indicatif::ProgressBar>,
    last_line: Instant,
    iteration_start: Instant,
    start_step: u32,
    stop: StopSignals,
    checkpoint_every: Option<Duration>,
    last_checkpoint: Instant,
    checkpoint_path: PathBuf,
    /// One per view, in order.
    images: Vec<cli::outputs::ImagePaths>,
    attributes: &'a dyn Fn(u32) -> [(&'static str, String); 4],
}

/// Seconds between progress lines when stderr is not a terminal.
const PLAIN_PROGRESS_SECONDS: u64 = 5;

impl Hooks for CliHooks<'_> {
    fn phase(&mut self, name: &str, ms: f64) {
        if !self.quiet {
            if let Some(bar) = &self.bar {
                bar.println(format!("{name}: {ms:.0} ms"));
            } else {
                say(&format!("{name}: {ms:.0} ms"));
            }
        }
        self.iteration_start = Instant::now();
    }

    fn progress(&mut self, done: u32, total: u32) {
        if self.quiet {
            return;
        }
        let elapsed = self.iteration_start.elapsed().as_secs_f64();
        let rate = (done - self.start_step.min(done)) as f64 / elapsed.max(1e-9);
        if std::io::stderr().is_terminal() {
            let bar = self.bar.get_or_insert_with(|| {
                let bar = if total == u32::MAX {
                    indicatif::ProgressBar::new_spinner()
                } else {
                    indicatif::ProgressBar::new(total as u64)
                };
                bar.set_style(
                    indicatif::ProgressStyle::with_template(
                        "{spinner} [{bar:40}] step {pos}/{len} {per_sec} elapsed {elapsed} remaining {eta}",
                    )
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
                bar
            });
            bar.set_position(done as u64);
        } else if self.last_line.elapsed().as_secs() >= PLAIN_PROGRESS_SECONDS {
            self.last_line = Instant::now();
            let of = if total == u32::MAX { String::new() } else { format!("/{total}") };
            say(&format!("step {done}{of}, {rate:.1} steps/s, {elapsed:.0} s"));
        }
    }

    fn stop_requested(&self) -> bool {
        self.stop.requested()
    }

    fn checkpoint_due(&mut self) -> bool {
        self.checkpoint_every.is_some_and(|every| self.last_checkpoint.elapsed() >= every)
    }

    fn wants_final_checkpoint(&self) -> bool {
        self.checkpoint_every.is_some() || self.stop_requested()
    }

    fn checkpoint(&mut self, checkpoint: Checkpoint, images: &[RenderedImage]) -> firstshot::Result<()> {
        for (image, paths) in images.iter().zip(&self.images) {
            image.write_exr(&paths.exr, &(self.attributes)(checkpoint.step))?;
            image.write_png(&paths.png, image.auto_exposure())?;
        }
        checkpoint.write(&self.checkpoint_path)?;
        self.last_checkpoint = Instant::now();
        Ok(())
    }
}

pub(crate) fn usage(message: String) -> Failure {
    Failure { status: 2, error: anyhow::anyhow!(message) }
}

fn main() -> ExitCode {
    // SAFETY: the first thing the process does; no other thread exists yet.
    unsafe { firstshot::gpu::context::set_cpu_adapter_threads() };
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Compare { a, b }) => compare(&a, &b),
        Some(Command::Merge(m)) => merge(&m),
        Some(Command::View(v)) => viewer::run(*v),
        None => run(cli.render),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            say(&format!("error: {}", cli::io::describe(&f.error)));
            ExitCode::from(f.status)
        }
    }
}

fn compare(a: &Path, b: &Path) -> Result<(), Failure> {
    let ia = Image::read_exr(a)?;
    let ib = Image::read_exr(b)?;
    let e = image_error(&ia, &ib)?;
    let mut out = String::new();
    out.push_str(&format!("relative RMSE      {:.5}\n", e.relative_rmse));
    out.push_str(&format!(
        "ratio of means     {:.4} {:.4} {:.4}  (error of the mean {:+.2}% {:+.2}% {:+.2}%)\n",
        e.mean_ratio[0],
        e.mean_ratio[1],
        e.mean_ratio[2],
        (e.mean_ratio[0] - 1.0) * 100.0,
        (e.mean_ratio[1] - 1.0) * 100.0,
        (e.mean_ratio[2] - 1.0) * 100.0
    ));
    out.push_str(&format!("means of A         {:.5} {:.5} {:.5}\n", e.mean[0], e.mean[1], e.mean[2]));
    out.push_str(&format!(
        "means of B         {:.5} {:.5} {:.5}\n",
        e.reference_mean[0], e.reference_mean[1], e.reference_mean[2]
    ));
    out.push_str(&format!("pixels counted     {} (2x2 downsampled, lights left out)\n", e.pixels));
    cli::io::print_stdout(&out).map_err(stdout_failure)
}

fn stdout_failure(e: std::io::Error) -> Failure {
    Failure { status: 1, error: anyhow::anyhow!("writing to standard output: {e}") }
}

fn merge(m: &MergeArgs) -> Result<(), Failure> {
    let request = firstshot::merge::MergeRequest {
        out: &m.out,
        parts: &m.parts,
        stats: m.stats.as_deref(),
        complete: m.complete,
        quiet: m.quiet,
    };
    firstshot::merge::merge_files(&request)?;
    Ok(())
}

fn print_adapters() -> Result<(), Failure> {
    let adapters = list_adapters();
    let mut out = String::new();
    if adapters.is_empty() {
        out.push_str("no adapters found\n");
    }
    for (a, unusable) in adapters {
        out.push_str(&format!("{}\t{}\t{}\t{}", a.name, a.backend, a.device_type, a.driver));
        // A fifth column only where firstshot cannot run on the adapter.
        if let Some(why) = unusable {
            out.push_str(&format!("\tunusable: {why}"));
        }
        out.push('\n');
    }
    cli::io::print_stdout(&out).map_err(stdout_failure)
}

/// Progress messages on stderr, none with --quiet.
#[derive(Clone, Copy)]
pub(crate) struct Say {
    quiet: bool,
}

impl Say {
    pub(crate) fn say(self, s: String) {
        if !self.quiet {
            say(&s);
        }
    }
}

/// The most seconds `--time` and `--checkpoint-every` take: about 31 years, far below what
/// a `Duration` holds, and a round number for the message.
const MAX_SECONDS: f64 = 1e9;

/// The most passes of a direct-light image: their stratification grid is held in memory.
const MAX_DIRECT_PASSES: u32 = 1 << 20;

/// A flag's number of seconds as a `Duration`: finite, > 0 and at most `MAX_SECONDS`
/// (`Duration::from_secs_f64` panics on what it cannot hold).
fn seconds(flag: &str, value: f64) -> Result<Duration, Failure> {
    match Duration::try_from_secs_f64(value) {
        Ok(d) if value > 0.0 && value <= MAX_SECONDS => Ok(d),
        _ => Err(usage(format!(
            "{flag} {}: expected a number of seconds > 0 and at most {MAX_SECONDS:e} (e.g. {flag} 60)",
            short_number(value)
        ))),
    }
}

/// A number for a message: `1e300`, not three hundred digits.
fn short_number(value: f64) -> String {
    if value != 0.0 && !(1e-3..1e9).contains(&value.abs()) { format!("{value:e}") } else { format!("{value}") }
}

/// The scene's render options with the flags applied, each flag checked for its range.
fn render_options(args: &RenderArgs, scene: &scene::Scene) -> Result<RenderOptions, Failure> {
    let mut options = RenderOptions::from_scene(scene);
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
        options.time_limit = Some(seconds("--time", t)?);
        if args.iterations.is_none() {
            options.iterations = u32::MAX;
        }
    }
    options.first_shot = !args.no_first_shot;
    if let Some(v) = args.light_window {
        options.light_window = v;
    }
    for (flag, v, least) in [
        ("--width", args.width, 1),
        ("--height", args.height, 1),
        ("--hemicube-resolution", args.hemicube_resolution.and_then(|r| r.0), 1),
        // A projection keeps a pixel of margin on each side of the scene's bounding sphere.
        ("--bundle-resolution", args.bundle_resolution.and_then(|r| r.0), firstshot::iteration::MIN_BUNDLE_RESOLUTION),
        ("--shadow-resolution", args.shadow_resolution, 1),
    ] {
        if let Some(v) = v
            && !(least..=16384).contains(&v)
        {
            return Err(usage(format!("{flag} {v}: expected {least} to 16384 pixels")));
        }
    }
    options.width = args.width.unwrap_or(options.width);
    options.height = args.height.unwrap_or(options.height);
    if let Some(r) = args.hemicube_resolution {
        options.hemicube_resolution = r.0;
    }
    if let Some(r) = args.bundle_resolution {
        options.bundle_resolution = r.0;
    }
    options.shadow_resolution = args.shadow_resolution;
    if let Some(v) = args.direct_passes {
        if !(1..=MAX_DIRECT_PASSES).contains(&v) {
            return Err(usage(format!("--direct-passes {v}: expected 1 to {MAX_DIRECT_PASSES} passes")));
        }
        options.direct_passes = v;
    }
    options.burn_in = args.burn_in.or(options.burn_in);
    options.memory_limit = args.memory_limit.map(|mib| mib << 20);
    options.patch_first_bounce |= args.patch_first_bounce;
    options.gather = args.gather;
    options.light_visibility = args.light_visibility;
    if let Some(b) = args.bundles_per_step {
        options.bundles_per_step = b.0;
    }
    if let Some(w) = args.wide_lines {
        options.wide_lines = w.0;
    }
    if let Some(v) = args.window_steps {
        if v == 0 {
            return Err(usage("--window-steps 0: expected at least 1 step".into()));
        }
        options.window_steps = v;
    }
    Ok(options)
}

/// The checkpoint to resume from (with --resume): a file at the checkpoint's place that
/// belongs to this scene and these flags, with numbers a run can write.
fn read_resume(
    args: &RenderArgs,
    plan: &OutputPlan,
    scene: &scene::Scene,
    patches: &scene::Patches,
    options: &RenderOptions,
) -> Result<Option<Checkpoint>, Failure> {
    if !args.resume {
        return Ok(None);
    }
    if options.iterations == 0 {
        return Err(usage(
            "--resume with --iterations 0: a direct-light image has no iteration state to continue; drop one of the two".into(),
        ));
    }
    let path = &plan.checkpoint;
    if !path.exists() {
        return Err(usage(format!(
            "--resume: no checkpoint at {} (it is written beside --out by --checkpoint-every or a stop signal)",
            path.display()
        )));
    }
    let checkpoint = Checkpoint::read(path)?;
    if checkpoint.fingerprint != firstshot::render::fingerprint(scene, options) {
        return Err(usage(format!(
            "--resume: {} belongs to another scene or other flags (patch size, resolutions, seed, image size, first shot); run with the same ones or without --resume",
            path.display()
        )));
    }
    let (burn_in, _) =
        firstshot::render::burn_in_steps(scene, patches, options, options.bundles_per_step_for(scene, patches));
    let pixels: Vec<u64> =
        options.views(scene).iter().map(|v| v.camera.width as u64 * v.camera.height as u64).collect();
    let schedule = firstshot::render::DirectSchedule::of(scene, patches, options);
    checkpoint.check_numbers(path, burn_in, &|n| schedule.estimates(n), Some(&pixels))?;
    Ok(Some(checkpoint))
}

/// Everything a render needs once the flags, the scene and the adapter have been checked.
struct Job<'a> {
    args: &'a RenderArgs,
    scene_path: &'a Path,
    scene: &'a scene::Scene,
    patches: &'a scene::Patches,
    options: &'a RenderOptions,
    ctx: &'a Context,
    paths: &'a OutputPlan,
    stop: &'a StopSignals,
    checkpoint_every: Option<Duration>,
    say: Say,
    start: Instant,
    tessellation_ms: f64,
    shard: Option<firstshot::shard::ShardRun>,
}

fn run(args: RenderArgs) -> Result<(), Failure> {
    if args.list_adapters {
        return print_adapters();
    }
    let Some(scene_path) = args.scene.clone() else {
        return Err(usage("a scene file is required".into()));
    };
    // First, so that a stop signal at any later moment is a graceful one.
    let stop = StopSignals::install();
    let say = Say { quiet: args.quiet };
    let start = Instant::now();
    // Every check that can refuse comes before any folder is made or file written.
    let mut scene = scene::load(&scene_path)?;
    // What the scene's files hold but the renderer ignores (docs/SCENE_FORMAT.md).
    for note in &scene.notes {
        say.say(format!("note: {note}"));
    }
    if let Some(name) = &args.camera {
        scene.select_camera(name).map_err(|e| usage(format!("--camera {name}: {e}")))?;
    }
    let mut options = render_options(&args, &scene)?;
    if args.path.is_some() {
        return cli::walkthrough::run(&args, &scene_path, &scene, &options, &stop, say, start);
    }
    if args.all_cameras {
        // Each camera at its own size, unless --width / --height give every camera theirs.
        options.cameras = scene
            .cameras
            .iter()
            .map(|c| {
                let (width, height) = (args.width.unwrap_or(c.camera.width), args.height.unwrap_or(c.camera.height));
                scene::NamedCamera { name: c.name.clone(), camera: scene::Camera { width, height, ..c.camera } }
            })
            .collect();
    }
    let checkpoint_every = args.checkpoint_every.map(|s| seconds("--checkpoint-every", s)).transpose()?;
    // A shard (docs/DISTRIBUTED.md): its own seed and share of the steps, its own file names.
    let shard = firstshot::shard::from_cli(args.shard.as_deref(), args.shard_count)?;
    if args.all_cameras && shard.is_some() {
        return Err(usage(
            "--all-cameras with a shard: a shard's part holds one image; render the cameras' shards one camera at a time (--camera NAME)".into(),
        ));
    }
    let shard = shard.map(|s| s.apply(&scene, &mut options)).transpose()?;
    let exr = cli::outputs::exr_path(args.out.as_deref(), &scene_path)?;
    let (exr, stats) = match &shard {
        Some(s) => (s.shard.path(&exr), args.stats.as_deref().map(|p| s.shard.path(p))),
        None => (exr, args.stats.clone()),
    };
    let mut plan = if args.all_cameras {
        // OUT_NAME.exr per camera; the checkpoint (all the cameras' image sums) is OUT.checkpoint.
        let exrs = options
            .cameras
            .iter()
            .map(|c| cli::outputs::exr_beside(&exr, &c.name, "--all-cameras: camera"))
            .collect::<Result<Vec<_>, _>>()?;
        OutputPlan::with_images(&exr, &exrs, stats.as_deref(), &scene_path, false)?
    } else {
        OutputPlan::new(&exr, stats.as_deref(), &scene_path, shard.is_some())?
    };
    firstshot::render::check_options(&scene, &options)?;
    say.say(format!("loaded {} in {:.0} ms", scene_path.display(), start.elapsed().as_secs_f64() * 1e3));

    // The adapter opens while the scene is tessellated (`Context::open_while`).
    let (ctx, tessellated) = Context::open_while(&args.adapter, || {
        let t = Instant::now();
        scene::tessellate(&scene, options.patch_size).map(|p| (p, t.elapsed().as_secs_f64() * 1e3))
    });
    let (patches, tessellation_ms) = tessellated?;
    say.say(format!(
        "tessellated into {} patches and {} light samples in {tessellation_ms:.0} ms",
        patches.patches.len(),
        patches.samples.len()
    ));
    let camera_notes = firstshot::render::camera_notes(&scene, &patches, &options);
    for note in patches.notes.iter().chain(&options.coarse_bundle_note(&scene, &patches)).chain(&camera_notes) {
        say.say(format!("note: {note}"));
    }
    let resume = read_resume(&args, &plan, &scene, &patches, &options)?;
    let ctx = ctx?;
    firstshot::render::check_limits(&ctx.limits(), &patches, &options)?;
    say.say(format!("adapter: {}", ctx.summary));
    let memory = firstshot::render::predict_memory(&ctx, &scene, &patches, &options);
    say.say(memory.summary());
    memory.check()?;
    if stop.requested() {
        return Err(interrupted(&stop, "before the render began; nothing was written".into()));
    }
    plan.make_folders()?;

    let job = Job {
        args: &args,
        scene_path: &scene_path,
        scene: &scene,
        patches: &patches,
        options: &options,
        ctx: &ctx,
        paths: &plan,
        stop: &stop,
        checkpoint_every,
        say,
        start,
        tessellation_ms,
        shard,
    };
    let result = job.render(resume);
    if result.as_ref().is_err_and(|f| f.status == 2) {
        // A refusal that only the render could find: leave no folder behind either.
        plan.undo_folders();
    }
    result
}

/// The exit of a run that a stop signal ended: 128 + the signal's number.
pub(crate) fn interrupted(stop: &StopSignals, when: String) -> Failure {
    let status = stop.exit_status().unwrap_or(130);
    Failure { status, error: anyhow::anyhow!("interrupted by {} {when}", stop.name()) }
}

impl Job<'_> {
    /// The EXR metadata of an image after `steps` steps.
    fn attributes(&self, steps: u32) -> [(&'static str, String); 4] {
        [
            ("firstshot.scene", self.scene_path.display().to_string()),
            ("firstshot.seed", self.options.seed.to_string()),
            ("firstshot.iterations", steps.to_string()),
            ("firstshot.adapter", self.ctx.summary.to_string()),
        ]
    }

    /// Renders with progress, stop signals and checkpoints, then writes and reports.
    fn render(&self, resume: Option<Checkpoint>) -> Result<(), Failure> {
        let attributes = |steps: u32| self.attributes(steps);
        let mut hooks = CliHooks {
            quiet: self.args.quiet,
            bar: None,
            last_line: Instant::now(),
            iteration_start: Instant::now(),
            start_step: resume.as_ref().map_or(0, |c| c.step),
            stop: self.stop.clone(),
            checkpoint_every: self.checkpoint_every,
            last_checkpoint: Instant::now(),
            checkpoint_path: self.paths.checkpoint.clone(),
            images: self.paths.images.clone(),
            attributes: &attributes,
        };
        let result = render_with(self.ctx, self.scene, self.patches, self.options, resume.as_ref(), &mut hooks);
        if let Some(bar) = hooks.bar.take() {
            bar.finish_and_clear();
        }
        let mut rendered = result?;
        if rendered.stats.first_shot {
            self.say.say(format!(
                "first shot: {} light samples, {} faces of {r}x{r}, {} pairs, {:.0} ms",
                rendered.stats.light_samples,
                rendered.stats.first_shot_faces,
                rendered.stats.first_shot_pairs,
                rendered.stats.first_shot_ms,
                r = rendered.stats.hemicube_resolution
            ));
        }
        rendered.stats.tessellation_ms = self.tessellation_ms;
        rendered.stats.total_ms = self.start.elapsed().as_secs_f64() * 1e3;
        self.write(&rendered)
    }

    /// Writes the image, PNG and stats, and reports; an interrupted run exits with 130.
    fn write(&self, rendered: &firstshot::render::Rendered) -> Result<(), Failure> {
        let (options, stats, paths) = (self.options, &rendered.stats, self.paths);
        let t = Instant::now();
        let steps = if options.iterations == 0 { 0 } else { stats.iterations };
        let images = std::iter::once(&rendered.image).chain(rendered.other_views.iter().map(|v| &v.image));
        for (image, to) in images.zip(&paths.images) {
            image.write_exr(&to.exr, &self.attributes(steps))?;
            image.write_png(&to.png, image.auto_exposure())?;
        }
        if let (Some(run), Some(part)) = (&self.shard, &paths.part) {
            let scene = self.scene_path.display().to_string();
            let (w, h) = (options.width, options.height);
            firstshot::merge::Part::of_shard(run, &scene, w, h, &rendered.image_sum, steps)?.write(part)?;
        }
        if self.args.stats.is_some() {
            let json = match &self.shard {
                None => serde_json::to_string_pretty(stats),
                Some(run) => serde_json::to_value(stats).and_then(|mut json| {
                    json["shard"] = firstshot::shard::stats_json(run);
                    serde_json::to_string_pretty(&json)
                }),
            };
            let json = json.context("encoding the stats")?;
            paths.write_stats(format!("{json}\n").as_bytes())?;
        }
        if stats.iterations > 0 && options.iterations > 0 {
            let bundles = match stats.bundles_per_step {
                1 => format!("one {r}x{r} bundle", r = stats.bundle_resolution),
                n => format!("{n} interleaved {r}x{r} bundles", r = stats.bundle_resolution),
            };
            self.say.say(format!(
                "iteration: {} steps of {bundles}, median {:.1} ms per step ({:.1} steps/s)",
                stats.iterations,
                stats.iteration_ms_median,
                1e3 / stats.iteration_ms_median.max(1e-9),
            ));
        }
        let written: Vec<String> =
            paths.images.iter().map(|i| format!("{} and {}", i.exr.display(), i.png.display())).collect();
        self.say.say(format!(
            "wrote {} in {:.0} ms ({:.0} ms in all)",
            written.join(", "),
            t.elapsed().as_secs_f64() * 1e3,
            self.start.elapsed().as_secs_f64() * 1e3
        ));
        if options.iterations > 0 && stats.iterations == 0 {
            self.say.say(format!(
                "the time limit ended the run before any step reached the image: it holds the direct light ({} of {} passes)",
                stats.camera_samples, options.direct_passes
            ));
        }
        if rendered.interrupted {
            let when = if options.iterations == 0 || stats.iterations == 0 {
                format!(
                    "after pass {} of the direct-light image (which averages the passes done; it cannot be resumed)",
                    stats.camera_samples
                )
            } else {
                format!(
                    "after step {}: continue with the same flags and --resume ({})",
                    stats.iterations,
                    paths.checkpoint.display()
                )
            };
            return Err(interrupted(self.stop, when));
        }
        Ok(())
    }
}

/// `--bundle-resolution`, `--hemicube-resolution`: a number of pixels, or "auto" (`None`).
#[derive(Debug, Clone, Copy)]
struct Resolution(Option<u32>);

fn parse_resolution(value: &str) -> std::result::Result<Resolution, String> {
    match value {
        "auto" => Ok(Resolution(None)),
        _ => value
            .parse()
            .map(|r| Resolution(Some(r)))
            .map_err(|_| format!("expected a number of pixels or \"auto\", got {value:?}")),
    }
}

/// A count from a fixed set, or "auto" (`None`): `--bundles-per-step`, `--wide-lines`.
#[derive(Debug, Clone, Copy)]
struct Choice(Option<u32>);

fn parse_choice(value: &str, choices: &[u32]) -> std::result::Result<Choice, String> {
    if value == "auto" {
        return Ok(Choice(None));
    }
    value.parse::<u32>().ok().filter(|n| choices.contains(n)).map(|n| Choice(Some(n))).ok_or_else(|| {
        let listed: Vec<String> = choices.iter().map(u32::to_string).collect();
        format!("expected {} or \"auto\", got {value:?}", listed.join(", "))
    })
}

fn parse_gather(value: &str) -> std::result::Result<GatherChoice, String> {
    match value {
        "auto" => Ok(GatherChoice::Auto),
        "fused" => Ok(GatherChoice::Fused),
        "split" => Ok(GatherChoice::Split),
        _ => Err(format!("expected \"auto\", \"fused\" or \"split\", got {value:?}")),
    }
}
