//! Every struct shared with WGSL, written once here and once in `wgsl/common/layout.wgsl`
//! (same names, same field order). `tests/layout_sync.rs` compares naga's offsets and sizes
//! with `offset_of!` and `size_of`, so the two copies cannot drift apart silently.
//!
//! Rules: `#[repr(C)]`, Pod, fields of u32 / f32 / 16-byte vectors, size a multiple of 16.

use bytemuck::{Pod, Zeroable};

/// Bits of `Patch::flags` (reach WGSL through the generated header, see `gpu::kernel`).
pub const PATCH_TWIN: u32 = 1;
/// The patch belongs to a first-shot light: its emission is seen by the camera but left out
/// of the iteration, where its first reflection replaces it (paper eq. 11).
pub const PATCH_FIRST_SHOT_LIGHT: u32 = 2;
/// `PATCH_SMOOTH_EDGE << k`: the edge opposite vertex k continues into another patch of the
/// scene within `SMOOTH_EDGE_COS` of this one's plane (the same surface goes on there), so
/// that a shadow test across that edge still meets the surface (a sun's, and a point's past a
/// patch its texels show); without the bit the edge is an outline or a crease
/// (`scene_buffers::smooth_edges`).
pub const PATCH_SMOOTH_EDGE: u32 = 4;
/// The cosine between two patches' planes within which they are taken for one (possibly
/// curved) surface: 30 degrees. The host's smooth edges use it, and WGSL's shadow test for
/// the planes near x that are x's neighbours (image_estimate.wgsl, `blocks`).
pub const SMOOTH_EDGE_COS: f32 = 0.866;
/// Item buffers store patch index + 1; this value means "no surface".
pub const NO_PATCH: u32 = 0;
/// Camera and cube item buffers pack the twin bit into the top bit of the vertex's patch id.
pub const VERTEX_TWIN_BIT: u32 = 1 << 31;
/// The lattice word of a rasterised vertex (the second vertex stream, `scene_buffers::
/// raster_triangles`): bits 0-15 k, the source triangle's lattice side (1 for a triangle that
/// is one patch), bits 16-17 which corner of the lattice the vertex is (0: v0 at (0, 0), 1:
/// v1 at (k, 0), 2: v2 at (0, k)), and `LATTICE_TWINS` where the lattice's twins interleave
/// with its patches. k <= 2^15 always: 2^25 patches at most.
pub const LATTICE_SIDE_MASK: u32 = 0xffff;
pub const LATTICE_CORNER_SHIFT: u32 = 16;
pub const LATTICE_TWINS: u32 = 1 << 18;
/// Sums that must not depend on thread order are accumulated as exact 64-bit integers
/// (two u32 atomics) of values in [0, 1] scaled by this.
pub const FIXED_POINT_SCALE: f32 = 2147483648.0;
/// Bundle fragments carry their patch's facing (front toward +d) in the top bit of the id.
pub const FRAGMENT_FRONT_BIT: u32 = 1 << 31;
/// `GpuBundle::image_step`: a step of the burn-in, a step of an image whose directions are
/// the run's blocks (`rng::stratified_direction`), or one of an image whose directions are
/// its own stratified set (`rng::image_direction`), which keeps Lbar_j as it was.
pub const BURN_IN_STEP: u32 = 0;
pub const IMAGE_STEP: u32 = 1;
pub const IMAGE_STEP_OWN_DIRECTIONS: u32 = 2;
/// Fragment slots each bundle line owns (`wgsl/bundle_visibility.wgsl`): a line's first
/// surfaces go there in one pass; the rest spill into a list chained per line. 8 slots of
/// 8 bytes are one 64-byte cache line.
pub const LINE_BUCKET: u32 = 8;
/// Entries of the bundle's `tally` (u32 counters, cleared every step): spill nodes taken and
/// lines listed as long by bundle_visibility, fragments of the long lines' slices taken by
/// bundle_transfer.
pub const TALLY_SPILLED: u32 = 0;
pub const TALLY_LONG: u32 = 1;
pub const TALLY_LONG_LINES: u32 = 2;
/// Workgroups (of 64) of bundle_transfer's `gather_long_lines`, which stride over the list of
/// long lines: a fixed grid, since the list's length is known only on the GPU.
pub const LONG_LINES_WORKGROUPS: u32 = 64;
/// Prefix sums: invocations per workgroup, and values each scans in a run of its own (long
/// runs keep the barrier-bound workgroup scan a small share of the work on CPU adapters).
pub const PREFIX_SUM_WORKGROUP: u32 = 256;
pub const PREFIX_SUM_PER_THREAD: u32 = 16;
/// Texels of a face's row that one invocation of the first shot's `reduce_face` adds up: a
/// run of them seen through one patch is one pair of atomic adds, not one a texel (the
/// atomics and the patch loads were most of the first shot's time on the CPU adapter).
pub const FIRST_SHOT_RUN: u32 = 8;
/// `LightSample::kind` and `DirectLight::kind`: a point light, or a point on an area light
/// (a vertex of its mesh in the first shot, a point drawn on it in the direct light), a
/// spot light or a directional light.
pub const LIGHT_POINT: u32 = 0;
pub const LIGHT_AREA: u32 = 1;
/// A spot light: a point light whose light falls off with its cone (`scene::SpotCone`).
pub const LIGHT_SPOT: u32 = 2;
/// A directional light (sun): parallel light, seen through one orthographic view.
pub const LIGHT_DIRECTIONAL: u32 = 3;
/// `Camera::size.z`: the view is a parallel (orthographic) projection, not a pinhole.
pub const VIEW_ORTHOGRAPHIC: u32 = 1;
/// `Material::kind`: which BRDF a material evaluates (`scene::MaterialKind`). A max-Phong
/// material without a specular lobe is uploaded as diffuse: it is exactly Lambertian.
pub const MATERIAL_DIFFUSE: u32 = 0;
pub const MATERIAL_PHONG: u32 = 1;
/// Samples of each material's glossy-lobe albedo table (`scene::brdf::glossy_albedo_table`):
/// at cos theta = (i / (GLOSSY_ALBEDO_SAMPLES - 1))^2.
pub const GLOSSY_ALBEDO_SAMPLES: u32 = 129;
/// The most patches a scene may have (ids must leave the twin bit free).
pub const MAX_PATCHES: u32 = 1 << 27;

