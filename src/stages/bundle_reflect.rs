//! Bundle reflection (`wgsl/bundle_reflect.wgsl`): O_j of every patch into this step's
//! bundle, and the step's largest radiance.

use crate::gpu::kernel;
use crate::gpu::scene_buffers::{FirstShotTable, SceneBuffers};
use crate::layout::{GpuBundle, GpuMaterial, GpuPatch, GpuPatchState};
use crate::stages::prefix_sum::dispatch_size;

pub struct BundleReflect {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    table_group: wgpu::BindGroup,
    patch_count: u32,
}

impl BundleReflect {
    pub fn new(
        device: &wgpu::Device,
        scene: &SceneBuffers,
        bundle: &wgpu::Buffer,
        outgoing: &wgpu::Buffer,
        max_bits: &wgpu::Buffer,
    ) -> Self {
        let size = |n: usize| n as u64;
        let layout = kernel::buffer_layout(
            device,
            "firstshot.bundle_reflect.layout",
            wgpu::ShaderStages::COMPUTE,
            &[
                (true, true, size(std::mem::size_of::<GpuBundle>())),
                (false, true, size(std::mem::size_of::<GpuPatch>())),
                (false, true, size(std::mem::size_of::<GpuMaterial>())),
                (false, true, size(std::mem::size_of::<GpuPatchState>())),
                (false, false, 16),
                (false, false, 4),
            ],
        );
        let table_layout = FirstShotTable::layout(device);
        let module = kernel::module(device, "bundle_reflect");
        BundleReflect {
            pipeline: kernel::compute_pipeline(device, &module, "bundle_reflect", "main", &[&layout, &table_layout]),
            bind_group: kernel::buffer_bind_group(
                device,
                "firstshot.bundle_reflect.bind_group",
                &layout,
                &[bundle, &scene.patches, &scene.materials, &scene.state, outgoing, max_bits],
            ),
            table_group: scene.first_shot.bind_group(device, &table_layout, &scene.samples),
            patch_count: scene.patch_count,
        }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = dispatch_size(self.patch_count.div_ceil(64));
        let bind_groups = [&self.bind_group, &self.table_group];
        kernel::dispatch(encoder, "firstshot.bundle_reflect.pass", &self.pipeline, &bind_groups, groups);
    }
}
