//! Image estimate (`wgsl/image_estimate.wgsl`): adds one estimate of every camera pixel
//! (emission, per-pixel direct light, indirect light gathered through the step's bundle) to
//! the running sum of the image.

use crate::direct_light::DirectLights;
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{buffers, kernel};
use crate::iteration::GatherBuffers;
use crate::layout::{
    GpuBundle, GpuCamera, GpuDirectLight, GpuEstimateParams, GpuMaterial, GpuPatch, GpuWindowFace,
};
use crate::stages::camera_item_buffer::CameraItemBuffer;
use crate::{Error, Result};

const WORKGROUP: u32 = 8;

/// Pipeline, parameters and the image sum (vec4<f32> per pixel: rgb sum, w count).
pub struct ImageEstimate {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    direct_group: wgpu::BindGroup,
    gather_layout: wgpu::BindGroupLayout,
    gather_group: wgpu::BindGroup,
    pub params: wgpu::Buffer,
    pub image_sum: wgpu::Buffer,
    width: u32,
    height: u32,
}

fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    kernel::uint_texture_entry(binding)
}

impl ImageEstimate {
    /// `gather`: the bundle buffers of the iteration, or `None` for direct-light-only passes.
    pub fn new(
        device: &wgpu::Device,
        scene: &SceneBuffers,
        camera: &CameraItemBuffer,
        direct: &DirectLights,
        gather: Option<&GatherBuffers>,
    ) -> Self {
        use buffers::storage_entry as storage;
        let module = kernel::module(device, "image_estimate");
        let compute = wgpu::ShaderStages::COMPUTE;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.image_estimate.layout"),
            entries: &[
                buffers::uniform_entry::<GpuCamera>(0, compute),
                buffers::uniform_entry::<GpuEstimateParams>(1, compute),
                texture_entry(2),
                storage(3, true, std::mem::size_of::<GpuPatch>() as u64),
                storage(4, true, std::mem::size_of::<GpuMaterial>() as u64),
                storage(5, false, 16),
            ],
        });
        let direct_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.image_estimate.direct_layout"),
            entries: &[
                storage(0, true, std::mem::size_of::<GpuDirectLight>() as u64),
                storage(1, true, std::mem::size_of::<GpuWindowFace>() as u64),
                texture_entry(2),
                texture_entry(3),
            ],
        });
        let gather_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.image_estimate.gather_layout"),
            entries: &[
                buffers::uniform_entry::<GpuBundle>(0, compute),
                storage(1, true, 4),
                storage(2, true, 8),
                storage(3, true, 16),
            ],
        });
        let pipeline = kernel::compute_pipeline(
            device,
            &module,
            "image_estimate",
            "main",
            &[&layout, &direct_layout, &gather_layout],
        );
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
                wgpu::BindGroupEntry { binding: 5, resource: image_sum.as_entire_binding() },
            ],
        });
        let direct_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("firstshot.image_estimate.direct_group"),
            layout: &direct_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: direct.lights_buffer().as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: direct.faces_buffer().as_entire_binding() },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(direct.kept_atlas()),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(direct.pass_atlas()),
                },
            ],
        });
        let gather_group = Self::gather_group(device, &gather_layout, gather);
        ImageEstimate {
            pipeline,
            bind_group,
            direct_group,
            gather_group,
            gather_layout,
            params,
            image_sum,
            width: camera.width,
            height: camera.height,
        }
    }

    /// Group 2; without an iteration, placeholders that a pass with `gather` 0 never reads.
    fn gather_group(
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        gather: Option<&GatherBuffers>,
    ) -> wgpu::BindGroup {
        let placeholder;
        let (bundle, offsets, fragments, outgoing) = match gather {
            Some(g) => (&g.bundle, &g.offsets, &g.fragments, &g.outgoing),
            None => {
                let none = wgpu::BufferUsages::empty();
                placeholder = [
                    buffers::uniform(
                        device,
                        "firstshot.image_estimate.no_bundle",
                        &<GpuBundle as bytemuck::Zeroable>::zeroed(),
                    ),
                    buffers::storage_zeroed(device, "firstshot.image_estimate.no_offsets", 16, none),
                    buffers::storage_zeroed(device, "firstshot.image_estimate.no_fragments", 16, none),
                    buffers::storage_zeroed(device, "firstshot.image_estimate.no_outgoing", 16, none),
                ];
                (&placeholder[0], &placeholder[1], &placeholder[2], &placeholder[3])
            }
        };
        kernel::buffer_bind_group(
            device,
            "firstshot.image_estimate.gather_group",
            layout,
            &[bundle, offsets, fragments, outgoing],
        )
    }

    /// Binds the bundle buffers of a new iteration (after its fragment list grew).
    pub fn rebind_gather(&mut self, device: &wgpu::Device, gather: &GatherBuffers) {
        self.gather_group = Self::gather_group(device, &self.gather_layout, Some(gather));
    }

    /// Records one estimate of every pixel (reads the camera item buffer of this pass).
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = (self.width.div_ceil(WORKGROUP), self.height.div_ceil(WORKGROUP));
        let bind_groups = [&self.bind_group, &self.direct_group, &self.gather_group];
        kernel::dispatch(encoder, "firstshot.image_estimate.pass", &self.pipeline, &bind_groups, groups);
    }

    /// What the estimate adds where no surface is, how many direct lights it evaluates, and
    /// whether it gathers through a bundle.
    pub fn set_params(
        &self,
        queue: &wgpu::Queue,
        environment: [f32; 3],
        patch_count: u32,
        light_count: u32,
        gather: bool,
    ) {
        let params = GpuEstimateParams {
            environment: [environment[0], environment[1], environment[2], 0.0],
            patch_count,
            light_count,
            gather: gather as u32,
            _pad: 0,
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