/// One triangular patch. WGSL: `Patch`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuPatch {
    /// xyz: vertex 0; w: area A_j.
    pub v0: [f32; 4],
    /// xyz: vertex 1.
    pub v1: [f32; 4],
    /// xyz: vertex 2.
    pub v2: [f32; 4],
    /// xyz: unit front normal; w: plane offset dot(n, v0).
    pub normal: [f32; 4],
    /// rgb: emitted radiance on the front side.
    pub emission: [f32; 4],
    /// Index into the material table (black for area-light patches).
    pub material: u32,
    /// `PATCH_*` bits.
    pub flags: u32,
    /// For a patch of a first-shot emitting shape: the area that a direct-light pass's point
    /// on its triangle side stands for (T A_t, `direct_light.rs`), which gives the density
    /// of those points for multiple importance sampling (docs/ALGORITHM.md 6); else 0.
    pub light_pick_area: f32,
    /// The patch's piece for the image's gather (`scene::Piece`, `piece_bits`): how many
    /// steps before and after it its piece reaches (steps of 2 patches with `PIECE_TWINS`,
    /// of 1 without); 0 for a piece of its own.
    pub piece: u32,
}

/// `GpuPatch::piece`: the steps to the piece's last patch (bits 0-14), to its first (bits
/// 15-29), and whether twins interleave (bit 30). Pieces longer than `PIECE_REACH` steps
/// either way are cut to that reach around each patch, which only narrows what the gather
/// treats as one surface. WGSL: the same constants (`wgsl_constants`).
pub const PIECE_REACH: u32 = 0x7fff;
pub const PIECE_BEFORE_SHIFT: u32 = 15;
pub const PIECE_TWINS: u32 = 1 << 30;

