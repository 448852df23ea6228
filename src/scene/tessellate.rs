//! Surfaces -> patches; lights -> light samples (docs/ALGORITHM.md section 1).
//!
//! A surface triangle is first cut along the lines where other surfaces stand on it or
//! pass through it (`contact.rs`: no patch reaches under a box on the floor). Each triangle
//! or piece is then cut into k^2 congruent copies of itself scaled by 1/k, so every patch of
//! it has the same area and the source's normal, and the areas add up to the source's
//! without a gap. An area light is meshed on its own n x n grid, whatever the
//! patch size: its vertices are the first shot's samples, and the trapezoid weights need
//! exactly that grid.
//!
//! A shape with `emission` is a first-shot light too (docs/ALGORITHM.md 1, "Emitting
//! shapes"): every emitting side of its triangles gets a triangular grid of light samples
//! of its own (`emitter_grid` says how fine), up to `MAX_EMITTER_SAMPLES` for the scene.

use super::contact::{Contacts, PARALLEL_COS, Pieces, contacts};
use super::{Light, Rgb, Scene, SpotCone, Triangle};
use crate::{Error, Result};
use glam::DVec3;
use std::collections::HashMap;

/// The first-shot samples that emitting shapes share out by power: a triangle side that
/// emits a share s of all the shapes' emitted power gets a grid of at most about s times
/// this many samples (and never fewer than one).
pub const EMITTER_SAMPLE_SHARE: f64 = 64.0;

/// The most first-shot samples on emitting shapes. The
/// strongest triangle sides come first; those past the cap emit inside the iteration, as
/// with `--no-first-shot`, and `Patches::notes` says how many and how much power.
pub const MAX_EMITTER_SAMPLES: u64 = 4096;

/// The most patches a tessellation may produce (33 million). The count is checked before the
/// patches are made, the memory prediction (`--memory-limit`) only after: each patch costs
/// about 420 bytes on the host and 500 on the GPU (32.7 M patches took 13.6 GB and 16.3 GB
/// on an H200, docs/PERFORMANCE.md "Scaling on the GPU"), so past this a tessellation could
/// outgrow the host before the prediction refuses it. The GPU layout allows 4 times more
/// (`layout::MAX_PATCHES`); larger scenes are split into shards (docs/DISTRIBUTED.md).
pub const MAX_PATCHES: u64 = 1 << 25;

/// What a patch is part of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PatchKind {
    /// A triangle of a `[[shapes]]` entry.
    Surface { surface: u32 },
    /// A triangle of an area light's n x n grid: it emits `radiance` on its front, reflects
    /// nothing (black material) and occludes like any surface.
    AreaLight { light: u32 },
    /// A triangle of an emitting `[[shapes]]` entry whose emission is a first-shot light:
    /// `Patches::emitters[emitter]`. It reflects with its material like any surface patch;
    /// with first shot its emission is left out of the iteration (its first reflection
    /// replaces it) and the camera sees it directly. `side`: its triangle side in
    /// `Emitter::triangles`.
    Emitter { surface: u32, emitter: u32, side: u32 },
}

/// One triangular patch: the unit of the finite-element radiance representation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    /// Counter-clockwise seen from the front.
    pub vertices: [DVec3; 3],
    /// Unit front normal, normalize((v1 - v0) x (v2 - v0)).
    pub normal: DVec3,
    /// Exact area of the triangle.
    pub area: f64,
    /// Index into `Scene::materials`; `None` for area-light patches (black).
    pub material: Option<u32>,
    /// Diffuse emitted radiance on the front side.
    pub emission: Rgb,
    pub kind: PatchKind,
    /// This patch has a back-to-back twin (a `two_sided` shape): where both are seen at the
    /// same depth, only the one whose front faces the viewer counts.
    pub twin: bool,
}

/// One light sample y_i of the first shot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    pub position: DVec3,
    pub kind: SampleKind,
    /// S_i: the power of a point light, the radiance of an area light, the intensity of a
    /// spot light on its axis, the irradiance of a directional light.
    pub strength: Rgb,
    /// w_i: for an area-light vertex, (area of the light triangles sharing it) / 3; 1 for a
    /// point light.
    pub weight: f64,
    /// The source: an index into `Scene::lights`, or for a sample on an emitting shape,
    /// `Scene::lights.len()` + its index in `Patches::emitters`.
    pub light: u32,
}

/// What a light sample is, which decides its window and its weight in the first shot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SampleKind {
    /// A point light: a full cube window, S_i = power.
    Point,
    /// A vertex of an area light's mesh (with the trapezoid weight) or the centre of a cell of
    /// an emitting triangle's grid (with the cell's area), and that surface's unit normal: a
    /// window above it, S_i = radiance, the weight in `LightSample::weight`.
    AreaVertex { normal: DVec3 },
    /// A spot light: a point light's full cube window whose pixels count with the cone's
    /// falloff (`SpotCone`) about the unit `axis`; S_i = its intensity on the axis (W/sr).
    Spot { axis: DVec3, cone: SpotCone },
    /// A directional light (sun) travelling along the unit `direction`: one parallel
    /// projection along it over the scene's bounding sphere; S_i = its irradiance. Its
    /// `LightSample::position` means nothing (the origin) and is left out of the bounds.
    Directional { direction: DVec3 },
}

/// The tessellated scene.
///
/// Order: the surfaces' patches in the order of `Scene::surfaces` and their triangles (a
/// twin right after its patch), then the area lights' patches in the order of
/// `Scene::lights`; the samples in the order of `Scene::lights`, an area light's row by row
/// from v0 (index j (n + 1) + i for the vertex i steps from v0 towards v1 and j towards v3),
/// then the emitters' samples in the order of `emitters`.
#[derive(Debug, Clone, Default)]
pub struct Patches {
    pub patches: Vec<Patch>,
    pub samples: Vec<LightSample>,
    /// The emitting shapes whose emission is first shot, one per shape (`PatchKind::Emitter`).
    pub emitters: Vec<Emitter>,
    /// One line each about what tessellation could not do as asked (emitters past the cap).
    pub notes: Vec<String>,
    /// The runs of patches that one piece of the surfaces (after the contact cuts) was split
    /// into, in order: the image's gather treats the patches of a piece as one surface
    /// (`Piece`). Empty for patches made by hand: every patch is then a piece of its own.
    pub pieces: Vec<Piece>,
    /// The source triangles (after the contact cuts) that `split_into` cut into a lattice of
    /// k x k patches, k > 1, in order. The rasterising stages draw each once per side instead
    /// of its k^2 patches (`scene_buffers::raster_triangles`); every other patch is drawn as
    /// itself.
    pub lattices: Vec<Lattice>,
}

/// A source triangle cut into the k x k lattice of `SourceTriangle::split_into`: its patches
/// are `first..first + sides k^2`, row j (from v0 towards v2) after row j - 1, along a row
/// the upright triangle at step i (from v0 towards v1) and then the inverted one beside it,
/// a two-sided surface's twins interleaved (`sides` = 2). So the patch under lattice
/// coordinates (x, y) = k (barycentric weights of v1, v2) is computable from (x, y) alone
/// (`lattice_patch` in `wgsl/common/layout.wgsl`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    pub first: u32,
    pub k: u32,
    pub sides: u32,
    /// The source triangle, in the winding of its front patches.
    pub vertices: [DVec3; 3],
}

/// The patches `first..end` that one piece of the surfaces was split into (a convex polygon
/// that the contact cuts leave of a source triangle, or consecutive whole source triangles
/// whose union is convex, `ConvexRun`): coplanar, facing the same way, and with no contact
/// line between them (the contact cuts and the touched edges bound the pieces), so
/// a ray leaving any of them towards its front sees what one leaving a point of another
/// right beside it sees. A two-sided surface's twins interleave (`sides` = 2): the piece's
/// front patches are `first, first + 2, ...`, its backs `first + 1, first + 3, ...`, each a
/// piece of its own for the gather.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Piece {
    pub first: u32,
    pub end: u32,
    pub sides: u32,
}

/// Whole source triangles (no contact cut them) of one surface and one plane, made one
/// `Piece` while their union is a convex polygon and no contact runs along the edges they
/// share (`Contacts::touched_edges`): then, like a convex polygon of the cuts, no contact line
/// lies between any two of their points, and the gather may take one's fragment for
/// another's. A quad's two triangles become one piece, so the pixels along its diagonal no
/// longer go to the gather's edge search.
struct ConvexRun {
    /// Its triangles' surface, and whether they are first-shot emitters or not.
    surface: (usize, std::mem::Discriminant<PatchKind>),
    normal: DVec3,
    /// The union's corners, counter-clockwise about `normal`.
    corners: Vec<DVec3>,
    /// Whether a contact runs along the edge from corner i to corner i + 1.
    touched: Vec<bool>,
}

