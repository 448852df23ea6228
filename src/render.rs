//! The order of the pipeline: tessellated scene on the GPU -> first shot -> iteration loop
//! -> image. `main.rs` and the tests call `render`.

use crate::checkpoint::Checkpoint;
use crate::first_shot::{self, LightWindow};
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{AdapterSummary, Context};
use crate::image::Image;
use crate::layout::*;
use crate::rng::StepRng;
use crate::scene::{Patches, Scene};
use crate::stages::camera_item_buffer::{CameraItemBuffer, gpu_camera};
use crate::stages::image_estimate::ImageEstimate;
use crate::{Error, Result};
use serde::Serialize;
use std::time::Instant;

/// Camera samples per pixel (a stratified 8 x 8 grid) of an image without iteration, so
/// that its edges are anti-aliased like the references.
pub const DIRECT_CAMERA_SAMPLES_PER_AXIS: u32 = 8;

/// What a render is asked to do; `from_scene` takes the scene's `[settings]`, flags then
/// override fields.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub patch_size: f64,
    pub iterations: u32,
    pub seed: u64,
    /// Pixels along a full cube-face edge of the first shot's item buffers.
    pub hemicube_resolution: u32,
    pub light_window: LightWindow,
    /// Pixels along each edge of a bundle's parallel projection.
    pub bundle_resolution: u32,
    /// Whether lights are first shot (else area lights are emitters in the iteration).
    pub first_shot: bool,
    /// Stop the iteration after this much wall time, if given.
    pub time_limit: Option<std::time::Duration>,
    /// Initial fragment room of a bundle step; `None` takes the geometric bound, which no
    /// step exceeds. Tests set it small to exercise the overflow-and-redo path.
    pub bundle_capacity: Option<u64>,
}

impl RenderOptions {
    pub fn from_scene(scene: &Scene) -> Self {
        RenderOptions {
            width: scene.camera.width,
            height: scene.camera.height,
            patch_size: scene.settings.patch_size,
            iterations: scene.settings.iterations,
            seed: scene.settings.seed,
            hemicube_resolution: scene.settings.hemicube_resolution,
            light_window: LightWindow::Hemicube,
            bundle_resolution: scene.settings.bundle_resolution,
            first_shot: true,
            time_limit: None,
            bundle_capacity: None,
        }
    }
}

/// Run statistics (`--stats`, CLI.md).
#[derive(Debug, Clone, Serialize)]
pub struct RenderStats {
    pub adapter: AdapterSummary,
    pub scene: String,
    pub patches: usize,
    pub light_samples: usize,
    pub image: [u32; 2],
    pub patch_size: f64,
    pub camera_samples: u32,
    pub first_shot: bool,
    pub hemicube_resolution: u32,
    pub light_window: LightWindow,
    /// Stored (patch, light sample) pairs of the first shot.
    pub first_shot_pairs: u32,
    pub first_shot_faces: usize,
    pub first_shot_ms: f64,
    pub bundle_resolution: u32,
    /// Fragment capacity of a bundle step (grown if a step ever needed more).
    pub bundle_capacity: u32,
    /// Median wall time of a step, measured over batches of steps.
    pub iteration_ms_median: f64,
    pub iteration_ms: f64,
    pub iterations: u32,
    pub seed: u64,
    pub tessellation_ms: f64,
    pub upload_ms: f64,
    pub image_ms: f64,
    pub total_ms: f64,
}

/// The rendered image and how it was made.
pub struct Rendered {
    pub image: Image,
    pub stats: RenderStats,
    /// The run was stopped by `Hooks::stop_requested` before its step count.
    pub interrupted: bool,
}

