// Structs shared with the Rust host, mirrored field for field from `src/layout.rs`
// (`tests/layout_sync.rs` compares the offsets). Constants come from the generated header.

// One triangular patch (Rust: GpuPatch).
struct Patch {
    v0: vec4<f32>,       // xyz vertex 0, w area
    v1: vec4<f32>,
    v2: vec4<f32>,
    normal: vec4<f32>,   // xyz unit front normal, w dot(n, v0)
    emission: vec4<f32>, // rgb emitted radiance on the front
    material: u32,
    flags: u32,          // PATCH_* bits
    light_pick_area: f32, // first-shot emitting shape: T A_t of its side (MIS), else 0
    piece: u32,           // the patch's piece for the gather (Rust: GpuPatch::piece)
}

// Unified max-Phong material (Rust: GpuMaterial).
struct Material {
    diffuse: vec4<f32>,  // rgb kd
    specular: vec4<f32>, // rgb ks, w shininess
    kind: u32,           // MATERIAL_*
    glossy_control: f32, // c of the glossy control variate (scene::brdf::glossy_control_weight)
    _pad1: u32,
    _pad2: u32,
}

// A first-shot light sample (Rust: GpuLightSample).
struct LightSample {
    position: vec4<f32>, // xyz y_i
    normal: vec4<f32>,   // xyz n_L, spot axis or directional direction of travel; w trapezoid weight
    strength: vec4<f32>, // rgb S_i
    kind: u32,           // LIGHT_*
    cone_scale: f32,     // spot: falloff = clamp(cd cone_scale + cone_offset, 0, 1)^2
    cone_offset: f32,
    _pad0: u32,
}

// Iteration state of a patch (Rust: GpuPatchState).
struct PatchState {
    incoming: vec4<f32>,  // rgb J_j, w how many of `earlier` are written
    diffuse: vec3<f32>,   // K_j = J_j - (|n_j . d| - 1/2) Lbar_j, reflected diffusely
    direction: u32,       // win_j (octahedral_pack), 0 before step 1
    mean_radiance: vec4<f32>, // rgb Lbar_j, running estimate of the mean incoming radiance
    diffuse_sum: vec4<f32>, // rgb the sum of K_j over the image steps so far, w their number
    // J_j of the GLOSSY_HISTORY bundles before, newest first: x J's rgb
    // (pack_history_radiance), y win (octahedral_pack); the glossy reflection averages them.
    earlier: array<vec2<u32>, GLOSSY_HISTORY>,
}

// What a patch sends the image's gather this step (Rust: GpuImageSender).
struct ImageSender {
    outgoing: vec4<f32>,      // rgb what the image gathers from it, w s_j or Lfs_j's top
    mean_radiance: vec4<f32>, // rgb Lbar_j before this step, w 0 or Lfs_j's rest
}

// An rgb radiance (of either sign per channel) in 32 bits for the glossy history: a shared
// binary exponent e (8 bits: the largest magnitude within [63.5, 127.5) units of 2^(e-7))
// and each channel as a signed 8-bit multiple of that unit, rounded to nearest: each
// within half a unit, the largest channel within 0.8 %. The history's samples vary from
// step to step, so the rounding is noise of under a per cent against samples that vary by
// their own size, not a bias. (Three floats and a direction took 16 bytes an entry, this
// 8: twice the entries in the same state.)
fn pack_history_radiance(v: vec3<f32>) -> u32 {
    let largest = max(abs(v.x), max(abs(v.y), abs(v.z)));
    if (!(largest > 0.0)) {
        return 0u;
    }
    // Where the largest channel would round up to 128 units, the next exponent holds it.
    let below = frexp(largest).exp;
    let e = clamp(below + select(0, 1, round(largest * ldexp(1.0, 7 - below)) > 127.0), -120, 127);
    let q = vec3<i32>(clamp(round(v * ldexp(1.0, 7 - e)), vec3<f32>(-127.0), vec3<f32>(127.0)));
    var bits = u32(e + 128) << 24u;
    bits = insertBits(bits, bitcast<u32>(q.x), 0u, 8u);
    bits = insertBits(bits, bitcast<u32>(q.y), 8u, 8u);
    return insertBits(bits, bitcast<u32>(q.z), 16u, 8u);
}

fn unpack_history_radiance(bits: u32) -> vec3<f32> {
    let word = bitcast<i32>(bits);
    let q = vec3<i32>(extractBits(word, 0u, 8u), extractBits(word, 8u, 8u), extractBits(word, 16u, 8u));
    let e = i32(bits >> 24u) - 128;
    return vec3<f32>(q) * ldexp(1.0, e - 7);
}

// A unit direction in 32 bits: its octahedral map, two snorm16 (about 1e-4 rad).
fn octahedral_pack(v: vec3<f32>) -> u32 {
    var p = v.xy / max(abs(v.x) + abs(v.y) + abs(v.z), 1e-30);
    if (v.z < 0.0) {
        p = (1.0 - abs(p.yx)) * select(vec2<f32>(-1.0), vec2<f32>(1.0), p >= vec2<f32>(0.0));
    }
    return pack2x16snorm(p);
}

