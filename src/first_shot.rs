//! Incoming first shot (docs/ALGORITHM.md 1): item buffers around every light sample, reduced on
//! the GPU into the scalar factors r_ij, stored by patch in `SceneBuffers::first_shot`.

use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{Context, buffers};
use crate::layout::{FIXED_POINT_SCALE, GpuAppendParams, GpuFaceParams};
use crate::scene::{LightSample, Patches, SampleKind};
use crate::stages::camera_item_buffer::{CameraItemBuffer, View};
use crate::stages::first_shot_reduce::FirstShotReduce;
use crate::stages::first_shot_table;
use crate::{Error, Result};
use glam::DVec3;
use serde::Serialize;
use std::time::Instant;

/// The window of faces around an area-light sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LightWindow {
    /// One full and four half cube faces above the light (the paper's hemicube).
    Hemicube,
    /// Three faces of a cube whose corner points along the light's normal (cubic
    /// tetrahedron): fewer passes, larger pixels at the same resolution.
    Tetrahedron,
}

impl std::str::FromStr for LightWindow {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "hemicube" => Ok(LightWindow::Hemicube),
            "tetrahedron" => Ok(LightWindow::Tetrahedron),
            _ => Err(format!("expected hemicube or tetrahedron, got {s:?}")),
        }
    }
}

/// What the first shot did.
#[derive(Debug, Clone, Serialize)]
pub struct FirstShotStats {
    pub samples: usize,
    pub faces: usize,
    /// Stored (patch, sample) pairs: those that see each other.
    pub pairs: u32,
    pub resolution: u32,
    pub window: LightWindow,
    pub ms: f64,
}

/// One face to render: its view, the rows that lie in the window.
pub(crate) struct Face {
    pub view: View,
    pub rows: u32,
}

fn orthonormal_frame(n: DVec3) -> (DVec3, DVec3) {
    let t1 = n.any_orthonormal_vector();
    (t1, n.cross(t1))
}

/// The faces around `sample` at `resolution` pixels per face edge, and the solid angle
/// of a face's centre pixel (the same for all of them); for a directional light, its one
/// parallel view of the scene's bounding sphere `bounds` (centre, radius), and the area of
/// one of its pixels.
pub(crate) fn faces(
    sample: &LightSample,
    window: LightWindow,
    resolution: u32,
    near: f64,
    bounds: (DVec3, f64),
) -> (Vec<Face>, f64) {
    let view = |forward: DVec3, up: DVec3, tan: f64, centre: [f64; 2]| View {
        eye: sample.position,
        forward,
        up_hint: up,
        tan: [tan, tan],
        window_centre: centre,
        size: [resolution, resolution],
        near,
        orthographic: false,
    };
    let full = |view: View| Face { view, rows: resolution };
    let cube_pixel = 4.0 / (resolution as f64 * resolution as f64);
    match sample.kind {
        // A spot light sees through the whole cube, its pixels weighted by the cone's falloff
        // (zero outside the outer cone): simpler than picking the faces the cone touches,
        // and as exact.
        SampleKind::Point | SampleKind::Spot { .. } => {
            let axes = [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y, DVec3::Z, -DVec3::Z];
            let faces = axes
                .iter()
                .map(|&a| full(view(a, if a.y.abs() > 0.5 { DVec3::Z } else { DVec3::Y }, 1.0, [0.0, 0.0])))
                .collect();
            (faces, cube_pixel)
        }
        SampleKind::Directional { direction } => {
            // From the plane through the point 2 radii behind the centre, across the whole
            // bounding sphere: every surface lies at depths between 1 and 3 radii, inside the
            // linear depth's far distance of 4 radii.
            let (centre, radius) = bounds;
            let (up, _) = orthonormal_frame(direction);
            let face = View {
                eye: centre - 2.0 * radius * direction,
                forward: direction,
                up_hint: up,
                tan: [radius, radius],
                window_centre: [0.0, 0.0],
                size: [resolution, resolution],
                near: 4.0 * radius,
                orthographic: true,
            };
            let pixel = (2.0 * radius / resolution as f64).powi(2);
            (vec![full(face)], pixel)
        }
        SampleKind::AreaVertex { normal: n } => {
            let (t1, t2) = orthonormal_frame(n);
            match window {
                LightWindow::Hemicube => {
                    let mut faces = vec![full(view(n, t1, 1.0, [0.0, 0.0]))];
                    // Side faces with the light's normal as their up: the top half of
                    // each lies above the light's plane.
                    for side in [t1, -t1, t2, -t2] {
                        faces.push(Face { view: view(side, n, 1.0, [0.0, 0.0]), rows: resolution.div_ceil(2) });
                    }
                    (faces, cube_pixel)
                }
                LightWindow::Tetrahedron => {
                    // Three orthonormal axes e_k with n = (e_1 + e_2 + e_3) / sqrt(3). The
                    // face x_k = 1 is hit first where x_k is the largest coordinate; with
                    // n . u > 0 that is the triangle x_j, x_l <= 1, x_j + x_l > -1, inside
                    // the square [-2, 1]^2: a window of half extent 1.5 centred at -0.5.
                    let e: Vec<DVec3> = (0..3)
                        .map(|k| {
                            let a = 2.0 * std::f64::consts::PI * k as f64 / 3.0;
                            n / 3f64.sqrt() + (2.0f64 / 3.0).sqrt() * (a.cos() * t1 + a.sin() * t2)
                        })
                        .collect();
                    let faces = (0..3)
                        .map(|k| {
                            let (forward, a, b) = (e[k], e[(k + 1) % 3], e[(k + 2) % 3]);
                            let right = forward.cross(b).normalize();
                            let up = right.cross(forward);
                            let centre = forward - 0.5 * (a + b);
                            full(view(forward, b, 1.5, [centre.dot(right), centre.dot(up)]))
                        })
                        .collect();
                    let pixel = 9.0 / (resolution as f64 * resolution as f64);
                    (faces, pixel)
                }
            }
        }
    }
}

