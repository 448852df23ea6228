//! First-shot table (`wgsl/first_shot_table.wgsl`): appended pairs -> rows by patch, each
//! row in ascending sample order.

use crate::gpu::scene_buffers::FirstShotTable;
use crate::gpu::{buffers, kernel};
use crate::stages::prefix_sum::{PrefixSum, dispatch_size};

/// Records the build of the table from `pair_total` pairs and the row counts
/// (patch_count + 1 u32, the last 0), and returns it.
pub fn build(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    patch_count: u32,
    pairs: &wgpu::Buffer,
    pair_total: u32,
    row_counts: &wgpu::Buffer,
) -> (FirstShotTable, Vec<wgpu::Buffer>, PrefixSum) {
    let none = wgpu::BufferUsages::empty();
    let offsets = buffers::storage_zeroed(
        device,
        "firstshot.first_shot.offsets",
        4 * (patch_count as u64 + 1),
        wgpu::BufferUsages::COPY_SRC,
    );
    let entries = buffers::storage_zeroed(
        device,
        "firstshot.first_shot.entries",
        8 * pair_total.max(1) as u64,
        wgpu::BufferUsages::COPY_SRC,
    );
    let cursor = buffers::storage_zeroed(device, "firstshot.first_shot_table.cursor", 4 * patch_count as u64, none);
    let params = buffers::uniform(device, "firstshot.first_shot_table.params", &[pair_total, patch_count, 0, 0]);
    let scan = PrefixSum::new(device, patch_count + 1, row_counts, &offsets);
    scan.record(encoder);

    let module = kernel::module(device, "first_shot_table");
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("firstshot.first_shot_table.layout"),
        entries: &[
            buffers::uniform_entry::<[u32; 4]>(0, wgpu::ShaderStages::COMPUTE),
            buffers::storage_entry(1, true, 16),
            buffers::storage_entry(2, true, 4),
            buffers::storage_entry(3, false, 4),
            buffers::storage_entry(4, false, 8),
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("firstshot.first_shot_table.pipeline_layout"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = |entry: &str| {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(&format!("firstshot.first_shot_table.{entry}")),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    };
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("firstshot.first_shot_table.bind_group"),
        layout: &layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: pairs.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: offsets.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 3, resource: cursor.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 4, resource: entries.as_entire_binding() },
        ],
    });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("firstshot.first_shot_table.pass"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &bind_group, &[]);
        pass.set_pipeline(&pipeline("fill_rows"));
        let (x, y) = dispatch_size(pair_total.div_ceil(64));
        pass.dispatch_workgroups(x, y, 1);
        pass.set_pipeline(&pipeline("sort_rows"));
        let (x, y) = dispatch_size(patch_count.div_ceil(64));
        pass.dispatch_workgroups(x, y, 1);
    }
    (FirstShotTable { offsets, entries, entry_count: pair_total }, vec![cursor, params], scan)
}
