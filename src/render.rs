//! The order of the pipeline: tessellated scene on the GPU -> first shot -> iteration loop
//! -> image. `main.rs` and the tests call `render`.

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
}

/// Checks, before any GPU work, that the scene and image fit the device's limits.
pub fn check_limits(limits: &wgpu::Limits, patches: &Patches, options: &RenderOptions) -> Result<()> {
    let binding = limits.max_storage_buffer_binding_size as u64;
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
    Ok(())
}

fn milliseconds(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Renders `scene` (already tessellated into `patches`) on `ctx`.
pub fn render(ctx: &Context, scene: &Scene, patches: &Patches, options: &RenderOptions) -> Result<Rendered> {
    let start = Instant::now();
    check_limits(&ctx.limits(), patches, options)?;
    if options.iterations > 0 {
        return Err(Error::Usage(format!(
            "--iterations {} asks for the stochastic iteration, which this build does not have yet; use --iterations 0",
            options.iterations
        )));
    }
    let device = &ctx.device;
    let upload = Instant::now();
    let mut buffers = SceneBuffers::new(device, scene, patches, true);
    let camera = CameraItemBuffer::new(device, options.width, options.height);
    let upload_ms = milliseconds(upload);

    let fs = if patches.samples.is_empty() {
        None
    } else {
        Some(first_shot::run(ctx, &mut buffers, patches, options.hemicube_resolution, options.light_window)?)
    };
    // Built after the first shot: it binds the first-shot table.
    let estimate = ImageEstimate::new(device, &buffers, &camera);
    ctx.queue.write_buffer(
        &estimate.params,
        0,
        bytemuck::bytes_of(&GpuEstimateParams {
            environment: [scene.environment[0], scene.environment[1], scene.environment[2], 0.0],
            patch_count: buffers.patch_count,
            use_state: 0,
            _pad: [0; 2],
        }),
    );

    let image_start = Instant::now();
    let near = buffers.radius * 1e-5;
    let per_axis = DIRECT_CAMERA_SAMPLES_PER_AXIS;
    let mut rng = StepRng::new(options.seed, u64::MAX);
    for k in 0..per_axis * per_axis {
        let jitter = [
            ((k % per_axis) as f64 + rng.uniform()) / per_axis as f64,
            ((k / per_axis) as f64 + rng.uniform()) / per_axis as f64,
        ];
        let cam = gpu_camera(&scene.camera, options.width, options.height, near, [jitter[0] as f32, jitter[1] as f32]);
        ctx.queue.write_buffer(&camera.camera, 0, bytemuck::bytes_of(&cam));
        let mut encoder = device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.render.direct_image") });
        camera.record(&mut encoder, &buffers.vertices, buffers.patch_count);
        estimate.record(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
    }
    let pixels = estimate.read_mean(device, &ctx.queue)?;
    let image_ms = milliseconds(image_start);
    Ok(Rendered {
        image: Image::new(options.width, options.height, pixels),
        stats: RenderStats {
            adapter: ctx.summary.clone(),
            scene: scene.source.display().to_string(),
            patches: patches.patches.len(),
            light_samples: patches.samples.len(),
            image: [options.width, options.height],
            patch_size: options.patch_size,
            camera_samples: per_axis * per_axis,
            first_shot: fs.is_some(),
            hemicube_resolution: options.hemicube_resolution,
            light_window: options.light_window,
            first_shot_pairs: fs.as_ref().map_or(0, |f| f.pairs),
            first_shot_faces: fs.as_ref().map_or(0, |f| f.faces),
            first_shot_ms: fs.as_ref().map_or(0.0, |f| f.ms),
            iterations: 0,
            seed: options.seed,
            tessellation_ms: 0.0,
            upload_ms,
            image_ms,
            total_ms: milliseconds(start),
        },
    })
}
