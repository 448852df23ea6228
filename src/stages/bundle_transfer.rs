//! Bundle transfer (`wgsl/bundle_transfer.wgsl`): sorts every line's surfaces and adds the
//! radiance each patch receives to its fixed-point sums.

use crate::gpu::bindings::{KernelSpec, Resource, compute, read, read_write, uniform};
use crate::gpu::kernel;
use crate::gpu::scene_buffers::{OUTGOING, TRANSFER_SUMS};
use crate::layout::GpuBundle;

pub const SPEC: KernelSpec = KernelSpec {
    stem: "bundle_transfer",
    visibility: wgpu::ShaderStages::COMPUTE,
    // One invocation per line.
    entry_points: &[compute("main", [64, 1, 1])],
    groups: &[&[
        uniform::<GpuBundle>("bundle"),
        // Line starts, resolution^2 + 1.
        read::<u32>("offsets"),
        // (depth bits, patch | FRAGMENT_FRONT_BIT); each line's slice sorted in place by its
        // invocation.
        read_write::<[u32; 2]>("fragments"),
        // O_j from bundle_reflect.
        read::<[f32; 4]>("outgoing").paged(OUTGOING.pages),
        // 6 per patch: lo, hi per channel.
        read_write::<u32>("sums").paged(TRANSFER_SUMS.pages),
        // Largest radiance of the step.
        read::<u32>("max_bits"),
    ]],
};

pub struct BundleTransfer {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    lines: u32,
}

impl BundleTransfer {
    /// `buffers`: bundle, offsets, fragments, outgoing, sums, max_bits (`SPEC`'s group 0).
    pub fn new(device: &wgpu::Device, buffers: [Resource; 6], lines: u32) -> Self {
        let built = SPEC.build_paged(device, crate::gpu::bindings::paging(&buffers));
        BundleTransfer {
            pipeline: built.compute_pipeline(device, "main"),
            bind_group: built.resource_bind_group(device, 0, &buffers),
            lines,
        }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = SPEC.linear("main", self.lines);
        kernel::dispatch(encoder, "firstshot.bundle_transfer.pass", &self.pipeline, &[&self.bind_group], groups);
    }
}
