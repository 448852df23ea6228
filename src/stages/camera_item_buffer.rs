//! Camera item buffer (`wgsl/camera_item_buffer.wgsl`): patch id + 1 per camera pixel.

use crate::gpu::bindings::{Kernel, KernelSpec, fragment, uniform, vertex};
use crate::gpu::buffers;
use crate::gpu::scene_buffers::RasterMesh;
use crate::layout::{GpuCamera, RasterVertex, VIEW_ORTHOGRAPHIC};
use crate::scene::Camera;
use glam::DVec3;

/// Render pass: vertex input `RasterVertex`, an R32Uint target of patch index + 1.
pub const SPEC: KernelSpec = KernelSpec {
    stem: "camera_item_buffer",
    visibility: wgpu::ShaderStages::VERTEX,
    entry_points: &[vertex("vs_main"), fragment("fs_main")],
    groups: &[&[uniform::<GpuCamera>("camera")]],
};

/// Side of a camera pixel's block of item-buffer texels when the view is small enough
/// (`camera_supersample`): the camera's sample strata (`rng::PIXEL_STRATA`), so that one
/// raster holds every stratum of a block of image steps.
pub const CAMERA_SUPERSAMPLE: u32 = crate::rng::PIXEL_STRATA as u32;
/// The most texels a supersampled camera item buffer may take (id and depth, 8 bytes each:
/// 32 MiB, a 512 x 512 view).
pub const SUPERSAMPLED_TEXELS: u64 = 1 << 22;
/// The largest texture side every adapter wgpu opens by default allows.
const MAX_TEXTURE_SIDE: u32 = 8192;

/// Texels per pixel side of a view's camera item buffer: `CAMERA_SUPERSAMPLE` where the
/// view's texels stay within `SUPERSAMPLED_TEXELS` and the texture's sides within what every
/// adapter allows, else 1. Why: a camera raster costs about the same at any size on a CPU
/// adapter (it sets up every triangle on one thread: the Sierpinski scene's 16 404 triangles
/// about 6 ms at 256 x 256 and at 512 x 512), and each image step asked for a new one at its
/// sample point. Supersampled, one raster serves the `CAMERA_SUPERSAMPLE`^2 image steps of a
/// block of camera samples, which share their offset inside the strata
/// (`rng::stratified_pixel_sample`): each step reads its stratum's texel of every pixel.
pub fn camera_supersample(width: u32, height: u32) -> u32 {
    let s = CAMERA_SUPERSAMPLE;
    let texels = width as u64 * height as u64 * (s * s) as u64;
    if texels <= SUPERSAMPLED_TEXELS && width.max(height) * s <= MAX_TEXTURE_SIDE { s } else { 1 }
}

