//! Image estimate (`wgsl/image_estimate.wgsl`): adds one estimate of every camera pixel to
//! the running sum of the image.

use crate::gpu::scene_buffers::{FirstShotTable, SceneBuffers};
use crate::gpu::{buffers, kernel};
use crate::layout::{GpuCamera, GpuEstimateParams, GpuMaterial, GpuPatch, GpuPatchState};
use crate::stages::camera_item_buffer::CameraItemBuffer;
use crate::{Error, Result};

const WORKGROUP: u32 = 8;

/// Pipeline, parameters and the image sum (vec4<f32> per pixel: rgb sum, w count).
pub struct ImageEstimate {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    table_group: wgpu::BindGroup,
    pub params: wgpu::Buffer,
    pub image_sum: wgpu::Buffer,
    width: u32,
    height: u32,
}

impl ImageEstimate {
    pub fn new(device: &wgpu::Device, scene: &SceneBuffers, camera: &CameraItemBuffer) -> Self {
        use buffers::storage_entry as storage;
        let module = kernel::module(device, "image_estimate");
        let compute = wgpu::ShaderStages::COMPUTE;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.image_estimate.layout"),
            entries: &[
                buffers::uniform_entry::<GpuCamera>(0, compute),
                buffers::uniform_entry::<GpuEstimateParams>(1, compute),
                kernel::uint_texture_entry(2),
                storage(3, true, std::mem::size_of::<GpuPatch>() as u64),
                storage(4, true, std::mem::size_of::<GpuMaterial>() as u64),
                storage(5, true, std::mem::size_of::<GpuPatchState>() as u64),
                storage(6, false, 16),
            ],
        });
        let table_layout = FirstShotTable::layout(device);
        let pipeline = kernel::compute_pipeline(device, &module, "image_estimate", "main", &[&layout, &table_layout]);
        let params = buffers::uniform(
            device,
            "firstshot.image_estimate.params",
            &<GpuEstimateParams as bytemuck::Zeroable>::zeroed(),
        );
        let pixels = camera.width as u64 * camera.height as u64;
        let image_sum = buffers::storage_zeroed(
            device,
            "firstshot.image_estimate.image_sum",
            pixels * 16,
            wgpu::BufferUsages::COPY_SRC,
        );
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("firstshot.image_estimate.bind_group"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: camera.camera.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&camera.ids_view) },
                wgpu::BindGroupEntry { binding: 3, resource: scene.patches.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: scene.materials.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: scene.state.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 6, resource: image_sum.as_entire_binding() },
            ],
        });
        let table_group = scene.first_shot.bind_group(device, &table_layout, &scene.samples);
        ImageEstimate {
            pipeline,
            bind_group,
            table_group,
            params,
            image_sum,
            width: camera.width,
            height: camera.height,
        }
    }

    /// Records one estimate of every pixel (reads the camera item buffer of this pass).
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = (self.width.div_ceil(WORKGROUP), self.height.div_ceil(WORKGROUP));
        let bind_groups = [&self.bind_group, &self.table_group];
        kernel::dispatch(encoder, "firstshot.image_estimate.pass", &self.pipeline, &bind_groups, groups);
    }

    /// What the estimate adds where no surface is, and whether the iteration state holds J
    /// yet (before step 1 it does not).
    pub fn set_params(&self, queue: &wgpu::Queue, environment: [f32; 3], patch_count: u32, use_state: bool) {
        let params = GpuEstimateParams {
            environment: [environment[0], environment[1], environment[2], 0.0],
            patch_count,
            use_state: use_state as u32,
            _pad: [0; 2],
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    /// Clears the running sum.
    pub fn clear(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.image_sum, 0, None);
    }

    /// Reads the image back as the mean of the estimates, row by row from the top.
    pub fn read_mean(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<[f32; 3]>> {
        let pixels = self.width as u64 * self.height as u64;
        let sums: Vec<[f32; 4]> = buffers::read_back(device, queue, &self.image_sum, pixels * 16)?;
        sums.iter()
            .map(|s| {
                if s[3] > 0.0 {
                    Ok([s[0] / s[3], s[1] / s[3], s[2] / s[3]])
                } else {
                    Err(Error::Gpu("the image holds no estimate".into()))
                }
            })
            .collect()
    }
}
