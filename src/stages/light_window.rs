//! Light windows (`wgsl/light_window.wgsl`): item buffers of the lights' window faces, each
//! face a tile of one atlas texture, for the per-pixel direct light.

use crate::gpu::bindings::{KernelSpec, fragment, read, vertex};
use crate::gpu::scene_buffers::RasterMesh;
use crate::layout::GpuWindowFace;
use crate::stages::camera_item_buffer::{DEPTH_FORMAT, ID_FORMAT, begin_item_pass, item_pipeline};

/// Render pass: vertex input `RasterVertex`, an R32Uint target of patch index + 1; the
/// instance index picks the face.
pub const SPEC: KernelSpec = KernelSpec {
    stem: "light_window",
    visibility: wgpu::ShaderStages::VERTEX,
    entry_points: &[vertex("vs_main"), fragment("fs_main")],
    groups: &[&[read::<GpuWindowFace>("faces")]],
};

/// Pipeline and targets of one atlas of window faces.
pub struct WindowAtlas {
    /// None for an atlas without faces (every light of its kind takes shadow rays, or there is
    /// none): nothing is ever drawn into it, so its pipeline is not built.
    drawn: Option<(wgpu::RenderPipeline, wgpu::BindGroup)>,
    ids_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    pub size: [u32; 2],
}

impl WindowAtlas {
    /// An atlas of `size` texels whose faces are entries of `faces` (array<WindowFace>).
    pub fn new(device: &wgpu::Device, label: &str, faces: &wgpu::Buffer, size: [u32; 2]) -> Self {
        let drawn = (size[0] > 0 && size[1] > 0).then(|| {
            let built = SPEC.build(device);
            let pipeline = item_pipeline(device, &built, "firstshot.light_window.pipeline");
            let bind_group = built.bind_group(device, 0, &[("faces", faces.into())]);
            (pipeline, bind_group)
        });
        let texture = |format, usage, what: &str| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(&format!("firstshot.light_window.{label}.{what}")),
                size: wgpu::Extent3d { width: size[0].max(1), height: size[1].max(1), depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let ids =
            texture(ID_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING, "ids");
        let depth = texture(DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT, "depth");
        WindowAtlas {
            drawn,
            ids_view: ids.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            size,
        }
    }

    /// The atlas of patch ids, for the estimate to read.
    pub fn ids_view(&self) -> &wgpu::TextureView {
        &self.ids_view
    }

    /// Records one pass that clears the whole atlas and renders every patch into each of
    /// `faces` (index into the face table, and the face): one draw per face, the viewport on
    /// its tile, the scissor on its rows.
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder, raster: &RasterMesh, faces: &[(u32, GpuWindowFace)]) {
        let Some((pipeline, bind_group)) = &self.drawn else {
            assert!(faces.is_empty(), "an atlas of no texels has no faces to draw");
            return;
        };
        let mut pass = begin_item_pass(encoder, "firstshot.light_window.pass", &self.ids_view, &self.depth_view);
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        for (index, face) in faces {
            let [x, y, rows, _] = face.tile;
            let side = face.view.size[0];
            pass.set_viewport(x as f32, y as f32, side as f32, side as f32, 0.0, 1.0);
            let rows = rows.clamp(1, side);
            pass.set_scissor_rect(x, y, side, rows);
            raster.draw_in_view(&mut pass, *index..*index + 1, &face.view, rows);
        }
    }
}
