//! Exclusive prefix sum of u32 counts (`wgsl/prefix_sum.wgsl`), in as many levels as the
//! length needs (`BLOCK` values per block and level).

use crate::gpu::{buffers, kernel};

/// Values per workgroup and level (reaches WGSL through the generated header).
pub const BLOCK: u32 = crate::layout::PREFIX_SUM_WORKGROUP * crate::layout::PREFIX_SUM_PER_THREAD;

/// Workgroup counts for `blocks` workgroups, folded into 2D past the 65535 limit.
pub fn dispatch_size(blocks: u32) -> (u32, u32) {
    const MAX: u32 = 65535;
    if blocks <= MAX { (blocks.max(1), 1) } else { (MAX, blocks.div_ceil(MAX)) }
}

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
        let module = kernel::module(device, "prefix_sum");
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.prefix_sum.layout"),
            entries: &[
                buffers::uniform_entry::<[u32; 4]>(0, wgpu::ShaderStages::COMPUTE),
                buffers::storage_entry(1, true, 4),
                buffers::storage_entry(2, false, 4),
                buffers::storage_entry(3, false, 4),
            ],
        });
        let pipeline = |entry: &str| kernel::compute_pipeline(device, &module, "prefix_sum", entry, &[&layout]);
        let (scan_pipeline, add_pipeline) = (pipeline("scan_blocks"), pipeline("add_block_offsets"));
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
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("firstshot.prefix_sum.bind_group"),
                    layout: &layout,
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 1, resource: a.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 2, resource: b.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 3, resource: c.as_entire_binding() },
                    ],
                })
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
            let (x, y) = dispatch_size(level.n.div_ceil(BLOCK));
            pass.set_bind_group(0, &level.scan, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        pass.set_pipeline(&self.add_pipeline);
        for level in self.levels.iter().rev() {
            if let Some(add) = &level.add {
                let (x, y) = dispatch_size(level.n.div_ceil(BLOCK));
                pass.set_bind_group(0, add, &[]);
                pass.dispatch_workgroups(x, y, 1);
            }
        }
    }
}
