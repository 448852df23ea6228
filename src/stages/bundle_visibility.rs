//! Bundle visibility (`wgsl/bundle_visibility.wgsl`): every surface on every line of the
//! bundle's grid, by a counting pass, a prefix sum and a filling pass.

use crate::gpu::bindings::{KernelSpec, Resource, fragment, read, read_write, uniform, vertex};
use crate::gpu::scene_buffers::OUTGOING;
use crate::layout::GpuBundle;
use crate::stages::camera_item_buffer::raster_vertex_layout;

/// Render pass, no culling, no depth test, a depth-only attachment that nothing reads;
/// vertex input `RasterVertex`.
pub const SPEC: KernelSpec = KernelSpec {
    stem: "bundle_visibility",
    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
    entry_points: &[vertex("vs_main"), fragment("fs_count"), fragment("fs_fill")],
    groups: &[&[
        uniform::<GpuBundle>("bundle"),
        // resolution^2 + 1; fs_count.
        read_write::<u32>("counts"),
        // Exclusive prefix sums of counts; fs_fill.
        read::<u32>("offsets"),
        // resolution^2; fs_fill.
        read_write::<u32>("cursor"),
        // (bits of depth, patch | FRAGMENT_FRONT_BIT when the patch's front faces +d); fs_fill.
        read_write::<[u32; 2]>("fragments"),
        // Set when a slot lies past the capacity: the host grows the list and redoes the steps.
        read_write::<u32>("overflow"),
        // w: s_j from bundle_reflect; fs_fill.
        read::<[f32; 4]>("outgoing").paged(OUTGOING.pages),
    ]],
};

pub struct BundleVisibility {
    count: wgpu::RenderPipeline,
    fill: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    depth_view: wgpu::TextureView,
}

impl BundleVisibility {
    /// `buffers`: bundle, counts, offsets, cursor, fragments, overflow, outgoing (`SPEC`'s
    /// group 0).
    pub fn new(device: &wgpu::Device, buffers: [Resource; 7], resolution: u32) -> Self {
        let built = SPEC.build_paged(device, crate::gpu::bindings::paging(&buffers));
        let pipeline = |entry: &str| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(&format!("firstshot.bundle_visibility.{entry}")),
                layout: Some(&built.pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &built.module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(raster_vertex_layout())],
                },
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                // Only so that the pass has an attachment: every fragment must run.
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: wgpu::TextureFormat::Depth32Float,
                    depth_write_enabled: Some(false),
                    depth_compare: Some(wgpu::CompareFunction::Always),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &built.module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let depth = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("firstshot.bundle_visibility.depth"),
            size: wgpu::Extent3d { width: resolution, height: resolution, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Depth32Float,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        });
        BundleVisibility {
            count: pipeline("fs_count"),
            fill: pipeline("fs_fill"),
            bind_group: built.resource_bind_group(device, 0, &buffers),
            depth_view: depth.create_view(&Default::default()),
        }
    }

    fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pipeline: &wgpu::RenderPipeline,
        label: &str,
        vertices: &wgpu::Buffer,
        patch_count: u32,
    ) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth_view,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, vertices.slice(..));
        pass.draw(0..patch_count * 3, 0..1);
    }

    pub fn record_count(&self, encoder: &mut wgpu::CommandEncoder, vertices: &wgpu::Buffer, patch_count: u32) {
        self.record(encoder, &self.count, "firstshot.bundle_visibility.count", vertices, patch_count);
    }

    pub fn record_fill(&self, encoder: &mut wgpu::CommandEncoder, vertices: &wgpu::Buffer, patch_count: u32) {
        self.record(encoder, &self.fill, "firstshot.bundle_visibility.fill", vertices, patch_count);
    }
}
