//! Bundle transfer (`wgsl/bundle_transfer.wgsl`): sorts every line's surfaces and adds the
//! radiance each patch receives to its fixed-point sums.

use crate::gpu::kernel;
use crate::layout::GpuBundle;
use crate::stages::prefix_sum::dispatch_size;

pub struct BundleTransfer {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    lines: u32,
}

impl BundleTransfer {
    /// `buffers`: bundle, offsets, fragments, outgoing, sums, max_bits.
    pub fn new(device: &wgpu::Device, buffers: [&wgpu::Buffer; 6], lines: u32) -> Self {
        let layout = kernel::buffer_layout(
            device,
            "firstshot.bundle_transfer.layout",
            wgpu::ShaderStages::COMPUTE,
            &[
                (true, true, std::mem::size_of::<GpuBundle>() as u64),
                (false, true, 4),
                (false, false, 8),
                (false, true, 16),
                (false, false, 4),
                (false, true, 4),
            ],
        );
        let module = kernel::module(device, "bundle_transfer");
        BundleTransfer {
            pipeline: kernel::compute_pipeline(device, &module, "bundle_transfer", "main", &[&layout]),
            bind_group: kernel::buffer_bind_group(device, "firstshot.bundle_transfer.bind_group", &layout, &buffers),
            lines,
        }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = dispatch_size(self.lines.div_ceil(64));
        kernel::dispatch(encoder, "firstshot.bundle_transfer.pass", &self.pipeline, &[&self.bind_group], groups);
    }
}
