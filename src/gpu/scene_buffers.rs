//! The scene on the GPU: patches, materials, light samples, the triangles to rasterise and
//! the per-patch iteration state. Built once per render; stages bind what they need.

use super::bindings::{self, Binding, read};
use super::buffers;
use super::frustum::ChunkBoxes;
use crate::layout::*;
use crate::scene::{MaterialKind, PatchKind, Patches, SampleKind, Scene};
use glam::DVec3;

/// A per-patch array that may be larger than one storage binding: split over at most
/// `pages` buffers of `page_bytes / bytes` whole patches each (`Paged`), bound as one paged
/// binding (`gpu::bindings::Binding::paged`) that the WGSL reads through `<name>_at(i)`.
/// `pages` is fixed per array: every page is a storage binding of every kernel that reads the
/// array, within the device's storage buffers per shader stage (32 on lavapipe).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PerPatch {
    pub what: &'static str,
    /// Bytes per patch.
    pub bytes: u64,
    pub pages: u32,
}

impl PerPatch {
    /// Whole patches in one page of at most `page_bytes`.
    pub fn patches_per_page(&self, page_bytes: u64) -> u64 {
        page_bytes / self.bytes
    }
    /// The most patches the array holds with pages of at most `page_bytes`.
    pub fn capacity(&self, page_bytes: u64) -> u64 {
        self.pages as u64 * self.patches_per_page(page_bytes)
    }
}

/// The patch table (`GpuPatch`), read at random by patch id (image estimate, first shot).
pub const PATCH_TABLE: PerPatch = PerPatch { what: "the patch table", bytes: size_of::<GpuPatch>() as u64, pages: 8 };
/// The iteration state (`GpuPatchState`, 144 bytes a patch): 11 pages (10.25 M patches on
/// lavapipe, fewer than the patch table's 11.18 M); reflection then binds 32 storage buffers,
/// as many as lavapipe allows a stage, so a twelfth page would need a binding less there.
pub const PATCH_STATE: PerPatch =
    PerPatch { what: "the iteration state", bytes: size_of::<GpuPatchState>() as u64, pages: 11 };
/// O_j (vec4), read at random by the transfer.
pub const OUTGOING: PerPatch = PerPatch { what: "the outgoing radiance", bytes: 16, pages: 2 };
/// What each patch sends the image (`GpuImageSender`, 32 bytes), read at random by the
/// image's gather: one array in 3 pages where two of 16 bytes took 4, which made room in
/// reflection's 32 bindings for its bundle as a storage buffer (`bundle_reflect::SPEC`).
pub const IMAGE_SENDERS: PerPatch =
    PerPatch { what: "the image's senders", bytes: size_of::<GpuImageSender>() as u64, pages: 3 };
/// The transfer's signed 64-bit fixed-point sums (3 x 2 u32), added to at random.
pub const TRANSFER_SUMS: PerPatch = PerPatch { what: "the transfer sums", bytes: 24, pages: 2 };
/// The first shot's irradiance per patch (vec4).
pub const FIRST_SHOT_IRRADIANCE: PerPatch = PerPatch { what: "the first-shot irradiance", bytes: 16, pages: 2 };
/// The first shot's list of (patch, sample, r_ij) pairs (vec4<u32> a pair; "patches" are
/// pairs here), appended to at random: bounded by the lights' windows, not the patches, but
/// 45 faces of 512 x 512 can see more pairs than one 128 MiB binding holds (8.4 M). Not in
/// `PAGED_ARRAYS`: its length is known only once the first shot ran (`first_shot::run`).
/// 8 pages, so that a page as small as the patch table's holds a scene's pairs (4 to 5 a
/// patch in the Cornell box); the table's entries (8 bytes a pair, one binding) then bound
/// the pairs (`memory::max_pairs`: 16.7 M on lavapipe).
pub const FIRST_SHOT_PAIRS: PerPatch = PerPatch { what: "the first-shot pair list", bytes: 16, pages: 8 };
/// Every paged per-patch array.
pub const PAGED_ARRAYS: &[PerPatch] =
    &[PATCH_TABLE, PATCH_STATE, OUTGOING, IMAGE_SENDERS, TRANSFER_SUMS, FIRST_SHOT_IRRADIANCE];

/// The largest page of a paged array for a device: its largest storage binding (and buffer),
/// or `limit` if smaller (`RenderOptions::page_bytes`, a test knob that emulates a smaller
/// device). Each page is a buffer of its own, bound whole: no offset alignment applies.
pub fn page_bytes(limits: &wgpu::Limits, limit: Option<u64>) -> u64 {
    let device = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    limit.unwrap_or(u64::MAX).min(device)
}

/// The buffers of one paged per-patch array (`PerPatch`), in order; all but the last full.
/// A clone shares the buffers.
#[derive(Clone)]
pub struct Paged {
    pub pages: Vec<wgpu::Buffer>,
    /// Bytes of the whole array.
    pub bytes: u64,
}

