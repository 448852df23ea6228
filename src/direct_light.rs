//! Per-pixel direct light (docs/ALGORITHM.md 6): the first-shot lights as the image estimate sees
//! them, and the item buffers of their windows, which give each pixel its own visibility.
//!
//! A point light keeps its cube of six faces, rendered once, and so does a spot light (its
//! cone's falloff multiplies its light per pixel). A directional light keeps one parallel
//! view of the scene along its direction (an orthographic depth map of patch ids). An area light (or an emitting
//! shape, whose triangles may face different ways: the window is turned to the normal of
//! the triangle that holds the point) gets a new point y on it every pass, and its window (hemicube or cubic tetrahedron, as `--light-window`) is
//! rendered again there: pass k takes light triangle k mod T (of its T triangles, so every
//! T passes visit each once) and a point in it, which stands for T times that triangle's
//! area. The v-th visit of a triangle takes the v-th point of a low-discrepancy sequence (R2)
//! shifted by a random offset of that triangle (Cranley-Patterson rotation), so each point is
//! uniform in the triangle and the points of successive visits spread evenly over it. The
//! mean over passes is then the integral over the light, and penumbrae converge instead of
//! showing the hard shadows of a fixed grid.
//!
//! Memory stays bounded however many lights a scene has: all faces share two atlas textures
//! (the point lights' kept faces, the area lights' per-pass faces) of at most
//! `SHADOW_TEXEL_BUDGET` texels together; more lights get smaller faces.

use crate::first_shot::{self, LightWindow};
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{Context, buffers};
use crate::layout::{GpuDirectLight, GpuWindowFace, LIGHT_AREA, LIGHT_DIRECTIONAL, LIGHT_POINT, LIGHT_SPOT};
use crate::render::RenderOptions;
use crate::rng::StepRng;
use crate::scene::tessellate::median;
use crate::scene::{Light, LightSample, PatchKind, Patches, Rgb, SampleKind, Scene, SpotCone};
use crate::stages::light_window::WindowAtlas;
use glam::DVec3;

/// How the area lights and first-shot emitting shapes, whose point moves every pass, find each
/// pixel's visibility (`--light-visibility`): a shadow ray through the scene's BVH
/// (`shadow_bvh`, exact), or their windows rendered again at every pass (the paper's item
/// buffers, exact where an occluder covers a texel centre around the direction). Point, spot
/// and directional lights keep their windows either way: rendered once for the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LightVisibility {
    #[default]
    Rays,
    Windows,
}

impl std::str::FromStr for LightVisibility {
    type Err = String;

    /// `--light-visibility`'s value (the CLI and the harness).
    fn from_str(value: &str) -> Result<Self, String> {
        match value {
            "rays" => Ok(LightVisibility::Rays),
            "windows" => Ok(LightVisibility::Windows),
            _ => Err(format!("expected \"rays\" or \"windows\", got {value:?}")),
        }
    }
}

impl LightVisibility {
    pub fn name(self) -> &'static str {
        match self {
            LightVisibility::Rays => "rays",
            LightVisibility::Windows => "windows",
        }
    }
}

/// Whether a first-shot light of the scene takes a new point every pass: an area light or an
/// emitting shape, whose visibility `LightVisibility` chooses (the memory plan asks before any
/// GPU work, `DirectLights::new` when it builds the BVH).
pub fn has_moving_lights(scene: &Scene, patches: &Patches) -> bool {
    scene.lights.iter().any(|l| matches!(l, Light::Area { .. })) || !patches.emitters.is_empty()
}

/// Whether the scene has an environment (`[environment] radiance` not black), which the gather
/// then sees through each pixel's own ray where the BVH is built (SKY_RAYS in
/// `wgsl/image_estimate.wgsl`).
pub fn has_sky(scene: &Scene) -> bool {
    scene.environment.iter().any(|&c| c > 0.0)
}

/// Whether `--light-visibility rays` builds the scene's BVH: where the first shot runs and some
/// light moves its point (area lights, emitting shapes) or the gather asks whether a pixel
/// sees the environment (`has_sky`). The BVH may still not fit the device (`DirectLights::new`).
pub fn wants_shadow_bvh(scene: &Scene, patches: &Patches, first_shot: bool) -> bool {
    first_shot && (has_moving_lights(scene, patches) || has_sky(scene))
}

/// Texels of both atlases together at most (an id and a depth of 4 bytes each: 256 MiB).
pub const SHADOW_TEXEL_BUDGET: u64 = 1 << 25;
/// A directional light's parallel view has this many times the side of a cube face (16 times
/// its texels): its texel is the error of its shadows' outlines (docs/ALGORITHM.md 6), over
/// the whole scene.
pub const SUN_VIEW_SCALE: u32 = 4;
/// The smallest face side the budget may shrink faces to.
pub const MIN_SHADOW_RESOLUTION: u32 = 8;
/// The automatic shadow resolution (`auto_resolution`) makes a typical patch this many
/// texels across.
pub const TEXELS_PER_PATCH: f64 = 8.0;
/// The largest face side the automatic choice takes by itself (`--shadow-resolution` may ask
/// for more; the texel budget may give less).
pub const AUTO_RESOLUTION_MAX: u32 = 2048;

/// Generator streams of the triangles' shifts: (seed, SHIFT_STREAM - light), apart from the
/// steps' (seed, k) and the direct passes' (seed, u64::MAX - pass).
const SHIFT_STREAM: u64 = u64::MAX / 2;

/// The v-th point of the R2 sequence (Roberts 2018), shifted by `shift`, modulo 1.
fn r2_point(v: u64, shift: [f64; 2]) -> [f64; 2] {
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_3;
    let v = v as f64;
    [(shift[0] + v * A1).fract(), (shift[1] + v * A2).fract()]
}

/// Which atlas a face lives in (`WindowFace::tile.w`).
const KEPT: u32 = 0;
const PER_PASS: u32 = 1;