/// What a caller watches and steers during a render; every method has a do-nothing
/// default, so `NoHooks` is a full implementation.
pub trait Hooks {
    /// A phase ended after `ms` milliseconds ("first shot", "iteration", ...).
    fn phase(&mut self, _name: &str, _ms: f64) {}
    /// `done` steps so far of `total` (u32::MAX when only a time limit bounds the run).
    fn progress(&mut self, _done: u32, _total: u32) {}
    /// Asked after every step: stop after it (Ctrl-C). The run then ends as if its step
    /// count had been reached, with `Rendered::interrupted` set.
    fn stop_requested(&self) -> bool {
        false
    }
    /// Asked after every batch of steps: hand a checkpoint to `checkpoint` now?
    fn checkpoint_due(&mut self) -> bool {
        false
    }
    /// Whether `checkpoint` also gets the state at the end of the run.
    fn wants_final_checkpoint(&self) -> bool {
        false
    }
    /// The iteration state and the image so far.
    fn checkpoint(&mut self, _checkpoint: Checkpoint, _image: &Image) -> Result<()> {
        Ok(())
    }
}

/// Hooks that watch nothing and never stop.
pub struct NoHooks;
impl Hooks for NoHooks {}

/// Identifies a scene and every option that changes the image (not the step count or the
/// time limit, which a resumed run may change), so a checkpoint is only resumed by the run
/// it belongs to.
pub fn fingerprint(scene: &Scene, options: &RenderOptions) -> u64 {
    let mut scene = scene.clone();
    scene.source = Default::default();
    let mut options = options.clone();
    options.iterations = 0;
    options.time_limit = None;
    options.bundle_capacity = None;
    crate::checkpoint::fnv1a(format!("{scene:?}\n{options:?}").as_bytes())
}

/// Checks, before any GPU work, that `options` can be honoured for `scene`: `main.rs` calls
/// it before opening an adapter, so that such a refusal is a usage error (exit 2) even on a
/// machine without one.
pub fn check_options(scene: &Scene, options: &RenderOptions) -> Result<()> {
    if !options.first_shot && scene.lights.iter().any(|l| matches!(l, crate::scene::Light::Point { .. })) {
        return Err(Error::Usage(
            "--no-first-shot: the scene has point lights, which only the first shot can handle (a point has no area to emit from inside the iteration); drop --no-first-shot or replace them by small area lights".into(),
        ));
    }
    Ok(())
}

/// Checks, before any GPU work, that the scene and image fit the device's limits.
pub fn check_limits(limits: &wgpu::Limits, patches: &Patches, options: &RenderOptions) -> Result<()> {
    let binding = limits.max_storage_buffer_binding_size;
    let buffer = limits.max_buffer_size;
    let fit = |what: &str, bytes: u64, hint: &str| -> Result<()> {
        if bytes > binding.min(buffer) {
            Err(Error::Limits(format!(
                "{what} needs {bytes} bytes in one buffer, the device allows {} (max_storage_buffer_binding_size {binding}, max_buffer_size {buffer}); {hint}",
                binding.min(buffer)
            )))
        } else {
            Ok(())
        }
    };
    let n = patches.patches.len() as u64;
    if n > MAX_PATCHES as u64 {
        return Err(Error::Limits(format!("{n} patches exceed the limit of {MAX_PATCHES}; use a larger --patch-size")));
    }
    let fewer = "use a larger --patch-size or a GPU with more memory";
    fit("the patch table", n * std::mem::size_of::<GpuPatch>() as u64, fewer)?;
    fit("the rasterised triangles", n * 3 * std::mem::size_of::<RasterVertex>() as u64, fewer)?;
    fit("the iteration state", n * std::mem::size_of::<GpuPatchState>() as u64, fewer)?;
    let max_dim = limits.max_texture_dimension_2d;
    if options.width > max_dim || options.height > max_dim {
        return Err(Error::Limits(format!(
            "the image {}x{} exceeds the device's largest texture side {max_dim}; use a smaller --width/--height",
            options.width, options.height
        )));
    }
    fit("the image", options.width as u64 * options.height as u64 * 16, "use a smaller --width/--height")?;
    // The stages check these too, but only once the first shot (or the first shot and the
    // bundle buffers) exist: here they are refused before any GPU work, and the bundle's
    // line table, which no stage checked, cannot reach wgpu as a validation panic.
    if options.first_shot && options.hemicube_resolution > max_dim {
        return Err(Error::Limits(format!(
            "--hemicube-resolution {} exceeds the device's largest texture side {max_dim}; use a smaller --hemicube-resolution",
            options.hemicube_resolution
        )));
    }
    if options.iterations > 0 {
        let r = options.bundle_resolution;
        if !(crate::iteration::MIN_BUNDLE_RESOLUTION..=max_dim).contains(&r) {
            return Err(Error::Limits(format!(
                "--bundle-resolution {r}: expected {} to {max_dim} (the device's largest texture side)",
                crate::iteration::MIN_BUNDLE_RESOLUTION
            )));
        }
        fit("the ray-bundle line table", crate::iteration::line_table_bytes(r), "use a smaller --bundle-resolution")?;
    }
    Ok(())
}