impl Paged {
    fn split(array: PerPatch, n: u64, page_bytes: u64) -> Vec<std::ops::Range<u64>> {
        let per_page = array.patches_per_page(page_bytes).max(1);
        let count = n.div_ceil(per_page).max(1);
        assert!(
            count <= array.pages as u64,
            "{}: {n} patches need {count} pages of {per_page}, more than its {} (render::check_limits refuses that)",
            array.what,
            array.pages
        );
        (0..count).map(|k| k * per_page..((k + 1) * per_page).min(n).max(k * per_page + 1)).collect()
    }

    /// `n` patches of zeros.
    pub fn zeroed(
        device: &wgpu::Device,
        label: &str,
        array: PerPatch,
        n: u64,
        page_bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> Paged {
        let pages = Self::split(array, n, page_bytes)
            .into_iter()
            .enumerate()
            .map(|(k, r)| {
                buffers::storage_zeroed(device, &format!("{label}.page{k}"), (r.end - r.start) * array.bytes, extra)
            })
            .collect();
        Paged { pages, bytes: n.max(1) * array.bytes }
    }

    /// `data`, one element per patch.
    pub fn init<T: bytemuck::Pod>(
        device: &wgpu::Device,
        label: &str,
        array: PerPatch,
        data: &[T],
        page_bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> Paged {
        assert_eq!(size_of::<T>() as u64, array.bytes, "{}: one element per patch", array.what);
        let pages = Self::split(array, data.len() as u64, page_bytes)
            .into_iter()
            .enumerate()
            .map(|(k, r)| {
                let end = (r.end as usize).min(data.len());
                buffers::storage_init(device, &format!("{label}.page{k}"), &data[r.start as usize..end], extra)
            })
            .collect();
        Paged { pages, bytes: std::mem::size_of_val(data) as u64 }
    }

    /// `Paging::Whole` if the array has one page.
    pub fn paging(&self) -> crate::gpu::kernel::Paging {
        use crate::gpu::kernel::Paging;
        if self.pages.len() > 1 { Paging::Paged } else { Paging::Whole }
    }

    /// The binding resource of all pages.
    pub fn resource(&self) -> bindings::Resource<'_> {
        bindings::Resource::Pages(&self.pages)
    }

    /// Bytes of the whole array.
    pub fn size(&self) -> u64 {
        self.bytes
    }

    /// Records copies of the whole array into `to` (at least `size()` bytes), page by page.
    pub fn copy_to(&self, encoder: &mut wgpu::CommandEncoder, to: &wgpu::Buffer) {
        let mut at = 0;
        for page in &self.pages {
            let n = page.size().min(self.bytes - at);
            encoder.copy_buffer_to_buffer(page, 0, to, at, n);
            at += n;
        }
    }

    /// Records copies of the whole array from `from` (as laid out by `copy_to`).
    pub fn copy_from(&self, encoder: &mut wgpu::CommandEncoder, from: &wgpu::Buffer) {
        let mut at = 0;
        for page in &self.pages {
            let n = page.size().min(self.bytes - at);
            encoder.copy_buffer_to_buffer(from, at, page, 0, n);
            at += n;
        }
    }

    /// Writes the whole array (`size()` bytes) through `queue`, page by page.
    pub fn write(&self, queue: &wgpu::Queue, bytes: &[u8]) {
        assert_eq!(bytes.len() as u64, self.bytes);
        let mut at = 0usize;
        for page in &self.pages {
            let n = (page.size() as usize).min(bytes.len() - at);
            queue.write_buffer(page, 0, &bytes[at..at + n]);
            at += n;
        }
    }
}

/// GPU copies of the tessellated scene.
pub struct SceneBuffers {
    pub patch_count: u32,
    /// The largest page of the paged per-patch arrays (`page_bytes`).
    pub page_bytes: u64,
    pub patches: Paged,
    pub materials: wgpu::Buffer,
    /// `gpu_glossy_albedo`: the gather's control variate of the glossy lobe.
    pub glossy_albedo: wgpu::Buffer,
    pub samples: wgpu::Buffer,
    pub sample_count: u32,
    /// The triangles the rasterising stages draw (`raster_triangles`).
    pub raster: RasterMesh,
    /// `GpuPatchState` per patch (J_j, win_j).
    pub state: Paged,
    /// The first-shot factors r_ij, sparse by patch (empty until the first shot ran).
    pub first_shot: FirstShotTable,
    /// Bounding sphere of all geometry and light samples.
    pub centre: DVec3,
    pub radius: f64,
    /// Whether any material has a glossy lobe (`MATERIAL_PHONG`). Where none has, the image
    /// estimate is compiled without the glossy code (`constants`).
    pub glossy: bool,
    /// Whether any patch is a first-shot emitting shape whose light the image shares between
    /// its direct light and its gather (`GpuPatch::light_pick_area` > 0); where none is, the
    /// image estimate is compiled without that sharing (`constants`).
    pub shared_emitters: bool,
}

/// The material table as the GPU sees it; the last entry is black (area-light patches).
pub fn gpu_materials(scene: &Scene) -> Vec<GpuMaterial> {
    let mut out: Vec<GpuMaterial> = scene
        .materials
        .iter()
        .map(|m| match m.kind {
            MaterialKind::Diffuse { albedo } => GpuMaterial {
                diffuse: [albedo[0], albedo[1], albedo[2], 0.0],
                specular: [0.0; 4],
                kind: MATERIAL_DIFFUSE,
                glossy_control: 0.0,
                _pad: [0; 2],
            },
            MaterialKind::Phong { diffuse, specular, shininess } => GpuMaterial {
                diffuse: [diffuse[0], diffuse[1], diffuse[2], 0.0],
                specular: [specular[0], specular[1], specular[2], shininess],
                kind: if specular == [0.0; 3] { MATERIAL_DIFFUSE } else { MATERIAL_PHONG },
                glossy_control: crate::scene::brdf::glossy_control_weight(f64::from(shininess)) as f32,
                _pad: [0; 2],
            },
        })
        .collect();
    out.push(GpuMaterial::zeroed());
    out
}

/// The glossy-lobe albedo table (`scene::brdf::glossy_albedo_table`, for ks = 1) of each
/// material of `gpu_materials`, in its order, `GLOSSY_ALBEDO_SAMPLES` floats a material;
/// zeros for one without a glossy lobe.
pub fn gpu_glossy_albedo(materials: &[GpuMaterial]) -> Vec<f32> {
    let n = GLOSSY_ALBEDO_SAMPLES as usize;
    let mut out: Vec<f32> = Vec::with_capacity(materials.len() * n);
    for m in materials {
        if m.kind == MATERIAL_PHONG {
            out.extend(crate::scene::brdf::glossy_albedo_table(f64::from(m.specular[3])));
        } else {
            out.extend(std::iter::repeat_n(0.0, n));
        }
    }
    out
}

fn v4(v: DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

/// The patch table. `first_shot`: whether area lights and the first-shot triangles of
/// emitting shapes are first-shot lights (their emission is then left out of the iteration)
/// or plain emitters.
pub fn gpu_patches(scene: &Scene, patches: &Patches, first_shot: bool) -> Vec<GpuPatch> {
    use rayon::prelude::*;
    let black = scene.materials.len() as u32;
    let smooth = smooth_edges(patches);
    let pieces = piece_bits(patches);
    patches
        .patches
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let mut flags = smooth.get(i).copied().unwrap_or(0);
            if p.twin {
                flags |= PATCH_TWIN;
            }
            if first_shot && matches!(p.kind, PatchKind::AreaLight { .. } | PatchKind::Emitter { .. }) {
                flags |= PATCH_FIRST_SHOT_LIGHT;
            }
            GpuPatch {
                v0: v4(p.vertices[0], p.area),
                v1: v4(p.vertices[1], 0.0),
                v2: v4(p.vertices[2], 0.0),
                normal: v4(p.normal, p.normal.dot(p.vertices[0])),
                emission: [p.emission[0], p.emission[1], p.emission[2], 0.0],
                material: p.material.unwrap_or(black),
                flags,
                light_pick_area: light_pick_area(patches, p, first_shot) as f32,
                piece: pieces.get(i).copied().unwrap_or(0),
            }
        })
        .collect()
}