impl ConvexRun {
    fn new(surface: (usize, std::mem::Discriminant<PatchKind>), t: &[DVec3; 3], touched: [bool; 3]) -> ConvexRun {
        let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        ConvexRun { surface, normal, corners: t.to_vec(), touched: touched.to_vec() }
    }

    /// Adds triangle `t` (edge i from vertex i to i + 1 touched by a contact where `touched`
    /// says so) if it lies in the run's plane, facing its way, shares an edge with the
    /// union's boundary that no contact runs along, and the union stays convex.
    fn join(&mut self, t: &[DVec3; 3], touched: [bool; 3]) -> bool {
        let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        if normal.dot(self.normal) < PARALLEL_COS {
            return false;
        }
        let n = self.corners.len();
        for i in 0..3 {
            let (a, b, c) = (t[i], t[(i + 1) % 3], t[(i + 2) % 3]);
            // Both wind counter-clockwise, so the shared edge runs b -> a along the union.
            let Some(k) = (0..n).find(|&k| self.corners[k] == b && self.corners[(k + 1) % n] == a) else {
                continue;
            };
            if touched[i] || self.touched[k] {
                return false;
            }
            let mut corners = self.corners.clone();
            corners.insert(k + 1, c);
            if !is_convex(&corners, self.normal) {
                return false;
            }
            self.corners = corners;
            self.touched.splice(k..=k, [touched[(i + 1) % 3], touched[(i + 2) % 3]]);
            return true;
        }
        false
    }
}

/// Whether the polygon (corners counter-clockwise about `normal`) turns left, or runs
/// straight on, at every corner.
fn is_convex(corners: &[DVec3], normal: DVec3) -> bool {
    let n = corners.len();
    (0..n).all(|i| {
        let (p, q, r) = (corners[i], corners[(i + 1) % n], corners[(i + 2) % n]);
        let (e, f) = (q - p, r - q);
        e.cross(f).dot(normal) >= -1e-9 * e.length() * f.length()
    })
}

/// An emitting shape as a first-shot light: the sides of its triangles that emit, each a
/// planar one-sided Lambertian emitter of the shape's radiance.
#[derive(Debug, Clone, PartialEq)]
pub struct Emitter {
    /// Index into `Scene::surfaces`.
    pub surface: u32,
    pub radiance: Rgb,
    pub triangles: Vec<EmitterTriangle>,
}

/// One emitting side of a source triangle (a two-sided shape's back is the triangle with its
/// winding reversed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmitterTriangle {
    /// Counter-clockwise seen from the emitting side.
    pub vertices: [DVec3; 3],
    pub normal: DVec3,
    pub area: f64,
    /// k: the side's sample grid cuts each edge into k (k^2 cells, a sample at each centre).
    pub grid: u32,
}

/// A summary for progress output and `--stats`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PatchStats {
    /// Patches of `[[shapes]]`, twins included.
    pub surface_patches: usize,
    /// Patches of area lights.
    pub light_patches: usize,
    pub samples: usize,
    /// Sum of the areas of all patches (a two-sided surface counts twice).
    pub total_area: f64,
}

/// Patches a median over them looks at, at most (every k-th of a larger scene).
const MEDIAN_SAMPLE: usize = 1 << 16;

impl Patches {
    /// A regular sample of the patches of positive area (every k-th, at most about
    /// `MEDIAN_SAMPLE`): all that the medians of the automatic resolutions need.
    pub fn median_sample(&self) -> impl Iterator<Item = &Patch> + Clone {
        let stride = self.patches.len().div_ceil(MEDIAN_SAMPLE).max(1);
        self.patches.iter().step_by(stride).filter(|p| p.area > 0.0)
    }

    /// The median over `median_sample` of q = |centre - y| / sqrt(area), of the patches in
    /// front of a surface at `y` with normal `facing` where one is given: a window face whose
    /// full edge of R pixels spans 2 tangent units shows a patch at q, facing y, R / (2 q)
    /// pixels across (the automatic hemicube and shadow-window resolutions).
    pub fn median_distance_ratio(&self, y: DVec3, facing: Option<DVec3>) -> Option<f64> {
        let mut q: Vec<f64> = self
            .median_sample()
            .filter_map(|p| {
                let w = (p.vertices[0] + p.vertices[1] + p.vertices[2]) / 3.0 - y;
                (!facing.is_some_and(|n| n.dot(w) <= 0.0)).then(|| w.length() / p.area.sqrt())
            })
            .collect();
        median(&mut q)
    }

    pub fn stats(&self) -> PatchStats {
        let light_patches = self.patches.iter().filter(|p| matches!(p.kind, PatchKind::AreaLight { .. })).count();
        PatchStats {
            surface_patches: self.patches.len() - light_patches,
            light_patches,
            samples: self.samples.len(),
            total_area: self.patches.iter().map(|p| p.area).sum(),
        }
    }
}

/// The median of `q` (reordered), none if it is empty.
pub fn median(q: &mut [f64]) -> Option<f64> {
    if q.is_empty() {
        return None;
    }
    let middle = q.len() / 2;
    Some(*q.select_nth_unstable_by(middle, f64::total_cmp).1)
}

/// Tessellates every surface into triangles whose longest edge is at most `patch_size`
/// (a two-sided surface into back-to-back pairs), and meshes every area light into its
/// n x n grid: 2 n^2 patches and (n+1)^2 samples with trapezoid weights.
///
/// `patch_size = +inf` (what `Settings::default` holds when a scene names none) keeps every
/// triangle whole. A patch size that is NaN or not > 0, and a result of more than
/// `MAX_PATCHES` patches (counted before anything is allocated), are refused.
pub fn tessellate(scene: &Scene, patch_size: f64) -> Result<Patches> {
    if patch_size.is_nan() || patch_size <= 0.0 {
        return Err(Error::Usage(format!("patch size must be a number > 0, got {patch_size}")));
    }

    // Checked first, so that a degenerate triangle is reported as such, not as a contact.
    for (s, surface) in scene.surfaces.iter().enumerate() {
        for (t, triangle) in surface.triangles.iter().enumerate() {
            SourceTriangle::new(scene, s, t, triangle)?;
        }
    }
    let Contacts { pieces, touched_edges } = contacts(scene);
    let (mut count, mut light_count) = (0u64, 0u64);
    for (s, surface) in scene.surfaces.iter().enumerate() {
        let copies = if surface.two_sided { 2 } else { 1 };
        for (t, triangle) in surface.triangles.iter().enumerate() {
            for source in SourceTriangle::pieces(scene, s, t, triangle, &pieces)?.iter().flatten() {
                let k = source.splits(patch_size);
                count = count.saturating_add(k.saturating_mul(k).saturating_mul(copies));
            }
        }
    }
    for (l, light) in scene.lights.iter().enumerate() {
        if let Light::Area { subdivisions, .. } = *light {
            if subdivisions == 0 {
                return Err(Error::scene(
                    &scene.source,
                    format!("lights[{l}].subdivisions"),
                    "expected an integer >= 1, got 0",
                ));
            }
            let n = u64::from(subdivisions);
            light_count = light_count.saturating_add(n.saturating_mul(n).saturating_mul(2));
        }
    }
    if light_count > MAX_PATCHES {
        return Err(Error::Usage(format!(
            "the area lights' subdivisions make {light_count} patches, more than the limit \
             of {MAX_PATCHES}"
        )));
    }
    let count = count.saturating_add(light_count);
    if count > MAX_PATCHES {
        let shown = if count == u64::MAX { "more than 10^19".to_string() } else { count.to_string() };
        return Err(Error::Usage(format!(
            "patch size {patch_size} would make {shown} patches, more than the limit of \
             {MAX_PATCHES}; choose a larger --patch-size"
        )));
    }
    let sample_count: usize = scene
        .lights
        .iter()
        .map(|light| match *light {
            Light::Point { .. } | Light::Directional { .. } | Light::Spot { .. } => 1,
            Light::Area { subdivisions, .. } => (subdivisions as usize + 1).pow(2),
        })
        .sum();

    let plan = plan_emitters(scene, patch_size)?;
    let mut out = Patches {
        patches: Vec::with_capacity(count as usize),
        samples: Vec::with_capacity(sample_count),
        emitters: Vec::with_capacity(plan.emitters.len()),
        notes: plan.notes,
        pieces: Vec::new(),
        lattices: Vec::new(),
    };
    // The last piece while it is whole triangles whose union is convex (`ConvexRun`).
    let mut run: Option<ConvexRun> = None;
    for (s, surface) in scene.surfaces.iter().enumerate() {
        let copies = if surface.two_sided { 2 } else { 1 };
        for (t, triangle) in surface.triangles.iter().enumerate() {
            let kind = |back: bool| match plan.first_shot.get(&(s as u32, t as u32, back)) {
                Some(&(emitter, side)) => PatchKind::Emitter { surface: s as u32, emitter, side },
                None => PatchKind::Surface { surface: s as u32 },
            };
            for polygon in SourceTriangle::pieces(scene, s, t, triangle, &pieces)? {
                let first = out.patches.len() as u32;
                for source in polygon {
                    let base = Patch {
                        vertices: source.vertices,
                        normal: source.normal,
                        area: 0.0,
                        material: Some(triangle.material),
                        emission: surface.emission,
                        kind: kind(false),
                        twin: surface.two_sided,
                    };
                    let first = out.patches.len() as u32;
                    let k = source.split_into(&base, kind(true), patch_size, &mut out.patches);
                    if k > 1 {
                        out.lattices.push(Lattice { first, k: k as u32, sides: copies, vertices: source.vertices });
                    }
                }
                let end = out.patches.len() as u32;
                if pieces.contains_key(&(s, t)) {
                    run = None;
                } else {
                    // A whole triangle: it joins the piece before it where that stays one
                    // convex surface (a quad's two triangles, a fan, a strip).
                    let touched = touched_edges.get(&(s, t)).copied().unwrap_or_default();
                    let surface_key = (s, std::mem::discriminant(&kind(false)));
                    if let (Some(r), Some(last)) = (&mut run, out.pieces.last_mut())
                        && r.surface == surface_key
                        && last.end == first
                        && last.sides == copies
                        && r.join(&triangle.vertices, touched)
                    {
                        last.end = end;
                        continue;
                    }
                    run = Some(ConvexRun::new(surface_key, &triangle.vertices, touched));
                }
                out.pieces.push(Piece { first, end, sides: copies });
            }
        }
    }
    for (l, light) in scene.lights.iter().enumerate() {
        match *light {
            Light::Point { position, power } => out.samples.push(LightSample {
                position,
                kind: SampleKind::Point,
                strength: power,
                weight: 1.0,
                light: l as u32,
            }),
            Light::Area { vertices, radiance, subdivisions } => {
                mesh_area_light(scene, l, vertices, radiance, subdivisions, &mut out)?
            }
            Light::Spot { position, direction, intensity, inner_angle, outer_angle } => out.samples.push(LightSample {
                position,
                kind: SampleKind::Spot { axis: direction, cone: SpotCone::new(inner_angle, outer_angle) },
                strength: intensity,
                weight: 1.0,
                light: l as u32,
            }),
            Light::Directional { direction, irradiance } => out.samples.push(LightSample {
                position: DVec3::ZERO,
                kind: SampleKind::Directional { direction },
                strength: irradiance,
                weight: 1.0,
                light: l as u32,
            }),
        }
    }
    for (e, emitter) in plan.emitters.into_iter().enumerate() {
        emitter_samples(&emitter, (scene.lights.len() + e) as u32, &mut out.samples);
        out.emitters.push(emitter);
    }
    Ok(out)
}