fn milliseconds(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Renders `scene` (already tessellated into `patches`) on `ctx`.
pub fn render(ctx: &Context, scene: &Scene, patches: &Patches, options: &RenderOptions) -> Result<Rendered> {
    render_with(ctx, scene, patches, options, None, &mut NoHooks)
}

/// As `render`, continuing from `resume` if given, watched and steered by `hooks`.
pub fn render_with(
    ctx: &Context,
    scene: &Scene,
    patches: &Patches,
    options: &RenderOptions,
    resume: Option<&Checkpoint>,
    hooks: &mut dyn Hooks,
) -> Result<Rendered> {
    let start = Instant::now();
    check_options(scene, options)?;
    check_limits(&ctx.limits(), patches, options)?;
    let device = &ctx.device;
    let upload = Instant::now();
    let mut buffers = SceneBuffers::new(device, scene, patches, options.first_shot);
    let camera = CameraItemBuffer::new(device, options.width, options.height);
    let upload_ms = milliseconds(upload);

    let fs = if !options.first_shot || patches.samples.is_empty() {
        None
    } else {
        Some(first_shot::run(ctx, &mut buffers, patches, options.hemicube_resolution, options.light_window)?)
    };
    if let Some(f) = &fs {
        hooks.phase("first shot", f.ms);
    }
    // Built after the first shot: it binds the first-shot table.
    let estimate = ImageEstimate::new(device, &buffers, &camera);
    estimate.set_params(&ctx.queue, scene.environment, buffers.patch_count, false);

    let image_start = Instant::now();
    let near = buffers.radius * 1e-5;
    let mut iteration_stats = IterationStats::default();
    let camera_samples = if options.iterations == 0 {
        direct_image(ctx, scene, options, &buffers, &camera, &estimate, near);
        DIRECT_CAMERA_SAMPLES_PER_AXIS * DIRECT_CAMERA_SAMPLES_PER_AXIS
    } else {
        let run =
            Run { ctx, scene, patches, options, buffers: &buffers, camera: &camera, estimate: &estimate, near, start };
        iteration_stats = iterate(&run, resume, hooks)?;
        hooks.phase("iteration", iteration_stats.ms);
        iteration_stats.steps
    };
    let pixels = estimate.read_mean(device, &ctx.queue)?;
    let image_ms = milliseconds(image_start);
    ctx.check()?;
    Ok(Rendered {
        interrupted: iteration_stats.interrupted,
        image: Image::new(options.width, options.height, pixels),
        stats: RenderStats {
            adapter: ctx.summary.clone(),
            scene: scene.source.display().to_string(),
            patches: patches.patches.len(),
            light_samples: patches.samples.len(),
            image: [options.width, options.height],
            patch_size: options.patch_size,
            camera_samples,
            first_shot: fs.is_some(),
            hemicube_resolution: options.hemicube_resolution,
            light_window: options.light_window,
            first_shot_pairs: fs.as_ref().map_or(0, |f| f.pairs),
            first_shot_faces: fs.as_ref().map_or(0, |f| f.faces),
            first_shot_ms: fs.as_ref().map_or(0.0, |f| f.ms),
            bundle_resolution: options.bundle_resolution,
            bundle_capacity: iteration_stats.capacity,
            iteration_ms_median: iteration_stats.step_ms_median,
            iteration_ms: iteration_stats.ms,
            iterations: iteration_stats.steps,
            seed: options.seed,
            tessellation_ms: 0.0,
            upload_ms,
            image_ms,
            total_ms: milliseconds(start),
        },
    })
}

/// An image without iteration: emission and first shot, averaged over a stratified grid of
/// camera samples per pixel.
fn direct_image(
    ctx: &Context,
    scene: &Scene,
    options: &RenderOptions,
    buffers: &SceneBuffers,
    camera: &CameraItemBuffer,
    estimate: &ImageEstimate,
    near: f64,
) {
    let per_axis = DIRECT_CAMERA_SAMPLES_PER_AXIS;
    let mut rng = StepRng::new(options.seed, u64::MAX);
    for k in 0..per_axis * per_axis {
        let jitter = [
            ((k % per_axis) as f64 + rng.uniform()) / per_axis as f64,
            ((k / per_axis) as f64 + rng.uniform()) / per_axis as f64,
        ];
        let cam = gpu_camera(&scene.camera, options.width, options.height, near, [jitter[0] as f32, jitter[1] as f32]);
        ctx.queue.write_buffer(&camera.camera, 0, bytemuck::bytes_of(&cam));
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.render.direct_image") });
        camera.record(&mut encoder, &buffers.vertices, buffers.patch_count);
        estimate.record(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
    }
}

#[derive(Debug, Default, Clone, Copy)]
struct IterationStats {
    steps: u32,
    capacity: u32,
    step_ms_median: f64,
    ms: f64,
    interrupted: bool,
}

/// Steps per batch between checks of the fragment overflow flag (each check waits for the GPU).
const STEPS_PER_BATCH: u32 = 8;

/// What the iteration works on.
struct Run<'a> {
    ctx: &'a Context,
    scene: &'a Scene,
    patches: &'a Patches,
    options: &'a RenderOptions,
    buffers: &'a SceneBuffers,
    camera: &'a CameraItemBuffer,
    estimate: &'a ImageEstimate,
    near: f64,
    start: Instant,
}

impl Run<'_> {
    fn checkpoint(&self, step: u32) -> Result<(Checkpoint, Image)> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let state: Vec<u8> =
            crate::gpu::buffers::read_back(device, queue, &self.buffers.state, self.buffers.state.size())?;
        let image_sum: Vec<u8> =
            crate::gpu::buffers::read_back(device, queue, &self.estimate.image_sum, self.estimate.image_sum.size())?;
        let pixels = self.estimate.read_mean(device, queue)?;
        let checkpoint = Checkpoint { fingerprint: fingerprint(self.scene, self.options), step, state, image_sum };
        Ok((checkpoint, Image::new(self.options.width, self.options.height, pixels)))
    }
}