/// `GpuPatch::piece` of every patch, from `Patches::pieces` (0, a piece of its own, for a
/// patch in none).
pub fn piece_bits(patches: &Patches) -> Vec<u32> {
    let mut bits = vec![0u32; patches.patches.len()];
    for piece in &patches.pieces {
        let sides = piece.sides.max(1);
        let steps = (piece.end - piece.first) / sides;
        let twins = if sides == 2 { PIECE_TWINS } else { 0 };
        for i in piece.first..piece.end {
            let at = (i - piece.first) / sides;
            let before = at.min(PIECE_REACH);
            let after = (steps - 1 - at).min(PIECE_REACH);
            bits[i as usize] = twins | (before << PIECE_BEFORE_SHIFT) | after;
        }
    }
    bits
}

/// `PATCH_SMOOTH_EDGE` bits of every patch: for each edge (opposite vertex k), whether
/// another patch has the same two corners (as f32, what the GPU sees) and a plane within
/// `SMOOTH_EDGE_COS` of this one's, either way round. A two-sided surface's two sides (the
/// same three corners) are no neighbours of each other. Edges are matched by sorting (about
/// 32 bytes an edge, freed on return), not hashing, to keep a large scene's peak low.
pub fn smooth_edges(patches: &Patches) -> Vec<u32> {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicU32, Ordering};
    let key = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32].map(f32::to_bits);
    let corners = |i: u32| {
        let mut c = patches.patches[i as usize].vertices.map(key);
        c.sort_unstable();
        c
    };
    // (the edge's corners in order, patch, k) of every patch's three edges, on every core: at
    // 3.3 M patches the sort took 2 of the 4 s of the upload on one (docs/PERFORMANCE.md,
    // "Scaling"). Indexed, so that the list is built in place at its size (no second copy at
    // the peak); the flags do not depend on the order within a run.
    let mut edges: Vec<([[u32; 3]; 2], u32, u8)> = Vec::new();
    (0..3 * patches.patches.len())
        .into_par_iter()
        .map(|e| {
            let (i, k) = (e / 3, e % 3);
            let p = &patches.patches[i];
            let (a, b) = (key(p.vertices[(k + 1) % 3]), key(p.vertices[(k + 2) % 3]));
            ([a.min(b), a.max(b)], i as u32, k as u8)
        })
        .collect_into_vec(&mut edges);
    edges.par_sort_unstable_by_key(|e| e.0);
    let flags: Vec<AtomicU32> = (0..patches.patches.len()).map(|_| AtomicU32::new(0)).collect();
    edges.par_chunk_by(|x, y| x.0 == y.0).filter(|run| run.len() >= 2).for_each(|run| {
        for &(_, i, k) in run {
            let n = patches.patches[i as usize].normal;
            let smooth = run.iter().any(|&(_, other, _)| {
                other != i
                    && patches.patches[other as usize].normal.dot(n).abs() >= SMOOTH_EDGE_COS as f64
                    && corners(other) != corners(i)
            });
            if smooth {
                flags[i as usize].fetch_or(PATCH_SMOOTH_EDGE << k, Ordering::Relaxed);
            }
        }
    });
    flags.into_iter().map(AtomicU32::into_inner).collect()
}

