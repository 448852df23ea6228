//! BRDF probe (`wgsl/brdf_probe.wgsl`): evaluates the WGSL BRDF for given directions, so
//! that tests can hold it against the host's `scene::brdf::eval`.

use crate::Result;
use crate::gpu::bindings::{KernelSpec, Resource, compute, read, read_write};
use crate::gpu::{Context, buffers, kernel};
use crate::layout::GpuMaterial;
use glam::Vec3;

/// A test instrument, not part of a render.
pub const SPEC: KernelSpec = KernelSpec {
    stem: "brdf_probe",
    visibility: wgpu::ShaderStages::COMPUTE,
    // One invocation per query.
    entry_points: &[compute("main", [64, 1, 1])],
    groups: &[&[
        read::<GpuMaterial>("materials"),
        // 4 per query: n, w_in, w_out, (material, 0, 0, 0).
        read::<[f32; 4]>("queries"),
        // rgb f, one per query.
        read_write::<[f32; 4]>("results"),
    ]],
};

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
    let built = SPEC.build(device);
    let pipeline = built.compute_pipeline(device, "main");
    // Bound to the queries' length, which `arrayLength(&results)` reports to the kernel.
    let results_size = std::num::NonZeroU64::new(16 * queries.len().max(1) as u64).expect("non-zero");
    let bind_group = built.bind_group(
        device,
        0,
        &[
            ("materials", (&materials).into()),
            ("queries", (&queries_buf).into()),
            ("results", Resource::BufferPrefix(&results, results_size)),
        ],
    );
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.brdf_probe") });
    let groups = SPEC.grid("main", [queries.len() as u32, 1]);
    kernel::dispatch(&mut encoder, "firstshot.brdf_probe.pass", &pipeline, &[&bind_group], groups);
    ctx.queue.submit([encoder.finish()]);
    let out: Vec<[f32; 4]> = buffers::read_back(device, &ctx.queue, &results, 16 * queries.len() as u64)?;
    Ok(out.iter().map(|v| [v[0], v[1], v[2]]).collect())
}