/// The stochastic iteration: `options.iterations` steps (or fewer if `time_limit` or the
/// hooks end it), each adding one image estimate. Steps run in batches; the state and image
/// sum are kept at each batch's start, so a batch in which a line ran out of fragment room
/// is redone, exactly, with a larger list.
fn iterate(run: &Run, resume: Option<&Checkpoint>, hooks: &mut dyn Hooks) -> Result<IterationStats> {
    let Run { ctx, scene, patches, options, buffers, camera, estimate, near, start: run_start } = *run;
    let device = &ctx.device;
    let started = Instant::now();
    let resolution = options.bundle_resolution;
    let mut capacity = options
        .bundle_capacity
        .unwrap_or_else(|| crate::iteration::fragment_bound(patches, buffers.radius, resolution.max(4)));
    let mut iteration = crate::iteration::Iteration::new(ctx, buffers, resolution, capacity)?;
    let mut step = 0u32;
    if let Some(c) = resume {
        if c.fingerprint != fingerprint(scene, options) {
            return Err(Error::Usage(
                "the checkpoint belongs to another scene or other flags (patch size, resolutions, seed, image size, first shot); run with the same ones or without --resume".into(),
            ));
        }
        if c.state.len() as u64 != buffers.state.size() || c.image_sum.len() as u64 != estimate.image_sum.size() {
            return Err(Error::Usage("the checkpoint's state does not fit this scene; run without --resume".into()));
        }
        ctx.queue.write_buffer(&buffers.state, 0, &c.state);
        ctx.queue.write_buffer(&estimate.image_sum, 0, &c.image_sum);
        step = c.step;
    }
    let copy = |encoder: &mut wgpu::CommandEncoder, from: &wgpu::Buffer, to: &wgpu::Buffer| {
        encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
    };
    let backup = |b: &wgpu::Buffer, label: &str| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: b.size(),
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let state_backup = backup(&buffers.state, "firstshot.render.state_backup");
    let image_backup = backup(&estimate.image_sum, "firstshot.render.image_backup");
    estimate.set_params(&ctx.queue, scene.environment, buffers.patch_count, true);
    let mut batch_ms = Vec::new();
    let mut interrupted = false;
    while step < options.iterations && !interrupted {
        if let Some(limit) = options.time_limit
            && run_start.elapsed() >= limit
        {
            break;
        }
        let batch_start = Instant::now();
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.render.snapshot") });
        copy(&mut encoder, &buffers.state, &state_backup);
        copy(&mut encoder, &estimate.image_sum, &image_backup);
        iteration.clear_overflow(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        let mut batch = 0;
        while batch < STEPS_PER_BATCH && step + batch < options.iterations {
            let k = step + batch;
            let (mut bundle, mut rng) =
                crate::iteration::bundle_of_step(options.seed, k as u64, buffers.centre, buffers.radius, resolution);
            bundle.environment = [scene.environment[0], scene.environment[1], scene.environment[2], 0.0];
            bundle.patch_count = buffers.patch_count;
            bundle.capacity = iteration.capacity;
            bundle.use_state = (k > 0) as u32;
            ctx.queue.write_buffer(&iteration.bundle, 0, bytemuck::bytes_of(&bundle));
            let jitter = [rng.uniform() as f32, rng.uniform() as f32];
            let cam = gpu_camera(&scene.camera, options.width, options.height, near, jitter);
            ctx.queue.write_buffer(&camera.camera, 0, bytemuck::bytes_of(&cam));
            let mut encoder =
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.render.step") });
            iteration.record_step(&mut encoder, buffers);
            camera.record(&mut encoder, &buffers.vertices, buffers.patch_count);
            estimate.record(&mut encoder);
            ctx.queue.submit([encoder.finish()]);
            batch += 1;
            if hooks.stop_requested() {
                interrupted = true;
                break;
            }
        }
        let overflowed = iteration.overflowed(ctx)?;
        ctx.check()?;
        if overflowed {
            // A line held more surfaces than the list had room for: restore the batch's
            // start and redo it with twice the room.
            let mut encoder = device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.render.restore") });
            copy(&mut encoder, &state_backup, &buffers.state);
            copy(&mut encoder, &image_backup, &estimate.image_sum);
            ctx.queue.submit([encoder.finish()]);
            capacity = capacity.saturating_mul(2);
            iteration = crate::iteration::Iteration::new(ctx, buffers, resolution, capacity)?;
            interrupted = false;
            continue;
        }
        batch_ms.push(batch_start.elapsed().as_secs_f64() * 1e3 / batch as f64);
        step += batch;
        hooks.progress(step, options.iterations);
        if hooks.checkpoint_due() {
            let (checkpoint, image) = run.checkpoint(step)?;
            hooks.checkpoint(checkpoint, &image)?;
        }
    }
    ctx.wait()?;
    if hooks.wants_final_checkpoint() && step > 0 {
        let (checkpoint, image) = run.checkpoint(step)?;
        hooks.checkpoint(checkpoint, &image)?;
    }
    batch_ms.sort_by(f64::total_cmp);
    Ok(IterationStats {
        steps: step,
        capacity: iteration.capacity,
        step_ms_median: batch_ms.get(batch_ms.len() / 2).copied().unwrap_or(0.0),
        ms: started.elapsed().as_secs_f64() * 1e3,
        interrupted,
    })
}