pub const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The near distance of every pinhole view (a camera, a face of a light sample's window) as a
/// share of the scene's radius: 2^-20, sixteen of the last places of the single-precision
/// positions (relative to the scene's centre) that the GPU works in, so that a surface is cut
/// off only where it could not be told from the eye anyway. With reversed z in a 32-bit float
/// depth the near distance costs no precision further away (the depth near / z keeps its
/// relative precision), so a larger one gains nothing; a camera used to cut off what lay
/// within 1e-5 radii, a metre of a scene 100 km across.
pub const NEAR_OF_RADIUS: f64 = 1.0 / 1_048_576.0;

/// The uniform for `camera`, with the sample at `jitter` inside each pixel. `near` bounds
/// the reversed-z projection; with a 32-bit float depth it costs no precision further away.
pub fn gpu_camera(camera: &Camera, width: u32, height: u32, near: f64, jitter: [f32; 2]) -> GpuCamera {
    let tan_y = (camera.fov_y.to_radians() * 0.5).tan();
    let tan_x = tan_y * width as f64 / height as f64;
    View {
        eye: camera.position,
        forward: (camera.look_at - camera.position).normalize(),
        up_hint: camera.up,
        tan: [tan_x, tan_y],
        window_centre: [0.0, 0.0],
        size: [width, height],
        near,
        orthographic: false,
    }
    .gpu(jitter)
}

/// A pinhole view (a camera, or one face of a light sample's window), or a parallel one (a
/// directional light's window).
#[derive(Debug, Clone, Copy)]
pub struct View {
    pub eye: DVec3,
    /// Unit view direction (the face normal for a window face).
    pub forward: DVec3,
    /// Made orthogonal to `forward` to give the image's up.
    pub up_hint: DVec3,
    /// Half extents of the view window at focal distance 1 (orthographic: in scene units).
    pub tan: [f64; 2],
    /// Centre of the view window in (right, up) coordinates at focal distance 1.
    pub window_centre: [f64; 2],
    pub size: [u32; 2],
    /// The near distance of the reversed-z projection; for an orthographic view, the far
    /// distance of its linear depth 1 - z / far (every surface must lie within it).
    pub near: f64,
    /// A parallel projection along `forward` from the plane through `eye`.
    pub orthographic: bool,
}

impl View {
    /// Right-handed as docs/SCENE_FORMAT.md says: right = normalize(forward x up).
    pub fn gpu(&self, jitter: [f32; 2]) -> GpuCamera {
        let forward = self.forward.normalize();
        let right = forward.cross(self.up_hint).normalize();
        let up = right.cross(forward);
        let f = |v: DVec3, w: f64| [v.x as f32, v.y as f32, v.z as f32, w as f32];
        GpuCamera {
            eye: f(self.eye, 1.0),
            right: f(right, self.tan[0]),
            up: f(up, self.tan[1]),
            forward: f(forward, self.near),
            jitter: [jitter[0], jitter[1], self.window_centre[0] as f32, self.window_centre[1] as f32],
            size: [self.size[0], self.size[1], if self.orthographic { VIEW_ORTHOGRAPHIC } else { 0 }, 0],
        }
    }
}

/// Pipeline and targets of the camera item buffer.
pub struct CameraItemBuffer {
    kernel: Kernel,
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    /// The camera the pixels' estimates read (`width` x `height`, this step's sample); with
    /// `supersample` 1 the raster's too.
    pub camera: wgpu::Buffer,
    /// With `supersample` > 1: the raster's camera, at `supersample` times the size, its
    /// texel centres shifted by the block's offset inside the strata.
    pub raster_camera: Option<wgpu::Buffer>,
    pub ids: wgpu::Texture,
    pub ids_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    pub width: u32,
    pub height: u32,
    /// Texels per pixel side (`camera_supersample`; 1 for a light's faces).
    pub supersample: u32,
}

impl CameraItemBuffer {
    /// `supersample`: texels per pixel side (`camera_supersample`, or 1).
    /// `like`: an item buffer whose kernel and pipeline this one shares (another view of
    /// the same render: only the camera uniform, the textures and the bind group are new).
    pub fn new(device: &wgpu::Device, width: u32, height: u32, supersample: u32, like: Option<&Self>) -> Self {
        let supersample = supersample.max(1);
        let (built, pipeline) = match like {
            Some(like) => (like.kernel.clone(), like.pipeline.clone()),
            None => {
                let built = SPEC.build(device);
                let pipeline = item_pipeline(device, &built, "firstshot.camera_item_buffer.pipeline");
                (built, pipeline)
            }
        };
        let camera = buffers::uniform(
            device,
            "firstshot.camera_item_buffer.camera",
            &<GpuCamera as bytemuck::Zeroable>::zeroed(),
        );
        let raster_camera = (supersample > 1).then(|| {
            buffers::uniform(
                device,
                "firstshot.camera_item_buffer.raster_camera",
                &<GpuCamera as bytemuck::Zeroable>::zeroed(),
            )
        });
        let bind_group = built.bind_group(device, 0, &[("camera", raster_camera.as_ref().unwrap_or(&camera).into())]);
        let size =
            wgpu::Extent3d { width: width * supersample, height: height * supersample, depth_or_array_layers: 1 };
        let ids = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("firstshot.camera_item_buffer.ids"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: ID_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let depth = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("firstshot.camera_item_buffer.depth"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        });
        CameraItemBuffer {
            kernel: built,
            pipeline,
            bind_group,
            camera,
            raster_camera,
            ids_view: ids.create_view(&Default::default()),
            ids,
            depth_view: depth.create_view(&Default::default()),
            width,
            height,
            supersample,
        }
    }

    /// Records the pass: every patch rasterised with its id, as `view` (the camera its
    /// uniform holds) sees it; only the triangles that can reach the view are drawn
    /// (`RasterMesh::draw_in_view`: the same texels).
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder, raster: &RasterMesh, view: &GpuCamera) {
        self.record_rows(encoder, raster, self.height, view);
    }

    /// As `record`, rasterising only the top `rows` rows (half faces of a hemicube).
    pub fn record_rows(&self, encoder: &mut wgpu::CommandEncoder, raster: &RasterMesh, rows: u32, view: &GpuCamera) {
        let mut pass = begin_item_pass(encoder, "firstshot.camera_item_buffer.pass", &self.ids_view, &self.depth_view);
        pass.set_pipeline(&self.pipeline);
        let s = self.supersample;
        let rows = rows.clamp(1, self.height);
        pass.set_scissor_rect(0, 0, self.width * s, rows * s);
        pass.set_bind_group(0, &self.bind_group, &[]);
        raster.draw_in_view(&mut pass, 0..1, view, rows * s);
    }
}

/// The render pipeline of an item buffer (`vs_main`, `fs_main` of `kernel`): every patch
/// rasterised, no culling (a surface seen from its back still occludes), patch id + 1 into
/// `ID_FORMAT`, the nearest by reversed-z depth. Shared by the camera's and the light
/// windows' item buffers.
pub fn item_pipeline(device: &wgpu::Device, kernel: &Kernel, label: &str) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&kernel.pipeline_layout),
        vertex: wgpu::VertexState {
            module: &kernel.module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &raster_vertex_layouts(),
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &kernel.module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: ID_FORMAT,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A render pass that clears an item buffer (`ids` to NO_PATCH, its reversed-z depth to 0,
/// kept only while the pass runs), shared by the camera's and the light windows' passes.
pub fn begin_item_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    ids: &wgpu::TextureView,
    depth: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: ids,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// The vertex layouts of the rasterised triangles (`scene_buffers::RasterMesh`), shared by
/// every rasterising stage: buffer 0 `RasterVertex` (locations 0 position, 1 patch id),
/// buffer 1 the lattice word (location 2).
pub fn raster_vertex_layouts() -> [Option<wgpu::VertexBufferLayout<'static>>; 2] {
    const VERTEX: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32];
    const LATTICE: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![2 => Uint32];
    [
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<RasterVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &VERTEX,
        }),
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<u32>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &LATTICE,
        }),
    ]
}