/// A material in the unified max-Phong form (diffuse = Phong with ks = 0). WGSL: `Material`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuMaterial {
    /// rgb: kd (the diffuse albedo).
    pub diffuse: [f32; 4],
    /// rgb: ks; w: shininess n.
    pub specular: [f32; 4],
    /// `MATERIAL_*`.
    pub kind: u32,
    /// The weight c of the glossy lobe's control variate in the image's gather
    /// (`scene::brdf::glossy_control_weight`); 0 without a glossy lobe.
    pub glossy_control: f32,
    pub _pad: [u32; 2],
}

/// One light sample y_i of the first shot. WGSL: `LightSample`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuLightSample {
    /// xyz: y_i.
    pub position: [f32; 4],
    /// xyz: the area light's normal n_L, the spot light's axis, the directional light's
    /// direction of travel; w: trapezoid weight w_i.
    pub normal: [f32; 4],
    /// rgb: S_i (power of a point light, radiance of an area light, intensity of a spot
    /// light on its axis, irradiance of a directional light).
    pub strength: [f32; 4],
    /// `LIGHT_*`.
    pub kind: u32,
    /// A spot light's cone (`scene::SpotCone`): falloff = clamp(cd scale + offset, 0, 1)^2.
    pub cone_scale: f32,
    pub cone_offset: f32,
    pub _pad: u32,
}

/// Iteration state of one patch (docs/ALGORITHM.md 2): J_j and the direction win_j it travelled.
/// WGSL: `PatchState`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuPatchState {
    /// rgb: J_j; w: how many of `earlier` hold a step's J (at most `GLOSSY_HISTORY`).
    pub incoming: [f32; 4],
    /// K_j = J_j - (|n_j . d| - 1/2) Lbar_j, J_j with its control variate: what the patch
    /// reflects diffusely (docs/ALGORITHM.md 2.4).
    pub diffuse: [f32; 3],
    /// win_j, the direction of travel of J_j's light (unit), as its octahedral map in 32
    /// bits (`octahedral_pack` in wgsl/common/layout.wgsl, two snorm16: about 1e-4 rad),
    /// the form the history keeps it in; 0 before step 1. In the 4 bytes beside `diffuse`,
    /// not a vec4 of its own: 16 bytes a patch less, which the longer history took.
    pub direction: u32,
    /// rgb: Lbar_j, a running estimate of the mean radiance arriving at the patch (the
    /// control variate's weight).
    pub mean_radiance: [f32; 4],
    /// rgb: the sum of K_j over the image steps so far; w: their number. The image's senders
    /// reflect its mean diffusely (docs/ALGORITHM.md 6).
    pub diffuse_sum: [f32; 4],
    /// The J_j of the `GLOSSY_HISTORY` bundles before this one, newest first: x J's rgb in
    /// 32 bits (`pack_history_radiance` in wgsl/common/layout.wgsl: a shared exponent and
    /// three signed 8-bit mantissas), y its direction win (octahedral, `pack2x16snorm`);
    /// `incoming`'s w counts those written. With `incoming` they are the samples of win
    /// whose glossy reflections the transfer and the image's senders average
    /// (docs/ALGORITHM.md 2.2 and 6).
    pub earlier: [[u32; 2]; GLOSSY_HISTORY],
}

/// Earlier bundles' J_j kept per patch for the glossy reflection (`GpuPatchState::earlier`;
/// WGSL: `GLOSSY_HISTORY`): ten packed entries, so that the mean spans eleven bundles
/// (with four bundles a step, most of three steps' lines); six had 8 % more squared error
/// on the Sierpinski scene (docs/PERFORMANCE.md, "A longer glossy history").
pub const GLOSSY_HISTORY: usize = 10;

/// What a patch sends the image's gather in a step, written by `bundle_reflect` and read by
/// the image estimate at random by patch id; one array (`scene_buffers::IMAGE_SENDERS`) so
/// that it takes as few storage bindings as it can. WGSL: `ImageSender`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuImageSender {
    /// rgb: what the image gathers from the patch (its diffuse reflection of the mean J of
    /// the image steps so far, with the glossy part and the first shot's); w: s_j, or,
    /// where the image evaluates near senders' first bounce per point, the largest channel
    /// of Lfs_j (`pack_first_bounce` in wgsl/bundle_reflect.wgsl).
    pub outgoing: [f32; 4],
    /// rgb: Lbar_j as this step found it, before finalize updates it: the control variate
    /// of the gather at the patch's own pixels; w: 0, or the other two channels of Lfs_j.
    pub mean_radiance: [f32; 4],
}

