//! Timing of GPU work stage by stage, for the benchmark harness (`benches/harness`). The
//! product never uses it: it submits a whole step at once and waits only per batch.
//!
//! Each stage is recorded into its own encoder, submitted and waited for, so its wall time
//! holds the stage plus one submit-and-wait round trip; that works on every adapter. Where
//! the device was opened with `TIMESTAMP_FEATURES`, timestamps written just before and after
//! each stage also give the time the adapter itself spent on it.

use crate::Result;
use crate::gpu::{Context, buffers};
use serde::Serialize;
use std::time::Instant;

/// The optional features timestamps between stages need: timestamp queries, written on the
/// command encoder (stages record their own passes, so the writes go between them).
pub const TIMESTAMP_FEATURES: wgpu::Features =
    wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS);

/// A named stage: what it records into an encoder it is given.
pub type Stage<'a> = (&'static str, Box<dyn Fn(&mut wgpu::CommandEncoder) + 'a>);

/// One stage's times in milliseconds.
#[derive(Debug, Clone, Serialize)]
pub struct StageTime {
    pub name: &'static str,
    /// From submit to the end of the wait.
    pub wall_ms: f64,
    /// Between the timestamps written around the stage, where the device has them.
    pub gpu_ms: Option<f64>,
}

struct Timestamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    capacity: u32,
    period_ns: f64,
}

/// Times a list of stages; `new` decides once whether timestamps are available.
pub struct StageTimer {
    timestamps: Option<Timestamps>,
}

impl StageTimer {
    /// A timer for up to `max_stages` stages per run.
    pub fn new(ctx: &Context, max_stages: u32) -> Self {
        let timestamps = ctx.features().contains(TIMESTAMP_FEATURES).then(|| {
            let capacity = 2 * max_stages.max(1);
            Timestamps {
                set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("firstshot.profile.timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: capacity,
                }),
                resolved: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("firstshot.profile.resolved"),
                    size: 8 * capacity as u64,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                capacity,
                period_ns: ctx.queue.get_timestamp_period() as f64,
            }
        });
        StageTimer { timestamps }
    }

    pub fn has_timestamps(&self) -> bool {
        self.timestamps.is_some()
    }

    /// Runs `stages` in order, each submitted alone and waited for.
    pub fn run(&self, ctx: &Context, stages: &[Stage]) -> Result<Vec<StageTime>> {
        let ts = self.timestamps.as_ref().filter(|t| 2 * stages.len() as u32 <= t.capacity);
        let mut times = Vec::with_capacity(stages.len());
        for (i, (name, record)) in stages.iter().enumerate() {
            let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(name) });
            if let Some(t) = ts {
                encoder.write_timestamp(&t.set, 2 * i as u32);
            }
            record(&mut encoder);
            if let Some(t) = ts {
                encoder.write_timestamp(&t.set, 2 * i as u32 + 1);
            }
            let command = encoder.finish();
            let start = Instant::now();
            ctx.queue.submit([command]);
            ctx.wait()?;
            times.push(StageTime { name, wall_ms: start.elapsed().as_secs_f64() * 1e3, gpu_ms: None });
        }
        if let Some(t) = ts {
            let n = 2 * stages.len() as u32;
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.profile.resolve") });
            encoder.resolve_query_set(&t.set, 0..n, &t.resolved, 0);
            ctx.queue.submit([encoder.finish()]);
            let ticks: Vec<u64> = buffers::read_back(&ctx.device, &ctx.queue, &t.resolved, 8 * n as u64)?;
            for (i, time) in times.iter_mut().enumerate() {
                let (a, b) = (ticks[2 * i], ticks[2 * i + 1]);
                // A zero or backwards pair means the adapter wrote no usable timestamp.
                time.gpu_ms = (a != 0 && b >= a).then(|| (b - a) as f64 * t.period_ns * 1e-6);
            }
        }
        Ok(times)
    }
}
