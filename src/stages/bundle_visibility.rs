//! Bundle visibility (`wgsl/bundle_visibility.wgsl`): every surface on every line of the
//! bundle's grid, in one rasterisation pass into per-line buckets and a spill list.

use crate::gpu::bindings::{Kernel, KernelSpec, Resource, fragment, read, read_write, uniform, vertex};
use crate::gpu::scene_buffers::{OUTGOING, RasterMesh};
use crate::iteration::Grid;
use crate::layout::GpuBundle;
use crate::stages::camera_item_buffer::raster_vertex_layouts;

/// Render pass, no culling, no depth test, a depth-only attachment that nothing reads;
/// vertex input `RasterVertex`.
pub const SPEC: KernelSpec = KernelSpec {
    stem: "bundle_visibility",
    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
    entry_points: &[vertex("vs_main"), fragment("fs_fill")],
    groups: &[&[
        uniform::<GpuBundle>("bundle"),
        // Surfaces per line, resolution^2.
        read_write::<u32>("counts"),
        // The line's last spill node + 1 (0: none), resolution^2.
        read_write::<u32>("heads"),
        // LINE_BUCKET slots a line, then the long lines' slices (bundle_transfer):
        // (bits of depth, patch | FRAGMENT_FRONT_BIT when the patch's front faces +d).
        read_write::<[u32; 2]>("fragments"),
        // (fragment, next node + 1, unused) for a line's surfaces past its bucket.
        read_write::<[u32; 4]>("spill"),
        // TALLY_SPILLED: spill nodes taken; TALLY_LONG_LINES: lines listed.
        read_write::<u32>("tally"),
        // Set when a node lies past the capacity: the host grows the lists and redoes the steps.
        read_write::<u32>("overflow"),
        // The lines past their bucket (TALLY_LONG_LINES of them), for bundle_transfer.
        read_write::<u32>("long_lines"),
        // w: s_j from bundle_reflect; vs_main.
        read::<[f32; 4]>("outgoing").paged(OUTGOING.pages),
    ]],
};

pub struct BundleVisibility {
    kernel: Kernel,
    fill: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    depth_view: wgpu::TextureView,
    grid: Grid,
}

impl BundleVisibility {
    /// `buffers`: bundle, counts, heads, fragments, spill, tally, overflow, long_lines,
    /// outgoing (`SPEC`'s group 0). `grid`: the bundles' grid. `like`: a stage over arrays of
    /// the same paging whose pipeline this one shares (its depth attachment follows the
    /// resolution).
    pub fn new(device: &wgpu::Device, buffers: [Resource; 9], grid: Grid, like: Option<&Self>) -> Self {
        let resolution = grid.resolution;
        let built = match like {
            Some(like) => like.kernel.clone(),
            None => SPEC.build_paged(device, crate::gpu::bindings::paging(&buffers)),
        };
        let pipeline = |entry: &str| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(&format!("firstshot.bundle_visibility.{entry}")),
                layout: Some(&built.pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &built.module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &raster_vertex_layouts(),
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
            fill: like.map_or_else(|| pipeline("fs_fill"), |like| like.fill.clone()),
            bind_group: built.resource_bind_group(device, 0, &buffers),
            depth_view: depth.create_view(&Default::default()),
            kernel: built,
            grid,
        }
    }

    /// `fine_rect`: the bundle's fine window (`GpuBundle::fine_rect`), the whole grid with one
    /// level.
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder, raster: &RasterMesh, fine_rect: [u32; 4]) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("firstshot.bundle_visibility.fill"),
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
        pass.set_pipeline(&self.fill);
        pass.set_bind_group(0, &self.bind_group, &[]);
        // Two levels: the wide lines (instance 0) over the whole grid, of the triangles
        // outside the fine patches (those can only fall in the fine window, which the wide
        // lines leave to the fine ones); then the fine lines (instance 1) of every triangle,
        // in the window alone.
        if let Some(window) = self.grid.window {
            let wide = (self.grid.resolution / window.wide) as f32;
            pass.set_viewport(0.0, 0.0, wide, wide, 0.0, 1.0);
            raster.draw_wide(&mut pass, 0..1);
            let r = self.grid.resolution as f32;
            pass.set_viewport(0.0, 0.0, r, r, 0.0, 1.0);
            let [x, y, w, h] = fine_rect;
            pass.set_scissor_rect(x, y, w, h);
        }
        raster.draw(&mut pass, 1..2);
    }
}
