//! Bundle finalize (`wgsl/bundle_finalize.wgsl`): the fixed-point sums into J_j and win_j.

use crate::gpu::kernel;
use crate::layout::{GpuBundle, GpuPatch, GpuPatchState};
use crate::stages::prefix_sum::dispatch_size;

pub struct BundleFinalize {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    patch_count: u32,
}

impl BundleFinalize {
    /// `buffers`: bundle, patches, sums, max_bits, outgoing, state.
    pub fn new(device: &wgpu::Device, buffers: [&wgpu::Buffer; 6], patch_count: u32) -> Self {
        let layout = kernel::buffer_layout(
            device,
            "firstshot.bundle_finalize.layout",
            wgpu::ShaderStages::COMPUTE,
            &[
                (true, true, std::mem::size_of::<GpuBundle>() as u64),
                (false, true, std::mem::size_of::<GpuPatch>() as u64),
                (false, false, 4),
                (false, true, 4),
                (false, true, 16),
                (false, false, std::mem::size_of::<GpuPatchState>() as u64),
            ],
        );
        let module = kernel::module(device, "bundle_finalize");
        BundleFinalize {
            pipeline: kernel::compute_pipeline(device, &module, "bundle_finalize", "main", &[&layout]),
            bind_group: kernel::buffer_bind_group(device, "firstshot.bundle_finalize.bind_group", &layout, &buffers),
            patch_count,
        }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = dispatch_size(self.patch_count.div_ceil(64));
        kernel::dispatch(encoder, "firstshot.bundle_finalize.pass", &self.pipeline, &[&self.bind_group], groups);
    }
}