/// T A_t for a patch of a first-shot emitting shape: the area that a direct-light pass's
/// point on its triangle side t stands for, T being the number of the shape's sides
/// (`direct_light.rs`); 0 for every other patch, and without first shot.
pub fn light_pick_area(patches: &Patches, p: &crate::scene::Patch, first_shot: bool) -> f64 {
    match p.kind {
        PatchKind::Emitter { emitter, side, .. } if first_shot => {
            let triangles = &patches.emitters[emitter as usize].triangles;
            triangles.len() as f64 * triangles[side as usize].area
        }
        _ => 0.0,
    }
}

/// How many triangles `raster_triangles` draws for `patches`, without building them: one a
/// patch, less each lattice's patches but its one triangle a side.
pub fn raster_triangle_count(patches: &Patches) -> u64 {
    let saved: u64 = patches.lattices.iter().map(|l| u64::from(l.sides) * (u64::from(l.k).pow(2) - 1)).sum();
    patches.patches.len() as u64 - saved
}

/// The triangles the rasterising stages draw, as two vertex streams: `RasterVertex` (position
/// and the first patch id with the twin bit) and the lattice word (`LATTICE_SIDE_MASK`,
/// `LATTICE_CORNER_SHIFT`, `LATTICE_TWINS`).
///
/// Why not one triangle per patch: the CPU adapter sets up and bins every triangle inside the
/// view on one thread, which made triangle count, not pixels, the cost of
/// the bundle's visibility and the camera's and the lights' item buffers wherever patches are
/// finer than a source triangle. So each source triangle that tessellation cut into a k x k
/// lattice (`Patches::lattices`) is drawn once per side, and the fragment finds its patch on
/// the lattice (`lattice_patch` in `wgsl/common/layout.wgsl`) from the lattice coordinates the
/// rasteriser interpolates; every other patch is drawn as itself (k = 1).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RasterTriangles {
    pub vertices: Vec<RasterVertex>,
    pub lattice: Vec<u32>,
}

impl RasterTriangles {
    fn push(&mut self, corners: [DVec3; 3], order: [u32; 3], patch: u32, word: u32) {
        for (v, corner) in corners.into_iter().zip(order) {
            self.vertices.push(RasterVertex { position: [v.x as f32, v.y as f32, v.z as f32], patch });
            self.lattice.push(word | corner << LATTICE_CORNER_SHIFT);
        }
    }

    pub fn triangle_count(&self) -> u32 {
        (self.vertices.len() / 3) as u32
    }
}

/// The rasterised triangles of `patches`, in patch order: a lattice's front (its front
/// patches' winding), then its back where it has twins (the winding reversed, as the twins
/// have it), instead of its patches.
pub fn raster_triangles(patches: &Patches) -> RasterTriangles {
    let mut out = RasterTriangles::default();
    let mut lattices = patches.lattices.iter().peekable();
    let mut i = 0usize;
    let twin = |p: &crate::scene::Patch| if p.twin { VERTEX_TWIN_BIT } else { 0 };
    while i < patches.patches.len() {
        if let Some(lattice) = lattices.next_if(|l| l.first as usize == i) {
            debug_assert!(lattice.k > 1 && lattice.k <= LATTICE_SIDE_MASK);
            let id = i as u32 | twin(&patches.patches[i]);
            let twins = if lattice.sides == 2 { LATTICE_TWINS } else { 0 };
            let [v0, v1, v2] = lattice.vertices;
            out.push([v0, v1, v2], [0, 1, 2], id, lattice.k | twins);
            if lattice.sides == 2 {
                out.push([v0, v2, v1], [0, 2, 1], id + 1, lattice.k | twins);
            }
            i += (lattice.sides * lattice.k * lattice.k) as usize;
            continue;
        }
        let p = &patches.patches[i];
        out.push(p.vertices, [0, 1, 2], i as u32 | twin(p), 1);
        i += 1;
    }
    out
}