/// A pinhole camera with the sub-pixel position of this pass's sample. WGSL: `Camera`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuCamera {
    /// xyz: eye position.
    pub eye: [f32; 4],
    /// xyz: unit image right; w: tan(fov_x / 2).
    pub right: [f32; 4],
    /// xyz: unit image up; w: tan(fov_y / 2).
    pub up: [f32; 4],
    /// xyz: unit view direction; w: near distance of the reversed-z projection (for an
    /// orthographic view: the far distance of its linear depth 1 - z / far).
    pub forward: [f32; 4],
    /// xy: sample position inside the pixel, each in [0, 1); zw: centre of the view window
    /// in tangent units (0 for a camera; off-centre for the faces of a cubic tetrahedron).
    pub jitter: [f32; 4],
    /// x: width, y: height in pixels; z: `VIEW_ORTHOGRAPHIC` for a parallel projection (then
    /// `right.w` and `up.w` are the half extents of the view in scene units), else 0; w: for a
    /// camera whose item buffer is supersampled (`camera_item_buffer::camera_supersample`),
    /// its texels per pixel side S in bits 0-7 and the texel of this step's sample inside a
    /// pixel's S x S in bits 8-15 (x) and 16-23 (y) (`camera_texel` in WGSL); else 0.
    pub size: [u32; 4],
}

/// Per-pass parameters of the image estimate. WGSL: `EstimateParams`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuEstimateParams {
    /// rgb: environment radiance seen where no surface is.
    pub environment: [f32; 4],
    /// Number of patches (ids at or above are invalid).
    pub patch_count: u32,
    /// Entries of the direct-light table.
    pub light_count: u32,
    /// 1 when the image gathers (G) as well: the direct light of emitting shapes is then
    /// shared between D and G by multiple importance sampling; 0 for a direct-light image.
    pub mis: u32,
    /// The image row where this band of the image sum starts (`image_estimate`'s bands).
    pub first_row: u32,
    /// 1 when the image gathers: the emission Le a pixel sees is then added by the gather on
    /// every step, and `direct` leaves it out; 0 for a direct-light image (Le with D). The
    /// environment stays with D either way.
    pub seen_in_gather: u32,
    pub _pad: [u32; 3],
}

/// A light as the per-pixel direct light sees it in one pass (docs/ALGORITHM.md 6). WGSL:
/// `DirectLight`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuDirectLight {
    /// xyz: the point or spot light's position, or this pass's point y on the area light
    /// (unused for a directional light).
    pub position: [f32; 4],
    /// xyz: the area light's unit normal n_L, the spot light's axis, the directional light's
    /// direction of travel (zero for a point light).
    pub normal: [f32; 4],
    /// rgb: what multiplies V f cos / r^2: a point light's intensity power / (4 pi), a spot
    /// light's intensity on its axis (times its falloff); for an area light, its radiance
    /// times the area this pass's point stands for (cos_L too); what multiplies V f cos for
    /// a directional light: its irradiance.
    pub strength: [f32; 4],
    /// x, y: a spot light's cone scale and offset (`scene::SpotCone`); else 0.
    pub cone: [f32; 4],
    /// `LIGHT_*`.
    pub kind: u32,
    /// The faces of the light's window in the face table: `first_face..first_face + faces`.
    pub first_face: u32,
    pub faces: u32,
    pub _pad: u32,
}

/// One face of a light's window in the shadow atlas: a view, and where its item buffer lies.
/// WGSL: `WindowFace`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuWindowFace {
    /// The face's view (`size` = its full square in pixels, `jitter` = texel centres).
    pub view: GpuCamera,
    /// x, y: the tile's top-left texel in the atlas; z: rows of the face in the window (the
    /// half faces of a hemicube stop early).
    pub tile: [u32; 4],
}

