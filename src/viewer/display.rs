//! What the window shows: the tonemapped image (the PNG's bytes, `Image::srgb8`), drawn
//! pixel for pixel into the largest rectangle of its aspect that fits the window, and the
//! egui overlay on top. Also reads back what was drawn (`screenshot`), for scripted tests.

use firstshot::Error;
use firstshot::gpu::context::Context;
use firstshot::image::Image;
use std::sync::Arc;
use winit::window::Window;

/// Draws the image texture with one triangle over the viewport; each fragment loads its
/// texel (no filtering), so that a window of the image's size shows the image's bytes.
const SHADER: &str = r#"
@group(0) @binding(0) var image: texture_2d<f32>;

struct Out {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs(@builtin(vertex_index) i: u32) -> Out {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: Out;
    out.position = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

@fragment
fn fs(in: Out) -> @location(0) vec4<f32> {
    let size = textureDimensions(image);
    let texel = min(vec2<u32>(in.uv * vec2<f32>(size)), size - vec2<u32>(1u));
    return vec4<f32>(textureLoad(image, texel, 0).rgb, 1.0);
}
"#;

/// Points of the overlay's text: small, so that it covers little of a small window.
const OVERLAY_TEXT_SIZE: f32 = 10.0;

/// Grey around the image where the window's aspect differs from it.
const BACKGROUND: wgpu::Color = wgpu::Color { r: 0.05, g: 0.05, b: 0.05, a: 1.0 };

pub struct Display {
    pub window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// Whether the surface's texture can be copied from (else a screenshot draws the same
    /// pass into a texture of its own).
    surface_readable: bool,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// The tonemapped image, and its bind group; remade when the image size changes.
    texture: Option<(wgpu::Texture, wgpu::BindGroup)>,
    egui: egui::Context,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
}

/// The image's sRGB bytes as RGBA (the texture's layout).
fn rgba(image: &Image, exposure: f32) -> Vec<u8> {
    image.srgb8(exposure).chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect()
}

impl Display {
    pub fn new(ctx: &Context, window: Arc<Window>, surface: wgpu::Surface<'static>) -> Result<Display, Error> {
        let caps = surface.get_capabilities(&ctx.adapter);
        // A linear 8-bit format takes the PNG's bytes as they are; an sRGB one decodes the
        // texture (then made sRGB too) and encodes again.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| matches!(f, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm))
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| Error::Adapter(format!("{}: the window's surface offers no format", ctx.summary)))?;
        let surface_readable = caps.usages.contains(wgpu::TextureUsages::COPY_SRC);
        let mut usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        if surface_readable {
            usage |= wgpu::TextureUsages::COPY_SRC;
        }
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 1,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&ctx.device, &config);
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("firstshot.viewer.show_image"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("firstshot.viewer.image_layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("firstshot.viewer.show_image"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("firstshot.viewer.show_image"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            multiview_mask: None,
            cache: None,
        });
        let egui = egui::Context::default();
        let egui_state = egui_winit::State::new(
            egui.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(device.limits().max_texture_dimension_2d as usize),
        );
        let egui_renderer = egui_wgpu::Renderer::new(device, format, Default::default());
        Ok(Display {
            window,
            surface,
            config,
            surface_readable,
            pipeline,
            layout,
            texture: None,
            egui,
            egui_state,
            egui_renderer,
        })
    }

    /// The surface's format, for the closing line of a session.
    pub fn format(&self) -> wgpu::TextureFormat {
        self.config.format
    }

    /// Passes a window event to egui (it needs the window's size and scale).
    pub fn on_window_event(&mut self, event: &winit::event::WindowEvent) {
        let _ = self.egui_state.on_window_event(&self.window, event);
    }

    pub fn resize(&mut self, ctx: &Context, width: u32, height: u32) {
        if width > 0 && height > 0 {
            self.config.width = width;
            self.config.height = height;
            self.surface.configure(&ctx.device, &self.config);
        }
    }