/// The rasterised triangles on the GPU: `raster_triangles`' two streams, vertex buffers 0
/// and 1 of every rasterising pipeline (`camera_item_buffer::raster_vertex_layouts`).
pub struct RasterMesh {
    pub vertices: wgpu::Buffer,
    pub lattice: wgpu::Buffer,
    pub triangles: u32,
    /// Bounding boxes of runs of consecutive triangles, for `draw_in_view`.
    pub chunks: ChunkBoxes,
    /// Whether `draw_in_view` skips the chunks outside the view (the default); tests turn it
    /// off to check that the item buffers do not change.
    pub cull: bool,
    /// The first patch of each triangle (`set_fine_patches`).
    triangle_patches: Vec<u32>,
    /// The runs of triangles `draw_wide` draws: all of them unless `set_fine_patches` left
    /// some out.
    wide_runs: Vec<std::ops::Range<u32>>,
}

impl RasterMesh {
    pub fn new(device: &wgpu::Device, triangles: &RasterTriangles) -> Self {
        let usage = wgpu::BufferUsages::VERTEX;
        RasterMesh {
            vertices: buffers::storage_init(device, "firstshot.scene.raster_vertices", &triangles.vertices, usage),
            lattice: buffers::storage_init(device, "firstshot.scene.raster_lattice", &triangles.lattice, usage),
            triangles: triangles.triangle_count(),
            chunks: ChunkBoxes::of(&triangles.vertices),
            cull: true,
            triangle_patches: triangles.vertices.iter().step_by(3).map(|v| v.patch & !VERTEX_TWIN_BIT).collect(),
            wide_runs: std::iter::once(0..triangles.triangle_count()).collect(),
        }
    }

    /// Leaves the triangles of the patches `fine` says are fine out of `draw_wide`: a
    /// bundle's wide lines never meet them (`iteration::FineWindow`). Where they are
    /// scattered among the others in more than `MAX_WIDE_RUNS` runs, every triangle stays
    /// (the wide lines' draw leaves the fine window's fragments anyway).
    pub fn set_fine_patches(&mut self, fine: impl Fn(u32) -> bool) {
        const MAX_WIDE_RUNS: usize = 64;
        let mut runs: Vec<std::ops::Range<u32>> = Vec::new();
        for (t, &patch) in self.triangle_patches.iter().enumerate() {
            if fine(patch) {
                continue;
            }
            let t = t as u32;
            match runs.last_mut() {
                Some(run) if run.end == t => run.end = t + 1,
                _ => runs.push(t..t + 1),
            }
        }
        self.wide_runs = if runs.len() <= MAX_WIDE_RUNS { runs } else { std::iter::once(0..self.triangles).collect() };
    }

    /// Draws the triangles a bundle's wide lines can meet (`set_fine_patches`).
    pub fn draw_wide(&self, pass: &mut wgpu::RenderPass<'_>, instances: std::ops::Range<u32>) {
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_vertex_buffer(1, self.lattice.slice(..));
        for run in &self.wide_runs {
            pass.draw(run.start * 3..run.end * 3, instances.clone());
        }
    }

    /// Draws every triangle, once per instance of `instances`.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, instances: std::ops::Range<u32>) {
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_vertex_buffer(1, self.lattice.slice(..));
        pass.draw(0..self.triangles * 3, instances);
    }

    /// Draws, once per instance of `instances`, the triangles that can reach the top `rows`
    /// rows of `view` (all of them at its `size.y`): the chunks wholly outside are skipped
    /// (`frustum`), which changes no texel of the item buffer.
    pub fn draw_in_view(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        instances: std::ops::Range<u32>,
        view: &GpuCamera,
        rows: u32,
    ) {
        if !self.cull {
            return self.draw(pass, instances);
        }
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_vertex_buffer(1, self.lattice.slice(..));
        for run in self.chunks.visible(view, rows) {
            pass.draw(run.start * 3..run.end * 3, instances.clone());
        }
    }
}

/// The light-sample table.
pub fn gpu_samples(patches: &Patches) -> Vec<GpuLightSample> {
    patches
        .samples
        .iter()
        .map(|s| GpuLightSample {
            position: v4(s.position, 0.0),
            normal: v4(
                match s.kind {
                    SampleKind::Point => DVec3::ZERO,
                    SampleKind::AreaVertex { normal } => normal,
                    SampleKind::Spot { axis, .. } => axis,
                    SampleKind::Directional { direction } => direction,
                },
                s.weight,
            ),
            strength: [s.strength[0], s.strength[1], s.strength[2], 0.0],
            kind: match s.kind {
                SampleKind::Point => LIGHT_POINT,
                SampleKind::AreaVertex { .. } => LIGHT_AREA,
                SampleKind::Spot { .. } => LIGHT_SPOT,
                SampleKind::Directional { .. } => LIGHT_DIRECTIONAL,
            },
            cone_scale: match s.kind {
                SampleKind::Spot { cone, .. } => cone.scale as f32,
                _ => 0.0,
            },
            cone_offset: match s.kind {
                SampleKind::Spot { cone, .. } => cone.offset as f32,
                _ => 0.0,
            },
            _pad: 0,
        })
        .collect()
}