/// A node of the shadow rays' BVH (`shadow_bvh`), in depth-first order, 16 bytes: its box as
/// six half floats in the tree's frame (`ShadowBvh::frame`; min x y, min z max x, max y z,
/// each pair as WGSL's `pack2x16float`), and `link`: for an inner node, whose first child is
/// the next node, the node to go on with where a segment misses its box (its escape); for a
/// leaf, whose escape is always the next node, `shadow_bvh::LEAF` | its first triangle <<
/// `LEAF_COUNT_BITS` | (its triangle count - 1). WGSL: `BvhNode`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuBvhNode {
    pub bounds: [u32; 3],
    pub link: u32,
}

/// A triangle of the shadow rays' BVH, as the segment test wants it: a corner and the two
/// edges from it; and which patch a ray that meets it meets (`shadow_bvh::ShadowBvh::build`):
/// `first_patch` the first patch of its rasterised triangle (the back's, where it has one,
/// is first_patch + 1), `lattice` corner v0's lattice word, `corners` the lattice corners of v1 and v2
/// (bits 0-1, 2-3) and `BVH_TRIANGLE_BACK` where a twin reflects its back. WGSL: `BvhTriangle`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuBvhTriangle {
    pub v0: [f32; 3],
    pub first_patch: u32,
    pub e1: [f32; 3],
    pub lattice: u32,
    pub e2: [f32; 3],
    pub corners: u32,
}

/// `GpuBvhTriangle::corners`: the triangle's surface has a twin, its back (first_patch + 1).
pub const BVH_TRIANGLE_BACK: u32 = 1 << 4;

/// One face of a light sample's window, for the first-shot reduction.
/// WGSL: `FaceParams`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuFaceParams {
    /// Index of the light sample.
    pub sample: u32,
    /// Number of patches (ids above are invalid).
    pub patch_count: u32,
    /// Rows of the face that lie in the window (half faces of a hemicube stop early).
    pub rows: u32,
    pub _pad: u32,
}

/// Parameters of turning a sample's sums into r_ij and appending them. WGSL: `AppendParams`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuAppendParams {
    pub sample: u32,
    pub patch_count: u32,
    /// Capacity of the pair list; pairs past it are counted, not written.
    pub capacity: u32,
    pub _pad0: u32,
    /// Solid angle of a pixel at the face centre times 1/(4 pi) (point light) or w_i
    /// (area-light vertex), divided by the fixed-point scale.
    pub factor: f32,
    pub _pad1: [u32; 3],
}

/// One ray bundle: a global direction and the parallel projection grid around it.
/// WGSL: `Bundle`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuBundle {
    /// xyz: the bundle's direction d (unit); w: pixel area dP.
    pub direction: [f32; 4],
    /// xyz: grid axis u divided by the grid's half extent (clip x = dot(p - centre, u));
    /// w: the grid's random sub-pixel shift in clip units.
    pub axis_u: [f32; 4],
    /// As `axis_u`, for the grid's y axis.
    pub axis_v: [f32; 4],
    /// xyz: centre of the scene's bounding sphere; w: 1 / radius.
    pub centre: [f32; 4],
    /// rgb: environment radiance.
    pub environment: [f32; 4],
    /// Pixels along each edge of the grid.
    pub resolution: u32,
    pub patch_count: u32,
    /// Capacity of the spill list and of the long lines' slices (fragments past the lines'
    /// buckets).
    pub capacity: u32,
    /// 1 once the iteration state holds J (after step 1).
    pub use_state: u32,
    /// `BURN_IN_STEP`, or past the burn-in, `IMAGE_STEP` or `IMAGE_STEP_OWN_DIRECTIONS`:
    /// its J joins the running sum of the state.
    pub image_step: u32,
    /// The image's gather through this bundle takes one pixel of each pixel_stride x
    /// pixel_stride block (`pixel_shuffle`): one class of the interleaved bundles of a step
    /// (`iteration::BUNDLES_PER_STEP`).
    pub pixel_class: u32,
    /// 1 (every pixel gathers through the one bundle of a step) or 2 (four bundles a step).
    pub pixel_stride: u32,
    /// The image's shuffle of the classes within each 2 x 2 block, the same for a step's four
    /// bundles and for every step of the image: block b's pixel at offset (pixel_class +
    /// hash(b, pixel_shuffle)) mod 4 gathers through bundle pixel_class, so that every pixel
    /// gathers once a step, always through the same bundle (whose directions are a
    /// stratified set, `rng::image_direction`), and no fixed pattern of classes shows.
    pub pixel_shuffle: u32,
    /// The fine window of a grid of two levels (`iteration::FineWindow`): x0, y0, width and
    /// height in fine lines, multiples of `wide`. Its lines are the grid's own; outside
    /// it every `wide` x `wide` block of them is one wide line. With one level (wide
    /// 1) the whole grid: 0, 0, resolution, resolution.
    pub fine_rect: [u32; 4],
    /// Fine lines along a wide line's edge: 1 (one level), 2 or 4.
    pub wide: u32,
    /// Lines the buffers hold (their allocation): the transfer's fragment list starts the
    /// long lines' slices past that many buckets.
    pub line_capacity: u32,
    /// Wide lines, (resolution / wide)^2, numbered first; 0 with one level.
    pub wide_lines: u32,
    /// This bundle's lines: wide_lines + the fine window's width x height.
    pub line_count: u32,
}

