//! Image estimate (`wgsl/image_estimate.wgsl`): adds one estimate of every camera pixel
//! (emission, per-pixel direct light, indirect light gathered through the step's bundle) to
//! the running sum of the image.

use crate::direct_light::DirectLights;
use crate::gpu::bindings::{Kernel, KernelSpec, compute, read, read_write, uint_texture, uniform};
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{buffers, kernel};
use crate::iteration::GatherBuffers;
use crate::layout::{GpuBundle, GpuCamera, GpuDirectLight, GpuEstimateParams, GpuMaterial, GpuPatch, GpuWindowFace};
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
            // One pixel per invocation: no race.
            read_write::<[f32; 4]>("image_sum"),
        ],
        // The direct light (`direct_light::DirectLights`).
        &[
            read::<GpuDirectLight>("lights"),
            read::<GpuWindowFace>("faces"),
            // Faces with tile.w == 0: the point lights' kept cubes.
            uint_texture("kept_atlas"),
            // Faces with tile.w == 1: the area lights' windows of this pass.
            uint_texture("pass_atlas"),
        ],
        // The gather (`iteration::GatherBuffers`), after the step's transfer sorted its lines.
        &[
            uniform::<GpuBundle>("bundle"),
            // Line starts, resolution^2 + 1.
            read::<u32>("offsets"),
            // (depth bits, patch | FRAGMENT_FRONT_BIT), each line sorted by depth.
            read::<[u32; 2]>("fragments"),
            // O_j of this step.
            read::<[f32; 4]>("outgoing"),
        ],
    ],
};

/// Pipeline, parameters and the image sum (vec4<f32> per pixel: rgb sum, w count).
pub struct ImageEstimate {
    built: Kernel,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    direct_group: wgpu::BindGroup,
    gather_group: wgpu::BindGroup,
    pub params: wgpu::Buffer,
    pub image_sum: wgpu::Buffer,
    width: u32,
    height: u32,
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
                ("image_sum", (&image_sum).into()),
            ],
        );
        let direct_group = built.bind_group(
            device,
            1,
            &[
                ("lights", direct.lights_buffer().into()),
                ("faces", direct.faces_buffer().into()),
                ("kept_atlas", direct.kept_atlas().into()),
                ("pass_atlas", direct.pass_atlas().into()),
            ],
        );
        let gather_group = Self::gather_group(device, &built, gather);
        ImageEstimate {
            built,
            pipeline,
            bind_group,
            direct_group,
            gather_group,
            params,
            image_sum,
            width: camera.width,
            height: camera.height,
        }
    }

    /// Group 2; without an iteration, placeholders that a pass with `gather` 0 never reads.
    fn gather_group(device: &wgpu::Device, built: &Kernel, gather: Option<&GatherBuffers>) -> wgpu::BindGroup {
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
        built.bind_group(
            device,
            2,
            &[
                ("bundle", bundle.into()),
                ("offsets", offsets.into()),
                ("fragments", fragments.into()),
                ("outgoing", outgoing.into()),
            ],
        )
    }

    /// Binds the bundle buffers of a new iteration (after its fragment list grew).
    pub fn rebind_gather(&mut self, device: &wgpu::Device, gather: &GatherBuffers) {
        self.gather_group = Self::gather_group(device, &self.built, Some(gather));
    }

    /// Records one estimate of every pixel (reads the camera item buffer of this pass).
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = SPEC.grid("main", [self.width, self.height]);
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

    /// Reads the image sum back (rgb sum, w the number of estimates), row by row from the top.
    pub fn read_sum(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<[f32; 4]>> {
        let pixels = self.width as u64 * self.height as u64;
        buffers::read_back(device, queue, &self.image_sum, pixels * 16)
    }

    /// Reads the image back as the mean of the estimates, row by row from the top.
    pub fn read_mean(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<[f32; 3]>> {
        mean_of(&self.read_sum(device, queue)?)
    }
}

/// The mean of every pixel's estimates: its rgb sum over its count (in f32, as the image has
/// always been written; `merge` reproduces it bit for bit from a part).
pub fn mean_of(sums: &[[f32; 4]]) -> Result<Vec<[f32; 3]>> {
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
