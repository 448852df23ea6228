//! The benchmark harness of firstshot (issue #5): throughput per adapter, the convergence
//! study of the paper's figure 6, the scaling study, firstshot against Mitsuba 3 (peers), and
//! what a scene's extra cameras cost (views). Prints tables, writes JSON and SVG.
//!
//! ```sh
//! cargo bench --bench harness -- [throughput|convergence|scaling|all|peers|views] [options]
//! cargo bench --bench harness -- --help
//! ```
//!
//! Timings are medians over repeats after a warm-up run (the first run of a pipeline pays
//! for shader compilation, and on lavapipe for LLVM's JIT). Nothing here asserts a time.

mod convergence;
mod mitsuba;
mod peers;
mod scaling;
mod session;
mod stats;
mod svg;
mod throughput;
mod views;

use clap::{Parser, ValueEnum};
use firstshot::gpu::profile::TIMESTAMP_FEATURES;
use firstshot::gpu::{AdapterChoice, AdapterSummary, Context, context::list_adapters};
use firstshot::render::RenderOptions;
use firstshot::scene::{Camera, NamedCamera, Patches, Scene};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Mode {
    /// First-shot time, step time, stages, fragments, per adapter (the default).
    Throughput,
    /// RMSE against time with and without first shot; equal-error speed-up; SVG plot.
    Convergence,
    /// Step time against patch count (Sierpinski levels) and bundle resolution.
    Scaling,
    /// The three, in that order.
    All,
    /// Time to reach 10, 5 and 2 % image error, firstshot against Mitsuba 3 on the same
    /// machine (whole processes; needs tools/mitsuba/setup.sh, else skips visibly).
    Peers,
    /// One camera against all of a scene's cameras (`--all-cameras`) at the same steps, in
    /// alternated pairs of whole processes: the ratio of their times and what a view adds to
    /// a step.
    Views,
}