/// A vertex of the rasterised patch triangles: position and patch id (with
/// `VERTEX_TWIN_BIT`). Only a vertex buffer, so it has no WGSL struct.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct RasterVertex {
    pub position: [f32; 3],
    pub patch: u32,
}

macro_rules! assert_size_multiple_of_16 {
    ($($t:ty),*) => { $(const _: () = assert!(std::mem::size_of::<$t>() % 16 == 0);)* };
}
assert_size_multiple_of_16!(
    GpuPatch,
    GpuMaterial,
    GpuLightSample,
    GpuPatchState,
    GpuImageSender,
    GpuCamera,
    GpuEstimateParams,
    GpuDirectLight,
    GpuWindowFace,
    GpuBvhNode,
    GpuBvhTriangle,
    GpuFaceParams,
    GpuAppendParams,
    GpuBundle,
    RasterVertex
);

/// One shared struct as the sync test sees it: (WGSL name, size, [(field, offset)]).
pub type StructLayout = (&'static str, usize, Vec<(&'static str, usize)>);

macro_rules! layout {
    ($t:ty => $wgsl:literal { $($f:ident),* $(,)? }) => {
        ($wgsl, std::mem::size_of::<$t>(), vec![$((stringify!($f), std::mem::offset_of!($t, $f))),*])
    };
}

/// The layouts of every struct mirrored in `wgsl/common/layout.wgsl` (padding excluded).
pub fn shared_layouts() -> Vec<StructLayout> {
    vec![
        layout!(GpuPatch => "Patch" { v0, v1, v2, normal, emission, material, flags, light_pick_area, piece }),
        layout!(GpuMaterial => "Material" { diffuse, specular, kind, glossy_control }),
        layout!(GpuLightSample => "LightSample" { position, normal, strength, kind, cone_scale, cone_offset }),
        layout!(GpuPatchState => "PatchState" { incoming, diffuse, direction, mean_radiance, diffuse_sum, earlier }),
        layout!(GpuImageSender => "ImageSender" { outgoing, mean_radiance }),
        layout!(GpuCamera => "Camera" { eye, right, up, forward, jitter, size }),
        layout!(GpuEstimateParams => "EstimateParams" { environment, patch_count, light_count, mis, first_row }),
        layout!(GpuDirectLight => "DirectLight" { position, normal, strength, cone, kind, first_face, faces }),
        layout!(GpuWindowFace => "WindowFace" { view, tile }),
        layout!(GpuBvhNode => "BvhNode" { bounds, link }),
        layout!(GpuBvhTriangle => "BvhTriangle" { v0, first_patch, e1, lattice, e2, corners }),
        layout!(GpuFaceParams => "FaceParams" { sample, patch_count, rows }),
        layout!(GpuAppendParams => "AppendParams" { sample, patch_count, capacity, factor }),
        layout!(GpuBundle => "Bundle" { direction, axis_u, axis_v, centre, environment, resolution, patch_count, capacity, use_state, image_step, pixel_class, pixel_stride, pixel_shuffle, fine_rect, wide, line_capacity, wide_lines, line_count }),
    ]
}