enum Source {
    Point {
        power: Rgb,
    },
    /// Its intensity on the axis, the unit axis and the cone.
    Spot {
        intensity: Rgb,
        axis: DVec3,
        cone: SpotCone,
    },
    /// A sun: its irradiance and the unit direction it travels.
    Directional {
        irradiance: Rgb,
        direction: DVec3,
    },
    /// An area light or an emitting shape (`Patches::emitters`).
    Area {
        radiance: Rgb,
        /// An emitting shape: its direct light is shared with the gather by multiple
        /// importance sampling (docs/ALGORITHM.md 6), so the table holds T A_t.
        shared: bool,
        /// The light's triangles (an area light's patches, an emitting shape's emitting
        /// triangle sides), their unit normals, areas and the random shifts of their
        /// low-discrepancy sequences.
        triangles: Vec<([DVec3; 3], DVec3, f64, [f64; 2])>,
    },
}

struct Planned {
    source: Source,
    /// Its entries in the face table.
    faces: std::ops::Range<usize>,
}

/// The direct-light table, the window faces and their atlases.
pub struct DirectLights {
    lights: Vec<Planned>,
    table: Vec<GpuDirectLight>,
    faces: Vec<GpuWindowFace>,
    lights_buffer: wgpu::Buffer,
    faces_buffer: wgpu::Buffer,
    kept: WindowAtlas,
    per_pass: WindowAtlas,
    window: LightWindow,
    /// Pixels along the edge of the largest face of a point's window, after the memory budget
    /// (a sun's view: `SUN_VIEW_SCALE` times as many).
    pub resolution: u32,
    /// Pixels along each face's edge, as `faces`.
    sides: Vec<u32>,
    /// The pass whose points the tables hold.
    prepared: Option<u64>,
    near: f64,
    /// The scene's bounding sphere (centre, radius), which a directional light's view covers.
    bounds: (DVec3, f64),
    /// What the area lights' visibility used: rays where asked and the BVH could be built
    /// within the device's limits, else windows.
    pub visibility: LightVisibility,
    /// The shadow rays' BVH (`shadow_bvh`): one zeroed entry each where unused.
    shadow_nodes: wgpu::Buffer,
    shadow_triangles: wgpu::Buffer,
    /// `ShadowBvh::frame` of the tree in `shadow_nodes` (none: the identity).
    shadow_frame: (glam::Vec3, f32),
    /// A word a patch (`unshadowed`): bit i where the patch sees all of light i past every
    /// occluder; one zeroed word where unused.
    unshadowed: wgpu::Buffer,
    /// Whether `unshadowed` holds the bits (the kernel reads them: SHADOW_SHAFTS).
    pub shafts: bool,
    /// Whether the gather asks each pixel's own ray for the environment (SKY_RAYS): the scene
    /// has one (`has_sky`) and the BVH was built.
    pub sky_rays: bool,
    /// The search for the bits, until `take_shaft_job` hands it to a thread.
    shaft_job: Option<ShaftJob>,
    /// What the search found: patches with some bit, and its milliseconds.
    pub shaft_stats: Option<(u64, f64)>,
}

/// The face side asked of the lights' windows: `options.shadow_resolution`, else
/// `auto_resolution` with the first shot's `hemicube_resolution` (the one in use,
/// `RenderOptions::hemicube_resolution_for`) as its floor (before the atlas budget, which
/// may halve it). The caller resolves the hemicube resolution once: its automatic choice
/// is a median over the patches for every light sample.
pub fn shadow_resolution(scene: &Scene, patches: &Patches, options: &RenderOptions, hemicube_resolution: u32) -> u32 {
    options.shadow_resolution.unwrap_or_else(|| auto_resolution(scene, patches, hemicube_resolution))
}

/// The face side of the per-pixel direct light's windows when none is asked for: at least
/// `floor` (the hemicube resolution), and enough for a typical patch, seen from the light
/// that needs it most, to be `TEXELS_PER_PATCH` texels across.
///
/// Why: a window texel tells which patch is seen through its centre, and V(y, x) tests the
/// segment from y to x against the patches of the 2 x 2 texels around x's direction
/// (docs/ALGORITHM.md 6). An occluding patch that covers none of those four centres is
/// missed, so light leaks through a band up to a texel wide inside the outline of every
/// occluding patch (between the patches of one smooth, finely tessellated occluder too,
/// until `blocks` in wgsl/image_estimate.wgsl went on past their smooth edges):
/// the share of an occluder's shadow that leaks is about (texel size) / (patch size). Every
/// patch may occlude, so the typical patch is the median over all of them (by count): with
/// patch j of area A_j at distance d_j from the light, a texel of a face of side R spans
/// 2 / R radians at the face centre and the patch sqrt(A_j) / d_j, so it is R / (2 q_j)
/// texels across, q_j = d_j / sqrt(A_j), and R = 2 TEXELS_PER_PATCH median(q_j), rounded up
/// to a multiple of 16 and at most `AUTO_RESOLUTION_MAX`. Directional lights are left out
/// (their view tests planes, not triangles: docs/ALGORITHM.md 6). An emitting shape counts
/// from up to eight of its triangles' centres, and at most 65 536 patches (every k-th)
/// count per point: the cost is patches times points.
///
/// Measured on the Sierpinski scene (16 384 fractal triangles of edge 0.031 seen from
/// 2.5-4 m: median q 170, so 2048), the direct light's error against Mitsuba 3 is 8.7 % at
/// 512, 2.8 % at 1024 and 1.3 % at 2048; the Cornell boxes (median q 21-24) get 464 and 416,
/// which still leak a little light into the umbra beside the tall block, most likely where the
/// light sees a face nearly edge-on (docs/PERFORMANCE.md, "Where the error stops falling").
pub fn auto_resolution(scene: &Scene, patches: &Patches, floor: u32) -> u32 {
    let mut points: Vec<DVec3> = Vec::new();
    for light in &scene.lights {
        match *light {
            Light::Point { position, .. } | Light::Spot { position, .. } => points.push(position),
            Light::Area { vertices, .. } => points.push(vertices.iter().sum::<DVec3>() / 4.0),
            Light::Directional { .. } => {}
        }
    }
    for emitter in &patches.emitters {
        let step = emitter.triangles.len().div_ceil(8).max(1);
        for t in emitter.triangles.iter().step_by(step) {
            points.push(t.vertices.iter().sum::<DVec3>() / 3.0);
        }
    }
    let worst = points.into_iter().filter_map(|y| patches.median_distance_ratio(y, None)).fold(0.0, f64::max);
    side_for(worst, floor)
}

