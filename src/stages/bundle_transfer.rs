//! Bundle transfer (`wgsl/bundle_transfer.wgsl`): sorts every line's surfaces and adds the
//! radiance each patch receives to its fixed-point sums.

use crate::gpu::bindings::{Kernel, KernelSpec, Resource, compute, read, read_write, uniform};
use crate::gpu::kernel;
use crate::gpu::scene_buffers::{OUTGOING, TRANSFER_SUMS};
use crate::layout::GpuBundle;

pub const SPEC: KernelSpec = KernelSpec {
    stem: "bundle_transfer",
    visibility: wgpu::ShaderStages::COMPUTE,
    // `gather_long_lines`: LONG_LINES_WORKGROUPS; `main`: one invocation per line.
    entry_points: &[compute("gather_long_lines", [64, 1, 1]), compute("main", [64, 1, 1])],
    groups: &[&[
        uniform::<GpuBundle>("bundle"),
        // Surfaces per line, resolution^2 (bundle_visibility).
        read::<u32>("counts"),
        // Each line's spill chain (bundle_visibility).
        read::<u32>("heads"),
        // (depth bits, patch | FRAGMENT_FRONT_BIT): the lines' buckets, then the long lines'
        // slices, which this pass fills; each line's slice sorted in place by its invocation.
        read_write::<[u32; 2]>("fragments"),
        read::<[u32; 4]>("spill"),
        // TALLY_LONG: fragments of the long lines' slices taken; TALLY_LONG_LINES: lines listed.
        read_write::<u32>("tally"),
        // Set when a long line's slice lies past the capacity.
        read_write::<u32>("overflow"),
        // (begin, end) of each long line's slice of `fragments` (gather_long_lines), for
        // `main` and the image's gather.
        read_write::<[u32; 2]>("slices"),
        // The lines past their bucket (bundle_visibility).
        read::<u32>("long_lines"),
        // O_j from bundle_reflect.
        read::<[f32; 4]>("outgoing").paged(OUTGOING.pages),
        // 6 per patch: lo, hi per channel.
        read_write::<u32>("sums").paged(TRANSFER_SUMS.pages),
        // Largest radiance of the step.
        read::<u32>("max_bits"),
    ]],
};

pub struct BundleTransfer {
    kernel: Kernel,
    long_lines: wgpu::ComputePipeline,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    lines: u32,
}

impl BundleTransfer {
    /// `buffers`: bundle, counts, heads, fragments, spill, tally, overflow, slices,
    /// long_lines, outgoing, sums, max_bits (`SPEC`'s group 0).
    /// `like`: a stage over arrays of the same paging whose pipelines this one shares.
    pub fn new(device: &wgpu::Device, buffers: [Resource; 12], lines: u32, like: Option<&Self>) -> Self {
        let (kernel, long_lines, pipeline) = match like {
            Some(like) => (like.kernel.clone(), like.long_lines.clone(), like.pipeline.clone()),
            None => {
                let built = SPEC.build_paged(device, crate::gpu::bindings::paging(&buffers));
                let long_lines = built.compute_pipeline(device, "gather_long_lines");
                let pipeline = built.compute_pipeline(device, "main");
                (built, long_lines, pipeline)
            }
        };
        BundleTransfer {
            bind_group: kernel.resource_bind_group(device, 0, &buffers),
            kernel,
            long_lines,
            pipeline,
            lines,
        }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        kernel::dispatch(
            encoder,
            "firstshot.bundle_transfer.long_lines",
            &self.long_lines,
            &[&self.bind_group],
            (crate::layout::LONG_LINES_WORKGROUPS, 1),
        );
        let groups = SPEC.linear("main", self.lines);
        kernel::dispatch(encoder, "firstshot.bundle_transfer.pass", &self.pipeline, &[&self.bind_group], groups);
    }
}