/// Bounding sphere of the patches and light samples, never of zero radius.
pub fn bounding_sphere(patches: &Patches) -> (DVec3, f64) {
    let (centre, radius) = crate::scene::tessellate::scene_bounds(patches);
    (centre, radius.max(1e-9))
}

/// How kernels reach the per-patch arrays (`PAGED_ARRAYS`) of `patch_count` patches in pages
/// of `page_bytes`: `Paging::Whole` when each fits in one page.
pub fn paging_of(patch_count: u64, page_bytes: u64) -> crate::gpu::kernel::Paging {
    let bytes: Vec<u64> = PAGED_ARRAYS.iter().map(|a| a.bytes).collect();
    crate::gpu::kernel::Paging::of(patch_count, &bytes, page_bytes)
}

impl SceneBuffers {
    /// How kernels reach the per-patch arrays of this scene (`paging_of`).
    pub fn paging(&self) -> crate::gpu::kernel::Paging {
        paging_of(self.patch_count as u64, self.page_bytes)
    }

    pub fn new(device: &wgpu::Device, scene: &Scene, patches: &Patches, first_shot: bool) -> SceneBuffers {
        Self::with_pages(device, scene, patches, first_shot, page_bytes(&device.limits(), None))
    }

    /// As `new`, the per-patch arrays in pages of at most `page_bytes` (`page_bytes`).
    pub fn with_pages(
        device: &wgpu::Device,
        scene: &Scene,
        patches: &Patches,
        first_shot: bool,
        page_bytes: u64,
    ) -> SceneBuffers {
        let gpu = gpu_patches(scene, patches, first_shot);
        let materials = gpu_materials(scene);
        let samples = gpu_samples(patches);
        let (centre, radius) = bounding_sphere(patches);
        let none = wgpu::BufferUsages::empty();
        let glossy = materials.iter().any(|m| m.kind == MATERIAL_PHONG);
        let shared_emitters = gpu.iter().any(|p| p.light_pick_area > 0.0);
        SceneBuffers {
            patch_count: gpu.len() as u32,
            page_bytes,
            patches: Paged::init(device, "firstshot.scene.patches", PATCH_TABLE, &gpu, page_bytes, none),
            materials: buffers::storage_init(device, "firstshot.scene.materials", &materials, none),
            glossy_albedo: buffers::storage_init(
                device,
                "firstshot.scene.glossy_albedo",
                &gpu_glossy_albedo(&materials),
                none,
            ),
            samples: buffers::storage_init(device, "firstshot.scene.light_samples", &samples, none),
            sample_count: samples.len() as u32,
            raster: RasterMesh::new(device, &raster_triangles(patches)),
            state: Paged::zeroed(
                device,
                "firstshot.scene.patch_state",
                PATCH_STATE,
                gpu.len() as u64,
                page_bytes,
                wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            ),
            first_shot: FirstShotTable::empty(device, gpu.len() as u32, page_bytes),
            centre,
            radius,
            glossy,
            shared_emitters,
        }
    }

    /// The `override` constants the image estimate's kernels are built with for this scene:
    /// `GLOSSY` (wgsl/common/brdf.wgsl) and `MIS` (wgsl/image_estimate.wgsl). A CPU adapter
    /// pays for the code of a branch that no invocation takes (docs/PERFORMANCE.md, "Branches
    /// cost both sides on the CPU adapter"), so the code of what the scene lacks is left out.
    pub fn constants(&self) -> [(&'static str, f64); 2] {
        [("GLOSSY", self.glossy as u32 as f64), ("MIS", self.shared_emitters as u32 as f64)]
    }
}

use bytemuck::Zeroable;

/// The first-shot factors in compressed-row form: the entries of patch j are
/// `entries[offsets[j]..offsets[j + 1]]`, each (light sample index, bits of r_ij as f32),
/// in ascending sample order.
pub struct FirstShotTable {
    /// patch_count + 1 u32.
    pub offsets: wgpu::Buffer,
    /// vec2<u32> per stored pair.
    pub entries: wgpu::Buffer,
    /// vec4<f32> per patch: rgb sum_i S_i r_ij (all a diffuse patch needs).
    pub irradiance: Paged,
    pub entry_count: u32,
}

/// Bind group 1 of the kernels that evaluate first-shot radiance
/// (`wgsl/common/first_shot_table.wgsl`), in their `KernelSpec`s.
pub const FIRST_SHOT_TABLE_GROUP: &[Binding] = &[
    // Row starts, patches + 1.
    read::<u32>("fs_offsets"),
    // (sample, bits of r_ij).
    read::<[u32; 2]>("fs_entries"),
    read::<GpuLightSample>("samples"),
    // rgb sum_i S_i r_ij per patch.
    read::<[f32; 4]>("fs_irradiance").paged(FIRST_SHOT_IRRADIANCE.pages),
];

impl FirstShotTable {
    /// The table as bind group 1 (`FIRST_SHOT_TABLE_GROUP`) over `layout`, with the light
    /// samples it indexes.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        paging: crate::gpu::kernel::Paging,
        samples: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        bindings::bind_group(
            device,
            "firstshot.first_shot_table.bind_group",
            layout,
            FIRST_SHOT_TABLE_GROUP,
            paging,
            &[
                ("fs_offsets", (&self.offsets).into()),
                ("fs_entries", (&self.entries).into()),
                ("samples", samples.into()),
                ("fs_irradiance", self.irradiance.resource()),
            ],
        )
    }

