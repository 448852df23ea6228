//! One scene set up on one adapter by `render::Renderer`, kept alive so that steps can be
//! timed in batches, profiled stage by stage, and their fragments counted.
//!
//! The headline numbers come from `render` itself; this exists for what `render` does not
//! expose: each stage's time, the fragments of a step, and many steps on one first shot.

use firstshot::Result;
use firstshot::first_shot::FirstShotStats;
use firstshot::gpu::Context;
use firstshot::gpu::profile::{Stage, StageTime, StageTimer};
use firstshot::layout::{GpuLightSample, GpuMaterial, GpuPatch, GpuPatchState, RasterVertex};
use firstshot::render::{NoHooks, RenderOptions, Renderer};
use firstshot::scene::{Patches, Scene};
use std::time::Instant;

/// Times of batches of steps, per step, in ms.
#[derive(Debug, Default)]
pub struct Batches {
    /// Wall time of each batch.
    pub step_ms: Vec<f64>,
    /// Of that, the host's time to write the step's uniforms and record its commands (not
    /// the submit: lavapipe runs the commands inside it): a floor under the step time that
    /// no adapter can lower.
    pub host_ms: Vec<f64>,
}

/// The name of the empty stage `profile_step` times first.
pub const IDLE: &str = "idle";

pub struct Session<'a> {
    ctx: &'a Context,
    renderer: Renderer<'a>,
    pixels: f64,
    next_step: u32,
    /// Steps per direct-light estimate (`RenderOptions::window_steps`).
    window_steps: u32,
    pub first_shot: Option<FirstShotStats>,
    pub pairs: u32,
}

impl<'a> Session<'a> {
    pub fn new(ctx: &'a Context, scene: &'a Scene, patches: &Patches, options: &RenderOptions) -> Result<Self> {
        // No burn-in: every timed step is a whole step, image stages included.
        let options = RenderOptions { iterations: options.iterations.max(1), burn_in: Some(0), ..options.clone() };
        let renderer = Renderer::new(ctx, scene, patches, &options, &mut NoHooks)?;
        let first_shot = renderer.first_shot().cloned();
        Ok(Session {
            ctx,
            renderer,
            pixels: options.width as f64 * options.height as f64,
            next_step: 0,
            window_steps: options.window_steps.max(1),
            pairs: first_shot.as_ref().map_or(0, |f| f.pairs),
            first_shot,
        })
    }

    pub fn capacity(&self) -> u32 {
        self.renderer.bundle_size().0
    }

    /// Times `batches` batches of `size` steps, each batch submitted step by step and waited
    /// for once at its end (as `render` does).
    pub fn time_batches(&mut self, batches: usize, size: u32) -> Result<Batches> {
        let mut out = Batches::default();
        self.renderer.clear_overflow();
        for _ in 0..batches {
            let start = Instant::now();
            let mut host = 0.0;
            for _ in 0..size {
                let recording = Instant::now();
                let k = self.next_step;
                self.next_step += 1;
                self.renderer.write_step(k);
                let mut encoder = self
                    .ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.bench.step") });
                for (_, record) in self.renderer.step_stages(k) {
                    record(&mut encoder);
                }
                let command = encoder.finish();
                host += recording.elapsed().as_secs_f64();
                self.ctx.queue.submit([command]);
            }
            self.ctx.wait()?;
            out.step_ms.push(start.elapsed().as_secs_f64() * 1e3 / size as f64);
            out.host_ms.push(host * 1e3 / size as f64);
        }
        if self.renderer.overflowed()? {
            // Cannot happen with the geometric bound as capacity; say so if it ever does.
            return Err(firstshot::Error::Gpu("a bundle step overflowed its fragment list".into()));
        }
        Ok(out)
    }

    /// One step that estimates the direct light too (the next of every `window_steps`), so
    /// that every stage is timed, stage by stage; then the fragments it produced. The first
    /// entry, `idle`, is an empty submission: the round trip that every other entry's wall
    /// time includes.
    pub fn profile_step(&mut self, timer: &StageTimer) -> Result<(Vec<StageTime>, u64)> {
        let k = self.next_step.div_ceil(self.window_steps) * self.window_steps;
        self.next_step = k + 1;
        let idle: Vec<Stage> = vec![(IDLE, Box::new(|_: &mut wgpu::CommandEncoder| {}))];
        let times = self.renderer.profile_step(k, timer, idle)?;
        Ok((times, self.renderer.fragments()?))
    }

    /// Fragments of the last step.
    pub fn fragments(&self) -> Result<u64> {
        self.renderer.fragments()
    }

    /// The sizes the byte model needs.
    pub fn sizes(&self, fragments: u64) -> Sizes {
        let r = self.renderer.bundle_size().1 as f64;
        Sizes {
            patches: self.renderer.patch_count() as f64,
            lines: r * r,
            fragments: fragments as f64,
            pixels: self.pixels,
            pairs: self.pairs as f64,
        }
    }
}

/// A stage's own time from its profiled wall time, its timestamps (if any) and the idle
/// round trip, and whether the timestamps are plausible: within a factor 2 of the wall
/// time less the round trip (lavapipe puts some compute dispatches outside their
/// timestamps). Stages shorter than a round trip cannot be checked and are trusted.
pub fn own_time(wall_ms: f64, gpu_ms: Option<f64>, idle_ms: f64) -> (f64, Option<bool>) {
    let net = (wall_ms - idle_ms).max(0.0);
    match gpu_ms {
        Some(g) => {
            let plausible = net < 0.05 + idle_ms || (g >= 0.5 * net && g <= 2.0 * net);
            (if plausible { g } else { net }, Some(plausible))
        }
        None => (net, None),
    }
}