    /// Uploads the image, tonemapped with `exposure`.
    pub fn set_image(&mut self, ctx: &Context, image: &Image, exposure: f32) {
        let size = wgpu::Extent3d { width: image.width, height: image.height, depth_or_array_layers: 1 };
        let fits = self.texture.as_ref().is_some_and(|(t, _)| t.size() == size);
        if !fits {
            let format = match self.config.format.is_srgb() {
                true => wgpu::TextureFormat::Rgba8UnormSrgb,
                false => wgpu::TextureFormat::Rgba8Unorm,
            };
            let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("firstshot.viewer.image"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            });
            let view = texture.create_view(&Default::default());
            let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("firstshot.viewer.image"),
                layout: &self.layout,
                entries: &[wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) }],
            });
            self.texture = Some((texture, bind_group));
        }
        let (texture, _) = self.texture.as_ref().expect("made above");
        ctx.queue.write_texture(
            texture.as_image_copy(),
            &rgba(image, exposure),
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * image.width), rows_per_image: None },
            size,
        );
    }

    /// The largest rectangle of the image's aspect inside a target of `width` x `height`,
    /// centred: x, y, w, h in pixels.
    fn image_rect(&self, width: u32, height: u32) -> Option<[f32; 4]> {
        let (texture, _) = self.texture.as_ref()?;
        let (iw, ih) = (texture.width() as f32, texture.height() as f32);
        let scale = (width as f32 / iw).min(height as f32 / ih);
        let (w, h) = ((iw * scale).round().max(1.0), (ih * scale).round().max(1.0));
        Some([((width as f32 - w) / 2.0).floor(), ((height as f32 - h) / 2.0).floor(), w, h])
    }

    /// Records the image pass into `target` (`width` x `height`).
    fn draw_image(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView, width: u32, height: u32) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("firstshot.viewer.show_image"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(BACKGROUND), store: wgpu::StoreOp::Store },
            })],
            ..Default::default()
        });
        if let (Some((_, bind_group)), Some([x, y, w, h])) = (&self.texture, self.image_rect(width, height)) {
            pass.set_viewport(x, y, w, h, 0.0, 1.0);
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.draw(0..3, 0..1);
        }
    }

    /// Draws a frame: the image, then the overlay's `lines` (if any) in a box at the top
    /// left, and presents it. With `screenshot`, also reads back the image as drawn (before
    /// the overlay) and returns it.
    pub fn frame(
        &mut self,
        ctx: &Context,
        lines: Option<&[String]>,
        screenshot: bool,
    ) -> Result<Option<Image8>, Error> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f) | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            // The window changed size: configure again and draw the next frame.
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.surface.configure(&ctx.device, &self.config);
                return Ok(None);
            }
            // Hidden or busy: skip this frame (the steps go on).
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(None),
            other => {
                ctx.check()?;
                return Err(Error::Gpu(format!("the window's surface cannot be drawn on ({other:?})")));
            }
        };
        let (width, height) = (frame.texture.width(), frame.texture.height());
        let view = frame.texture.create_view(&Default::default());
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.draw_image(&mut encoder, &view, width, height);
        let mut shot = None;
        if screenshot {
            if self.surface_readable {
                shot = Some(Readback::record(ctx, &mut encoder, &frame.texture));
            } else {
                // The same pass into a texture of the surface's format that can be copied.
                let copy = ctx.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("firstshot.viewer.screenshot"),
                    size: frame.texture.size(),
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: self.config.format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                self.draw_image(&mut encoder, &copy.create_view(&Default::default()), width, height);
                shot = Some(Readback::record(ctx, &mut encoder, &copy));
            }
        }
        if let Some(lines) = lines {
            self.draw_overlay(ctx, &mut encoder, &view, lines, [width, height]);
        }
        ctx.queue.submit([encoder.finish()]);
        self.window.pre_present_notify();
        ctx.queue.present(frame);
        let image = shot.map(|s| s.read(ctx, self.config.format)).transpose()?;
        // A screenshot is the image's rectangle of the window (the whole window when it is
        // of the image's size).
        Ok(image.map(|i| match self.image_rect(width, height) {
            Some([x, y, w, h]) => i.crop(x as u32, y as u32, w as u32, h as u32),
            None => i,
        }))
    }

    fn draw_overlay(
        &mut self,
        ctx: &Context,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        lines: &[String],
        size: [u32; 2],
    ) {
        let input = self.egui_state.take_egui_input(&self.window);
        let output = self.egui.run_pass(input, |egui| {
            egui::Area::new(egui::Id::unique("firstshot.overlay")).fixed_pos(egui::pos2(6.0, 6.0)).show(egui, |ui| {
                egui::Frame::popup(ui.style()).fill(egui::Color32::from_black_alpha(170)).inner_margin(6.0).show(
                    ui,
                    |ui| {
                        for line in lines {
                            ui.label(
                                egui::RichText::new(line)
                                    .monospace()
                                    .size(OVERLAY_TEXT_SIZE)
                                    .color(egui::Color32::from_gray(230)),
                            );
                        }
                    },
                );
            });
        });
        self.egui_state.handle_platform_output(&self.window, output.platform_output);
        let jobs = self.egui.tessellate(output.shapes, output.pixels_per_point);
        let screen = egui_wgpu::ScreenDescriptor { size_in_pixels: size, pixels_per_point: output.pixels_per_point };
        for (id, deltas) in &output.textures_delta.set {
            for delta in deltas {
                self.egui_renderer.update_texture(&ctx.device, &ctx.queue, *id, delta);
            }
        }
        let extra = self.egui_renderer.update_buffers(&ctx.device, &ctx.queue, encoder, &jobs, &screen);
        if !extra.is_empty() {
            ctx.queue.submit(extra);
        }
        {
            let pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("firstshot.viewer.overlay"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
                })],
                ..Default::default()
            });
            self.egui_renderer.render(&mut pass.forget_lifetime(), &jobs, &screen);
        }
        for id in &output.textures_delta.free {
            self.egui_renderer.free_texture(id);
        }
    }
}