    /// No light pairs: every patch's row is empty.
    pub fn empty(device: &wgpu::Device, patch_count: u32, page_bytes: u64) -> Self {
        FirstShotTable {
            offsets: buffers::storage_zeroed(
                device,
                "firstshot.first_shot.offsets",
                4 * (patch_count as u64 + 1),
                wgpu::BufferUsages::COPY_SRC,
            ),
            entries: buffers::storage_zeroed(device, "firstshot.first_shot.entries", 16, wgpu::BufferUsages::COPY_SRC),
            irradiance: Paged::zeroed(
                device,
                "firstshot.first_shot.irradiance",
                FIRST_SHOT_IRRADIANCE,
                patch_count as u64,
                page_bytes,
                wgpu::BufferUsages::COPY_SRC,
            ),
            entry_count: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `piece_bits` read back as `in_piece` in wgsl/image_estimate.wgsl reads them: patch m is
    /// of j's piece exactly when the two are on one side of one `Piece` (twins interleaved
    /// in a two-sided one), and a piece longer than the reach is cut to it around each patch.
    #[test]
    fn piece_bits_name_the_patches_of_the_same_piece_and_side() {
        use crate::scene::{Patch, Piece};
        let in_piece = |m: u32, j: u32, bits: u32| {
            let step = if bits & PIECE_TWINS != 0 { 2 } else { 1 };
            let first = j - ((bits >> PIECE_BEFORE_SHIFT) & PIECE_REACH) * step;
            let last = j + (bits & PIECE_REACH) * step;
            m >= first && m <= last && (m - j).is_multiple_of(step)
        };
        let patch = Patch {
            vertices: [DVec3::ZERO, DVec3::X, DVec3::Y],
            normal: DVec3::Z,
            area: 0.5,
            material: Some(0),
            emission: [0.0; 3],
            kind: PatchKind::Surface { surface: 0 },
            twin: false,
        };
        // A patch of its own (0), a one-sided piece of 3, a two-sided piece of 2 x 3, a lone
        // patch again, and a one-sided piece past the reach.
        let long = 2 * PIECE_REACH + 10;
        let pieces = vec![
            Piece { first: 1, end: 4, sides: 1 },
            Piece { first: 4, end: 10, sides: 2 },
            Piece { first: 11, end: 11 + long, sides: 1 },
        ];
        let patches =
            Patches { patches: vec![patch; (11 + long) as usize], pieces: pieces.clone(), ..Default::default() };
        let bits = piece_bits(&patches);
        let piece_of = |i: u32| {
            pieces
                .iter()
                .position(|p| (p.first..p.end).contains(&i))
                .map(|k| (k, (i - pieces[k].first) % pieces[k].sides))
        };
        for j in 0..14 {
            for m in 0..14 {
                let same = j == m || (piece_of(j).is_some() && piece_of(j) == piece_of(m));
                assert_eq!(in_piece(m, j, bits[j as usize]), same, "patches {m} and {j}");
            }
        }
        // Past the reach: the reach either way of each patch, no further.
        let j = 11 + long / 2;
        assert!(in_piece(j - PIECE_REACH, j, bits[j as usize]) && !in_piece(j - PIECE_REACH - 1, j, bits[j as usize]));
        assert!(in_piece(j + PIECE_REACH, j, bits[j as usize]) && !in_piece(j + PIECE_REACH + 1, j, bits[j as usize]));
        assert!(in_piece(11 + long - 1, 11 + long - 1, bits[(11 + long - 1) as usize]));
        assert!(!in_piece(11 + long, 11 + long - 1, bits[(11 + long - 1) as usize]));
    }

    /// `smooth_edges` (sorted on every core) against the rule read plainly: every pair of
    /// patches that share an edge's two f32 corners, found through a map, on the shipped
    /// Sierpinski room (22 k patches: the fractal's creases and the walls' lattices),
    /// sun_room (boxes, a window's outline) and the benchmarks' glossy gallery (a two-sided
    /// screen, whose two sides share their corners and are no neighbours).
    #[test]
    fn smooth_edges_on_every_core_are_the_plain_rules() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        for name in ["scenes/sierpinski.toml", "scenes/sun_room.toml", "benches/scenes/glossy_gallery.toml"] {
            let scene = crate::scene::load::load(&root.join(name)).unwrap();
            let patches = crate::scene::tessellate(&scene, scene.settings.patch_size).unwrap();
            let key = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32].map(f32::to_bits);
            let mut sharing: std::collections::HashMap<[[u32; 3]; 2], Vec<(usize, usize)>> = Default::default();
            for (i, p) in patches.patches.iter().enumerate() {
                for k in 0..3 {
                    let (a, b) = (key(p.vertices[(k + 1) % 3]), key(p.vertices[(k + 2) % 3]));
                    sharing.entry([a.min(b), a.max(b)]).or_default().push((i, k));
                }
            }
            let same_triangle = |i: usize, j: usize| {
                let mut a = patches.patches[i].vertices.map(key);
                let mut b = patches.patches[j].vertices.map(key);
                a.sort_unstable();
                b.sort_unstable();
                a == b
            };
            let mut expected = vec![0u32; patches.patches.len()];
            for list in sharing.values() {
                for &(i, k) in list {
                    let n = patches.patches[i].normal;
                    if list.iter().any(|&(j, _)| {
                        j != i
                            && patches.patches[j].normal.dot(n).abs() >= SMOOTH_EDGE_COS as f64
                            && !same_triangle(i, j)
                    }) {
                        expected[i] |= PATCH_SMOOTH_EDGE << k;
                    }
                }
            }
            let flags = smooth_edges(&patches);
            let smooth = flags.iter().map(|f| f.count_ones()).sum::<u32>();
            assert!(smooth > 0 && (smooth as usize) < 3 * patches.patches.len(), "{name}: {smooth} smooth edges");
            assert_eq!(flags, expected, "{name}");
        }
    }