#[derive(Parser, Debug)]
#[command(name = "harness", about = "firstshot benchmarks: throughput, convergence, scaling, peers, views")]
struct Args {
    /// What to measure.
    #[arg(value_enum, default_value_t = Mode::Throughput)]
    mode: Mode,
    /// Scenes: names in scenes/ (sierpinski, cornell_box) or paths to TOML files.
    /// Default: sierpinski,cornell_box (scaling always uses sierpinski; peers:
    /// cornell_box,cornell_point,sierpinski; views: benches/scenes/sierpinski_4cameras.toml
    /// and benches/scenes/cornell_box_4cameras.toml).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    scenes: Option<Vec<String>>,
    /// Adapters: all | first | cpu | gpu | a comma list of indices (as --list-adapters
    /// orders them) or substrings of "name backend type" (e.g. vulkan,gl); all, first, cpu
    /// and gpu leave out adapters firstshot cannot run on (--list-adapters marks them).
    /// Default: all for throughput, first for convergence, scaling, peers and views.
    #[arg(long, value_name = "SPEC")]
    adapters: Option<String>,
    /// Directory for JSON and SVG.
    #[arg(long, value_name = "DIR", default_value = "target/bench")]
    out: PathBuf,
    /// Small sizes (128 x 128 image, bundles and hemicube; few steps): a smoke run.
    #[arg(long)]
    quick: bool,
    /// Repeats of every timed run (default 5; --quick 1).
    #[arg(long, value_name = "N")]
    repeats: Option<usize>,
    /// Steps per timed render in throughput (default 40; --quick 8).
    #[arg(long, value_name = "N")]
    steps: Option<u32>,
    /// Area lights as emitters in the iteration instead of first shot (throughput and
    /// scaling; convergence always measures both).
    #[arg(long)]
    no_first_shot: bool,
    /// Override the scenes' bundle resolution (throughput and convergence).
    #[arg(long, value_name = "R")]
    bundle_resolution: Option<u32>,
    /// Bundles a step draws, as `firstshot --bundles-per-step` (1 or 4; default: the
    /// automatic choice, four at Sierpinski's own 512 x 512), so that a step's time can be
    /// held against a run that drew another number (throughput, scaling, convergence).
    #[arg(long, value_name = "N", value_parser = parse_bundles_per_step)]
    bundles_per_step: Option<u32>,
    /// Wide lines outside the glossy patches' window, as `firstshot --wide-lines` (1: one
    /// level; default: the automatic choice).
    #[arg(long, value_name = "N")]
    wide_lines: Option<u32>,
    /// The area lights' visibility, as `firstshot --light-visibility` (default: rays).
    #[arg(long, value_name = "rays|windows")]
    light_visibility: Option<String>,
    /// Render every camera of each scene (`[camera]` and its `[[cameras]]`) in each step, as
    /// `firstshot --all-cameras` does (throughput: the stage profile then shows each view's
    /// image stages).
    #[arg(long)]
    all_cameras: bool,
    /// Steps of the long runs the convergence study measures against (default 2000;
    /// --quick 64).
    #[arg(long, value_name = "N")]
    long_steps: Option<u32>,
    /// Step counts of the convergence series (default 5,10,20,50,100,200,500;
    /// --quick 2,4,8,16).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    series: Option<Vec<u32>>,
    /// An external reference image (EXR) for the convergence study, used for the scene whose
    /// file stem starts its file name (cornell_box.full.exr -> cornell_box), or for the only
    /// scene. May be repeated.
    #[arg(long, value_name = "PATH")]
    reference: Vec<PathBuf>,
    /// Reuse long runs already in --out (their file names hold every parameter).
    #[arg(long)]
    reuse_long: bool,
    /// Sierpinski levels of the scaling study (default 3,4,5,6,7; --quick 3,4,5).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    levels: Option<Vec<u32>>,
    /// Bundle resolutions of the scaling study (default 256,512,1024,1280; --quick 64,128;
    /// the lines' buckets of 1448 and more exceed one binding of 128 MiB, lavapipe's).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    resolutions: Option<Vec<u32>>,
    /// Patch sizes of the scaling study's whole-process runs of the Sierpinski scene
    /// (`firstshot --patch-size X`, 128 x 128 image, two image steps; default 0.35,0.1,0.03;
    /// --quick 0.35). 0.0085 gives 10 M patches (docs/PERFORMANCE.md, Scaling).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    patch_sizes: Option<Vec<f64>>,
    /// Image sizes WxH of the scaling study's whole-process runs of the Cornell box (two
    /// image steps; default 512x512,2048x2048; --quick 256x256). 7680x4320 is 8K.
    #[arg(long, value_delimiter = ',', value_name = "LIST", value_parser = stats::parse_image_size)]
    images: Option<Vec<(u32, u32)>>,
    /// Steps per timed configuration of the scaling study (default 20; --quick 4).
    #[arg(long, value_name = "N")]
    scaling_steps: Option<u32>,
    /// Image height of the peers study (width from the scene's aspect ratio; default 256;
    /// --quick 128).
    #[arg(long, value_name = "PIXELS")]
    peer_size: Option<u32>,
    /// firstshot's step counts in the peers study (default 2,5,10,20,50,100,200,500,1000;
    /// --quick 4,16,64,256).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    peer_steps: Option<Vec<u32>>,
    /// Mitsuba's samples per pixel in the peers study (default 1,2,4,...,1024; --quick 4,16,64,256).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    peer_spp: Option<Vec<u32>>,
    /// Samples per pixel of a reference the peers study renders itself, for a scene with no
    /// refs/<scene>.full.exr (default 4096; --quick 256). Kept in --out for the next run.
    #[arg(long, value_name = "N")]
    peer_reference_spp: Option<u32>,
    /// Image steps of each process of the views study (default 100; --quick 8).
    #[arg(long, value_name = "N")]
    view_steps: Option<u32>,
    /// Image size WxH of every camera in the views study (default 256x256; --quick 128x128).
    #[arg(long, value_name = "WxH", value_parser = stats::parse_image_size)]
    view_size: Option<(u32, u32)>,
    /// Open devices without timestamp queries (stage times are then wall times only).
    #[arg(long)]
    no_timestamps: bool,
    /// Passed by `cargo bench`; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

/// The arguments with the defaults of the mode and of --quick filled in.
pub struct Config {
    pub quick: bool,
    pub timestamps: bool,
    pub out: PathBuf,
    pub scenes: Vec<PathBuf>,
    pub repeats: usize,
    pub steps: u32,
    pub bundle_resolution: Option<u32>,
    pub bundles_per_step: Option<u32>,
    pub wide_lines: Option<u32>,
    pub light_visibility: firstshot::direct_light::LightVisibility,
    pub all_cameras: bool,
    pub first_shot: bool,
    pub long_steps: u32,
    pub series: Vec<u32>,
    pub references: Vec<PathBuf>,
    pub reuse_long: bool,
    pub levels: Vec<u32>,
    pub resolutions: Vec<u32>,
    pub scaling_steps: u32,
    pub patch_sizes: Vec<f64>,
    pub images: Vec<(u32, u32)>,
    pub peer_size: u32,
    pub peer_steps: Vec<u32>,
    pub peer_spp: Vec<u32>,
    pub peer_reference_spp: u32,
    pub view_steps: u32,
    pub view_size: (u32, u32),
}

impl Config {
    /// The scene's options at the sizes of this run: --quick shrinks image, hemicube and
    /// bundles to 128 so that a smoke run is short; --bundle-resolution overrides.
    pub fn options(&self, scene: &Scene) -> RenderOptions {
        let mut o = RenderOptions::from_scene(scene);
        if self.quick {
            (o.width, o.height, o.hemicube_resolution, o.bundle_resolution) = (128, 128, Some(128), Some(128));
        }
        if let Some(r) = self.bundle_resolution {
            o.bundle_resolution = Some(r);
        }
        if self.bundles_per_step.is_some() {
            o.bundles_per_step = self.bundles_per_step;
        }
        if self.wide_lines.is_some() {
            o.wide_lines = self.wide_lines;
        }
        o.light_visibility = self.light_visibility;
        o.first_shot = self.first_shot;
        if self.all_cameras {
            // Every camera at the run's image size, as `firstshot --all-cameras --width W --height H`.
            o.cameras = scene
                .cameras
                .iter()
                .map(|c| NamedCamera {
                    name: c.name.clone(),
                    camera: Camera { width: o.width, height: o.height, ..c.camera },
                })
                .collect();
        }
        o
    }
}

fn parse_bundles_per_step(value: &str) -> Result<u32, String> {
    let choices = firstshot::iteration::BUNDLES_PER_STEP_CHOICES;
    value.parse::<u32>().ok().filter(|n| choices.contains(n)).ok_or_else(|| {
        let listed: Vec<String> = choices.iter().map(u32::to_string).collect();
        format!("expected one of {}, got {value:?}", listed.join(", "))
    })
}

/// `scenes/NAME.toml` for a bare name, else the path itself.
fn scene_path(name: &str) -> PathBuf {
    let p = Path::new(name);
    if p.extension().is_some() || p.components().count() > 1 {
        p.to_path_buf()
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(format!("{name}.toml"))
    }
}

/// A loaded, tessellated scene.
pub struct LoadedScene {
    pub name: String,
    pub scene: Scene,
    pub patches: Patches,
}

/// A scene file loaded and tessellated at its own patch size; every error names the file.
pub fn load_scene(path: &Path) -> Result<LoadedScene, String> {
    // The loader's errors name the file already; tessellation's do not.
    let scene = firstshot::scene::load(path).map_err(|e| e.to_string())?;
    let patches = firstshot::scene::tessellate(&scene, scene.settings.patch_size)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let name = path.file_stem().unwrap_or_default().to_string_lossy().into_owned();
    Ok(LoadedScene { name, scene, patches })
}

/// An adapter picked for a run: its place in `list_adapters()` and what it is.
#[derive(Debug, Clone, Serialize)]
pub struct Slot {
    pub index: usize,
    pub adapter: AdapterSummary,
}

impl Slot {
    pub fn label(&self) -> String {
        format!("#{} {} {}", self.index, self.adapter.backend, self.adapter.device_type)
    }