fn octahedral_unpack(bits: u32) -> vec3<f32> {
    let p = unpack2x16snorm(bits);
    var v = vec3<f32>(p, 1.0 - abs(p.x) - abs(p.y));
    if (v.z < 0.0) {
        v = vec3<f32>((1.0 - abs(v.yx)) * select(vec2<f32>(-1.0), vec2<f32>(1.0), v.xy >= vec2<f32>(0.0)), v.z);
    }
    return normalize(v);
}

// Pinhole camera with this pass's sub-pixel sample (Rust: GpuCamera).
struct Camera {
    eye: vec4<f32>,
    right: vec4<f32>,    // w tan(fov_x / 2)
    up: vec4<f32>,       // w tan(fov_y / 2)
    forward: vec4<f32>,  // w near distance (orthographic: far distance of depth 1 - z / far)
    jitter: vec4<f32>,   // xy in [0, 1), zw window centre (tangent units)
    size: vec4<u32>,     // x width, y height, z VIEW_ORTHOGRAPHIC (right.w, up.w: half extents)
}

// Image estimate parameters (Rust: GpuEstimateParams).
struct EstimateParams {
    environment: vec4<f32>,
    patch_count: u32,
    light_count: u32,
    mis: u32,            // 1: emitting shapes' direct light shared between D and G
    first_row: u32,      // the image row of this band's first (its image_sum starts there)
    seen_in_gather: u32, // 1: Le added by the gather, every step, not by `direct`
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// A light for the per-pixel direct light of one pass (Rust: GpuDirectLight).
struct DirectLight {
    position: vec4<f32>, // xyz point or spot light, or this pass's point on the area light
    normal: vec4<f32>,   // xyz n_L, spot axis, sun's direction of travel (zero for a point light); w T A_t of an emitting shape (MIS), else 0
    strength: vec4<f32>, // rgb factor of V f cos / r^2 (cos_L too for an area light; V f cos for a sun)
    cone: vec4<f32>,     // xy spot cone scale and offset
    kind: u32,           // LIGHT_*
    first_face: u32,     // its window's faces in the face table
    faces: u32,
    _pad0: u32,
}

// One face of a light's window in the shadow atlas (Rust: GpuWindowFace).
struct WindowFace {
    view: Camera,
    tile: vec4<u32>,     // xy top-left texel in the atlas, z rows inside the window
}

// A node of the shadow rays' BVH in depth-first order (Rust: GpuBvhNode): its box as six
// half floats in the tree's frame (min x y, min z max x, max y z); link: an inner node's
// escape (its first child is the next node), or SHADOW_LEAF | first triangle <<
// SHADOW_LEAF_COUNT_BITS | (count - 1) for a leaf (whose escape is the next node).
struct BvhNode {
    bounds: vec3<u32>,
    link: u32,
}

// A triangle of the shadow rays' BVH (Rust: GpuBvhTriangle): a corner and its two edges.
struct BvhTriangle {
    v0: vec3<f32>,
    first_patch: u32,
    e1: vec3<f32>,
    lattice: u32,
    e2: vec3<f32>,
    corners: u32,
}

// One face of a light sample's window (Rust: GpuFaceParams).
struct FaceParams {
    sample: u32,
    patch_count: u32,
    rows: u32,
    _pad0: u32,
}

// Sums -> r_ij for one light sample (Rust: GpuAppendParams).
struct AppendParams {
    sample: u32,
    patch_count: u32,
    capacity: u32,
    _pad0: u32,
    factor: f32,
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
}

// One ray bundle (Rust: GpuBundle).
struct Bundle {
    direction: vec4<f32>,   // xyz d, w pixel area dP
    axis_u: vec4<f32>,      // xyz u / half extent, w sub-pixel shift (clip units)
    axis_v: vec4<f32>,
    centre: vec4<f32>,      // xyz bounding-sphere centre, w 1 / radius
    environment: vec4<f32>,
    resolution: u32,
    patch_count: u32,
    capacity: u32,
    use_state: u32,
    image_step: u32,      // 1 past the burn-in: this step's K joins diffuse_sum
    pixel_class: u32,     // the gather's pixels: one of each stride x stride block
    pixel_stride: u32,    // 1, or 2 with four interleaved bundles a step
    pixel_shuffle: u32,   // the step's shuffle of the classes within the blocks
    fine_rect: vec4<u32>, // the fine window: x0, y0, width, height in fine lines
    wide: u32,            // fine lines along a wide line's edge (1: one level)
    line_capacity: u32,   // lines the buffers hold
    wide_lines: u32,      // wide lines, numbered first (0 with one level)
    line_count: u32,      // wide_lines + the fine window's lines
}

// Which way patch j looks along a bundle: +1 if its front faces +d, else -1 (s_j).
fn bundle_side(n: vec3<f32>, d: vec3<f32>) -> f32 {
    return select(-1.0, 1.0, dot(n, d) >= 0.0);
}

// The texel of the camera item buffer that holds `pixel` at this step's sample: with a
// supersampled buffer (camera.size.w, GpuCamera in src/layout.rs) the sample's stratum among
// the pixel's S x S texels, else the pixel itself.
fn camera_texel(camera: Camera, pixel: vec2<u32>) -> vec2<i32> {
    let s = max(camera.size.w & 0xffu, 1u);
    let cell = vec2<u32>((camera.size.w >> 8u) & 0xffu, (camera.size.w >> 16u) & 0xffu);
    return vec2<i32>(pixel * s + min(cell, vec2<u32>(s - 1u)));
}

// Direction (not normalised) through the sample point of pixel `pixel` of a camera or face:
// forward + window position in tangent units.
fn pixel_direction(camera: Camera, pixel: vec2<u32>) -> vec3<f32> {
    let size = vec2<f32>(camera.size.xy);
    let ndc = vec2<f32>(
        2.0 * (f32(pixel.x) + camera.jitter.x) / size.x - 1.0,
        1.0 - 2.0 * (f32(pixel.y) + camera.jitter.y) / size.y);
    let window = ndc * vec2<f32>(camera.right.w, camera.up.w) + camera.jitter.zw;
    return camera.forward.xyz + window.x * camera.right.xyz + window.y * camera.up.xyz;
}

// A spot light's falloff at cosine cd to its axis (glTF KHR_lights_punctual, scene::SpotCone).
fn spot_falloff(cd: f32, scale: f32, offset: f32) -> f32 {
    let f = clamp(cd * scale + offset, 0.0, 1.0);
    return f * f;
}

// Clip position of a scene point in a camera or window face's item buffer: a pinhole view
// (reversed-z, the sample point inside the pixel moved onto the rasteriser's pixel centre)
// or a parallel one (VIEW_ORTHOGRAPHIC: linear depth 1 - z / far, greater is nearer).
fn view_clip(view: Camera, position: vec3<f32>) -> vec4<f32> {
    let rel = position - view.eye.xyz;
    let x = dot(rel, view.right.xyz);
    let y = dot(rel, view.up.xyz);
    let z = dot(rel, view.forward.xyz);
    let size = vec2<f32>(view.size.xy);
    // Shift so that the sample point inside the pixel maps to the pixel's centre.
    let shift = vec2<f32>(2.0 * (0.5 - view.jitter.x) / size.x, -2.0 * (0.5 - view.jitter.y) / size.y);
    if (view.size.z == VIEW_ORTHOGRAPHIC) {
        return vec4<f32>(x / view.right.w + shift.x, y / view.up.w + shift.y, 1.0 - z / view.forward.w, 1.0);
    }
    let window = vec2<f32>(x, y) - view.jitter.zw * z;
    return vec4<f32>(window.x / view.right.w + shift.x * z, window.y / view.up.w + shift.y * z, view.forward.w, z);
}

// A rasterised triangle's vertex on its lattice (src/gpu/scene_buffers.rs, `raster_triangles`):
// (0, 0), (k, 0) or (0, k) for corner 0, 1 or 2 of the lattice word.
fn lattice_corner(word: u32) -> vec2<f32> {
    let k = f32(word & LATTICE_SIDE_MASK);
    let corner = (word >> LATTICE_CORNER_SHIFT) & 3u;
    return vec2<f32>(select(0.0, k, corner == 1u), select(0.0, k, corner == 2u));
}

// The patch under lattice coordinates `at` of a triangle drawn for the patches from `first`
// (src/scene/tessellate.rs, `Lattice`): row j = floor(y) holds 2 (k - j) - 1 patches, so
// (2 k - j) j come before it; along it the upright triangle of step i = floor(x), then the
// inverted one where frac(x) + frac(y) > 1. Coordinates a rounding outside the triangle
// are clamped onto its nearest patch. A triangle that is one patch (k = 1) gives `first`.
fn lattice_patch(first: u32, word: u32, at: vec2<f32>) -> u32 {
    let k = word & LATTICE_SIDE_MASK;
    let j = min(u32(max(at.y, 0.0)), k - 1u);
    let i = min(u32(max(at.x, 0.0)), k - 1u - j);
    let inverted = (at.x - f32(i)) + (at.y - f32(j)) > 1.0 && i + j + 2u <= k;
    let local = (2u * k - j) * j + 2u * i + select(0u, 1u, inverted);
    return first + select(1u, 2u, (word & LATTICE_TWINS) != 0u) * local;
}

fn patch_centre(p: Patch) -> vec3<f32> {
    return (p.v0.xyz + p.v1.xyz + p.v2.xyz) / 3.0;
}