    /// A floor quad cut into patches, a box standing on it and a two-sided square: which
    /// edges `smooth_edges` finds smooth.
    #[test]
    fn smooth_edges_are_the_shared_ones_of_one_plane() {
        let text = r#"
format = 1
[camera]
position = [0.0, 3.0, -3.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 50.0
width = 8
height = 8
[settings]
patch_size = 0.5
[materials.grey]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]
[[shapes]]
type = "quad"
vertices = [[-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]]
material = "grey"
[[shapes]]
type = "box"
min = [3.0, 0.0, 0.0]
max = [4.0, 1.0, 1.0]
material = "grey"
[[shapes]]
type = "quad"
vertices = [[-1.0, 2.0, -1.0], [1.0, 2.0, -1.0], [1.0, 2.0, 1.0], [-1.0, 2.0, 1.0]]
material = "grey"
two_sided = true
[[lights]]
type = "directional"
direction = [0.0, -1.0, 0.2]
irradiance = [1.0, 1.0, 1.0]
"#;
        let scene = crate::scene::load::load_str(text, std::path::Path::new("memory/smooth.toml")).unwrap();
        let patches = crate::scene::tessellate(&scene, 0.5).unwrap();
        let flags = smooth_edges(&patches);
        // Both ends on the side |c| = 1 of a square of side 2 centred on the axis.
        let on_side = |a: f64, b: f64| (a.abs() - 1.0).abs() < 1e-9 && (a - b).abs() < 1e-9;
        let (mut floor_inner, mut floor_outline, mut box_edges, mut twins) = (0, 0, 0, 0);
        for (p, &f) in patches.patches.iter().zip(&flags) {
            for k in 0..3 {
                let (a, b) = (p.vertices[(k + 1) % 3], p.vertices[(k + 2) % 3]);
                let smooth = f & (PATCH_SMOOTH_EDGE << k) != 0;
                let mid = (a + b) / 2.0;
                if mid.x.abs() <= 1.0 && mid.y == 0.0 {
                    // The floor: its outline (|x| or |z| = 1 along the edge) is no neighbour's.
                    let outline = on_side(a.x, b.x) || on_side(a.z, b.z);
                    assert_eq!(smooth, !outline, "floor edge {a} - {b}");
                    if outline { floor_outline += 1 } else { floor_inner += 1 }
                } else if mid.x >= 3.0 {
                    // The box: a 90-degree edge between two faces is a crease.
                    let on_box_edge = [mid.x, mid.y, mid.z]
                        .iter()
                        .zip([3.0, 0.0, 0.0])
                        .filter(|(m, lo)| (**m - *lo).abs() < 1e-9 || (**m - *lo - 1.0).abs() < 1e-9)
                        .count()
                        >= 2;
                    if on_box_edge {
                        assert!(!smooth, "box edge {a} - {b}");
                        box_edges += 1;
                    }
                } else if mid.y == 2.0 && p.twin {
                    // Each side of a two-sided surface has the other side's neighbours, not the
                    // other side itself.
                    twins += 1;
                    let outline = on_side(a.x, b.x) || on_side(a.z, b.z);
                    assert_eq!(smooth, !outline, "two-sided edge {a} - {b}");
                }
            }
        }
        assert!(floor_inner > 0 && floor_outline > 0 && box_edges > 0 && twins > 0);
    }
}