/// The face side that makes a patch of median q `TEXELS_PER_PATCH` texels across: a
/// multiple of 16, at least `floor`, at most `AUTO_RESOLUTION_MAX` unless `floor` is more.
fn side_for(median_q: f64, floor: u32) -> u32 {
    floor.max(first_shot::face_side(median_q, TEXELS_PER_PATCH, AUTO_RESOLUTION_MAX))
}

/// The side `auto_resolution`'s rule asks of each face of a window at `y` whose faces look
/// along `forwards` (one face per forward, as `first_shot::faces` orders them), from the
/// patches that face sees: each patch counts for the face whose forward is nearest its
/// direction from y (the face `visible` in `wgsl/image_estimate.wgsl` looks it up in), and
/// for an area light only the patches in front of it (`lit`, its normal). A face that sees
/// only large or distant patches (a hemicube's side faces on the walls, with the small
/// patches of an object below the light in its top face) then gets the fewer texels it
/// needs, and a window costs its texels (the Sierpinski scene's area-light window: 2048 on
/// top, 512 on the sides; its atlas 8.4 M texels instead of 21 M). At least `floor`, at most
/// `AUTO_RESOLUTION_MAX`; a face that sees no patch gets `floor`.
pub fn auto_face_sides(y: DVec3, forwards: &[DVec3], lit: Option<DVec3>, patches: &Patches, floor: u32) -> Vec<u32> {
    let mut q: Vec<Vec<f64>> = vec![Vec::new(); forwards.len()];
    for p in patches.median_sample() {
        let w = (p.vertices[0] + p.vertices[1] + p.vertices[2]) / 3.0 - y;
        if lit.is_some_and(|n| n.dot(w) <= 0.0) {
            continue;
        }
        let nearest = (0..forwards.len()).max_by(|&a, &b| forwards[a].dot(w).total_cmp(&forwards[b].dot(w)));
        if let Some(f) = nearest {
            q[f].push(w.length() / p.area.sqrt());
        }
    }
    q.into_iter().map(|mut q| median(&mut q).map_or(floor, |m| side_for(m, floor))).collect()
}

/// The faces of the window around `sample`, face k at `sides[k]` pixels per edge (the
/// orientation of each face does not depend on its side).
fn faces_at(
    sample: &LightSample,
    window: LightWindow,
    sides: &[u32],
    near: f64,
    bounds: (DVec3, f64),
) -> Vec<first_shot::Face> {
    sides
        .iter()
        .enumerate()
        .map(|(k, &side)| first_shot::faces(sample, window, side, near, bounds).0.swap_remove(k))
        .collect()
}

/// Places tiles of (side, rows) texels on shelves at most `width` wide; returns their
/// top-left corners and the atlas size.
fn pack(tiles: &[(u32, u32)], width: u32) -> (Vec<[u32; 2]>, [u32; 2]) {
    let (mut x, mut y, mut shelf, mut used) = (0u32, 0u32, 0u32, 0u32);
    let mut corners = Vec::with_capacity(tiles.len());
    for &(side, rows) in tiles {
        if x + side > width {
            (x, y, shelf) = (0, y + shelf, 0);
        }
        corners.push([x, y]);
        x += side;
        used = used.max(x);
        shelf = shelf.max(rows);
    }
    (corners, [used, y + shelf])
}

/// A uniform point of the triangle from two uniform numbers.
fn point_in_triangle([a, b, c]: [DVec3; 3], u1: f64, u2: f64) -> DVec3 {
    let r = u1.sqrt();
    (1.0 - r) * a + r * (1.0 - u2) * b + r * u2 * c
}

/// The normal a source's window is turned to: an area light's (its first triangle's), else
/// none.
fn source_normal(source: &Source) -> DVec3 {
    match source {
        Source::Area { triangles, .. } => triangles[0].1,
        _ => DVec3::ZERO,
    }
}

/// A sample at `position` whose window is the source's: a cube for a point or spot light, a
/// window above `normal` (the normal of the triangle the point lies on) for an area source,
/// a parallel view for a directional light.
fn window_sample(source: &Source, position: DVec3, normal: DVec3) -> LightSample {
    let kind = match *source {
        Source::Point { .. } | Source::Spot { .. } => SampleKind::Point,
        Source::Area { .. } => SampleKind::AreaVertex { normal },
        Source::Directional { direction, .. } => SampleKind::Directional { direction },
    };
    LightSample { position, kind, strength: [0.0; 3], weight: 1.0, light: 0 }
}

