//! First-shot reduction (`wgsl/first_shot_reduce.wgsl`): face pixels -> per-patch sums ->
//! appended (patch, sample, r_ij) pairs.

use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{buffers, kernel};
use crate::layout::{GpuAppendParams, GpuCamera, GpuFaceParams, GpuLightSample, GpuPatch};
use crate::stages::camera_item_buffer::CameraItemBuffer;
use crate::stages::prefix_sum::dispatch_size;

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
    pub pairs: wgpu::Buffer,
    pub pair_count: wgpu::Buffer,
    pub capacity: u32,
    face_size: [u32; 2],
    patch_count: u32,
}

impl FirstShotReduce {
    pub fn new(device: &wgpu::Device, scene: &SceneBuffers, faces: &CameraItemBuffer, capacity: u32) -> Self {
        use buffers::storage_entry as storage;
        let compute = wgpu::ShaderStages::COMPUTE;
        let module = kernel::module(device, "first_shot_reduce");
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.first_shot_reduce.layout"),
            entries: &[
                buffers::uniform_entry::<GpuCamera>(0, compute),
                buffers::uniform_entry::<GpuFaceParams>(1, compute),
                kernel::uint_texture_entry(2),
                storage(3, true, std::mem::size_of::<GpuPatch>() as u64),
                storage(4, true, std::mem::size_of::<GpuLightSample>() as u64),
                storage(5, false, 8),
                buffers::uniform_entry::<GpuAppendParams>(6, compute),
                storage(7, false, 4),
                storage(8, false, 16),
                storage(9, false, 4),
            ],
        });
        let pipeline = |entry: &str| kernel::compute_pipeline(device, &module, "first_shot_reduce", entry, &[&layout]);
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
        let pairs =
            buffers::storage_zeroed(device, "firstshot.first_shot_reduce.pairs", 16 * capacity.max(1) as u64, none);
        let pair_count =
            buffers::storage_zeroed(device, "firstshot.first_shot_reduce.pair_count", 4, wgpu::BufferUsages::COPY_SRC);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("firstshot.first_shot_reduce.bind_group"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: faces.camera.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: face_params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&faces.ids_view) },
                wgpu::BindGroupEntry { binding: 3, resource: scene.patches.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: scene.samples.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: sums.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 6, resource: append_params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 7, resource: row_counts.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 8, resource: pairs.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 9, resource: pair_count.as_entire_binding() },
            ],
        });
        FirstShotReduce {
            reduce: pipeline("reduce_face"),
            append: pipeline("append_sample"),
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
        let groups = (self.face_size[0].div_ceil(8), rows.div_ceil(8));
        kernel::dispatch(encoder, "firstshot.first_shot_reduce.reduce_face", &self.reduce, &[&self.bind_group], groups);
    }

    /// Appends the sample's pairs (its `append_params` written) and clears the sums.
    pub fn record_append(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = dispatch_size(self.patch_count.div_ceil(64));
        kernel::dispatch(
            encoder,
            "firstshot.first_shot_reduce.append_sample",
            &self.append,
            &[&self.bind_group],
            groups,
        );
    }
}