/// Constants that WGSL needs, emitted as a header in front of every kernel so that they
/// are written once (here).
pub fn wgsl_constants() -> String {
    format!(
        "const PATCH_TWIN: u32 = {PATCH_TWIN}u;\n\
         const PATCH_FIRST_SHOT_LIGHT: u32 = {PATCH_FIRST_SHOT_LIGHT}u;\n\
         const PATCH_SMOOTH_EDGE: u32 = {PATCH_SMOOTH_EDGE}u;\n\
         const NO_PATCH: u32 = {NO_PATCH}u;\n\
         const PIECE_REACH: u32 = {PIECE_REACH}u;\n\
         const PIECE_BEFORE_SHIFT: u32 = {PIECE_BEFORE_SHIFT}u;\n\
         const PIECE_TWINS: u32 = {PIECE_TWINS}u;\n\
         const VERTEX_TWIN_BIT: u32 = {VERTEX_TWIN_BIT}u;\n\
         const LATTICE_SIDE_MASK: u32 = {LATTICE_SIDE_MASK}u;\n\
         const LATTICE_CORNER_SHIFT: u32 = {LATTICE_CORNER_SHIFT}u;\n\
         const LATTICE_TWINS: u32 = {LATTICE_TWINS}u;\n\
         const BVH_TRIANGLE_BACK: u32 = {BVH_TRIANGLE_BACK}u;\n\
         const FRAGMENT_FRONT_BIT: u32 = {FRAGMENT_FRONT_BIT}u;\n\
         const BURN_IN_STEP: u32 = {BURN_IN_STEP}u;\n\
         const IMAGE_STEP: u32 = {IMAGE_STEP}u;\n\
         const IMAGE_STEP_OWN_DIRECTIONS: u32 = {IMAGE_STEP_OWN_DIRECTIONS}u;\n\
         const LINE_BUCKET: u32 = {LINE_BUCKET}u;\n\
         const TALLY_SPILLED: u32 = {TALLY_SPILLED}u;\n\
         const TALLY_LONG: u32 = {TALLY_LONG}u;\n\
         const TALLY_LONG_LINES: u32 = {TALLY_LONG_LINES}u;\n\
         const LONG_LINES_WORKGROUPS: u32 = {LONG_LINES_WORKGROUPS}u;\n\
         const LIGHT_POINT: u32 = {LIGHT_POINT}u;\n\
         const LIGHT_AREA: u32 = {LIGHT_AREA}u;\n\
         const LIGHT_SPOT: u32 = {LIGHT_SPOT}u;\n\
         const LIGHT_DIRECTIONAL: u32 = {LIGHT_DIRECTIONAL}u;\n\
         const VIEW_ORTHOGRAPHIC: u32 = {VIEW_ORTHOGRAPHIC}u;\n\
         const MATERIAL_DIFFUSE: u32 = {MATERIAL_DIFFUSE}u;\n\
         const MATERIAL_PHONG: u32 = {MATERIAL_PHONG}u;\n\
         const GLOSSY_ALBEDO_SAMPLES: u32 = {GLOSSY_ALBEDO_SAMPLES}u;\n\
         const PREFIX_SUM_WORKGROUP: u32 = {PREFIX_SUM_WORKGROUP}u;\n\
         const PREFIX_SUM_PER_THREAD: u32 = {PREFIX_SUM_PER_THREAD}u;\n\
         const FIRST_SHOT_RUN: u32 = {FIRST_SHOT_RUN}u;\n\
         const GLOSSY_HISTORY: u32 = {GLOSSY_HISTORY}u;\n\
         const SHADOW_LEAF: u32 = {SHADOW_LEAF}u;\n\
         const SHADOW_LEAF_COUNT_BITS: u32 = {SHADOW_LEAF_COUNT_BITS}u;\n\
         const PI: f32 = {pi:?};\n\
         const FIXED_POINT_SCALE: f32 = {scale:?};\n\
         const SMOOTH_EDGE_COS: f32 = {smooth:?};\n",
        SHADOW_LEAF = crate::shadow_bvh::LEAF,
        SHADOW_LEAF_COUNT_BITS = crate::shadow_bvh::LEAF_COUNT_BITS,
        pi = std::f32::consts::PI,
        scale = FIXED_POINT_SCALE,
        smooth = SMOOTH_EDGE_COS
    )
}