    /// A device on this adapter, with timestamp queries where it has them and `timestamps`.
    pub fn open(&self, timestamps: bool) -> Result<Context, String> {
        let features = if timestamps { TIMESTAMP_FEATURES } else { wgpu::Features::empty() };
        let ctx = Context::new_with_features(&AdapterChoice::Index(self.index), features).map_err(|e| e.to_string())?;
        if ctx.summary != self.adapter {
            eprintln!("warning: adapter #{} opened as {}, listed as {}", self.index, ctx.summary, self.adapter);
        }
        Ok(ctx)
    }
}

fn select_adapters(spec: &str, all: &[AdapterSummary], usable: &[bool]) -> Result<Vec<Slot>, String> {
    let usable = |i: usize| usable.get(i).copied().unwrap_or(true);
    let first_usable = (0..all.len()).find(|&i| usable(i));
    let slots = |keep: &dyn Fn(usize, &AdapterSummary) -> bool| -> Vec<Slot> {
        all.iter()
            .enumerate()
            .filter(|(i, a)| keep(*i, a))
            .map(|(index, a)| Slot { index, adapter: a.clone() })
            .collect()
    };
    let picked = match spec.to_ascii_lowercase().as_str() {
        "all" => slots(&|i, _| usable(i)),
        "first" => slots(&|i, _| Some(i) == first_usable),
        "cpu" => slots(&|i, a| usable(i) && a.is_cpu()),
        "gpu" => slots(&|i, a| usable(i) && !a.is_cpu() && a.device_type != "Other"),
        list => {
            let items: Vec<&str> = list.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
            slots(&|i, a| {
                let text = format!("{} {} {}", a.name, a.backend, a.device_type).to_lowercase();
                items.iter().any(|item| item.parse::<usize>().map_or_else(|_| text.contains(item), |n| n == i))
            })
        }
    };
    if picked.is_empty() {
        let found: Vec<String> = all.iter().enumerate().map(|(i, a)| format!("#{i} {a}")).collect();
        return Err(format!("--adapters {spec}: no adapter fits; found: {}", found.join("; ")));
    }
    Ok(picked)
}

/// Runs `f`, turning an error or a panic (wgpu reports validation errors by panicking)
/// into a message, so that one failing adapter or scene does not end the whole run.
pub fn guarded<T>(f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => Err(format!(
            "panicked: {}",
            payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "(no message)".into())
        )),
    }
}

