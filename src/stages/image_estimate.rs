//! Image estimate (`wgsl/image_estimate.wgsl`): adds one estimate of every camera pixel to
//! the running sum of the image.

use crate::gpu::bindings::{KernelSpec, compute, read, read_write, uint_texture, uniform};
use crate::gpu::scene_buffers::{FIRST_SHOT_TABLE_GROUP, SceneBuffers};
use crate::gpu::{buffers, kernel};
use crate::layout::{GpuCamera, GpuEstimateParams, GpuMaterial, GpuPatch, GpuPatchState};
use crate::stages::camera_item_buffer::CameraItemBuffer;
use crate::{Error, Result};

pub const SPEC: KernelSpec = KernelSpec {
    stem: "image_estimate",
    visibility: wgpu::ShaderStages::COMPUTE,
    // One invocation per pixel.
    entry_points: &[compute("main", [8, 8, 1])],
    groups: &[
        &[
            uniform::<GpuCamera>("camera"),
            uniform::<GpuEstimateParams>("params"),
            // Patch index + 1 per pixel.
            uint_texture("item_buffer"),
            read::<GpuPatch>("patches"),
            read::<GpuMaterial>("materials"),
            read::<GpuPatchState>("state"),
            // One pixel per invocation: no race.
            read_write::<[f32; 4]>("image_sum"),
        ],
        FIRST_SHOT_TABLE_GROUP,
    ],
};

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
        let built = SPEC.build(device);
        let pipeline = built.compute_pipeline(device, "main");
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
        let bind_group = built.bind_group(
            device,
            0,
            &[
                ("camera", (&camera.camera).into()),
                ("params", (&params).into()),
                ("item_buffer", (&camera.ids_view).into()),
                ("patches", (&scene.patches).into()),
                ("materials", (&scene.materials).into()),
                ("state", (&scene.state).into()),
                ("image_sum", (&image_sum).into()),
            ],
        );
        let table_group = scene.first_shot.bind_group(device, &built.layouts[1], &scene.samples);
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
        let groups = SPEC.grid("main", [self.width, self.height]);
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