/// Runs the first shot and stores its table in `buffers.first_shot`.
pub fn run(
    ctx: &Context,
    buffers: &mut SceneBuffers,
    patches: &Patches,
    resolution: u32,
    window: LightWindow,
) -> Result<FirstShotStats> {
    let start = Instant::now();
    let device = &ctx.device;
    // The resolution was checked against the device by `render::check_limits`.
    let limits = ctx.limits();
    let n = buffers.patch_count as u64;
    let samples = patches.samples.len() as u64;
    let max_pairs = crate::memory::max_pairs(&limits, buffers.page_bytes);
    // Every pair fits when each patch sees every sample; start there when that is small,
    // else grow on overflow below.
    let mut capacity = crate::memory::initial_pair_capacity(&limits, buffers.page_bytes, n, samples) as u32;
    let near = buffers.radius * crate::stages::camera_item_buffer::NEAR_OF_RADIUS;
    let item_buffer = CameraItemBuffer::new(device, resolution, resolution, 1, None);
    loop {
        let reduce = FirstShotReduce::new(device, buffers, &item_buffer, capacity);
        let mut face_count = 0;
        for (i, sample) in patches.samples.iter().enumerate() {
            let (faces, pixel) = faces(sample, window, resolution, near, (buffers.centre, buffers.radius));
            for face in &faces {
                let view = face.view.gpu([0.5, 0.5]);
                ctx.queue.write_buffer(&item_buffer.camera, 0, bytemuck::bytes_of(&view));
                let params =
                    GpuFaceParams { sample: i as u32, patch_count: buffers.patch_count, rows: face.rows, _pad: 0 };
                ctx.queue.write_buffer(&reduce.face_params, 0, bytemuck::bytes_of(&params));
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("firstshot.first_shot.face"),
                });
                item_buffer.record_rows(&mut encoder, &buffers.raster, face.rows, &view);
                reduce.record_face(&mut encoder, face.rows);
                ctx.queue.submit([encoder.finish()]);
                face_count += 1;
            }
            let factor = pixel
                * match sample.kind {
                    SampleKind::Point => 1.0 / (4.0 * std::f64::consts::PI),
                    SampleKind::AreaVertex { .. } => sample.weight,
                    // S_i is the intensity: r_ij = (sum of falloff dOmega_p) / A_j.
                    SampleKind::Spot { .. } => 1.0,
                    // S_i is the irradiance: r_ij = (area of the pixels that see j) / A_j,
                    // i.e. cos(theta) times the share of the patch in the light.
                    SampleKind::Directional { .. } => 1.0,
                }
                / FIXED_POINT_SCALE as f64;
            let append = GpuAppendParams {
                sample: i as u32,
                patch_count: buffers.patch_count,
                capacity,
                _pad0: 0,
                factor: factor as f32,
                _pad1: [0; 3],
            };
            ctx.queue.write_buffer(&reduce.append_params, 0, bytemuck::bytes_of(&append));
            let mut encoder = device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.first_shot.append") });
            reduce.record_append(&mut encoder);
            ctx.queue.submit([encoder.finish()]);
        }
        let total = buffers::read_back::<u32>(device, &ctx.queue, &reduce.pair_count, 4)?[0];
        if total > capacity {
            if total as u64 > max_pairs {
                return Err(Error::Limits(format!(
                    "the first shot found {total} (patch, light sample) pairs, more than this device holds ({max_pairs}: {} pages of 16-byte pairs, and their table entries of 8 bytes in one binding); use a smaller --hemicube-resolution, a larger --patch-size or fewer light subdivisions",
                    crate::gpu::scene_buffers::FIRST_SHOT_PAIRS.pages
                )));
            }
            // The list was too short: pairs past its end were counted, not stored. Run
            // again with room for all of them.
            capacity = total;
            continue;
        }
        let mut encoder = device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.first_shot.table") });
        let (table, _temporaries, _scan) =
            first_shot_table::build(device, &mut encoder, buffers, &reduce.pairs, total, &reduce.row_counts);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        buffers.first_shot = table;
        return Ok(FirstShotStats {
            samples: patches.samples.len(),
            faces: face_count,
            pairs: total,
            resolution,
            window,
            ms: start.elapsed().as_secs_f64() * 1e3,
        });
    }
}