impl DirectLights {
    /// The lights of `scene` that are first shot (none without `options.first_shot`), their
    /// windows (`options.light_window`) at `options.shadow_resolution` pixels per face edge
    /// (less if the budget or the device needs it), and the point lights' kept faces rendered.
    pub fn new(
        ctx: &Context,
        scene: &Scene,
        patches: &Patches,
        buffers: &SceneBuffers,
        options: &RenderOptions,
    ) -> Self {
        let (first_shot, window, seed) = (options.first_shot, options.light_window, options.seed);
        let hemicube_resolution = options.hemicube_resolution_for(patches);
        let resolution = shadow_resolution(scene, patches, options, hemicube_resolution);
        let mut sources = Vec::new();
        for (l, light) in scene.lights.iter().enumerate().filter(|_| first_shot) {
            match *light {
                Light::Point { position, power } => sources.push((Source::Point { power }, position)),
                Light::Spot { position, direction, intensity, inner_angle, outer_angle } => {
                    let cone = SpotCone::new(inner_angle, outer_angle);
                    sources.push((Source::Spot { intensity, axis: direction, cone }, position))
                }
                Light::Directional { direction, irradiance } => {
                    sources.push((Source::Directional { irradiance, direction }, DVec3::ZERO))
                }
                Light::Area { vertices, radiance, .. } => {
                    let own: Vec<_> =
                        patches.patches.iter().filter(|p| p.kind == PatchKind::AreaLight { light: l as u32 }).collect();
                    if own.is_empty() {
                        continue;
                    }
                    let mut shifts = StepRng::new(seed, SHIFT_STREAM - l as u64);
                    let triangles = own
                        .iter()
                        .map(|p| (p.vertices, p.normal, p.area, [shifts.uniform(), shifts.uniform()]))
                        .collect();
                    let centre = vertices.iter().sum::<DVec3>() / 4.0;
                    sources.push((Source::Area { radiance, shared: false, triangles }, centre));
                }
            }
        }
        // Emitting shapes: their emitting triangle sides whole (not their patches: fewer
        // triangles, the same points), each pass a point on one of them.
        for (e, emitter) in patches.emitters.iter().enumerate().filter(|_| first_shot) {
            let mut shifts = StepRng::new(seed, SHIFT_STREAM - (scene.lights.len() + e) as u64);
            let triangles: Vec<_> = emitter
                .triangles
                .iter()
                .map(|t| (t.vertices, t.normal, t.area, [shifts.uniform(), shifts.uniform()]))
                .collect();
            let centre = triangles[0].0.iter().sum::<DVec3>() / 3.0;
            sources.push((Source::Area { radiance: emitter.radiance, shared: true, triangles }, centre));
        }
        let near = buffers.radius * crate::stages::camera_item_buffer::NEAR_OF_RADIUS;
        let bounds = (buffers.centre, buffers.radius);
        let max_side = ctx.limits().max_texture_dimension_2d;
        // Shadow rays where asked, where some light moves its point, and where the BVH fits
        // the device's bindings (else the windows, as `--stats` reports).
        let bvh = match options.light_visibility {
            LightVisibility::Rays if wants_shadow_bvh(scene, patches, first_shot) => {
                let binding = ctx.limits().max_storage_buffer_binding_size;
                crate::shadow_bvh::ShadowBvh::build(&crate::gpu::scene_buffers::raster_triangles(patches)).filter(|b| {
                    let fits = |len: usize, size: usize| (len * size) as u64 <= binding;
                    fits(b.nodes.len(), std::mem::size_of::<crate::layout::GpuBvhNode>())
                        && fits(b.triangles.len(), std::mem::size_of::<crate::layout::GpuBvhTriangle>())
                })
            }
            _ => None,
        };
        let rays = bvh.is_some();
        // Which patches see which area lights past every occluder (no shadow rays there):
        // found on a thread beside the first shot (`ShaftJob`), where the BVH is in use, the
        // scene is not too large for the host's search, a light can have a bit and the table
        // of a word a patch fits one binding.
        let binding = ctx.limits().max_storage_buffer_binding_size;
        let patch_count = patches.patches.len();
        let tolerance = 4.0 * f64::from(f32::EPSILON) * (buffers.centre.abs().max_element() + buffers.radius);
        // The lights' hulls are found only where the search runs (`shaft_lights`).
        let area_sources = sources.iter().take(SHAFT_LIGHTS).filter(|(s, _)| matches!(s, Source::Area { .. })).count();
        let pairs = patch_count as u64 * area_sources as u64;
        let pays =
            pairs <= SHAFT_MAX_PAIRS && patch_count as u64 * SHAFT_PIXELS_PER_PATCH <= options.view_pixels(scene);
        let wants_shafts =
            options.light_shafts.unwrap_or(pays) && patch_count as u64 * 4 <= binding && area_sources > 0;
        // The side each face asks for: `--shadow-resolution` for all, else the automatic rule
        // per face where a window keeps its orientation (point and spot lights, an area light:
        // `auto_face_sides`), the whole scene's rule for the rest (an emitting shape's window
        // turns with its triangles; a sun's one view gets SUN_VIEW_SCALE times it below).
        let wanted: Vec<Vec<u32>> = sources
            .iter()
            .map(|(source, position)| {
                let sample = window_sample(source, *position, source_normal(source));
                let forwards: Vec<DVec3> =
                    first_shot::faces(&sample, window, 16, near, bounds).0.iter().map(|f| f.view.forward).collect();
                let per_face = match source {
                    _ if options.shadow_resolution.is_some() => None,
                    Source::Point { .. } | Source::Spot { .. } => Some(None),
                    Source::Area { shared: false, triangles, .. } => Some(Some(triangles[0].1)),
                    Source::Area { shared: true, .. } | Source::Directional { .. } => None,
                };
                match per_face {
                    Some(lit) => auto_face_sides(*position, &forwards, lit, patches, hemicube_resolution),
                    None => vec![resolution; forwards.len()],
                }
            })
            .collect();
        // The face layout with every side halved `halvings` times: (source index, face,
        // atlas, side) for every face.
        let layout = |halvings: u32| -> Vec<(usize, first_shot::Face, u32, u32)> {
            sources
                .iter()
                .zip(&wanted)
                .enumerate()
                // With shadow rays the area lights have no windows.
                .filter(|(_, ((source, _), _))| !(rays && matches!(source, Source::Area { .. })))
                .flat_map(|(i, ((source, position), wanted))| {
                    let atlas = if matches!(source, Source::Area { .. }) { PER_PASS } else { KEPT };
                    // A sun's one view spans the whole scene where a cube face spans a quarter
                    // of a point's surroundings: it gets SUN_VIEW_SCALE times the side.
                    let scale = if matches!(source, Source::Directional { .. }) { SUN_VIEW_SCALE } else { 1 };
                    let sides: Vec<u32> = wanted
                        .iter()
                        .map(|&w| ((w >> halvings).clamp(MIN_SHADOW_RESOLUTION, max_side) * scale).min(max_side))
                        .collect();
                    let sample = window_sample(source, *position, source_normal(source));
                    faces_at(&sample, window, &sides, near, bounds)
                        .into_iter()
                        .zip(sides)
                        .map(move |(f, side)| (i, f, atlas, side))
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let mut halvings = 0;
        let (faces, corners, sizes) = loop {
            let faces = layout(halvings);
            let tiles = |atlas: u32| -> Vec<(u32, u32)> {
                faces.iter().filter(|f| f.2 == atlas).map(|f| (f.1.view.size[0], f.1.rows)).collect()
            };
            let (kept_corners, kept_size) = pack(&tiles(KEPT), max_side);
            let (pass_corners, pass_size) = pack(&tiles(PER_PASS), max_side);
            let texels = |s: [u32; 2]| s[0] as u64 * s[1] as u64;
            let fits = kept_size[1] <= max_side
                && pass_size[1] <= max_side
                && texels(kept_size) + texels(pass_size) <= SHADOW_TEXEL_BUDGET;
            let smallest = faces.iter().all(|f| f.3 <= MIN_SHADOW_RESOLUTION);
            if fits || smallest {
                break (faces, [kept_corners, pass_corners], [kept_size, pass_size]);
            }
            halvings += 1;
        };
        // The largest side of a point's window (a sun's view is SUN_VIEW_SCALE times it).
        let r = faces
            .iter()
            .map(|f| if matches!(sources[f.0].0, Source::Directional { .. }) { f.3 / SUN_VIEW_SCALE } else { f.3 })
            .max()
            .unwrap_or((resolution >> halvings).clamp(MIN_SHADOW_RESOLUTION, max_side));
        let sides: Vec<u32> = faces.iter().map(|f| f.3).collect();
        let mut next = [0usize; 2];
        let mut table_faces = Vec::with_capacity(faces.len());
        for (_, face, atlas, _) in &faces {
            let [x, y] = corners[*atlas as usize][next[*atlas as usize]];
            next[*atlas as usize] += 1;
            table_faces.push(GpuWindowFace { view: face.view.gpu([0.5, 0.5]), tile: [x, y, face.rows, *atlas] });
        }
        let mut lights = Vec::with_capacity(sources.len());
        let mut table = Vec::with_capacity(sources.len());
        for (i, (source, position)) in sources.into_iter().enumerate() {
            let first = faces.iter().position(|f| f.0 == i).unwrap_or(0);
            let count = faces.iter().filter(|f| f.0 == i).count();
            // A point or spot light's intensity, a sun's irradiance; an area light's point and
            // strength are set per pass.
            let v4 = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
            let (kind, strength, normal, cone) = match &source {
                Source::Point { power } => {
                    let k = 1.0 / (4.0 * std::f32::consts::PI);
                    (LIGHT_POINT, [power[0] * k, power[1] * k, power[2] * k, 0.0], [0.0; 4], [0.0; 4])
                }
                Source::Spot { intensity: c, axis, cone } => {
                    (LIGHT_SPOT, [c[0], c[1], c[2], 0.0], v4(*axis), [cone.scale as f32, cone.offset as f32, 0.0, 0.0])
                }
                Source::Directional { irradiance: c, direction } => {
                    (LIGHT_DIRECTIONAL, [c[0], c[1], c[2], 0.0], v4(*direction), [0.0; 4])
                }
                Source::Area { .. } => (LIGHT_AREA, [0.0; 4], [0.0; 4], [0.0; 4]),
            };
            let entry = GpuDirectLight {
                position: v4(position),
                normal,
                strength,
                cone,
                kind,
                first_face: first as u32,
                faces: count as u32,
                _pad: 0,
            };
            table.push(entry);
            lights.push(Planned { source, faces: first..first + count });
        }
        let device = &ctx.device;
        let usage = wgpu::BufferUsages::COPY_DST;
        let lights_buffer = buffers::storage_init(device, "firstshot.direct_light.lights", &non_empty(&table), usage);
        let faces_buffer =
            buffers::storage_init(device, "firstshot.direct_light.faces", &non_empty(&table_faces), usage);
        let kept = WindowAtlas::new(device, "kept", &faces_buffer, sizes[0]);
        let per_pass = WindowAtlas::new(device, "per_pass", &faces_buffer, sizes[1]);
        let none = wgpu::BufferUsages::empty();
        let nodes = bvh.as_ref().map_or(&[][..], |b| &b.nodes);
        let shadow_nodes =
            buffers::storage_init(device, "firstshot.direct_light.shadow_nodes", &non_empty(nodes), none);
        let shafts = wants_shafts && bvh.is_some();
        // Zeroed until the job's bits come (`set_unshadowed`): every pixel casts its rays then.
        let unshadowed = match shafts {
            true => buffers::storage_zeroed(device, "firstshot.direct_light.unshadowed", patch_count as u64 * 4, usage),
            false => buffers::storage_init(device, "firstshot.direct_light.unshadowed", &[0u32], none),
        };
        let triangles = bvh.as_ref().map_or(&[][..], |b| &b.triangles);
        let shadow_triangles =
            buffers::storage_init(device, "firstshot.direct_light.shadow_triangles", &non_empty(triangles), none);
        let mut out = DirectLights {
            lights,
            table,
            faces: table_faces,
            lights_buffer,
            faces_buffer,
            kept,
            per_pass,
            window,
            resolution: r,
            sides,
            prepared: None,
            near,
            bounds,
            visibility: if rays { LightVisibility::Rays } else { LightVisibility::Windows },
            shadow_nodes,
            shadow_triangles,
            shadow_frame: bvh.as_ref().map_or((glam::Vec3::ZERO, 1.0), |b| b.frame),
            unshadowed,
            shafts,
            sky_rays: rays && has_sky(scene),
            shaft_job: None,
            shaft_stats: None,
        };
        if shafts {
            out.shaft_job = bvh.map(|bvh| ShaftJob { bvh, lights: shaft_lights(&out.lights, tolerance), tolerance });
        }
        let kept_faces = out.faces_in(KEPT);
        if !kept_faces.is_empty() {
            let mut encoder = device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.direct_light.kept") });
            out.kept.record(&mut encoder, &buffers.raster, &kept_faces);
            ctx.queue.submit([encoder.finish()]);
        }
        out
    }

    fn faces_in(&self, atlas: u32) -> Vec<(u32, GpuWindowFace)> {
        self.faces.iter().enumerate().filter(|(_, f)| f.tile[3] == atlas).map(|(i, f)| (i as u32, *f)).collect()
    }

    /// Entries of the light table.
    pub fn count(&self) -> u32 {
        self.table.len() as u32
    }

    /// The `override` constants of image_estimate's `direct` entry point for this table: the
    /// kinds of light it holds (bit `1 << LIGHT_*`), the face counts of their windows (bit
    /// `1 << faces`) and the atlases their faces lie in (bit `1 << KEPT`, `1 << PER_PASS`),
    /// so that the kernel is compiled without the others' code. An empty table keeps the
    /// defaults (every kind): nothing is evaluated then. The BVH's frame is in
    /// `bvh_specialization`, which every pipeline of the kernel takes.
    pub fn specialization(&self) -> [(&'static str, f64); 5] {
        let bit = |n: u32| 1u32.checked_shl(n).unwrap_or(u32::MAX);
        let kinds = self.table.iter().fold(0u32, |bits, l| bits | bit(l.kind));
        let faces = self.table.iter().fold(0u32, |bits, l| bits | bit(l.faces));
        let atlases = self.faces.iter().fold(0u32, |bits, f| bits | bit(f.tile[3]));
        let rays = ("SHADOW_RAYS", f64::from(u8::from(self.visibility == LightVisibility::Rays)));
        let (kinds, faces, atlases) = match self.table.is_empty() {
            true => (u32::MAX as f64, u32::MAX as f64, 3.0),
            false => (kinds as f64, faces as f64, atlases as f64),
        };
        [
            ("LIGHT_KINDS", kinds),
            ("WINDOW_FACE_COUNTS", faces),
            ("ATLASES", atlases),
            rays,
            ("SHADOW_SHAFTS", f64::from(u8::from(self.shafts))),
        ]
    }

    /// The `override` constants of the BVH's walks in image_estimate, for every pipeline of it:
    /// the frame of the BVH's boxes (the direct light's shadow rays, the gathers' pixel rays),
    /// SKY_RAYS (`sky_rays`) and SKY_REACH, a length past which a ray from inside the boxes has
    /// left them (twice the frame's unit, the largest float where the frame degenerates).
    pub fn bvh_specialization(&self) -> [(&'static str, f64); 6] {
        let (centre, scale) = self.shadow_frame;
        let reach = (2.02 / f64::from(scale)).min(f64::from(f32::MAX));
        [
            ("SKY_RAYS", f64::from(u8::from(self.sky_rays))),
            ("SKY_REACH", reach),
            ("SHADOW_FRAME_X", f64::from(centre.x)),
            ("SHADOW_FRAME_Y", f64::from(centre.y)),
            ("SHADOW_FRAME_Z", f64::from(centre.z)),
            ("SHADOW_FRAME_SCALE", f64::from(scale)),
        ]
    }

    /// Whether a pass must render windows of its own (the scene has first-shot area lights).
    pub fn has_area_lights(&self) -> bool {
        self.lights.iter().any(|l| matches!(l.source, Source::Area { .. }))
    }

    pub fn shadow_nodes(&self) -> &wgpu::Buffer {
        &self.shadow_nodes
    }

    /// The search for `unshadowed`'s bits, to run on a thread while the device works (once:
    /// `None` after, and where there is none).
    pub fn take_shaft_job(&mut self) -> Option<ShaftJob> {
        self.shaft_job.take()
    }

    /// Writes `ShaftJob::run`'s bits (the queue orders them before any later pass).
    pub fn set_unshadowed(&mut self, queue: &wgpu::Queue, bits: &[u32], ms: f64) {
        assert!(self.shafts, "a table without the kernel's SHADOW_SHAFTS");
        queue.write_buffer(&self.unshadowed, 0, bytemuck::cast_slice(bits));
        self.shaft_stats = Some((bits.iter().filter(|&&b| b != 0).count() as u64, ms));
    }

    pub fn unshadowed(&self) -> &wgpu::Buffer {
        &self.unshadowed
    }

    pub fn shadow_triangles(&self) -> &wgpu::Buffer {
        &self.shadow_triangles
    }

    pub fn lights_buffer(&self) -> &wgpu::Buffer {
        &self.lights_buffer
    }

    pub fn faces_buffer(&self) -> &wgpu::Buffer {
        &self.faces_buffer
    }

    pub fn kept_atlas(&self) -> &wgpu::TextureView {
        self.kept.ids_view()
    }

    pub fn pass_atlas(&self) -> &wgpu::TextureView {
        self.per_pass.ids_view()
    }

    /// Texels of both atlases.
    pub fn atlas_texels(&self) -> u64 {
        [self.kept.size, self.per_pass.size].iter().map(|s| s[0] as u64 * s[1] as u64).sum()
    }

    /// Places pass `pass`'s point on every area light and writes the light and face tables
    /// for it, unless they already hold that pass. Returns whether the area lights' windows
    /// must be rendered again (`record_pass`).
    pub fn prepare_pass(&mut self, queue: &wgpu::Queue, pass: u64) -> bool {
        if !self.has_area_lights() || self.prepared == Some(pass) {
            return false;
        }
        self.prepared = Some(pass);
        for (planned, entry) in self.lights.iter().zip(self.table.iter_mut()) {
            let Source::Area { radiance, shared, triangles } = &planned.source else { continue };
            let count = triangles.len() as u64;
            let (vertices, normal, area, shift) = triangles[(pass % count.max(1)) as usize];
            let [u1, u2] = r2_point(pass / count.max(1), shift);
            let y = point_in_triangle(vertices, u1, u2);
            let weight = (area * count as f64) as f32;
            entry.position = [y.x as f32, y.y as f32, y.z as f32, 0.0];
            let pick_area = if *shared { weight } else { 0.0 };
            entry.normal = [normal.x as f32, normal.y as f32, normal.z as f32, pick_area];
            entry.strength = [radiance[0] * weight, radiance[1] * weight, radiance[2] * weight, 0.0];
            let sides = &self.sides[planned.faces.clone()];
            let faces =
                faces_at(&window_sample(&planned.source, y, normal), self.window, sides, self.near, self.bounds);
            for (slot, face) in self.faces[planned.faces.clone()].iter_mut().zip(faces) {
                slot.view = face.view.gpu([0.5, 0.5]);
            }
        }
        queue.write_buffer(&self.lights_buffer, 0, bytemuck::cast_slice(&self.table));
        queue.write_buffer(&self.faces_buffer, 0, bytemuck::cast_slice(&self.faces));
        true
    }

    /// Records the item buffers of this pass's area-light windows.
    pub fn record_pass(&self, encoder: &mut wgpu::CommandEncoder, buffers: &SceneBuffers) {
        let faces = self.faces_in(PER_PASS);
        if !faces.is_empty() {
            self.per_pass.record(encoder, &buffers.raster, &faces);
        }
    }
}

/// `items`, or one zeroed item: a storage binding cannot be empty.
fn non_empty<T: bytemuck::Pod + bytemuck::Zeroable>(items: &[T]) -> Vec<T> {
    if items.is_empty() { vec![T::zeroed()] } else { items.to_vec() }
}

/// Light-table entries past this many keep their shadow rays at every pixel: `unshadowed`
/// has a bit for each of the first 32.
pub const SHAFT_LIGHTS: usize = 32;

/// Past this many (patch, light) pairs the search is not run (every pixel keeps its shadow
/// rays): it costs about a microsecond a pair on one core of the 2-core machine here
/// (docs/PERFORMANCE.md, "Shadow rays left out where nothing can block them"), and the render
/// waits for it after the first shot.
pub const SHAFT_MAX_PAIRS: u64 = 1 << 20;

/// The search runs where the views have at least this many pixels a patch. It costs about
/// 1.5 us of host time a patch; a direct-light pass on lavapipe about 0.1 us a pixel whose
/// ray it leaves out, and a run makes 16 in front, then one every eighth step: so it pays
/// where the pixels are at least about twice the patches. (The engine room, 295 463 patches
/// at 480 x 360: the search took 0.4 s and 20 steps were no faster; the Sierpinski scene,
/// 22 420 at 512 x 512: 9 % less time for 20 steps.)
pub const SHAFT_PIXELS_PER_PATCH: u64 = 2;

/// The area sources that get bits: (light-table index, the corners of their hull).
fn shaft_lights(lights: &[Planned], tolerance: f64) -> Vec<(usize, Vec<DVec3>)> {
    lights
        .iter()
        .enumerate()
        .take(SHAFT_LIGHTS)
        .filter_map(|(i, light)| match &light.source {
            Source::Area { triangles, .. } => Some((i, light_corners(triangles.iter().map(|t| t.0), tolerance))),
            _ => None,
        })
        .collect()
}

/// The search for `DirectLights::unshadowed`'s bits, apart from the device: what
/// `ShaftJob::run` needs.
pub struct ShaftJob {
    bvh: crate::shadow_bvh::ShadowBvh,
    lights: Vec<(usize, Vec<DVec3>)>,
    tolerance: f64,
}

impl ShaftJob {
    /// For each patch, bit i where no triangle of the scene can cross a segment between area
    /// source i (an entry of the light table, i < SHAFT_LIGHTS) and the patch (`Shaft`,
    /// `ShaftTree::is_clear`): the direct light's kernel casts no shadow ray from that light
    /// to a point on that patch. Most of a room's walls see a light past every occluder;
    /// the patches near an occluder's shadow keep their rays.
    pub fn run(&self, patches: &Patches) -> Vec<u32> {
        use crate::shadow_bvh::{SHAFT_POINTS, Shaft};
        use rayon::prelude::*;
        let tree = self.bvh.shafts();
        let tolerance = self.tolerance;
        patches
            .patches
            .par_iter()
            .map(|patch| {
                let mut bits = 0u32;
                for (i, corners) in &self.lights {
                    // A patch that faces no point of the light gets no light from it: no bit
                    // (nor any ray: the kernel tests the cosines first).
                    if !corners.iter().any(|c| patch.normal.dot(*c - patch.vertices[0]) > tolerance) {
                        continue;
                    }
                    let mut points = [DVec3::ZERO; SHAFT_POINTS];
                    points[..corners.len()].copy_from_slice(corners);
                    points[corners.len()..corners.len() + 3].copy_from_slice(&patch.vertices);
                    if tree.is_clear(&Shaft::hull(&points[..corners.len() + 3], tolerance)) {
                        bits |= 1 << i;
                    }
                }
                bits
            })
            .collect()
    }
}

/// The points whose hull is a light's: the corners of its triangles, fewer where they lie
/// in one plane (the hull of the polygon in that plane: a subdivided quad's four corners; a
/// polygon of more than 12, the rectangle about it in its plane), else all of them up to 12,
/// else the corners of their box (a larger hull: fewer bits). Linear in the corners but for
/// the planar hull's sort: an emitting mesh may have many.
fn light_corners(triangles: impl Iterator<Item = [DVec3; 3]>, tolerance: f64) -> Vec<DVec3> {
    let all: Vec<DVec3> = triangles.flatten().collect();
    // The distinct corners, up to 13: past 12 their number no longer matters.
    let mut distinct: Vec<DVec3> = Vec::new();
    for &p in &all {
        if distinct.len() > 12 {
            break;
        }
        if !distinct.iter().any(|q| q.distance_squared(p) <= tolerance * tolerance) {
            distinct.push(p);
        }
    }
    if distinct.len() < 3 {
        return distinct;
    }
    // A plane through the first corner, the one farthest from it, and the one farthest from
    // the line of those two.
    let first = all[0];
    let far = all.iter().copied().max_by(|a, b| a.distance_squared(first).total_cmp(&b.distance_squared(first)));
    let far = far.unwrap_or(first);
    let normal = all
        .iter()
        .map(|p| (far - first).cross(*p - first))
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
        .unwrap_or(DVec3::ZERO);
    if normal.length_squared() > 0.0 {
        let n = normal.normalize();
        if all.iter().all(|p| n.dot(*p - first).abs() <= tolerance) {
            let hull = planar_hull(&all, n);
            if hull.len() <= 12 {
                return hull;
            }
            // A polygon of many corners (a disc): the rectangle about it in its plane.
            let (u, v) = n.any_orthonormal_pair();
            let (lo, hi) = hull.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                let q = DVec3::new(u.dot(*p), v.dot(*p), 0.0);
                (lo.min(q), hi.max(q))
            });
            let height = n.dot(first);
            return [(lo.x, lo.y), (hi.x, lo.y), (hi.x, hi.y), (lo.x, hi.y)]
                .map(|(a, b)| a * u + b * v + height * n)
                .to_vec();
        }
    }
    if distinct.len() <= 12 {
        return distinct;
    }
    let (lo, hi) = all.iter().fold((first, first), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    let mut corners: Vec<DVec3> = Vec::new();
    for k in 0..8 {
        let c = DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        if !corners.contains(&c) {
            corners.push(c);
        }
    }
    corners
}

/// The corners of the convex hull of `points`, which lie in a plane of normal `n` (Andrew's
/// monotone chain in the plane's coordinates).
fn planar_hull(points: &[DVec3], n: DVec3) -> Vec<DVec3> {
    let (u, v) = n.any_orthonormal_pair();
    let mut flat: Vec<(f64, f64, DVec3)> = points.iter().map(|p| (u.dot(*p), v.dot(*p), *p)).collect();
    flat.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let turn = |o: &(f64, f64, DVec3), a: &(f64, f64, DVec3), b: &(f64, f64, DVec3)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut hull: Vec<(f64, f64, DVec3)> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let sequence: Box<dyn Iterator<Item = &(f64, f64, DVec3)>> =
            if pass == 0 { Box::new(flat.iter()) } else { Box::new(flat.iter().rev()) };
        for p in sequence {
            while hull.len() >= start + 2 && turn(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0 {
                hull.pop();
            }
            hull.push(*p);
        }
        hull.pop();
    }
    hull.into_iter().map(|(_, _, p)| p).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn d(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    /// Whether `corners` has a point within 1e-9 of `p`.
    fn has(corners: &[DVec3], p: DVec3) -> bool {
        corners.iter().any(|c| c.distance(p) < 1e-9)
    }

    #[test]
    fn test01_a_lights_hull_keeps_its_outline() {
        // A quad light cut 2 x 2 (8 triangles, 9 corners, as the tessellation makes it): its
        // four outer corners alone.
        let at = |i: usize, k: usize| d(-0.4 + 0.4 * i as f64, 3.98, 0.4 * k as f64);
        let mut quad = Vec::new();
        for i in 0..2 {
            for k in 0..2 {
                quad.push([at(i, k), at(i + 1, k), at(i + 1, k + 1)]);
                quad.push([at(i, k), at(i + 1, k + 1), at(i, k + 1)]);
            }
        }
        let corners = light_corners(quad.into_iter(), 1e-9);
        assert_eq!(corners.len(), 4, "{corners:?}");
        for p in [at(0, 0), at(2, 0), at(2, 2), at(0, 2)] {
            assert!(has(&corners, p), "{p} missing from {corners:?}");
        }
        // A disc of 64 fan triangles in a tilted plane: the rectangle about it, in its plane,
        // holding every rim point.
        let (u, v) = (d(1.0, 1.0, 0.0).normalize(), d(0.0, 0.0, 1.0));
        let rim = |k: usize| {
            let a = std::f64::consts::TAU * k as f64 / 64.0;
            d(5.0, 1.0, 2.0) + a.cos() * u + a.sin() * v
        };
        let centre = d(5.0, 1.0, 2.0);
        let corners = light_corners((0..64).map(|k| [centre, rim(k), rim(k + 1)]), 1e-9);
        assert_eq!(corners.len(), 4, "{corners:?}");
        let n = u.cross(v);
        for c in &corners {
            assert!(n.dot(*c - centre).abs() < 1e-9, "{c} off the disc's plane");
        }
        let (cu, cv) = (corners.iter().map(|c| u.dot(*c - centre)), corners.iter().map(|c| v.dot(*c - centre)));
        let (lo_u, hi_u) = cu.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(x), h.max(x)));
        let (lo_v, hi_v) = cv.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(x), h.max(x)));
        for k in 0..64 {
            let (a, b) = (u.dot(rim(k) - centre), v.dot(rim(k) - centre));
            assert!(a >= lo_u - 1e-9 && a <= hi_u + 1e-9 && b >= lo_v - 1e-9 && b <= hi_v + 1e-9, "rim {k} outside");
        }
        // A closed box of 12 triangles (8 corners, not in one plane): its corners; an
        // emitting sphere of many: the 8 corners of its box.
        let cube = |k: usize| d((k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64);
        let faces = [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ];
        let corners = light_corners(faces.iter().map(|f| f.map(cube)), 1e-9);
        assert_eq!(corners.len(), 8);
        assert!((0..8).all(|k| has(&corners, cube(k))));
        let point = |i: usize, j: usize| {
            let (t, p) = (std::f64::consts::PI * i as f64 / 16.0, std::f64::consts::TAU * j as f64 / 32.0);
            d(t.sin() * p.cos(), t.cos(), t.sin() * p.sin())
        };
        let sphere = (0..16).flat_map(|i| (0..32).map(move |j| [point(i, j), point(i + 1, j), point(i + 1, j + 1)]));
        let corners = light_corners(sphere, 1e-9);
        assert_eq!(corners.len(), 8, "{corners:?}");
        assert!(corners.iter().all(|c| (c.abs() - DVec3::ONE).abs().max_element() < 1e-9), "{corners:?}");
    }
}
