//! BRDF probe (`wgsl/brdf_probe.wgsl`): evaluates the WGSL BRDF for given directions, so
//! that tests can hold it against the host's `scene::brdf::eval`.

use crate::Result;
use crate::gpu::{Context, buffers, kernel};
use crate::layout::GpuMaterial;
use glam::Vec3;

/// One query: material index, normal, w_in, w_out (unit, pointing away from the surface).
#[derive(Debug, Clone, Copy)]
pub struct BrdfQuery {
    pub material: u32,
    pub normal: Vec3,
    pub w_in: Vec3,
    pub w_out: Vec3,
}

/// Evaluates every query on the GPU and returns f per query.
pub fn evaluate(ctx: &Context, materials: &[GpuMaterial], queries: &[BrdfQuery]) -> Result<Vec<[f32; 3]>> {
    let device = &ctx.device;
    let module = kernel::module(device, "brdf_probe");
    let packed: Vec<[f32; 4]> = queries
        .iter()
        .flat_map(|q| {
            [
                q.normal.extend(0.0).to_array(),
                q.w_in.extend(0.0).to_array(),
                q.w_out.extend(0.0).to_array(),
                [q.material as f32, 0.0, 0.0, 0.0],
            ]
        })
        .collect();
    let none = wgpu::BufferUsages::empty();
    let materials = buffers::storage_init(device, "firstshot.brdf_probe.materials", materials, none);
    let queries_buf = buffers::storage_init(device, "firstshot.brdf_probe.queries", &packed, none);
    let results = buffers::storage_zeroed(
        device,
        "firstshot.brdf_probe.results",
        16 * queries.len() as u64,
        wgpu::BufferUsages::COPY_SRC,
    );
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("firstshot.brdf_probe.pipeline"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("firstshot.brdf_probe.bind_group"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: materials.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: queries_buf.as_entire_binding() },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &results,
                    offset: 0,
                    size: std::num::NonZeroU64::new(16 * queries.len().max(1) as u64),
                }),
            },
        ],
    });
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.brdf_probe") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("firstshot.brdf_probe.pass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((queries.len() as u32).div_ceil(64), 1, 1);
    }
    ctx.queue.submit([encoder.finish()]);
    let out: Vec<[f32; 4]> = buffers::read_back(device, &ctx.queue, &results, 16 * queries.len() as u64)?;
    Ok(out.iter().map(|v| [v[0], v[1], v[2]]).collect())
}
