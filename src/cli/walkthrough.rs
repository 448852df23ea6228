//! `--path`: a walkthrough (docs/CAMERA_PATH.md). The frames' cameras come from the path
//! file; `render::render_path` renders them from one iteration; this writes each frame as it
//! comes (`OUT_0000.exr` and its PNG), then a checkpoint of the state after it
//! (`OUT.checkpoint`), so that `--resume` goes on after the last frame written.

use super::outputs::{OutputPlan, exr_beside, exr_path};
use super::signals::StopSignals;
use crate::{Failure, RenderArgs, Say, interrupted, usage};
use anyhow::Context as _;
use firstshot::checkpoint::{Checkpoint, fnv1a};
use firstshot::gpu::context::Context;
use firstshot::image::Image;
use firstshot::render::{FrameHooks, Hooks, PathStart, RenderOptions, Walkthrough, render_path};
use firstshot::scene::camera_path::{CameraPath, load_path};
use firstshot::scene::{Camera, Scene};
use std::path::Path;
use std::time::Instant;

/// The most frames of one walkthrough: every frame's outputs are checked before any work.
const MAX_FRAMES: u32 = 100_000;

/// Identifies the scene, every option that changes the frames, the path and its frame and
/// step counts: a checkpoint resumes only the walkthrough it belongs to.
fn fingerprint(scene: &Scene, options: &RenderOptions, path: &CameraPath, frames: u32, steps: u32) -> u64 {
    let base = firstshot::render::fingerprint(scene, options);
    fnv1a(format!("{base}\npath {:?}\nframes {frames}\nsteps per frame {steps}", path.keyframes).as_bytes())
}

/// Writes each frame and the state after it, and says how far the walkthrough is.
struct FrameWriter<'a> {
    plan: &'a OutputPlan,
    attributes: &'a dyn Fn(u32, u32) -> Vec<(&'static str, String)>,
    fingerprint: u64,
    /// One exposure for every frame's PNG (frame 0's automatic one), so that the PNGs do
    /// not flicker in brightness from frame to frame.
    exposure: Option<f32>,
    frames: u32,
    stop: StopSignals,
    say: Say,
    frame_start: Instant,
}

impl Hooks for FrameWriter<'_> {
    fn phase(&mut self, name: &str, ms: f64) {
        self.say.say(format!("{name}: {ms:.0} ms"));
    }

    fn stop_requested(&self) -> bool {
        self.stop.requested()
    }
}

impl FrameHooks for FrameWriter<'_> {
    fn frame(&mut self, index: u32, image: &Image, step: u32, state: Vec<u8>) -> firstshot::Result<()> {
        let paths = &self.plan.images[index as usize];
        let exposure = *self.exposure.get_or_insert_with(|| image.auto_exposure());
        image.write_exr(&paths.exr, &(self.attributes)(index, step))?;
        image.write_png(&paths.png, exposure)?;
        // After the frame's files: a checkpoint never claims a frame that is not written.
        let checkpoint = Checkpoint { fingerprint: self.fingerprint, step, state, image_sum: Vec::new() };
        checkpoint.write(&self.plan.checkpoint)?;
        self.say.say(format!(
            "frame {}/{} in {:.0} ms: {}",
            index + 1,
            self.frames,
            self.frame_start.elapsed().as_secs_f64() * 1e3,
            paths.exr.display()
        ));
        self.frame_start = Instant::now();
        Ok(())
    }
}