/// An 8-bit sRGB image, R, G, B per pixel, row by row: what the window showed.
pub struct Image8 {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Image8 {
    fn crop(&self, x: u32, y: u32, w: u32, h: u32) -> Image8 {
        let mut rgb = Vec::with_capacity((w * h * 3) as usize);
        for row in y..y + h {
            let start = ((row * self.width + x) * 3) as usize;
            rgb.extend_from_slice(&self.rgb[start..start + (w * 3) as usize]);
        }
        Image8 { width: w, height: h, rgb }
    }

    pub fn write_png(&self, path: &std::path::Path) -> Result<(), Error> {
        let mut bytes = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut bytes, self.width, self.height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            let err = |e: png::EncodingError| Error::Image { path: path.to_path_buf(), message: e.to_string() };
            let mut writer = encoder.write_header().map_err(err)?;
            writer.write_image_data(&self.rgb).map_err(err)?;
        }
        firstshot::files::write_atomically(path, &bytes)
    }
}

/// A copy of a drawn texture into a buffer, to map once the frame is submitted.
struct Readback {
    buffer: wgpu::Buffer,
    width: u32,
    height: u32,
    bytes_per_row: u32,
}

impl Readback {
    fn record(ctx: &Context, encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture) -> Readback {
        let (width, height) = (texture.width(), texture.height());
        let bytes_per_row = (4 * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("firstshot.viewer.screenshot"),
            size: bytes_per_row as u64 * height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(bytes_per_row),
                    rows_per_image: None,
                },
            },
            texture.size(),
        );
        Readback { buffer, width, height, bytes_per_row }
    }

    fn read(self, ctx: &Context, format: wgpu::TextureFormat) -> Result<Image8, Error> {
        let slice = self.buffer.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        ctx.wait()?;
        let data = slice.get_mapped_range().map_err(|e| Error::Gpu(format!("reading back the window's image: {e}")))?;
        let bgra = matches!(format, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb);
        let mut rgb = Vec::with_capacity((self.width * self.height * 3) as usize);
        for row in data.chunks_exact(self.bytes_per_row as usize) {
            for p in row[..(4 * self.width) as usize].chunks_exact(4) {
                rgb.extend_from_slice(&if bgra { [p[2], p[1], p[0]] } else { [p[0], p[1], p[2]] });
            }
        }
        Ok(Image8 { width: self.width, height: self.height, rgb })
    }
}
