//! Bundle finalize (`wgsl/bundle_finalize.wgsl`): the fixed-point sums into J_j and win_j.

use crate::gpu::bindings::{Kernel, KernelSpec, Resource, compute, read, read_write, uniform};
use crate::gpu::kernel;
use crate::gpu::scene_buffers::{OUTGOING, PATCH_STATE, PATCH_TABLE, TRANSFER_SUMS};
use crate::layout::{GpuBundle, GpuMaterial, GpuPatch, GpuPatchState};

pub const SPEC: KernelSpec = KernelSpec {
    stem: "bundle_finalize",
    visibility: wgpu::ShaderStages::COMPUTE,
    // One invocation per patch.
    entry_points: &[compute("main", [64, 1, 1])],
    groups: &[&[
        uniform::<GpuBundle>("bundle"),
        read::<GpuPatch>("patches").paged(PATCH_TABLE.pages),
        // 6 per patch (lo, hi per channel), cleared for the next step; one invocation per patch.
        read_write::<u32>("sums").paged(TRANSFER_SUMS.pages),
        read::<u32>("max_bits"),
        // w: s_j.
        read::<[f32; 4]>("outgoing").paged(OUTGOING.pages),
        // One writer per patch.
        read_write::<GpuPatchState>("state").paged(PATCH_STATE.pages),
        // Which patches keep a glossy history (the others' goes unread).
        read::<GpuMaterial>("materials"),
    ]],
};

pub struct BundleFinalize {
    kernel: Kernel,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    patch_count: u32,
}

impl BundleFinalize {
    /// `buffers`: bundle, patches, sums, max_bits, outgoing, state, materials (`SPEC`'s group 0).
    /// `like`: a stage over arrays of the same paging whose pipeline this one shares.
    pub fn new(device: &wgpu::Device, buffers: [Resource; 7], patch_count: u32, like: Option<&Self>) -> Self {
        let (kernel, pipeline) = match like {
            Some(like) => (like.kernel.clone(), like.pipeline.clone()),
            None => {
                let built = SPEC.build_paged(device, crate::gpu::bindings::paging(&buffers));
                let pipeline = built.compute_pipeline(device, "main");
                (built, pipeline)
            }
        };
        BundleFinalize { bind_group: kernel.resource_bind_group(device, 0, &buffers), kernel, pipeline, patch_count }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = SPEC.linear("main", self.patch_count);
        kernel::dispatch(encoder, "firstshot.bundle_finalize.pass", &self.pipeline, &[&self.bind_group], groups);
    }
}
