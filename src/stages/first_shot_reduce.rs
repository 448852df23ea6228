//! First-shot reduction (`wgsl/first_shot_reduce.wgsl`): face pixels -> per-patch sums ->
//! appended (patch, sample, r_ij) pairs.

use crate::gpu::bindings::{KernelSpec, compute, read, read_write, uint_texture, uniform};
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{buffers, kernel};
use crate::layout::{FIRST_SHOT_RUN, GpuAppendParams, GpuCamera, GpuFaceParams, GpuLightSample, GpuPatch};
use crate::stages::camera_item_buffer::CameraItemBuffer;

pub const SPEC: KernelSpec = KernelSpec {
    stem: "first_shot_reduce",
    visibility: wgpu::ShaderStages::COMPUTE,
    entry_points: &[
        // One invocation per face pixel.
        compute("reduce_face", [8, 8, 1]),
        // One invocation per patch.
        compute("append_sample", [64, 1, 1]),
    ],
    groups: &[&[
        // reduce_face: the face's view.
        uniform::<GpuCamera>("face"),
        uniform::<GpuFaceParams>("params"),
        // reduce_face: the face's item buffer.
        uint_texture("item_buffer"),
        read::<GpuPatch>("patches").paged(crate::gpu::scene_buffers::PATCH_TABLE.pages),
        read::<GpuLightSample>("samples"),
        // lo, hi per patch.
        read_write::<[u32; 2]>("sums"),
        // append_sample.
        uniform::<GpuAppendParams>("append"),
        // Pairs per patch; one writer per patch.
        read_write::<u32>("row_counts"),
        // (patch, sample, bits of r_ij, 0).
        read_write::<[u32; 4]>("pairs").paged(crate::gpu::scene_buffers::FIRST_SHOT_PAIRS.pages),
        // May exceed the capacity: then the host grows the list and runs the first shot again.
        read_write::<u32>("pair_count"),
    ]],
};

/// Pipelines, parameters and the pair list of the first shot.
pub struct FirstShotReduce {
    reduce: wgpu::ComputePipeline,
    append: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    pub face_params: wgpu::Buffer,
    pub append_params: wgpu::Buffer,
    /// Two u32 per patch; cleared by `append_sample` as it reads them.
    pub sums: wgpu::Buffer,
    /// Pairs per patch, patch_count + 1 u32 (the last stays 0, so that an exclusive prefix
    /// sum over all of them ends with the total).
    pub row_counts: wgpu::Buffer,
    /// `scene_buffers::FIRST_SHOT_PAIRS`, `capacity` of them.
    pub pairs: crate::gpu::scene_buffers::Paged,
    pub pair_count: wgpu::Buffer,
    pub capacity: u32,
    face_size: [u32; 2],
    patch_count: u32,
}

impl FirstShotReduce {
    pub fn new(device: &wgpu::Device, scene: &SceneBuffers, faces: &CameraItemBuffer, capacity: u32) -> Self {
        let n = scene.patch_count as u64;
        let none = wgpu::BufferUsages::empty();
        let face_params = buffers::uniform(
            device,
            "firstshot.first_shot_reduce.face_params",
            &<GpuFaceParams as bytemuck::Zeroable>::zeroed(),
        );
        let append_params = buffers::uniform(
            device,
            "firstshot.first_shot_reduce.append_params",
            &<GpuAppendParams as bytemuck::Zeroable>::zeroed(),
        );
        let sums = buffers::storage_zeroed(device, "firstshot.first_shot_reduce.sums", 8 * n, none);
        let row_counts = buffers::storage_zeroed(device, "firstshot.first_shot_reduce.row_counts", 4 * (n + 1), none);
        let pairs = crate::gpu::scene_buffers::Paged::zeroed(
            device,
            "firstshot.first_shot_reduce.pairs",
            crate::gpu::scene_buffers::FIRST_SHOT_PAIRS,
            capacity.max(1) as u64,
            scene.page_bytes,
            none,
        );
        let pair_count =
            buffers::storage_zeroed(device, "firstshot.first_shot_reduce.pair_count", 4, wgpu::BufferUsages::COPY_SRC);
        let built = SPEC.build_paged(device, scene.paging().or(pairs.paging()));
        let bind_group = built.bind_group(
            device,
            0,
            &[
                ("face", (&faces.camera).into()),
                ("params", (&face_params).into()),
                ("item_buffer", (&faces.ids_view).into()),
                ("patches", scene.patches.resource()),
                ("samples", (&scene.samples).into()),
                ("sums", (&sums).into()),
                ("append", (&append_params).into()),
                ("row_counts", (&row_counts).into()),
                ("pairs", pairs.resource()),
                ("pair_count", (&pair_count).into()),
            ],
        );
        FirstShotReduce {
            reduce: built.compute_pipeline(device, "reduce_face"),
            append: built.compute_pipeline(device, "append_sample"),
            bind_group,
            face_params,
            append_params,
            sums,
            row_counts,
            pairs,
            pair_count,
            capacity,
            face_size: [faces.width, faces.height],
            patch_count: scene.patch_count,
        }
    }

    /// Adds the weights of the face just rendered (its uniform and `face_params` written).
    pub fn record_face(&self, encoder: &mut wgpu::CommandEncoder, rows: u32) {
        let groups = SPEC.grid("reduce_face", [self.face_size[0].div_ceil(FIRST_SHOT_RUN), rows]);
        kernel::dispatch(encoder, "firstshot.first_shot_reduce.reduce_face", &self.reduce, &[&self.bind_group], groups);
    }

    /// Appends the sample's pairs (its `append_params` written) and clears the sums.
    pub fn record_append(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = SPEC.linear("append_sample", self.patch_count);
        kernel::dispatch(
            encoder,
            "firstshot.first_shot_reduce.append_sample",
            &self.append,
            &[&self.bind_group],
            groups,
        );
    }
}