/// CPU time (user + system) of this process so far, seconds: on a software adapter the
/// driver's threads run in this process, so CPU time over wall time is the cores it kept
/// busy. Linux only (`/proc/self/stat`, whose ticks are USER_HZ = 100 per second).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 / 100.0)
}

/// The 1, 5 and 15 minute load averages: others' work on a shared machine shows here.
pub fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let v: Vec<f64> = text.split_whitespace().take(3).filter_map(|x| x.parse().ok()).collect();
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// Where the figures came from.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    pub os: String,
    /// LP_NUM_THREADS (lavapipe/llvmpipe's thread count: `set_cpu_adapter_threads`'s four a
    /// core unless the environment set it).
    pub lp_num_threads: Option<String>,
    pub adapters: Vec<AdapterSummary>,
    pub commit: Option<String>,
    /// At the start of the run.
    pub load_average: Option<[f64; 3]>,
    pub unix_time: u64,
    pub utc: String,
}

fn machine(adapters: &[AdapterSummary]) -> Machine {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let cpu = cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let os = std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .map(|s| format!("{} {}", std::env::consts::OS, s.trim()))
        .unwrap_or_else(|_| std::env::consts::OS.to_string());
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    let unix_time = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    Machine {
        cpu,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        os,
        lp_num_threads: std::env::var("LP_NUM_THREADS").ok(),
        adapters: adapters.to_vec(),
        commit,
        load_average: load_average(),
        unix_time,
        utc: utc(unix_time),
    }
}