/// Which emitting triangle sides are first-shot lights, and their grids.
struct EmitterPlan {
    emitters: Vec<Emitter>,
    /// (surface, triangle, back side) -> (index into `emitters`, into its `triangles`).
    first_shot: HashMap<(u32, u32, bool), (u32, u32)>,
    notes: Vec<String>,
}

/// The largest k >= 1 whose grid, k^2 cells and as many samples, has at most `n`.
fn grid_for_samples(n: f64) -> u64 {
    let k = n.max(0.0).sqrt().floor();
    if k.is_finite() { (k as u64).max(1) } else { 1 }
}

fn grid_samples(k: u64) -> u64 {
    k * k
}

/// Every emitting side of every shape's triangles, strongest first (power pi A mean(Le)),
/// gets a grid of k x k congruent cells (`split_into`'s lattice), one sample at the centre
/// of each, with
///
///     k = min(k_area, k_power)
///
/// k_area: the least k that cuts its longest edge to at most the patch size (the grid is as
///         fine as the surfaces' patches, no finer);
/// k_power: the largest k >= 1 with k^2 <= `EMITTER_SAMPLE_SHARE` x (its share of the
///         emitting shapes' power), so weak emitters get coarse grids.
///
/// Sides are taken in that order until the next one would pass `MAX_EMITTER_SAMPLES`; the
/// rest stay emitters of the iteration, reported in one note.
fn plan_emitters(scene: &Scene, patch_size: f64) -> Result<EmitterPlan> {
    struct Side {
        surface: u32,
        triangle: u32,
        back: bool,
        vertices: [DVec3; 3],
        normal: DVec3,
        area: f64,
        power: f64,
        k_area: u64,
    }
    let mut sides = Vec::new();
    for (s, surface) in scene.surfaces.iter().enumerate() {
        let mean = surface.emission.iter().map(|&c| c as f64).sum::<f64>() / 3.0;
        // Emission is checked >= 0 and finite on loading: a mean of 0 is the only non-emitter.
        if mean <= 0.0 {
            continue;
        }
        for (t, triangle) in surface.triangles.iter().enumerate() {
            let source = SourceTriangle::new(scene, s, t, triangle)?;
            let power = std::f64::consts::PI * source.area * mean;
            let k_area = source.splits(patch_size);
            let [a, b, c] = triangle.vertices;
            for back in [false, true].into_iter().take(if surface.two_sided { 2 } else { 1 }) {
                let (vertices, normal) = if back { ([a, c, b], -source.normal) } else { ([a, b, c], source.normal) };
                sides.push(Side {
                    surface: s as u32,
                    triangle: t as u32,
                    back,
                    vertices,
                    normal,
                    area: source.area,
                    power,
                    k_area,
                });
            }
        }
    }
    let total_power: f64 = sides.iter().map(|side| side.power).sum();
    let mut order: Vec<usize> = (0..sides.len()).collect();
    order.sort_by(|&a, &b| sides[b].power.total_cmp(&sides[a].power));
    let (mut used, mut grids) = (0u64, vec![None; sides.len()]);
    for &i in &order {
        let side = &sides[i];
        let k_power = grid_for_samples(EMITTER_SAMPLE_SHARE * side.power / total_power);
        let k = side.k_area.min(k_power);
        if used + grid_samples(k) > MAX_EMITTER_SAMPLES {
            break;
        }
        used += grid_samples(k);
        grids[i] = Some(k as u32);
    }
    let mut plan = EmitterPlan { emitters: Vec::new(), first_shot: HashMap::new(), notes: Vec::new() };
    for (side, grid) in sides.iter().zip(&grids) {
        let Some(grid) = *grid else { continue };
        if plan.emitters.last().is_none_or(|e: &Emitter| e.surface != side.surface) {
            let radiance = scene.surfaces[side.surface as usize].emission;
            plan.emitters.push(Emitter { surface: side.surface, radiance, triangles: Vec::new() });
        }
        let e = plan.emitters.len() - 1;
        plan.emitters[e].triangles.push(EmitterTriangle {
            vertices: side.vertices,
            normal: side.normal,
            area: side.area,
            grid,
        });
        let index = (e as u32, plan.emitters[e].triangles.len() as u32 - 1);
        plan.first_shot.insert((side.surface, side.triangle, side.back), index);
    }
    let left = grids.iter().filter(|g| g.is_none()).count();
    if left > 0 {
        let power: f64 = sides.iter().zip(&grids).filter(|(_, g)| g.is_none()).map(|(s, _)| s.power).sum();
        plan.notes.push(format!(
            "{left} of {} emitting triangle sides ({:.1} % of the emitting shapes' power) are past the \
             first shot's cap of {MAX_EMITTER_SAMPLES} samples on emitting shapes: they emit inside \
             the iteration instead",
            sides.len(),
            100.0 * power / total_power
        ));
    }
    Ok(plan)
}

