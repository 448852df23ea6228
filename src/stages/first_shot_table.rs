//! First-shot table (`wgsl/first_shot_table.wgsl`): appended pairs -> rows by patch, each
//! row in ascending sample order, and each row's irradiance sum for diffuse patches.

use crate::gpu::bindings::{KernelSpec, compute, read, read_write, uniform};
use crate::gpu::scene_buffers::{FIRST_SHOT_IRRADIANCE, FirstShotTable, SceneBuffers};
use crate::gpu::{buffers, kernel};
use crate::layout::GpuLightSample;
use crate::stages::prefix_sum::PrefixSum;

pub const SPEC: KernelSpec = KernelSpec {
    stem: "first_shot_table",
    visibility: wgpu::ShaderStages::COMPUTE,
    entry_points: &[
        // One invocation per pair.
        compute("fill_rows", [64, 1, 1]),
        // One per patch.
        compute("sort_rows", [64, 1, 1]),
        compute("row_irradiance", [64, 1, 1]),
    ],
    groups: &[&[
        // x: pairs, y: patches.
        uniform::<[u32; 4]>("params"),
        read::<[u32; 4]>("pairs").paged(crate::gpu::scene_buffers::FIRST_SHOT_PAIRS.pages),
        // patches + 1 row starts.
        read::<u32>("offsets"),
        // Zeroed before fill_rows.
        read_write::<u32>("cursor"),
        // (sample, bits of r_ij).
        read_write::<[u32; 2]>("entries"),
        read::<GpuLightSample>("samples"),
        // rgb sum_i S_i r_ij per patch.
        read_write::<[f32; 4]>("irradiance").paged(FIRST_SHOT_IRRADIANCE.pages),
    ]],
};

/// Records the build of the table from `pair_total` pairs, the row counts (patch_count + 1
/// u32, the last 0) and the light samples, and returns it with the temporaries the
/// recorded commands still use (keep them until the commands are submitted).
/// `scene` gives the patch count, the light samples and the page size of the irradiance.
pub fn build(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    scene: &SceneBuffers,
    pairs: &crate::gpu::scene_buffers::Paged,
    pair_total: u32,
    row_counts: &wgpu::Buffer,
) -> (FirstShotTable, Vec<wgpu::Buffer>, PrefixSum) {
    let (patch_count, samples, page_bytes) = (scene.patch_count, &scene.samples, scene.page_bytes);
    let n = patch_count as u64;
    let usage = wgpu::BufferUsages::COPY_SRC;
    let offsets = buffers::storage_zeroed(device, "firstshot.first_shot.offsets", 4 * (n + 1), usage);
    let entries = buffers::storage_zeroed(device, "firstshot.first_shot.entries", 8 * pair_total.max(1) as u64, usage);
    let irradiance = crate::gpu::scene_buffers::Paged::zeroed(
        device,
        "firstshot.first_shot.irradiance",
        FIRST_SHOT_IRRADIANCE,
        n,
        page_bytes,
        usage,
    );
    let cursor =
        buffers::storage_zeroed(device, "firstshot.first_shot_table.cursor", 4 * n, wgpu::BufferUsages::empty());
    let params = buffers::uniform(device, "firstshot.first_shot_table.params", &[pair_total, patch_count, 0, 0]);
    let scan = PrefixSum::new(device, patch_count + 1, row_counts, &offsets);
    scan.record(encoder);

    let built = SPEC.build_paged(device, scene.paging().or(pairs.paging()));
    let bind_group = built.bind_group(
        device,
        0,
        &[
            ("params", (&params).into()),
            ("pairs", pairs.resource()),
            ("offsets", (&offsets).into()),
            ("cursor", (&cursor).into()),
            ("entries", (&entries).into()),
            ("samples", samples.into()),
            ("irradiance", irradiance.resource()),
        ],
    );
    for (entry, invocations) in [("fill_rows", pair_total), ("sort_rows", patch_count), ("row_irradiance", patch_count)]
    {
        let pipeline = built.compute_pipeline(device, entry);
        let groups = SPEC.linear(entry, invocations);
        kernel::dispatch(encoder, &format!("firstshot.first_shot_table.{entry}"), &pipeline, &[&bind_group], groups);
    }
    (FirstShotTable { offsets, entries, irradiance, entry_count: pair_total }, vec![cursor, params], scan)
}