/// `YYYY-MM-DD HH:MM UTC` from Unix seconds (civil-from-days, H. Hinnant), so that no date
/// crate is needed.
fn utc(secs: u64) -> String {
    let days = (secs / 86400) as i64;
    let rem = secs % 86400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + (m <= 2) as i64;
    format!("{y:04}-{m:02}-{d:02} {:02}:{:02} UTC", rem / 3600, rem % 3600 / 60)
}

/// Writes `value` as pretty JSON to `dir/name`.
pub fn write_json<T: Serialize>(dir: &Path, name: &str, value: &T) -> Result<PathBuf, String> {
    let path = dir.join(name);
    let json = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
    firstshot::image::write_atomically(&path, json.as_bytes()).map_err(|e| e.to_string())?;
    Ok(path)
}

pub fn write_text(dir: &Path, name: &str, text: &str) -> Result<PathBuf, String> {
    let path = dir.join(name);
    firstshot::image::write_atomically(&path, text.as_bytes()).map_err(|e| e.to_string())?;
    Ok(path)
}

/// A table with right-aligned columns (the first left-aligned).
pub fn print_table(headers: &[&str], rows: &[Vec<String>]) {
    let mut widths: Vec<usize> = headers.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: Vec<String>| {
        let parts: Vec<String> = cells
            .iter()
            .zip(&widths)
            .enumerate()
            .map(|(i, (c, w))| if i == 0 { format!("{c:<w$}") } else { format!("{c:>w$}") })
            .collect();
        println!("{}", parts.join("  ").trim_end());
    };
    line(headers.iter().map(|s| s.to_string()).collect());
    line(widths.iter().map(|w| "-".repeat(*w)).collect());
    for row in rows {
        line(row.clone());
    }
}

/// `median [min-max]` with `digits` decimals.
pub fn spread(s: &stats::Summary, digits: usize) -> String {
    format!("{:.d$} [{:.d$}-{:.d$}]", s.median, s.min, s.max, d = digits)
}