/// The table read back: for every patch, its (sample, r_ij) pairs. For tests and tools.
pub fn read_table(ctx: &Context, buffers: &SceneBuffers) -> Result<Vec<Vec<(u32, f32)>>> {
    let n = buffers.patch_count as usize;
    let offsets: Vec<u32> =
        buffers::read_back(&ctx.device, &ctx.queue, &buffers.first_shot.offsets, 4 * (n as u64 + 1))?;
    let count = buffers.first_shot.entry_count as u64;
    let entries: Vec<[u32; 2]> = if count == 0 {
        vec![]
    } else {
        buffers::read_back(&ctx.device, &ctx.queue, &buffers.first_shot.entries, 8 * count)?
    };
    Ok((0..n)
        .map(|j| {
            entries[offsets[j] as usize..offsets[j + 1] as usize].iter().map(|e| (e[0], f32::from_bits(e[1]))).collect()
        })
        .collect())
}

/// The automatic hemicube resolution makes a typical patch, seen from the light sample that
/// needs most pixels, this many pixels across (about two pixels of area). Why so few: the
/// first shot's factor r_ij is a sum over the pixels that see patch j, whose error falls as
/// the patch covers more of them, but it reaches the image only through the iteration (the
/// per-pixel direct light has its own windows, `direct_light`). Measured (docs/PERFORMANCE.md,
/// "Automatic hemicube resolution"): on the Sierpinski scene, whose glossy fractal reflects
/// its first shot into the image patch by patch, a median patch 0.74 pixels across made the
/// 50-step image error 19 % larger than at 1.48, and 2.96 made it 3 % smaller for 2.4 times
/// the first shot's time; on the Cornell boxes 2.4 pixels gave the error of 9.8 to 0.5 %.
pub const PIXELS_PER_PATCH: f64 = 1.5;
/// The automatic hemicube resolution's bounds (a multiple of 16 between them).
pub const AUTO_RESOLUTION_MIN: u32 = 64;
pub const AUTO_RESOLUTION_MAX: u32 = 1024;
/// At most this many light samples, evenly spread, are looked at.
const AUTO_SAMPLES: usize = 64;

/// The hemicube resolution when none is asked for (`--hemicube-resolution`, `[settings]
/// hemicube_resolution`): enough for the median patch, seen from the light sample that needs
/// most, to be `PIXELS_PER_PATCH` pixels across, a multiple of 16 within
/// [`AUTO_RESOLUTION_MIN`, `AUTO_RESOLUTION_MAX`].
///
/// A patch of area A at distance d, facing the sample, spans sqrt(A) / d of a face's tangent
/// plane, whose full edge of R pixels spans 2: R / (2 q) pixels with q = d / sqrt(A), so R =
/// 2 k q for k pixels. An area-light sample counts only the patches in front of it. A
/// directional light's parallel view spans the scene's bounding sphere (2 r) with
/// `direct_light::SUN_VIEW_SCALE` R pixels: sqrt(A) S R / (2 r) pixels, the same rule with
/// q = r / (S sqrt(A)).
pub fn auto_resolution(patches: &Patches) -> u32 {
    let step = patches.samples.len().div_ceil(AUTO_SAMPLES).max(1);
    let mut worst = 0.0f64;
    let mut suns = false;
    for sample in patches.samples.iter().step_by(step) {
        let q = match sample.kind {
            SampleKind::Directional { .. } => {
                suns = true;
                continue;
            }
            SampleKind::AreaVertex { normal } => patches.median_distance_ratio(sample.position, Some(normal)),
            SampleKind::Point | SampleKind::Spot { .. } => patches.median_distance_ratio(sample.position, None),
        };
        worst = worst.max(q.unwrap_or(0.0));
    }
    if suns {
        // Every sun's view spans the same sphere, whatever its direction. (The bounding
        // sphere is a pass over every patch: only a sun needs it.)
        let radius = crate::gpu::scene_buffers::bounding_sphere(patches).1;
        let scale = crate::direct_light::SUN_VIEW_SCALE as f64;
        let mut q: Vec<f64> = patches.median_sample().map(|p| radius / (scale * p.area.sqrt())).collect();
        worst = worst.max(crate::scene::tessellate::median(&mut q).unwrap_or(0.0));
    }
    face_side(worst, PIXELS_PER_PATCH, AUTO_RESOLUTION_MAX).clamp(AUTO_RESOLUTION_MIN, AUTO_RESOLUTION_MAX)
}

/// The face side, a multiple of 16, that shows a patch at q (`Patches::median_distance_ratio`)
/// `pixels_across` pixels across (R = 2 pixels_across q), before rounding at most `max`.
pub fn face_side(q: f64, pixels_across: f64, max: u32) -> u32 {
    let wanted = (2.0 * pixels_across * q).ceil().min(max as f64) as u32;
    wanted.div_ceil(16) * 16
}