/// The samples of an emitter: the centre of every cell of every side's k x k grid, weighted
/// by the cell's area (the midpoint rule). Not the cells' corners, as on an area light: a
/// corner on the edge of an emitting shape can lie on another surface (an emitting floor
/// meets the walls), and the part of its window behind that surface, which the surface
/// would receive from points just inside the edge, would see nothing at all.
fn emitter_samples(emitter: &Emitter, light: u32, samples: &mut Vec<LightSample>) {
    for side in &emitter.triangles {
        let k = side.grid as u64;
        let [v0, v1, v2] = side.vertices;
        let kf = k as f64;
        let at = |i: u64, j: u64| v0 + (v1 - v0) * (i as f64 / kf) + (v2 - v0) * (j as f64 / kf);
        let cell = side.area / (kf * kf);
        let mut add = |[a, b, c]: [DVec3; 3]| {
            samples.push(LightSample {
                position: (a + b + c) / 3.0,
                kind: SampleKind::AreaVertex { normal: side.normal },
                strength: emitter.radiance,
                weight: cell,
                light,
            });
        };
        for j in 0..k {
            for i in 0..k - j {
                add([at(i, j), at(i + 1, j), at(i, j + 1)]);
                if i + j + 2 <= k {
                    add([at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
    }
}

/// The bounding sphere of every patch vertex and light sample (but a directional light's,
/// which has no position): the centre of their axis-aligned box and the distance from it to
/// the farthest point. `(0, 0)` when empty.
pub fn scene_bounds(patches: &Patches) -> (DVec3, f64) {
    let placed = |s: &&LightSample| !matches!(s.kind, SampleKind::Directional { .. });
    let points = || {
        patches.patches.iter().flat_map(|p| p.vertices).chain(patches.samples.iter().filter(placed).map(|s| s.position))
    };
    let Some((lo, hi)) = super::bounding_box(points()) else {
        return (DVec3::ZERO, 0.0);
    };
    let center = 0.5 * (lo + hi);
    let radius = points().map(|p| p.distance(center)).fold(0.0, f64::max);
    (center, radius)
}

/// The distance from `point` to the nearest patch (0 on one), or `None` without patches: what
/// a camera there may see nearest (`render::camera_notes`). All cores, one pass.
pub fn nearest_patch_distance(patches: &Patches, point: DVec3) -> Option<f64> {
    use rayon::prelude::*;
    patches
        .patches
        .par_iter()
        .map(|p| closest_point_on_triangle(point, p.vertices).distance(point))
        .reduce_with(f64::min)
}

/// The point of triangle `[a, b, c]` nearest `p`: by which of the triangle's seven regions
/// (three corners, three edges, the inside) the projection of `p` falls in, each told by the
/// signs of dot products with the edges (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn closest_point_on_triangle(p: DVec3, [a, b, c]: [DVec3; 3]) -> DVec3 {
    let (ab, ac) = (b - a, c - a);
    let (d1, d2) = (ab.dot(p - a), ac.dot(p - a));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let (d3, d4) = (ab.dot(p - b), ac.dot(p - b));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let (d5, d6) = (ab.dot(p - c), ac.dot(p - c));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let inside = 1.0 / (va + vb + vc);
    a + ab * (vb * inside) + ac * (vc * inside)
}

/// A surface triangle, checked, with what its patches share.
struct SourceTriangle {
    vertices: [DVec3; 3],
    normal: DVec3,
    area: f64,
    longest_edge: f64,
}

impl SourceTriangle {
    fn new(scene: &Scene, s: usize, t: usize, triangle: &Triangle) -> Result<Self> {
        let [v0, v1, v2] = triangle.vertices;
        let cross = (v1 - v0).cross(v2 - v0);
        let area = 0.5 * cross.length();
        let longest_edge = (v1 - v0).length().max((v2 - v1).length()).max((v0 - v2).length());
        // The loader refuses these; a scene built in code must not reach the GPU with them.
        if !(area > 0.0 && area.is_finite() && longest_edge.is_finite()) {
            let origin = &scene.surfaces[s].origin;
            return Err(Error::scene(
                &scene.source,
                format!("{origin}, triangle {t}"),
                format!("degenerate or non-finite triangle {:?}", triangle.vertices.map(|v| v + scene.file_origin)),
            ));
        }
        Ok(SourceTriangle { vertices: triangle.vertices, normal: cross.normalize(), area, longest_edge })
    }

    /// The triangle, or the convex polygons that contact cuts (`contact.rs`) leave of it,
    /// each as the triangles fanned from it, each with the source's own normal so that all
    /// its patches stay exactly coplanar. One polygon's patches are one `Piece`.
    fn pieces(scene: &Scene, s: usize, t: usize, triangle: &Triangle, pieces: &Pieces) -> Result<Vec<Vec<Self>>> {
        let whole = SourceTriangle::new(scene, s, t, triangle)?;
        let Some(cut) = pieces.get(&(s, t)) else {
            return Ok(vec![vec![whole]]);
        };
        Ok(cut
            .iter()
            .map(|fan| {
                fan.iter()
                    .map(|&[v0, v1, v2]| SourceTriangle {
                        vertices: [v0, v1, v2],
                        normal: whole.normal,
                        area: 0.5 * (v1 - v0).cross(v2 - v0).length(),
                        longest_edge: (v1 - v0).length().max((v2 - v1).length()).max((v0 - v2).length()),
                    })
                    .collect()
            })
            .collect())
    }

    /// k: the number of pieces each edge is cut into. Saturates instead of overflowing, so
    /// that an absurd patch size is reported by the patch limit.
    fn splits(&self, patch_size: f64) -> u64 {
        let ratio = self.longest_edge / patch_size;
        if ratio > (1u64 << 32) as f64 {
            return 1 << 32;
        }
        let mut k = (ratio.ceil() as u64).max(1);
        // ceil may land one short when longest / patch_size rounds down to an integer.
        while self.longest_edge / k as f64 > patch_size {
            k += 1;
        }
        k
    }

    /// Appends the k^2 patches (and twins): on the lattice v0 + (i e1 + j e2) / k, the
    /// "upright" triangles are translates of the source scaled by 1/k and the "inverted"
    /// ones are those rotated by 180 degrees in its plane, so all keep its winding. The order
    /// is `Lattice`'s. Returns k.
    fn split_into(&self, base: &Patch, twin_kind: PatchKind, patch_size: f64, out: &mut Vec<Patch>) -> u64 {
        let k = self.splits(patch_size);
        let [v0, v1, v2] = self.vertices;
        let kf = k as f64;
        let (e1, e2) = (v1 - v0, v2 - v0);
        let at = |i: u64, j: u64| v0 + e1 * (i as f64 / kf) + e2 * (j as f64 / kf);
        let area = self.area / (kf * kf);
        let mut push = |vertices: [DVec3; 3]| {
            let patch = Patch { vertices, normal: self.normal, area, ..*base };
            out.push(patch);
            if base.twin {
                let [a, b, c] = vertices;
                out.push(Patch { vertices: [a, c, b], normal: -self.normal, kind: twin_kind, ..patch });
            }
        };
        if k == 1 {
            push(self.vertices);
            return 1;
        }
        for j in 0..k {
            for i in 0..k - j {
                push([at(i, j), at(i + 1, j), at(i, j + 1)]);
                if i + j + 2 <= k {
                    push([at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
        k
    }
}

/// The n x n grid of an area light: vertex (i, j) is the bilinear blend of v0..v3 at
/// (i/n, j/n), cell (i, j) is cut along the same diagonal as the quad itself (v0-v2), so
/// n = 1 gives the loader's own two triangles. Each sample's weight is a third of the area
/// of the triangles around it: the trapezoid rule over the light's triangles.
fn mesh_area_light(
    scene: &Scene,
    l: usize,
    [v0, v1, v2, v3]: [DVec3; 4],
    radiance: Rgb,
    n: u32,
    out: &mut Patches,
) -> Result<()> {
    let normal = (v2 - v0).cross(v3 - v1).normalize_or_zero();
    if normal == DVec3::ZERO || !normal.is_finite() {
        return Err(Error::scene(
            &scene.source,
            format!("lights[{l}].vertices"),
            "degenerate or non-finite area light",
        ));
    }
    let n = n as usize;
    let row = n + 1;
    let first_sample = out.samples.len();
    for j in 0..=n {
        for i in 0..=n {
            let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
            let position = (1.0 - v) * ((1.0 - u) * v0 + u * v1) + v * ((1.0 - u) * v3 + u * v2);
            out.samples.push(LightSample {
                position,
                kind: SampleKind::AreaVertex { normal },
                strength: radiance,
                weight: 0.0,
                light: l as u32,
            });
        }
    }
    for j in 0..n {
        for i in 0..n {
            let corners = [j * row + i, j * row + i + 1, (j + 1) * row + i + 1, (j + 1) * row + i];
            for [a, b, c] in [[0, 1, 2], [0, 2, 3]] {
                let ids = [corners[a], corners[b], corners[c]];
                let vertices = ids.map(|id| out.samples[first_sample + id].position);
                let cross = (vertices[1] - vertices[0]).cross(vertices[2] - vertices[0]);
                let area = 0.5 * cross.length();
                if !(area > 0.0 && area.is_finite()) {
                    return Err(Error::scene(
                        &scene.source,
                        format!("lights[{l}].vertices"),
                        "the light's grid has a degenerate cell: is the quad convex?",
                    ));
                }
                for id in ids {
                    out.samples[first_sample + id].weight += area / 3.0;
                }
                out.patches.push(Patch {
                    vertices,
                    normal: cross.normalize(),
                    area,
                    material: None,
                    emission: radiance,
                    kind: PatchKind::AreaLight { light: l as u32 },
                    twin: false,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scene::{Camera, Material, MaterialKind, Settings, Surface};
    use rand_core::{RngCore, SeedableRng};
    use rand_pcg::Pcg64;

    /// Patches are built from the same f64 numbers as their source: what is exact on paper
    /// may be off by a few ulps of the scene's size, never more.
    const ROUNDING: f64 = 1e-12;

    /// Against a dense grid of the triangle's points (a different computation: no regions),
    /// for points all around random triangles, slivers among them: the closest point is never
    /// farther than the grid's best and at most the grid's spacing nearer, and it lies on the
    /// triangle.
    #[test]
    fn the_closest_point_on_a_triangle_is_the_nearest_of_its_points() {
        let mut rng = Pcg64::seed_from_u64(7);
        let mut u = || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        let n = 200;
        for case in 0..300 {
            let mut tri = [0; 3].map(|_| DVec3::new(u(), u(), u()));
            if case % 10 == 0 {
                tri[2] = tri[0].lerp(tri[1], 0.3) + DVec3::new(u(), u(), u()) * 1e-3;
            }
            let p = DVec3::new(u(), u(), u()) * 2.0;
            let q = closest_point_on_triangle(p, tri);
            let mut grid_best = f64::INFINITY;
            for j in 0..=n {
                for i in 0..=n - j {
                    let (b1, b2) = (i as f64 / n as f64, j as f64 / n as f64);
                    let x = tri[0] + (tri[1] - tri[0]) * b1 + (tri[2] - tri[0]) * b2;
                    grid_best = grid_best.min(x.distance(p));
                }
            }
            let longest = (0..3).map(|k| tri[k].distance(tri[(k + 1) % 3])).fold(0.0, f64::max);
            let d = q.distance(p);
            assert!(d <= grid_best + 1e-12, "case {case}: {d} farther than the grid's {grid_best}");
            assert!(d >= grid_best - longest / n as f64, "case {case}: {d} too near ({grid_best})");
            // On the triangle: in its plane and inside its three edges.
            let normal = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
            assert!(normal.dot(q - tri[0]).abs() <= 1e-9 * normal.length(), "case {case}: off the plane");
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                assert!((b - a).cross(q - a).dot(normal) >= -1e-9 * normal.length_squared(), "case {case}: outside");
            }
        }
        // A unit square in z = 0 cut into patches: 3 above a point inside it, 5 from a point
        // 3 above and 4 beside its edge.
        let square =
            [[DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0)], [DVec3::ZERO, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]];
        let patches = tessellate(&scene_of(vec![surface(&square, false)], vec![]), 0.3).unwrap();
        assert!(patches.patches.len() > 8);
        let near = |p: DVec3| nearest_patch_distance(&patches, p).unwrap();
        assert!((near(DVec3::new(0.37, 0.61, 3.0)) - 3.0).abs() < 1e-12);
        assert!((near(DVec3::new(5.0, 0.5, 3.0)) - 5.0).abs() < 1e-12);
        assert_eq!(nearest_patch_distance(&Patches::default(), DVec3::ZERO), None);
    }

    /// A scene made of the given surfaces and lights, with one diffuse material.
    pub(crate) fn scene_of(surfaces: Vec<Surface>, lights: Vec<Light>) -> Scene {
        let camera = Camera {
            position: DVec3::new(0.0, 0.0, 5.0),
            look_at: DVec3::ZERO,
            up: DVec3::Y,
            fov_y: 45.0,
            width: 64,
            height: 64,
        };
        Scene {
            source: "test.toml".into(),
            camera,
            cameras: vec![crate::scene::NamedCamera { name: "camera".into(), camera }],
            environment: [0.0; 3],
            settings: Settings::default(),
            materials: vec![Material { name: "white".into(), kind: MaterialKind::Diffuse { albedo: [0.5; 3] } }],
            surfaces,
            lights,
            notes: Vec::new(),
            file_origin: DVec3::ZERO,
        }
    }

    pub(crate) fn surface(triangles: &[[DVec3; 3]], two_sided: bool) -> Surface {
        Surface {
            origin: "shapes[0] (test)".into(),
            triangles: triangles.iter().map(|&vertices| Triangle { vertices, material: 0 }).collect(),
            emission: [0.25, 0.5, 1.0],
            two_sided,
        }
    }

    fn uniform(rng: &mut Pcg64) -> f64 {
        (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Triangles of every shape: slivers, obtuse, large and far from the origin.
    fn random_triangles(seed: u64, count: usize) -> Vec<[DVec3; 3]> {
        let mut rng = Pcg64::seed_from_u64(seed);
        let mut point = |scale: f64| DVec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * scale;
        (0..count)
            .map(|t| {
                let offset = point(100.0);
                let scale = [0.3, 1.0, 7.0][t % 3];
                [offset + point(scale), offset + point(scale), offset + point(scale)]
            })
            .collect()
    }

    fn triangle_area([a, b, c]: [DVec3; 3]) -> f64 {
        0.5 * (b - a).cross(c - a).length()
    }

    fn longest_edge([a, b, c]: [DVec3; 3]) -> f64 {
        a.distance(b).max(b.distance(c)).max(c.distance(a))
    }

    fn square_light(side: f64, n: u32) -> Light {
        // Counter-clockwise seen from below: a ceiling light facing -y.
        Light::Area {
            vertices: [
                DVec3::new(0.0, 2.0, 0.0),
                DVec3::new(side, 2.0, 0.0),
                DVec3::new(side, 2.0, side),
                DVec3::new(0.0, 2.0, side),
            ],
            radiance: [10.0, 20.0, 30.0],
            subdivisions: n,
        }
    }

    #[test]
    fn area_is_preserved_and_edges_are_short() {
        let triangles = random_triangles(7, 60);
        let scene = scene_of(vec![surface(&triangles, false)], vec![]);
        let source_area: f64 = triangles.iter().copied().map(triangle_area).sum();
        for patch_size in [0.05, 0.3, 1.0, 2.5, 100.0] {
            let patches = tessellate(&scene, patch_size).unwrap();
            let total: f64 = patches.patches.iter().map(|p| p.area).sum();
            assert!((total - source_area).abs() <= ROUNDING * source_area);
            for p in &patches.patches {
                assert!(longest_edge(p.vertices) <= patch_size * (1.0 + ROUNDING));
                let area = triangle_area(p.vertices);
                assert!((area - p.area).abs() <= 1e-9 * p.area, "{area} vs {}", p.area);
            }
            // k is the least that works, so no more patches than ceil(longest / size)^2.
            let expected: usize =
                triangles.iter().map(|&t| ((longest_edge(t) / patch_size).ceil().max(1.0) as usize).pow(2)).sum();
            assert_eq!(patches.patches.len(), expected);
        }
    }

    #[test]
    fn an_edge_that_is_a_multiple_of_the_patch_size_is_cut_exactly() {
        let right = [DVec3::ZERO, DVec3::new(3.0, 0.0, 0.0), DVec3::new(0.0, 3.0, 0.0)];
        let scene = scene_of(vec![surface(&[right], false)], vec![]);
        // Hypotenuse 3 sqrt(2): k = 5 at size 3 sqrt(2) / 5, 1 at its own length.
        let hypotenuse = 3.0 * 2f64.sqrt();
        assert_eq!(tessellate(&scene, hypotenuse).unwrap().patches.len(), 1);
        assert_eq!(tessellate(&scene, hypotenuse / 5.0).unwrap().patches.len(), 25);
        assert_eq!(tessellate(&scene, f64::INFINITY).unwrap().patches.len(), 1);
    }

    #[test]
    fn patches_follow_the_winding_and_carry_the_surface() {
        let triangles = random_triangles(11, 30);
        let scene = scene_of(vec![surface(&triangles, false)], vec![]);
        let patches = tessellate(&scene, 0.7).unwrap();
        let mut next = 0;
        for &[a, b, c] in &triangles {
            let source_normal = (b - a).cross(c - a).normalize();
            let k = (longest_edge([a, b, c]) / 0.7).ceil().max(1.0) as usize;
            for p in &patches.patches[next..next + k * k] {
                assert_eq!(p.normal, source_normal);
                let [v0, v1, v2] = p.vertices;
                let winding = (v1 - v0).cross(v2 - v0).normalize();
                assert!(winding.dot(p.normal) > 1.0 - 1e-9);
                assert_eq!(p.material, Some(0));
                assert_eq!(p.emission, [0.25, 0.5, 1.0]);
                // It emits, so its emission is a first-shot light.
                assert!(matches!(p.kind, PatchKind::Emitter { surface: 0, emitter: 0, .. }));
                assert!(!p.twin);
            }
            next += k * k;
        }
        assert_eq!(next, patches.patches.len());
    }

    #[test]
    fn two_sided_surfaces_give_back_to_back_twins() {
        let triangles = random_triangles(13, 9);
        let one = tessellate(&scene_of(vec![surface(&triangles, false)], vec![]), 0.9).unwrap();
        let two = tessellate(&scene_of(vec![surface(&triangles, true)], vec![]), 0.9).unwrap();
        assert_eq!(two.patches.len(), 2 * one.patches.len());
        for (front, pair) in one.patches.iter().zip(two.patches.chunks(2)) {
            let (a, b) = (pair[0], pair[1]);
            assert!(a.twin && b.twin);
            assert_eq!(a.vertices, front.vertices);
            let [v0, v1, v2] = a.vertices;
            assert_eq!(b.vertices, [v0, v2, v1]);
            assert_eq!(b.normal, -a.normal);
            let [w0, w1, w2] = b.vertices;
            assert!((w1 - w0).cross(w2 - w0).normalize().dot(b.normal) > 1.0 - 1e-9);
            assert_eq!((b.area, b.material, b.emission), (a.area, a.material, a.emission));
        }
    }

    #[test]
    fn square_light_grid_has_trapezoid_weights() {
        let side = 0.8;
        for n in [1u32, 2, 3, 5] {
            let scene = scene_of(vec![], vec![square_light(side, n)]);
            let patches = tessellate(&scene, 1e-3).unwrap();
            let n = n as usize;
            assert_eq!(patches.patches.len(), 2 * n * n);
            assert_eq!(patches.samples.len(), (n + 1) * (n + 1));
            let area = side * side;
            let sum: f64 = patches.samples.iter().map(|s| s.weight).sum();
            assert!((sum - area).abs() <= ROUNDING * area);
            // Trapezoid rule on cells of h^2: h^2 inside, h^2 / 2 on an edge, and the four
            // corners share h^2. With one diagonal per cell, the diagonal's two end corners
            // touch two triangles (h^2 / 3) and the other two corners one (h^2 / 6).
            let h2 = area / (n * n) as f64;
            for (id, s) in patches.samples.iter().enumerate() {
                let (i, j) = (id % (n + 1), id / (n + 1));
                let (i_edge, j_edge) = (i == 0 || i == n, j == 0 || j == n);
                let expected = match (i_edge, j_edge) {
                    (false, false) => h2,
                    (true, false) | (false, true) => h2 / 2.0,
                    (true, true) if i == j => h2 / 3.0,
                    (true, true) => h2 / 6.0,
                };
                assert!((s.weight - expected).abs() <= ROUNDING * h2, "({i}, {j})");
                assert_eq!(s.kind, SampleKind::AreaVertex { normal: DVec3::NEG_Y });
                assert_eq!(s.strength, [10.0, 20.0, 30.0]);
                assert_eq!(s.light, 0);
            }
            for p in &patches.patches {
                assert!(p.normal.dot(DVec3::NEG_Y) > 1.0 - 1e-12);
                assert_eq!(p.material, None);
                assert_eq!(p.emission, [10.0, 20.0, 30.0]);
                assert_eq!(p.kind, PatchKind::AreaLight { light: 0 });
                assert!(!p.twin);
                let corners = p.vertices.map(|v| patches.samples.iter().filter(|s| s.position == v).count());
                assert_eq!(corners, [1, 1, 1], "patch vertices are the sample positions");
            }
        }
    }

    #[test]
    fn one_cell_light_is_the_quads_own_two_triangles() {
        let scene = scene_of(vec![], vec![square_light(1.0, 1)]);
        let patches = tessellate(&scene, 0.1).unwrap();
        let Light::Area { vertices: [v0, v1, v2, v3], .. } = scene.lights[0] else { unreachable!() };
        assert_eq!(patches.patches[0].vertices, [v0, v1, v2]);
        assert_eq!(patches.patches[1].vertices, [v0, v2, v3]);
    }

    #[test]
    fn convex_quad_light_that_is_no_parallelogram() {
        // A tilted trapezoid with one more skewed side, planar by construction.
        let (e1, e2) = (DVec3::new(1.0, 0.2, 0.0), DVec3::new(0.0, 0.3, 1.0));
        let origin = DVec3::new(-2.0, 3.0, 1.0);
        let at = |x: f64, y: f64| origin + x * e1 + y * e2;
        let vertices = [at(0.0, 0.0), at(2.0, 0.0), at(1.6, 1.1), at(0.3, 0.9)];
        let [v0, v1, v2, v3] = vertices;
        let area = triangle_area([v0, v1, v2]) + triangle_area([v0, v2, v3]);
        let normal = e1.cross(e2).normalize();
        for n in [1u32, 3, 4] {
            let light = Light::Area { vertices, radiance: [1.0; 3], subdivisions: n };
            let patches = tessellate(&scene_of(vec![], vec![light]), 1.0).unwrap();
            assert_eq!(patches.patches.len(), 2 * (n * n) as usize);
            assert_eq!(patches.samples.len(), ((n + 1) * (n + 1)) as usize);
            let weights: f64 = patches.samples.iter().map(|s| s.weight).sum();
            let patch_area: f64 = patches.patches.iter().map(|p| p.area).sum();
            assert!((weights - area).abs() <= ROUNDING * area, "{weights} vs {area}");
            assert!((patch_area - area).abs() <= ROUNDING * area);
            for s in &patches.samples {
                let SampleKind::AreaVertex { normal: n } = s.kind else { panic!("an area-light sample") };
                assert!(n.dot(normal) > 1.0 - 1e-12);
                assert!((s.position - v0).dot(normal).abs() <= ROUNDING);
                assert!(s.weight > 0.0);
            }
            for p in &patches.patches {
                assert!(p.normal.dot(normal) > 1.0 - 1e-12);
            }
        }
    }

    #[test]
    fn point_light_is_one_sample() {
        let light = Light::Point { position: DVec3::new(1.0, 2.0, 3.0), power: [5.0, 6.0, 7.0] };
        let patches = tessellate(&scene_of(vec![], vec![square_light(1.0, 2), light]), 1.0).unwrap();
        assert_eq!(patches.samples.len(), 10);
        let sample = patches.samples[9];
        assert_eq!(
            sample,
            LightSample {
                position: DVec3::new(1.0, 2.0, 3.0),
                kind: SampleKind::Point,
                strength: [5.0, 6.0, 7.0],
                weight: 1.0,
                light: 1,
            }
        );
    }

    #[test]
    fn bad_patch_sizes_are_refused() {
        let scene = scene_of(vec![surface(&random_triangles(3, 2), false)], vec![]);
        for size in [0.0, -1.0, f64::NAN, f64::NEG_INFINITY] {
            let error = tessellate(&scene, size).unwrap_err();
            assert!(matches!(error, Error::Usage(_)), "{error}");
        }
    }

    #[test]
    fn too_many_patches_are_refused_before_allocating() {
        let big = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let scene = scene_of(vec![surface(&[big], true)], vec![]);
        // sqrt(2) / 1e-4 -> k = 14143, 2 k^2 = 4e8 > 2^27; and an absurd size saturates.
        for size in [1e-4, 1e-300] {
            let error = tessellate(&scene, size).unwrap_err();
            assert!(error.to_string().contains("--patch-size"), "{error}");
            assert!(error.is_usage());
        }
        // Light grids count too: 2 * 8193^2 is just over 2^27.
        let light = |n| scene_of(vec![], vec![square_light(1.0, n)]);
        for n in [8193, u32::MAX] {
            let error = tessellate(&light(n), 1.0).unwrap_err();
            assert!(error.to_string().contains("subdivisions"), "{error}");
        }
    }

    #[test]
    fn degenerate_triangles_are_refused() {
        let flat = [DVec3::ZERO, DVec3::X, 2.0 * DVec3::X];
        let scene = scene_of(vec![surface(&[flat], false)], vec![]);
        let error = tessellate(&scene, 1.0).unwrap_err();
        assert!(error.to_string().contains("triangle 0"), "{error}");
        assert!(tessellate(&scene_of(vec![], vec![square_light(1.0, 0)]), 1.0).is_err());
    }

    #[test]
    fn bounds_enclose_patches_and_samples() {
        let cube_corner = [DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), DVec3::new(0.0, 2.0, 0.0)];
        let light = Light::Point { position: DVec3::new(0.0, 0.0, 2.0), power: [1.0; 3] };
        let patches = tessellate(&scene_of(vec![surface(&[cube_corner], false)], vec![light]), 0.5).unwrap();
        let (center, radius) = scene_bounds(&patches);
        assert!((center - DVec3::ONE).length() <= ROUNDING);
        assert!((radius - 3f64.sqrt()).abs() <= ROUNDING);
        assert_eq!(scene_bounds(&Patches::default()), (DVec3::ZERO, 0.0));
    }

    /// The level-l Sierpinski set of docs/SCENE_FORMAT.md, faces outward of their own
    /// tetrahedra: just enough of the loader's shape to count patches.
    fn sierpinski(center: DVec3, size: f64, level: u32) -> Vec<[DVec3; 3]> {
        let (h, r) = (size * (2.0f64 / 3.0).sqrt(), size / 3f64.sqrt());
        let base = |k: f64| {
            let angle = 2.0 * std::f64::consts::PI * k / 3.0;
            center + DVec3::new(r * angle.sin(), -h / 4.0, -r * angle.cos())
        };
        let mut tetrahedra = vec![[center + DVec3::new(0.0, 0.75 * h, 0.0), base(0.0), base(1.0), base(2.0)]];
        for _ in 0..level {
            tetrahedra = tetrahedra.iter().flat_map(|t| (0..4).map(move |c| t.map(|v| 0.5 * (v + t[c])))).collect();
        }
        let mut triangles = Vec::with_capacity(4 * tetrahedra.len());
        for t in &tetrahedra {
            for opposite in 0..4 {
                let [a, b, c] = [1, 2, 3].map(|o| t[(opposite + o) % 4]);
                let outward = (b - a).cross(c - a).dot(a - t[opposite]) > 0.0;
                triangles.push(if outward { [a, b, c] } else { [a, c, b] });
            }
        }
        triangles
    }

    /// Reads the geometry of a scene file with plain TOML (the loader is not this module's).
    pub(crate) fn scene_from_file(path: &std::path::Path) -> (Scene, f64) {
        let text = std::fs::read_to_string(path).unwrap();
        let table: toml::Table = text.parse().unwrap();
        let number = |v: &toml::Value| v.as_float().or(v.as_integer().map(|i| i as f64)).unwrap();
        let point = |v: &toml::Value| {
            let a = v.as_array().unwrap();
            DVec3::new(number(&a[0]), number(&a[1]), number(&a[2]))
        };
        let points = |v: &toml::Value| v.as_array().unwrap().iter().map(point).collect::<Vec<_>>();
        let colour = |v: &toml::Value| point(v).as_vec3().to_array();
        let mut surfaces = Vec::new();
        for shape in table["shapes"].as_array().unwrap() {
            let triangles = match shape["type"].as_str().unwrap() {
                "triangle" => {
                    let v = points(&shape["vertices"]);
                    vec![[v[0], v[1], v[2]]]
                }
                "quad" => {
                    let v = points(&shape["vertices"]);
                    vec![[v[0], v[1], v[2]], [v[0], v[2], v[3]]]
                }
                "sierpinski" => sierpinski(
                    point(&shape["center"]),
                    number(&shape["size"]),
                    shape["level"].as_integer().unwrap() as u32,
                ),
                other => panic!("shape type {other} is not read by this test"),
            };
            let two_sided = shape.get("two_sided").is_some_and(|v| v.as_bool().unwrap());
            let emission = shape.get("emission").map_or([0.0; 3], colour);
            surfaces.push(Surface { emission, ..surface(&triangles, two_sided) });
        }
        let mut lights = Vec::new();
        for light in table.get("lights").and_then(|l| l.as_array()).into_iter().flatten() {
            lights.push(match light["type"].as_str().unwrap() {
                "point" => Light::Point { position: point(&light["position"]), power: colour(&light["power"]) },
                _ => {
                    let v = points(&light["vertices"]);
                    Light::Area {
                        vertices: [v[0], v[1], v[2], v[3]],
                        radiance: colour(&light["radiance"]),
                        subdivisions: light.get("subdivisions").map_or(1, |n| n.as_integer().unwrap() as u32),
                    }
                }
            });
        }
        let patch_size = number(&table["settings"]["patch_size"]);
        (scene_of(surfaces, lights), patch_size)
    }

    #[test]
    fn sierpinski_scene_has_about_as_many_patches_as_the_papers() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sierpinski.toml");
        let (scene, patch_size) = scene_from_file(&path);
        let start = std::time::Instant::now();
        let patches = tessellate(&scene, patch_size).unwrap();
        let elapsed = start.elapsed();
        let stats = patches.stats();
        println!("{stats:?} in {elapsed:?}");
        assert!((20_000..=25_000).contains(&patches.patches.len()), "{stats:?}");
        assert_eq!(stats.light_patches, 8);
        assert_eq!(stats.samples, 9);
        let fractal = &scene.surfaces[6];
        assert_eq!(fractal.triangles.len(), 4usize.pow(7));
        let fractal_patches = patches.patches.iter().filter(|p| p.kind == PatchKind::Surface { surface: 6 }).count();
        assert_eq!(fractal_patches, fractal.triangles.len(), "the fractal is never cut");
        // The room is closed and faces inward: its patches' normals point at the centre.
        let (center, radius) = scene_bounds(&patches);
        assert!(radius > 0.0);
        for p in patches.patches.iter().filter(|p| matches!(p.kind, PatchKind::Surface { surface: 0..6 })) {
            assert!((center - p.vertices[0]).dot(p.normal) > 0.0);
        }
    }

    fn emitting(triangles: &[[DVec3; 3]], emission: Rgb, two_sided: bool) -> Surface {
        Surface { emission, ..surface(triangles, two_sided) }
    }

    fn quad_triangles([v0, v1, v2, v3]: [DVec3; 4]) -> Vec<[DVec3; 3]> {
        vec![[v0, v1, v2], [v0, v2, v3]]
    }

    #[test]
    fn emitting_quad_samples_are_its_cells_centres() {
        // The quad of an area light as an emitting shape whose grid the patch size makes
        // n x n per triangle: n^2 samples per triangle, each at a cell's centre, strictly
        // inside the quad, weighted by the cell's area.
        let Light::Area { vertices, .. } = square_light(0.8, 1) else { unreachable!() };
        let diagonal = vertices[0].distance(vertices[2]);
        for n in [1u32, 2, 3] {
            let shape = scene_of(vec![emitting(&quad_triangles(vertices), [2.0; 3], false)], vec![]);
            let patches = tessellate(&shape, diagonal / n as f64).unwrap();
            assert_eq!(patches.emitters.len(), 1);
            assert!(patches.emitters[0].triangles.iter().all(|t| t.grid == n));
            assert_eq!(patches.samples.len(), 2 * (n * n) as usize);
            let cell = 0.8 * 0.8 / (2 * n * n) as f64;
            let h = 0.8 / n as f64;
            for s in &patches.samples {
                assert_eq!(s.kind, SampleKind::AreaVertex { normal: DVec3::NEG_Y });
                assert!((s.weight - cell).abs() <= ROUNDING);
                assert_eq!((s.strength, s.light), ([2.0; 3], 0), "lights.len() + emitter 0");
                // A cell's centre lies a third of the cell's side from its legs (and nearer
                // no edge of the quad): in the lattice's coordinates, fractions of 1/3 or 2/3.
                let (x, z) = (s.position.x / h, s.position.z / h);
                for f in [x.fract(), z.fract()] {
                    assert!((f - 1.0 / 3.0).abs() < 1e-9 || (f - 2.0 / 3.0).abs() < 1e-9, "{}", s.position);
                }
                assert!(s.position.x > 0.0 && s.position.x < 0.8 && s.position.z > 0.0 && s.position.z < 0.8);
            }
            for p in &patches.patches {
                assert!(matches!(p.kind, PatchKind::Emitter { surface: 0, emitter: 0, .. }));
                assert_eq!(p.material, Some(0), "an emitting shape keeps its material");
            }
        }
    }

    #[test]
    fn emitter_grids_follow_area_and_power() {
        // Two emitting shapes, one 9 times as strong: their sample weights add up to their
        // areas, and k = min(k_area, k_power) on each.
        let tri = |x: f64| [DVec3::new(x, 0.0, 0.0), DVec3::new(x + 1.0, 0.0, 0.0), DVec3::new(x, 1.0, 0.0)];
        let strong = emitting(&[tri(0.0)], [9.0; 3], false);
        let weak = emitting(&[tri(5.0)], [1.0; 3], true);
        let scene = scene_of(vec![strong, weak], vec![]);
        for patch_size in [f64::INFINITY, 0.2, 0.05] {
            let patches = tessellate(&scene, patch_size).unwrap();
            assert_eq!(patches.emitters.len(), 2);
            let k_area = |p: f64| if p.is_infinite() { 1 } else { (2f64.sqrt() / p).ceil() as u32 };
            // Power shares: strong 9 / 11 of one side, weak 1 / 11 on each of its two sides.
            let k_power = |share: f64| grid_for_samples(EMITTER_SAMPLE_SHARE * share) as u32;
            assert_eq!(patches.emitters[0].triangles[0].grid, k_area(patch_size).min(k_power(9.0 / 11.0)));
            assert_eq!(patches.emitters[1].triangles.len(), 2, "both sides of a two-sided emitter");
            for t in &patches.emitters[1].triangles {
                assert_eq!(t.grid, k_area(patch_size).min(k_power(1.0 / 11.0)));
            }
            let normals: Vec<_> = patches.emitters[1].triangles.iter().map(|t| t.normal).collect();
            assert_eq!(normals, [DVec3::Z, DVec3::NEG_Z]);
            for (e, emitter) in patches.emitters.iter().enumerate() {
                let weights: f64 = patches.samples.iter().filter(|s| s.light == e as u32).map(|s| s.weight).sum();
                let area: f64 = emitter.triangles.iter().map(|t| t.area).sum();
                assert!((weights - area).abs() <= ROUNDING, "{weights} vs {area}");
            }
            for p in &patches.patches {
                let expected = if p.vertices[0].x < 2.0 { 0 } else { 1 };
                assert!(
                    matches!(p.kind, PatchKind::Emitter { surface, emitter, .. } if surface == expected && emitter == expected)
                );
            }
        }
        // k_power's own values: the largest k with k^2 <= n, at least 1.
        let ks: Vec<u64> = [0.0, 3.9, 4.0, 8.9, 9.0, 10.0, 32.0, 64.0].map(grid_for_samples).to_vec();
        assert_eq!(ks, [1, 1, 2, 2, 3, 3, 5, 8]);
    }

    #[test]
    fn emitters_past_the_cap_stay_in_the_iteration_with_a_note() {
        // More emitting triangles than the cap has samples for (one each at k = 1): the
        // brightest are first shot, the rest are plain surface patches, and a note says so.
        let count = MAX_EMITTER_SAMPLES as usize + 10;
        let tri = |i: usize| {
            let x = i as f64 * 2.0;
            [DVec3::new(x, 0.0, 0.0), DVec3::new(x + 1.0, 0.0, 0.0), DVec3::new(x, 1.0, 0.0)]
        };
        let dim = emitting(&(0..10).map(tri).collect::<Vec<_>>(), [0.5; 3], false);
        let bright = emitting(&(10..count).map(tri).collect::<Vec<_>>(), [1.0; 3], false);
        let patches = tessellate(&scene_of(vec![dim, bright], vec![]), f64::INFINITY).unwrap();
        assert_eq!(patches.samples.len() as u64, MAX_EMITTER_SAMPLES);
        assert_eq!(patches.emitters.len(), 1, "only the bright shape is first shot");
        assert_eq!(patches.emitters[0].surface, 1);
        assert!(patches.patches[..10].iter().all(|p| p.kind == PatchKind::Surface { surface: 0 }));
        assert!(patches.patches[10..].iter().all(|p| matches!(p.kind, PatchKind::Emitter { surface: 1, .. })));
        assert_eq!(patches.notes.len(), 1);
        assert!(patches.notes[0].starts_with("10 of "), "{}", patches.notes[0]);
    }

    #[test]
    fn shapes_without_emission_are_no_emitters() {
        let mut dark = surface(&random_triangles(3, 4), false);
        dark.emission = [0.0; 3];
        let patches = tessellate(&scene_of(vec![dark], vec![]), 1.0).unwrap();
        assert!(patches.emitters.is_empty() && patches.samples.is_empty() && patches.notes.is_empty());
    }

    #[test]
    fn stats_count_and_add_up() {
        let triangles = random_triangles(5, 4);
        let dark = Surface { emission: [0.0; 3], ..surface(&triangles, true) };
        let scene = scene_of(vec![dark], vec![square_light(0.5, 3)]);
        let patches = tessellate(&scene, 2.0).unwrap();
        let stats = patches.stats();
        assert_eq!(stats.light_patches, 18);
        assert_eq!(stats.surface_patches + 18, patches.patches.len());
        assert_eq!(stats.samples, 16);
        let area = 2.0 * triangles.iter().copied().map(triangle_area).sum::<f64>() + 0.25;
        assert!((stats.total_area - area).abs() <= ROUNDING * area);
    }

    /// Whole triangles of one plane join one piece while their union stays convex and no
    /// contact runs along the edges they share; anything else starts a piece of its own.
    #[test]
    fn whole_coplanar_triangles_join_one_convex_piece() {
        let v = |x: f64, z: f64| DVec3::new(x, 0.0, z);
        // A square floor (facing +y) as two triangles sharing the diagonal (0,0)-(2,2).
        let square = [[v(0.0, 0.0), v(2.0, 2.0), v(2.0, 0.0)], [v(0.0, 0.0), v(0.0, 2.0), v(2.0, 2.0)]];
        let pieces = |surfaces: Vec<Surface>, lights: Vec<Light>| {
            let patches = tessellate(&scene_of(surfaces, lights), 0.5).unwrap();
            patches.pieces.iter().map(|p| (p.first, p.end)).collect::<Vec<_>>()
        };
        let floor = pieces(vec![surface(&square, false)], vec![]);
        assert_eq!(floor.len(), 1, "{floor:?}");
        // Two-sided: one piece too, its twins interleaved.
        assert_eq!(pieces(vec![surface(&square, true)], vec![]).len(), 1);

        // A wall standing on the diagonal: a contact along the shared edge, which cuts
        // nothing, keeps the halves apart.
        let wall = [[v(0.0, 0.0), v(2.0, 2.0), DVec3::new(1.0, 1.0, 1.0)]];
        let walled = pieces(vec![surface(&square, false), surface(&wall, false)], vec![]);
        assert_eq!(walled.len(), 3, "{walled:?}");
        let contacts =
            crate::scene::contact::contacts(&scene_of(vec![surface(&square, false), surface(&wall, false)], vec![]));
        assert!(contacts.pieces.is_empty(), "the wall on the diagonal cuts nothing");
        // Edge 0 of the first triangle and edge 2 of the second are the diagonal.
        assert_eq!(contacts.touched_edges.get(&(0, 0)), Some(&[true, false, false]));
        assert_eq!(contacts.touched_edges.get(&(0, 1)), Some(&[false, false, true]));

        // An L of three triangles: the third would make the union concave.
        let l_shape = [square[0], square[1], [v(2.0, 0.0), v(2.0, 2.0), v(4.0, -2.0)]];
        let mut bent = l_shape;
        bent[2] = [v(2.0, 0.0), v(2.0, 2.0), v(3.0, 0.0)];
        assert_eq!(pieces(vec![surface(&bent, false)], vec![]).len(), 1, "a convex pentagon");
        assert_eq!(pieces(vec![surface(&l_shape, false)], vec![]).len(), 2, "concave at (2, 0)");

        // Not in one plane, facing the other way, or not sharing an edge: apart.
        let mut folded = square;
        folded[1] = [v(0.0, 0.0), DVec3::new(0.0, 0.5, 2.0), v(2.0, 2.0)];
        assert_eq!(pieces(vec![surface(&folded, false)], vec![]).len(), 2);
        let mut flipped = square;
        flipped[1] = [v(0.0, 0.0), v(2.0, 2.0), v(0.0, 2.0)];
        assert_eq!(pieces(vec![surface(&flipped, false)], vec![]).len(), 2);
        let apart = [square[0], [v(0.0, 3.0), v(0.0, 5.0), v(2.0, 5.0)]];
        assert_eq!(pieces(vec![surface(&apart, false)], vec![]).len(), 2);
        // Two surfaces are never one piece, even where they meet edge to edge.
        assert_eq!(pieces(vec![surface(&square[..1], false), surface(&square[1..], false)], vec![]).len(), 2);
    }
}