fn main() -> ExitCode {
    // As the command line does, so that the in-process studies measure what a user gets (the
    // machine's record says the value); the renderer processes the studies start set it too.
    // SAFETY: the first thing the process does; no other thread exists yet.
    unsafe { firstshot::gpu::context::set_cpu_adapter_threads() };
    let args = Args::parse();
    let quick = args.quick;
    let default_scenes: Vec<String> = if args.mode == Mode::Peers {
        ["cornell_box", "cornell_point", "sierpinski"].map(String::from).to_vec()
    } else if args.mode == Mode::Views {
        ["sierpinski_4cameras", "cornell_box_4cameras"]
            .map(|s| format!("{}/benches/scenes/{s}.toml", env!("CARGO_MANIFEST_DIR")))
            .to_vec()
    } else {
        vec!["sierpinski".to_string(), "cornell_box".to_string()]
    };
    let images = match args.images {
        Some(sizes) => sizes,
        None if quick => vec![(256, 256)],
        None => vec![(512, 512), (2048, 2048)],
    };
    let view_size = match args.view_size {
        Some(size) => size,
        None if quick => (128, 128),
        None => (256, 256),
    };
    let config = Config {
        quick,
        timestamps: !args.no_timestamps,
        out: args.out.clone(),
        scenes: args.scenes.clone().unwrap_or(default_scenes).iter().map(|s| scene_path(s)).collect(),
        repeats: args.repeats.unwrap_or(if quick { 1 } else { 5 }).max(1),
        steps: args.steps.unwrap_or(if quick { 8 } else { 40 }).max(1),
        bundle_resolution: args.bundle_resolution,
        bundles_per_step: args.bundles_per_step,
        wide_lines: args.wide_lines,
        light_visibility: match args.light_visibility.as_deref().map(str::parse).transpose() {
            Ok(v) => v.unwrap_or_default(),
            Err(e) => {
                eprintln!("--light-visibility: {e}");
                std::process::exit(2);
            }
        },
        all_cameras: args.all_cameras,
        first_shot: !args.no_first_shot,
        long_steps: args.long_steps.unwrap_or(if quick { 64 } else { 2000 }).max(1),
        series: args.series.clone().unwrap_or(if quick {
            vec![2, 4, 8, 16]
        } else {
            vec![5, 10, 20, 50, 100, 200, 500]
        }),
        references: args.reference.clone(),
        reuse_long: args.reuse_long,
        levels: args.levels.clone().unwrap_or(if quick { vec![3, 4, 5] } else { vec![3, 4, 5, 6, 7] }),
        resolutions: args.resolutions.clone().unwrap_or(if quick { vec![64, 128] } else { vec![256, 512, 1024, 1280] }),
        scaling_steps: args.scaling_steps.unwrap_or(if quick { 4 } else { 20 }).max(1),
        patch_sizes: args.patch_sizes.clone().unwrap_or(if quick { vec![0.35] } else { vec![0.35, 0.1, 0.03] }),
        images,
        peer_size: args.peer_size.unwrap_or(if quick { 128 } else { 256 }).max(2),
        peer_steps: args.peer_steps.clone().unwrap_or(if quick {
            vec![4, 16, 64, 256]
        } else {
            vec![2, 5, 10, 20, 50, 100, 200, 500, 1000]
        }),
        peer_spp: args.peer_spp.clone().unwrap_or(if quick {
            vec![4, 16, 64, 256]
        } else {
            (0..11).map(|k| 1 << k).collect()
        }),
        peer_reference_spp: args.peer_reference_spp.unwrap_or(if quick { 256 } else { 4096 }).max(2),
        view_steps: args.view_steps.unwrap_or(if quick { 8 } else { 100 }).max(1),
        view_size,
    };
    if let Err(e) = std::fs::create_dir_all(&config.out) {
        eprintln!("error: creating {}: {e}", config.out.display());
        return ExitCode::from(2);
    }
    let listed = list_adapters();
    // Adapters keep their places in the list (`--adapter INDEX`); `all`, `cpu` and `gpu`
    // leave out those firstshot cannot run on.
    let usable: Vec<bool> = listed.iter().map(|(_, why)| why.is_none()).collect();
    let all: Vec<AdapterSummary> = listed.iter().map(|(a, _)| a.clone()).collect();
    let machine = machine(&all);
    println!(
        "machine: {} ({} cores), {}, load average {}",
        machine.cpu,
        machine.cores,
        machine.os,
        machine.load_average.map_or("?".into(), |l| format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2]))
    );
    for (i, (a, why)) in listed.iter().enumerate() {
        let note = why.as_ref().map_or(String::new(), |w| format!(" (unusable: {w})"));
        println!("adapter #{i}: {a} [{}]{note}", a.driver);
    }
    let pick = |default: &str| select_adapters(args.adapters.as_deref().unwrap_or(default), &all, &usable);
    let modes: &[Mode] = match args.mode {
        Mode::All => &[Mode::Throughput, Mode::Convergence, Mode::Scaling],
        Mode::Throughput => &[Mode::Throughput],
        Mode::Convergence => &[Mode::Convergence],
        Mode::Scaling => &[Mode::Scaling],
        Mode::Peers => &[Mode::Peers],
        Mode::Views => &[Mode::Views],
    };
    let mut failed = false;
    for mode in modes {
        let result = match mode {
            Mode::Throughput => pick("all").and_then(|s| throughput::run(&config, &machine, &s)),
            Mode::Convergence => pick("first").and_then(|s| convergence::run(&config, &machine, &s)),
            Mode::Scaling => pick("first").and_then(|s| scaling::run(&config, &machine, &s)),
            Mode::Peers => pick("first").and_then(|s| peers::run(&config, &machine, &s)),
            Mode::Views => pick("first").and_then(|s| views::run(&config, &machine, &s)),
            Mode::All => unreachable!(),
        };
        if let Err(e) = result {
            eprintln!("error: {mode:?}: {e}");
            failed = true;
        }
    }
    if failed { ExitCode::FAILURE } else { ExitCode::SUCCESS }
}
