//! Exclusive prefix sum of u32 counts (`wgsl/prefix_sum.wgsl`), in as many levels as the
//! length needs (`BLOCK` values per block and level).

use crate::gpu::bindings::{KernelSpec, compute, read, read_write, uniform};
use crate::gpu::buffers;
use crate::layout::{PREFIX_SUM_PER_THREAD, PREFIX_SUM_WORKGROUP};

/// Values per workgroup and level (reaches WGSL through the generated header).
pub const BLOCK: u32 = PREFIX_SUM_WORKGROUP * PREFIX_SUM_PER_THREAD;

pub const SPEC: KernelSpec = KernelSpec {
    stem: "prefix_sum",
    visibility: wgpu::ShaderStages::COMPUTE,
    // One workgroup per block of BLOCK values, PREFIX_SUM_PER_THREAD per invocation.
    entry_points: &[
        compute("scan_blocks", [PREFIX_SUM_WORKGROUP, 1, 1]),
        compute("add_block_offsets", [PREFIX_SUM_WORKGROUP, 1, 1]),
    ],
    groups: &[&[
        // x: n.
        uniform::<[u32; 4]>("params"),
        // n counts.
        read::<u32>("values"),
        // n exclusive prefix sums.
        read_write::<u32>("scanned"),
        // scan_blocks writes one per block; add_block_offsets reads the scanned ones.
        read_write::<u32>("block_sums"),
    ]],
};

struct Level {
    n: u32,
    scan: wgpu::BindGroup,
    add: Option<wgpu::BindGroup>,
}

/// A prefix sum of a fixed length over fixed buffers, recorded as often as needed.
pub struct PrefixSum {
    scan_pipeline: wgpu::ComputePipeline,
    add_pipeline: wgpu::ComputePipeline,
    levels: Vec<Level>,
    _buffers: Vec<wgpu::Buffer>,
}

impl PrefixSum {
    /// `values` (n u32) are scanned into `scanned` (n u32, may not alias `values`).
    pub fn new(device: &wgpu::Device, n: u32, values: &wgpu::Buffer, scanned: &wgpu::Buffer) -> Self {
        let built = SPEC.build(device);
        let (scan_pipeline, add_pipeline) =
            (built.compute_pipeline(device, "scan_blocks"), built.compute_pipeline(device, "add_block_offsets"));
        let mut owned = Vec::new();
        let mut levels = Vec::new();
        // Level k scans `input` into `output`; its block sums are level k+1's input.
        let mut input = values.clone();
        let mut output = scanned.clone();
        let mut len = n;
        loop {
            let blocks = len.div_ceil(BLOCK).max(1);
            let sums = buffers::storage_zeroed(
                device,
                "firstshot.prefix_sum.block_sums",
                4 * blocks as u64,
                wgpu::BufferUsages::empty(),
            );
            let sums_scanned = buffers::storage_zeroed(
                device,
                "firstshot.prefix_sum.block_sums_scanned",
                4 * blocks as u64,
                wgpu::BufferUsages::empty(),
            );
            let params = buffers::uniform(device, "firstshot.prefix_sum.params", &[len, 0, 0, 0]);
            let group = |a: &wgpu::Buffer, b: &wgpu::Buffer, c: &wgpu::Buffer| {
                built.bind_group(
                    device,
                    0,
                    &[
                        ("params", (&params).into()),
                        ("values", a.into()),
                        ("scanned", b.into()),
                        ("block_sums", c.into()),
                    ],
                )
            };
            let scan = group(&input, &output, &sums);
            let last = blocks == 1;
            let add = (!last).then(|| group(&input, &output, &sums_scanned));
            levels.push(Level { n: len, scan, add });
            owned.extend([params]);
            if last {
                owned.extend([sums, sums_scanned]);
                break;
            }
            input = sums.clone();
            output = sums_scanned.clone();
            owned.extend([sums, sums_scanned]);
            len = blocks;
        }
        PrefixSum { scan_pipeline, add_pipeline, levels, _buffers: owned }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("firstshot.prefix_sum.pass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.scan_pipeline);
        for level in &self.levels {
            let (x, y) = SPEC.linear("scan_blocks", level.n.div_ceil(PREFIX_SUM_PER_THREAD));
            pass.set_bind_group(0, &level.scan, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        pass.set_pipeline(&self.add_pipeline);
        for level in self.levels.iter().rev() {
            if let Some(add) = &level.add {
                let (x, y) = SPEC.linear("add_block_offsets", level.n.div_ceil(PREFIX_SUM_PER_THREAD));
                pass.set_bind_group(0, add, &[]);
                pass.dispatch_workgroups(x, y, 1);
            }
        }
    }
}
