//! First-shot table (`wgsl/first_shot_table.wgsl`): appended pairs -> rows by patch, each
//! row in ascending sample order, and each row's irradiance sum for diffuse patches.

use crate::gpu::scene_buffers::FirstShotTable;
use crate::gpu::{buffers, kernel};
use crate::layout::GpuLightSample;
use crate::stages::prefix_sum::{PrefixSum, dispatch_size};

/// Records the build of the table from `pair_total` pairs, the row counts (patch_count + 1
/// u32, the last 0) and the light samples, and returns it with the temporaries the
/// recorded commands still use (keep them until the commands are submitted).
pub fn build(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    patch_count: u32,
    pairs: &wgpu::Buffer,
    pair_total: u32,
    row_counts: &wgpu::Buffer,
    samples: &wgpu::Buffer,
) -> (FirstShotTable, Vec<wgpu::Buffer>, PrefixSum) {
    let n = patch_count as u64;
    let usage = wgpu::BufferUsages::COPY_SRC;
    let offsets = buffers::storage_zeroed(device, "firstshot.first_shot.offsets", 4 * (n + 1), usage);
    let entries = buffers::storage_zeroed(device, "firstshot.first_shot.entries", 8 * pair_total.max(1) as u64, usage);
    let irradiance = buffers::storage_zeroed(device, "firstshot.first_shot.irradiance", 16 * n, usage);
    let cursor =
        buffers::storage_zeroed(device, "firstshot.first_shot_table.cursor", 4 * n, wgpu::BufferUsages::empty());
    let params = buffers::uniform(device, "firstshot.first_shot_table.params", &[pair_total, patch_count, 0, 0]);
    let scan = PrefixSum::new(device, patch_count + 1, row_counts, &offsets);
    scan.record(encoder);

    let layout = kernel::buffer_layout(
        device,
        "firstshot.first_shot_table.layout",
        wgpu::ShaderStages::COMPUTE,
        &[
            (true, true, 16),
            (false, true, 16),
            (false, true, 4),
            (false, false, 4),
            (false, false, 8),
            (false, true, std::mem::size_of::<GpuLightSample>() as u64),
            (false, false, 16),
        ],
    );
    let bind_group = kernel::buffer_bind_group(
        device,
        "firstshot.first_shot_table.bind_group",
        &layout,
        &[&params, pairs, &offsets, &cursor, &entries, samples, &irradiance],
    );
    let module = kernel::module(device, "first_shot_table");
    let pipeline = |entry: &str| kernel::compute_pipeline(device, &module, "first_shot_table", entry, &[&layout]);
    let per_patch = dispatch_size(patch_count.div_ceil(64));
    kernel::dispatch(
        encoder,
        "firstshot.first_shot_table.fill_rows",
        &pipeline("fill_rows"),
        &[&bind_group],
        dispatch_size(pair_total.div_ceil(64)),
    );
    kernel::dispatch(
        encoder,
        "firstshot.first_shot_table.sort_rows",
        &pipeline("sort_rows"),
        &[&bind_group],
        per_patch,
    );
    kernel::dispatch(
        encoder,
        "firstshot.first_shot_table.row_irradiance",
        &pipeline("row_irradiance"),
        &[&bind_group],
        per_patch,
    );
    (FirstShotTable { offsets, entries, irradiance, entry_count: pair_total }, vec![cursor, params], scan)
}