/// Renders the walkthrough of `args.path` (main.rs has checked the flags that conflict).
pub fn run(
    args: &RenderArgs,
    scene_path: &Path,
    scene: &Scene,
    options: &RenderOptions,
    stop: &StopSignals,
    say: Say,
    start: Instant,
) -> Result<(), Failure> {
    let (Some(file), Some(frames), Some(steps)) = (&args.path, args.frames, args.steps_per_frame) else {
        return Err(usage("--path needs --frames N and --steps-per-frame K".into()));
    };
    if !(1..=MAX_FRAMES).contains(&frames) {
        return Err(usage(format!("--frames {frames}: expected 1 to {MAX_FRAMES} frames")));
    }
    if steps == 0 {
        return Err(usage("--steps-per-frame 0: expected at least 1 step".into()));
    }
    if steps.checked_mul(frames).and_then(|n| n.checked_add(firstshot::render::MAX_BURN_IN)).is_none() {
        return Err(usage(format!("--frames {frames} x --steps-per-frame {steps}: more steps than a run counts")));
    }
    if firstshot::shard::from_cli(args.shard.as_deref(), args.shard_count)?.is_some() {
        return Err(usage(
            "--path in a shard (a Slurm array or an Indexed Job): render the walkthrough unsharded".into(),
        ));
    }
    // `up` and `fov_y` default to the scene's camera (or --camera's). The keyframes are in the
    // scene file's coordinates, the loaded scene in its own (`Scene::recentre`).
    let path = load_path(file, &scene.camera)?.moved(-scene.file_origin);
    let cameras: Vec<Camera> = path.cameras(frames, options.width, options.height)?;
    // As a run of frames x steps iterations (the burn-in and the stats' image steps).
    let options = RenderOptions { iterations: frames * steps, ..options.clone() };
    let exr = exr_path(args.out.as_deref(), scene_path)?;
    let digits = (frames - 1).to_string().len().max(4);
    let exrs =
        (0..frames).map(|f| exr_beside(&exr, &format!("{f:0digits$}"), "frame")).collect::<Result<Vec<_>, _>>()?;
    let mut plan = OutputPlan::with_images(&exr, &exrs, args.stats.as_deref(), scene_path, false)?;
    firstshot::render::check_options(scene, &options)?;
    let fingerprint = fingerprint(scene, &options, &path, frames, steps);
    // The adapter opens while the scene is tessellated (`Context::open_while`).
    let (ctx, patches) = Context::open_while(&args.adapter, || firstshot::scene::tessellate(scene, options.patch_size));
    let patches = patches?;
    let resume = match args.resume {
        false => None,
        true => {
            // Only a resume needs the burn-in before the renderer, which sizes it again (its
            // default walks the patches, src/burn_in.rs).
            let per_step = options.bundles_per_step_for(scene, &patches);
            let (burn_in, _) = firstshot::render::burn_in_steps(scene, &patches, &options, per_step);
            Some(read_resume(&plan, fingerprint, burn_in, steps, frames)?)
        }
    };
    let ctx = ctx?;
    firstshot::render::check_limits(&ctx.limits(), &patches, &options)?;
    say.say(format!("adapter: {}", ctx.summary));
    if stop.requested() {
        return Err(interrupted(stop, "before the render began; nothing was written".into()));
    }
    plan.make_folders()?;

    // On resume, the PNGs keep frame 0's exposure (read back from its EXR, if it is there).
    let exposure = match &resume {
        Some(_) => Image::read_exr(&plan.images[0].exr).ok().map(|i| i.auto_exposure()),
        None => None,
    };
    let attributes = |frame: u32, step: u32| {
        vec![
            ("firstshot.scene", scene_path.display().to_string()),
            ("firstshot.path", file.display().to_string()),
            ("firstshot.frame", frame.to_string()),
            ("firstshot.seed", options.seed.to_string()),
            ("firstshot.iterations", steps.to_string()),
            ("firstshot.step", step.to_string()),
            ("firstshot.adapter", ctx.summary.to_string()),
        ]
    };
    let mut writer = FrameWriter {
        plan: &plan,
        attributes: &attributes,
        fingerprint,
        exposure,
        frames,
        stop: stop.clone(),
        say,
        frame_start: Instant::now(),
    };
    let start_state = resume.as_ref().map(|c| PathStart { state: &c.state, step: c.step });
    let walk = Walkthrough { frames: &cameras, steps_per_frame: steps, start: start_state };
    let result = render_path(&ctx, scene, &patches, &options, &walk, &mut writer);
    let done = match result {
        Err(e) if e.is_usage() => {
            plan.undo_folders();
            return Err(e.into());
        }
        other => other?,
    };
    if args.stats.is_some() {
        let json = serde_json::json!({
            "adapter": ctx.summary,
            "scene": scene_path.display().to_string(),
            "path": file.display().to_string(),
            "patches": patches.patches.len(),
            "image": [options.width, options.height],
            "frames": frames,
            "steps_per_frame": steps,
            "frames_rendered": [done.frames.start, done.frames.end],
            "burn_in_steps": done.burn_in_steps,
            "iteration_ms_median": done.iteration_ms_median,
            "first_shot_ms": done.first_shot_ms,
            "total_ms": start.elapsed().as_secs_f64() * 1e3,
            "seed": options.seed,
        });
        let json = serde_json::to_string_pretty(&json).context("encoding the stats")?;
        plan.write_stats(format!("{json}\n").as_bytes())?;
    }
    if done.interrupted {
        return Err(interrupted(
            stop,
            format!(
                "after {} of {frames} frames (the frame in progress is dropped): continue with the same flags and --resume ({})",
                done.frames.end,
                plan.checkpoint.display()
            ),
        ));
    }
    if done.frames.is_empty() {
        say.say("every frame was already written: nothing to do".into());
    }
    say.say(format!(
        "wrote frames {} to {} ({:.0} ms in all, median {:.1} ms per step)",
        done.frames.start,
        done.frames.end.saturating_sub(1),
        start.elapsed().as_secs_f64() * 1e3,
        done.iteration_ms_median
    ));
    Ok(())
}

/// The checkpoint of `--resume`: the state after a whole number of frames of this
/// walkthrough (same scene, flags, path, frame and step counts).
fn read_resume(
    plan: &OutputPlan,
    fingerprint: u64,
    burn_in: u32,
    steps: u32,
    frames: u32,
) -> Result<Checkpoint, Failure> {
    let path = &plan.checkpoint;
    if !path.exists() {
        return Err(usage(format!(
            "--resume: no checkpoint at {} (a walkthrough writes it beside --out after each frame)",
            path.display()
        )));
    }
    let checkpoint = Checkpoint::read(path)?;
    if checkpoint.fingerprint != fingerprint {
        return Err(usage(format!(
            "--resume: {} belongs to another scene, path, frame or step count or other flags; run with the same ones or without --resume",
            path.display()
        )));
    }
    // The state's numbers (finite, past the burn-in); a walkthrough keeps no image sum.
    checkpoint.check_numbers(path, burn_in, &|n| n, Some(&[]))?;
    let image_steps = checkpoint.step - burn_in;
    if !image_steps.is_multiple_of(steps) || image_steps / steps > frames {
        return Err(usage(format!(
            "{}: not a usable checkpoint (step {} is not the end of a frame of {steps} steps after the burn-in of {burn_in}); delete it or run without --resume",
            path.display(),
            checkpoint.step
        )));
    }
    Ok(checkpoint)
}