/// What a step's memory traffic scales with.
#[derive(Debug, Clone, Copy)]
pub struct Sizes {
    pub patches: f64,
    pub lines: f64,
    pub fragments: f64,
    pub pixels: f64,
    /// Stored first-shot (patch, sample) pairs.
    pub pairs: f64,
}

/// Bytes a stage must at least read and write, from the sizes of what it touches (an
/// atomic add counts as a read and a write; caches and overdraw are ignored, so this is a
/// floor, good for orders of magnitude).
pub fn stage_bytes(stage: &str, s: Sizes) -> f64 {
    let sz = |n: usize| n as f64;
    let patch = sz(std::mem::size_of::<GpuPatch>());
    let state = sz(std::mem::size_of::<GpuPatchState>());
    let material = sz(std::mem::size_of::<GpuMaterial>());
    let vertex = 3.0 * sz(std::mem::size_of::<RasterVertex>());
    let sample = sz(std::mem::size_of::<GpuLightSample>());
    // First-shot entries per patch: each is 8 bytes plus its light sample.
    let table = s.pairs * (8.0 + sample) + 4.0 * s.patches;
    match stage {
        // counts, heads (u32 per line), the tally and max_bits are zeroed.
        "clear" => 8.0 * s.lines,
        IDLE => 0.0,
        // Patch, material, state and the first-shot entries in; O_j (vec4) and an atomic max out.
        "reflect" => s.patches * (patch + material + state + 16.0 + 8.0) + table,
        // Triangles in; per fragment its patch's O (facing), an atomic add on the line's
        // count and an 8-byte write into the line's bucket (the few past it: a spill node).
        "visibility" => s.patches * vertex + 28.0 * s.fragments,
        // Per line its count and slice (12 bytes); per fragment: read and write it (sort),
        // read its own and its neighbour's O (16 bytes each), three 64-bit fixed-point
        // atomic adds.
        "transfer" => 12.0 * s.lines + s.fragments * (16.0 + 32.0 + 24.0),
        // Sums (6 u32), patch, O in; state out.
        "finalize" => s.patches * (24.0 + patch + 16.0 + state),
        // Triangles in; an id and a depth per pixel out.
        "camera" => s.patches * vertex + 8.0 * s.pixels,
        // Triangles in once per face of the area lights' windows (at most 5 faces of up to
        // 512^2 texels a light; 0 without area lights): a floor, the faces are not counted.
        "light_windows" => s.patches * vertex,
        // Per pixel: id, patch, material, per light a face (112 bytes), 4 texels and up to
        // 4 triangles (48 bytes each) of the window, the running sum read and written.
        "direct" => s.pixels * (4.0 + patch + material + 112.0 + 16.0 + 4.0 * 48.0 + 32.0),
        // Per pixel: id, patch, material, the line's slice and 4 fragments with their
        // patches' planes and one O, the running sum read and written.
        "gather" => s.pixels * (4.0 + patch + material + 8.0 + 4.0 * (8.0 + 16.0) + 16.0 + 32.0),
        // The split gather's list passes (`ImageEstimate::gather_passes`): the list's count.
        // Their pixels, a few per cent of the image, are counted only on the GPU.
        "gather_edges" | "gather_first_bounce" => 4.0,
        _ => f64::NAN,
    }
}

/// The adapter's buffer-to-buffer copy rate in GB/s (bytes read plus bytes written), the
/// yardstick for the stages' memory traffic: median of a few 64 MiB copies.
pub fn copy_bandwidth(ctx: &Context) -> Result<f64> {
    const BYTES: u64 = 64 << 20;
    let buffer = |label| {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: BYTES,
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let (a, b) = (buffer("firstshot.bench.copy_a"), buffer("firstshot.bench.copy_b"));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.clear_buffer(&a, 0, None);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait()?;
    let mut times = Vec::new();
    for i in 0..6 {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&a, 0, &b, 0, BYTES);
        let command = encoder.finish();
        let start = Instant::now();
        ctx.queue.submit([command]);
        ctx.wait()?;
        // The first copy faults the pages of `b` in; it is the warm-up.
        if i > 0 {
            times.push(start.elapsed().as_secs_f64());
        }
    }
    Ok(2.0 * BYTES as f64 / crate::stats::median(&times) / 1e9)
}

/// A step's stages with the same name added together, in the order of their first run, each
/// with how many runs it adds: a step of four bundles runs the bundle stages and the gather
/// four times, a step of several views the image stages once per view.
pub fn merge_repeated_stages(times: Vec<StageTime>) -> Vec<(StageTime, u32)> {
    let mut merged: Vec<(StageTime, u32)> = Vec::new();
    for t in times {
        match merged.iter_mut().find(|(m, _)| m.name == t.name) {
            Some((m, runs)) => {
                m.wall_ms += t.wall_ms;
                m.gpu_ms = m.gpu_ms.zip(t.gpu_ms).map(|(a, b)| a + b);
                *runs += 1;
            }
            None => merged.push((t, 1)),
        }
    }
    merged
}
