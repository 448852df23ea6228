// Image estimate (docs/ALGORITHM.md 6): for every camera pixel, one estimate of the radiance that
// leaves the point x it sees toward the eye, added to the running sum of the image:
//   E = Le_j(w_e) + D(x, w_e) + G(x, w_e)
// D, the direct light of every first-shot light with its own visibility of x; G, the
// indirect light gathered through this step's bundle along the one line through x. x is the
// pixel's own surface point (the camera ray through this pass's sample hits patch j's plane
// there); the environment where no surface is, black on a back side.
//
// Visibility V(y, x) of a light point y: the item buffer of y's window, in the direction of
// x, gives the surfaces seen through the centres of the 2 x 2 texels around that direction;
// the segment from y to x is tested exactly against each of those triangles. So shadow edges
// are exact wherever an occluder covers one of those texel centres; an occluder that slips
// between all four (thinner than a texel) is missed.
//
// The gather: x projected onto the bundle's grid gives its line; along it, in x's front
// direction s d, the nearest surface m (by the exact distance along the ray from x to m's
// plane, among the fragments of the line near x) sends what it sends the image
// (`image_senders` of bundle_reflect) if its front faces x, black if its back does; the
// environment if there is none.
//
// The image sum has two halves, each a running sum (rgb) and count (w) per pixel: D (entry
// point `direct`, on the passes that draw new light points, with the environment) and
// Le + G (entry point `gather`, every step); the image is the sum of their means (the
// direct light converges in far fewer passes than the indirect, so it is not paid for every
// step; Le, one load a pixel, is). A direct-light image, which does not gather, has Le in
// the first half (params.seen_in_gather = 0).
//
// Each half is a buffer of its own, and each is cut into bands of whole rows, each band a
// buffer that one binding can hold: the host dispatches every band with its own group 0,
// binding that band's part of the half as image_sum and its first row in params.
// Compute, one invocation per pixel: the only writer of its entries of image_sum. Group 1:
// the direct lights and their window atlases; group 2: this step's bundle, sorted by
// bundle_transfer.
// Host: src/stages/image_estimate.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<uniform> params: EstimateParams;
@group(0) @binding(2) var item_buffer: texture_2d<u32>;
@group(0) @binding(3) var<storage, read> patches: array<Patch>;
@group(0) @binding(4) var<storage, read> materials: array<Material>;
@group(0) @binding(5) var<storage, read_write> image_sum: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> edges: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read> glossy_albedo: array<f32>;
@group(0) @binding(8) var<storage, read_write> near_senders: array<atomic<u32>>;
@group(1) @binding(0) var<storage, read> lights: array<DirectLight>;
@group(1) @binding(1) var<storage, read> faces: array<WindowFace>;
@group(1) @binding(2) var kept_atlas: texture_2d<u32>;
@group(1) @binding(3) var pass_atlas: texture_2d<u32>;
@group(1) @binding(4) var<storage, read> shadow_nodes: array<BvhNode>;
@group(1) @binding(5) var<storage, read> shadow_triangles: array<BvhTriangle>;
@group(1) @binding(6) var<storage, read> unshadowed: array<u32>;
@group(2) @binding(0) var<storage, read> bundle: Bundle;

// The step's bundle, read once by each gather invocation (`this_bundle = bundle`). It is bound
// as a storage buffer, not a uniform: lavapipe builds uniform values that steer a kernel's
// code into variants compiled at dispatch, and `gather` was compiled anew at every step of a
// new seed where the scene has no first shot. Its fields read from storage where they are
// used cost 4 ms more a gather at 256 x 256 (loaded again after each store to the image);
// a private copy is loaded once.
var<private> this_bundle: Bundle;
@group(2) @binding(1) var<storage, read> counts: array<u32>;
@group(2) @binding(2) var<storage, read> slices: array<vec2<u32>>;
@group(2) @binding(3) var<storage, read> fragments: array<vec2<u32>>;
@group(2) @binding(4) var<storage, read> image_senders: array<ImageSender>;

// The kinds of light (bit 1 << LIGHT_*) and of window (bit 1 << its face count) that the
// light table holds: the host builds the `direct` pipeline with them
// (`DirectLights::specialization`), so that the compiler drops the code of the others. A CPU
// adapter runs both sides of a branch for every vector of pixels, masked, and a loop at least
// once: code for a kind the scene lacks cost as much as if every pixel had taken it (the
// Sierpinski scene's direct pass took a third longer with the sun's and the cube's code in it).
// The defaults keep every kind.
override LIGHT_KINDS: u32 = 0xffffffffu;
override WINDOW_FACE_COUNTS: u32 = 0xffffffffu;
// Likewise the atlases its faces lie in: bit 1 << 0 the kept faces' (points, spots, suns),
// bit 1 << 1 the per-pass faces' (area lights, emitting shapes).
override ATLASES: u32 = 3u;
// True in the gather's pipeline (it runs only where the image gathers): `gather` adds the
// emission Le a pixel sees on every step, and `direct` leaves it out (params.seen_in_gather).
// At the outline of a light seen directly Le is most of the pixel, and only the camera
// samples find its share: with D, on one step in 8, the Cornell box's 64 pixels around its
// light held 20 % of a 1000-step image's squared error. A pipeline constant, not the
// parameter: on lavapipe the gather reading the parameter (and the environment) ran up to
// twice as long.
override SEEN_IN_GATHER: bool = false;

// True where the gather evaluates a near sender's first reflection of the first-shot lights
// at the point x's ray meets it (`gather_first_bounce`); the host sets it where no light is an
// emitting shape (`render::first_bounce_per_point`).
override FIRST_BOUNCE_PER_POINT: bool = false;

// True where `gather` finishes every pixel itself: the pixels it would list for
// `gather_edges` (near their patch's edge) and for `gather_first_bounce` (a near sender) take
// those passes' code inline, and the host records neither pass nor the lists' clears. A GPU
// pays for each pass of a view's step (a dispatch, a barrier and the host's recording of
// both), while the few lanes that take the inline code cost it little; a CPU adapter runs
// both sides of every branch for each vector of 8 pixels, so there the split passes stay
// (`image_estimate::fused_gather` chooses; docs/PERFORMANCE.md, "The gather in one pass on
// a GPU").
override FUSED_GATHER: bool = false;

// False where no patch is a first-shot emitting shape whose light D and G share
// (`SceneBuffers::shared_emitters`): the sharing's code is then left out of every pixel's
// gather and direct light (params.mis still says whether this run shares).
override MIS: bool = true;

// True where the area lights and emitting shapes find their visibility by shadow rays through
// the scene's BVH (`shadow_bvh`, `occluded`) instead of their windows: their table entries
// then have no faces.
override SHADOW_RAYS: bool = false;
// The frame of the shadow BVH's boxes (`ShadowBvh::frame`): p -> (p - centre) * scale.
override SHADOW_FRAME_X: f32 = 0.0;
override SHADOW_FRAME_Y: f32 = 0.0;
override SHADOW_FRAME_Z: f32 = 0.0;
override SHADOW_FRAME_SCALE: f32 = 1.0;
// Whether `unshadowed` holds, per patch, the area lights it sees past every occluder
// (`direct_light::ShaftJob`): a point on such a patch casts no shadow ray to them.
override SHADOW_SHAFTS: bool = false;
// True where the scene has an environment (a sky) and the BVH of the shadow rays: the gather
// finds what x receives along the step's direction by x's own ray through the BVH
// (`ray_received`) instead of by its line. The line stands for a patch, not for x: about half
// a line off x it passes through surfaces x's ray misses and beside ones it hits, and where
// the environment lights fine geometry (a fractal under a sky) it shaded x by those: a
// diffuse Sierpinski fractal lit by a sky alone came out 20 % dark at the automatic four
// bundles of 96 lines (docs/PERFORMANCE.md, "The sky by each pixel's own ray").
override SKY_RAYS: bool = false;
// How far x's ray goes (`nearest_hit`): past the BVH's box from any point in it (every corner
// lies within 1 / SHADOW_FRAME_SCALE of its centre; the host computes it in f64).
override SKY_REACH: f32 = 1.0;

fn has_light(kind: u32) -> bool {
    return (LIGHT_KINDS & (1u << kind)) != 0u;
}

fn has_window(faces: u32) -> bool {
    return (WINDOW_FACE_COUNTS & (1u << faces)) != 0u;
}

// Whether some window has a face count other than 1 (a sun's view), 5 (a hemicube) or 6 (a
// cube): only those are searched face by face (`window_face`).
fn has_other_windows() -> bool {
    return (WINDOW_FACE_COUNTS & ~((1u << 1u) | (1u << 5u) | (1u << 6u))) != 0u;
}

// The segment from y to x leaves out this share of its length at each end: its ends lie on
// the light and on x's own surface.
const SEGMENT_EPSILON: f32 = 1e-4;

// How far past a patch's smooth edge, in texels of the window, its surface is taken to go on
// (`crosses_surface`).
const CONTINUATION_TEXELS: f32 = 1.5;

// Whether the segment y + t dir, SEGMENT_EPSILON < t < 1 - SEGMENT_EPSILON, crosses the triangle
// with corner a and edges e1, e2 (Moller-Trumbore, either side).
fn segment_crosses(a: vec3<f32>, e1: vec3<f32>, e2: vec3<f32>, y: vec3<f32>, dir: vec3<f32>) -> bool {
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if (abs(det) < 1e-30) {
        return false;
    }
    let inv = 1.0 / det;
    let s = y - a;
    let u = dot(s, p) * inv;
    if (u < 0.0 || u > 1.0) {
        return false;
    }
    let q = cross(s, e1);
    let v = dot(dir, q) * inv;
    if (v < 0.0 || u + v > 1.0) {
        return false;
    }
    let t = dot(e2, q) * inv;
    return t > SEGMENT_EPSILON && t < 1.0 - SEGMENT_EPSILON;
}

// Where the line y + t dir meets the triangle with corner a and edges e1, e2 (Moller-Trumbore,
// either side): (t, u, v), the point a + u e1 + v e2; t = -1 where it misses.
fn triangle_crossing(a: vec3<f32>, e1: vec3<f32>, e2: vec3<f32>, y: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if (abs(det) < 1e-30) {
        return vec3<f32>(-1.0);
    }
    let inv = 1.0 / det;
    let s = y - a;
    let u = dot(s, p) * inv;
    let q = cross(s, e1);
    let v = dot(dir, q) * inv;
    if (u < 0.0 || u > 1.0 || v < 0.0 || u + v > 1.0) {
        return vec3<f32>(-1.0);
    }
    return vec3<f32>(dot(e2, q) * inv, u, v);
}

// Whether the segment from y to x (its ends left out) crosses patch k.
fn segment_hits(k: u32, y: vec3<f32>, x: vec3<f32>) -> bool {
    let a = patches_at(k).v0.xyz;
    return segment_crosses(a, patches_at(k).v1.xyz - a, patches_at(k).v2.xyz - a, y, x - y);
}

// Whether the segment y + t dir (its ends left out) crosses triangle k of the shadow rays' BVH.
fn shadow_triangle_hit(k: u32, y: vec3<f32>, dir: vec3<f32>) -> bool {
    return segment_crosses(shadow_triangles[k].v0, shadow_triangles[k].e1, shadow_triangles[k].e2, y, dir);
}

// A coordinate of magnitude m is held in f32 to m x 2^-23; a point computed on a surface (x
// from the camera ray and its patch's plane, y on its light) lies off that surface's plane by
// a fraction of that.
const POSITION_ULPS: f32 = 2.0 * 1.1920929e-7;

// The end p of a segment (on a surface of normal n) moved off its surface toward the
// segment's other end q by a few units in the last place of p's coordinates (POSITION_ULPS):
// so rounding cannot leave an end behind its own plane, where the segment would cross its
// own surface short of the SEGMENT_EPSILON left out at each end (a scene moved 1e5 from the
// origin lost 18 % of its light to that: tests/per_pixel.rs test22). No more than that: a
// point moved off the segment's line may fall into the shadow of a neighbour it touches at a
// concave edge (moved 1e-4 of the segment's length, points of the Sierpinski scene's fractal
// lost up to 19 % of their direct light).
fn lifted(p: vec3<f32>, n: vec3<f32>, q: vec3<f32>) -> vec3<f32> {
    let a = abs(p);
    return p + select(-n, n, dot(n, q - p) >= 0.0) * (POSITION_ULPS * max(a.x, max(a.y, a.z)));
}

// The two half floats of a word (low bits first), decoded by hand: `unpack2x16float` needs a
// capability (SHADER_FLOAT16_IN_FLOAT32) that the kernels do not ask of a device. Exact for
// every finite half; the tree's boxes hold no infinity or NaN (they lie within [-1, 1]).
fn halves(word: u32) -> vec2<f32> {
    let bits = vec2<u32>(word & 0xffffu, word >> 16u);
    let sign = (bits & vec2<u32>(0x8000u)) << vec2<u32>(16u);
    let exponent = (bits >> vec2<u32>(10u)) & vec2<u32>(0x1fu);
    let mantissa = bits & vec2<u32>(0x3ffu);
    let normal = bitcast<vec2<f32>>(sign | ((exponent + vec2<u32>(112u)) << vec2<u32>(23u)) | (mantissa << vec2<u32>(13u)));
    // Subnormal halves (and zero): mantissa x 2^-24.
    let small = bitcast<vec2<f32>>(sign | bitcast<vec2<u32>>(vec2<f32>(mantissa) * 5.9604645e-8));
    return select(normal, small, exponent == vec2<u32>(0u));
}

// The segment y + t dir (t in [0, 1]) in the BVH's frame, as its box tests take it: the
// start moved and scaled into the frame, and 1 / the scaled direction (a tiny component kept
// off zero).
struct FrameRay {
    origin: vec3<f32>,
    inv: vec3<f32>,
}

fn frame_ray(y: vec3<f32>, dir: vec3<f32>) -> FrameRay {
    let origin = (y - vec3<f32>(SHADOW_FRAME_X, SHADOW_FRAME_Y, SHADOW_FRAME_Z)) * SHADOW_FRAME_SCALE;
    let scaled = dir * SHADOW_FRAME_SCALE;
    return FrameRay(origin, 1.0 / select(scaled, vec3<f32>(1e-30), abs(scaled) < vec3<f32>(1e-30)));
}

// The first and last triangle (indices into shadow_triangles) of the leaf whose link is `link`.
fn leaf_triangles(link: u32) -> vec2<u32> {
    let first = (link & ~SHADOW_LEAF) >> SHADOW_LEAF_COUNT_BITS;
    return vec2<u32>(first, first + (link & ((1u << SHADOW_LEAF_COUNT_BITS) - 1u)));
}

// The span (entry, exit) of `ray` (in the tree's frame) within node `node`'s box: empty where
// entry > exit.
fn node_span(node: u32, ray: FrameRay) -> vec2<f32> {
    let bounds = shadow_nodes[node].bounds;
    let a = halves(bounds.x);
    let b = halves(bounds.y);
    let c = halves(bounds.z);
    let t0 = (vec3<f32>(a, b.x) - ray.origin) * ray.inv;
    let t1 = (vec3<f32>(b.y, c) - ray.origin) * ray.inv;
    let lo = min(t0, t1);
    let hi = max(t0, t1);
    return vec2<f32>(max(max(lo.x, lo.y), lo.z), min(min(hi.x, hi.y), hi.z));
}

// Whether some triangle of the scene crosses the segment from y (on a light of normal n_y) to
// x (on a surface of normal n_x), its ends moved off their surfaces (`lifted`) and left out: a
// shadow ray through the BVH (`shadow_bvh::ShadowBvh::occluded` is the same walk on the host).
// The nodes are in depth-first order with escapes, so the walk needs no stack (on lavapipe a
// per-lane stack in private memory cost a quarter more), and their boxes are half floats in
// the tree's frame (SHADOW_FRAME_*, `halves`), four words a node. Any hit ends it. Only the
// kept part of the segment enters a box: a box that holds an end alone (the light's own
// triangles, x's own surface) is skipped.
fn occluded(light_point: vec3<f32>, n_y: vec3<f32>, surface_point: vec3<f32>, n_x: vec3<f32>) -> bool {
    let y = lifted(light_point, n_y, surface_point);
    let x = lifted(surface_point, n_x, light_point);
    let dir = x - y;
    let ray = frame_ray(y, dir);
    let end = arrayLength(&shadow_nodes);
    var node = 0u;
    while (node < end) {
        let span = node_span(node, ray);
        let near = max(span.x, SEGMENT_EPSILON);
        let far = min(span.y, 1.0 - SEGMENT_EPSILON);
        let link = shadow_nodes[node].link;
        let leaf = (link & SHADOW_LEAF) != 0u;
        if (near <= far) {
            if (!leaf) {
                node++;
                continue;
            }
            let leaf_range = leaf_triangles(link);
            for (var k = leaf_range.x; k <= leaf_range.y; k++) {
                if (shadow_triangle_hit(k, y, dir)) {
                    return true;
                }
            }
        }
        node = select(link, node + 1u, leaf);
    }
    return false;
}

// The nearest triangle of the BVH that x's ray x + t toward meets, past x's own surface and
// within SKY_REACH (past the BVH's box): its index k (NO_HIT where the ray leaves the scene)
// and the point's barycentric coordinates (u, v) on it. `occluded`'s walk, with the segment
// cut short at the nearest hit so far.
const NO_HIT: u32 = 0xffffffffu;

struct Hit {
    k: u32,
    u: f32,
    v: f32,
}

fn nearest_hit(x: vec3<f32>, n: vec3<f32>, toward: vec3<f32>) -> Hit {
    let y = lifted(x, n, x + toward);
    let dir = toward * SKY_REACH;
    let ray = frame_ray(y, dir);
    var best = Hit(NO_HIT, 0.0, 0.0);
    var nearest = 1.0;
    let end = arrayLength(&shadow_nodes);
    var node = 0u;
    while (node < end) {
        let span = node_span(node, ray);
        let near = max(span.x, SEGMENT_EPSILON);
        let far = min(span.y, nearest);
        let link = shadow_nodes[node].link;
        let leaf = (link & SHADOW_LEAF) != 0u;
        if (near <= far) {
            if (!leaf) {
                node++;
                continue;
            }
            let leaf_range = leaf_triangles(link);
            for (var k = leaf_range.x; k <= leaf_range.y; k++) {
                let h = triangle_crossing(shadow_triangles[k].v0, shadow_triangles[k].e1, shadow_triangles[k].e2, y, dir);
                if (h.x > SEGMENT_EPSILON && h.x < nearest) {
                    nearest = h.x;
                    best = Hit(k, h.y, h.z);
                }
            }
        }
        node = select(link, node + 1u, leaf);
    }
    return best;
}

// The patch (index + 1) whose side facing the ray holds the point `hit` of its triangle:
// the front's patch where the triangle faces the ray, its twin's where it has one, else
// NO_PATCH (a one-sided surface's back, black). A lattice's point lies in the patch of its
// lattice coordinates (`lattice_patch`), from its corners' (`GpuBvhTriangle::corners`).
fn hit_patch(hit: Hit, toward: vec3<f32>) -> u32 {
    let tri = shadow_triangles[hit.k];
    let word = tri.lattice & ~(3u << LATTICE_CORNER_SHIFT);
    let c0 = lattice_corner(tri.lattice);
    let c1 = lattice_corner(word | ((tri.corners & 3u) << LATTICE_CORNER_SHIFT));
    let c2 = lattice_corner(word | (((tri.corners >> 2u) & 3u) << LATTICE_CORNER_SHIFT));
    let at = c0 + hit.u * (c1 - c0) + hit.v * (c2 - c0);
    if (dot(cross(tri.e1, tri.e2), toward) < 0.0) {
        return lattice_patch(tri.first_patch, tri.lattice, at) + 1u;
    }
    if ((tri.corners & BVH_TRIANGLE_BACK) != 0u) {
        return lattice_patch(tri.first_patch + 1u, tri.lattice, at) + 1u;
    }
    return NO_PATCH;
}

// What x receives along `toward` by its own ray (SKY_RAYS): the environment where the ray
// leaves the scene, black where it meets a back, else what the patch it meets sends.
fn ray_received(at: Seen, toward: vec3<f32>) -> Received {
    let hit = nearest_hit(at.x, at.n, toward);
    if (hit.k == NO_HIT) {
        return received_const(this_bundle.environment.rgb, true);
    }
    let id = hit_patch(hit, toward);
    if (id == NO_PATCH) {
        return received_const(vec3<f32>(0.0), true);
    }
    return received_from(id - 1u, at.x, toward);
}

// The id at texel `at` of atlas `atlas` (WindowFace::tile.w: 0 the kept faces', 1 the
// per-pass faces'). Where the light table uses one atlas alone (ATLASES), the other's load is
// compiled out: a CPU adapter loads from both for every texel otherwise, about a tenth of
// the Sierpinski scene's direct pass.
fn atlas_id(atlas: u32, at: vec2<i32>) -> u32 {
    if (ATLASES == 1u) {
        return textureLoad(kept_atlas, at, 0).x;
    }
    if (ATLASES == 2u) {
        return textureLoad(pass_atlas, at, 0).x;
    }
    if (atlas == 0u) {
        return textureLoad(kept_atlas, at, 0).x;
    }
    return textureLoad(pass_atlas, at, 0).x;
}

// Whether the surface `id` (patch index + 1) of a window texel lies on the segment from y to x,
// x on patch j of normal n (the caller's: not loaded again for each of a pixel's texels).
// With `by_plane` (a directional light's parallel view, `texel` its texel's side), whether
// the segment crosses that surface's plane: see `visible`. Else (a point's window,
// `texel_at_x` a texel's footprint at x's depth) whether it crosses the patch, or its
// surface a little past one of its smooth edges (`crosses_surface`).
fn blocks(id: u32, j: u32, n: vec3<f32>, y: vec3<f32>, x: vec3<f32>, by_plane: bool, texel: f32, texel_at_x: f32) -> bool {
    if (id == NO_PATCH || id - 1u == j || id > params.patch_count) {
        return false;
    }
    // Most surfaces around the direction cannot cross the segment: those whose plane has y
    // and x on one side, and those whose plane holds x: x's neighbours on its own surface
    // (in its plane, or within SMOOTH_EDGE_COS of it on a curved mesh; either side, so a
    // two-sided surface's twin too). One load of the plane rules them out before the
    // triangle test's three. A plane near x at a steeper angle is another surface meeting
    // x's at a crease, and it still blocks: a sun outside the room lit the creases of its
    // walls within a few millimetres of the wall beside them, a segment's SEGMENT_EPSILON
    // (sun_room: a spike of +11-25 % along every crease of the image).
    let plane = patches_at(id - 1u).normal;
    let side_y = dot(plane.xyz, y) - plane.w;
    let side_x = dot(plane.xyz, x) - plane.w;
    if (side_y * side_x > 0.0) {
        return false;
    }
    if (abs(side_x) <= SEGMENT_EPSILON * length(x - y)
        && abs(dot(plane.xyz, n)) >= SMOOTH_EDGE_COS) {
        return false;
    }
    if (by_plane) {
        return crosses_surface(id - 1u, y, x, texel);
    }
    if (segment_hits(id - 1u, y, x)) {
        return true;
    }
    // A surface cut into patches not much larger than a texel (a finely tessellated model):
    // the patch the segment crosses may cover none of the texel centres, while a neighbour
    // of its surface does. Past that neighbour's smooth edges the surface goes on, so it
    // blocks there too, within the reach of `crosses_surface` (the footprint of a texel
    // where the segment crosses, t of the way from y). Without this, light leaked through
    // such surfaces in proportion to texel / patch size: the engine_room model's shadows
    // let 2.5 % of the area light's light too many through at the 2048 cap
    // (docs/ALGORITHM.md 6, "Visibility"). Not within the largest reach of x (4 x
    // CONTINUATION_TEXELS texels): there the segment leaves x's own curved surface at a
    // grazing angle and the planes of x's neighbours, continued, would shade it.
    if (patches_at(id - 1u).flags >= PATCH_SMOOTH_EDGE) {
        let t = side_y / (side_y - side_x);
        if (t > SEGMENT_EPSILON && (1.0 - t) * length(x - y) > 4.0 * CONTINUATION_TEXELS * texel_at_x) {
            return crosses_surface(id - 1u, y, x, texel_at_x * t);
        }
    }
    return false;
}

// For a sun (`visible`), and past the smooth edges of a point's texels (`blocks`), given that
// the segment from y to x crosses the plane of patch k: whether it crosses k's surface there,
// `texel` the window's texel side where it does. Inside the triangle it does. Beyond an edge that
// continues into a neighbour of about the same plane (PATCH_SMOOTH_EDGE, set by the host)
// the surface goes on, and a neighbour the window's texels did not show may hold the crossing:
// it is taken to (a tessellated roof or wall, whose mesh vertices poke between the texel
// centres, does not leak). Beyond an outline or a crease it does not: the segment passes
// beside the surface there. Until 2026-11-26 every crossing of the plane blocked, and the
// floor within about a texel of a window's sunlit patch fell into shade (sun_room: the
// outline's pixels held about half of the image's squared error against Mitsuba).
fn crosses_surface(k: u32, y: vec3<f32>, x: vec3<f32>, texel: f32) -> bool {
    let a = patches_at(k).v0.xyz;
    let e1 = patches_at(k).v1.xyz - a;
    let e2 = patches_at(k).v2.xyz - a;
    let dir = x - y;
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if (abs(det) < 1e-30) {
        return false;
    }
    let inv = 1.0 / det;
    let s = y - a;
    let u = dot(s, p) * inv;
    let v = dot(dir, cross(s, e1)) * inv;
    let w = 1.0 - u - v;
    if (min(w, min(u, v)) >= 0.0) {
        return true;
    }
    // The barycentric weight of vertex i falls below 0 beyond the edge opposite it, -weight
    // times the triangle's height over that edge from it. A neighbour the texels missed is
    // thinner than about a texel where the segment meets it, so the surface is taken to go
    // on only that far: further out, the texels would have shown what lies there (and a
    // triangle whose corner touches the outline no longer carries its plane past it).
    let continues = patches_at(k).flags / PATCH_SMOOTH_EDGE;
    let twice_area = 2.0 * patches_at(k).v0.w;
    let n = patches_at(k).normal.xyz;
    let reach = CONTINUATION_TEXELS * texel / max(abs(dot(n, normalize(dir))), 0.25);
    let beyond = -vec3<f32>(w * twice_area / length(e2 - e1), u * twice_area / length(e2), v * twice_area / length(e1));
    let ok = vec3<bool>((continues & 1u) != 0u, (continues & 2u) != 0u, (continues & 4u) != 0u);
    return all((beyond <= vec3<f32>(0.0)) | (ok & (beyond <= vec3<f32>(reach))));
}

// The face of a window that holds direction w (from the light toward x): the one whose
// forward axis has the largest component of w, for all three windows (the host builds them
// in this order, `first_shot::faces`): a cube (+x, -x, +y, -y, +z, -z), a hemicube (n, t1,
// -t1, t2, -t2; its top face's up is t1 and its right t2) and a cubic tetrahedron (three
// orthonormal axes).
fn window_face(w: vec3<f32>, first: u32, count: u32) -> u32 {
    if (has_window(6u) && count == 6u) {
        let a = abs(w);
        if (a.x >= a.y && a.x >= a.z) {
            return first + select(0u, 1u, w.x < 0.0);
        }
        if (a.y >= a.z) {
            return first + 2u + select(0u, 1u, w.y < 0.0);
        }
        return first + 4u + select(0u, 1u, w.z < 0.0);
    }
    if (has_window(5u) && count == 5u) {
        let c = dot(w, faces[first].view.forward.xyz);
        let t1 = dot(w, faces[first].view.up.xyz);
        let t2 = dot(w, faces[first].view.right.xyz);
        if (c >= max(abs(t1), abs(t2))) {
            return first;
        }
        if (abs(t1) >= abs(t2)) {
            return first + select(1u, 2u, t1 < 0.0);
        }
        return first + select(3u, 4u, t2 < 0.0);
    }
    if (!has_other_windows()) {
        // A sun's single view.
        return first;
    }
    var best = first;
    var largest = dot(w, faces[first].view.forward.xyz);
    for (var f = first + 1u; f < first + count; f++) {
        let z = dot(w, faces[f].view.forward.xyz);
        if (z > largest) {
            largest = z;
            best = f;
        }
    }
    return best;
}

// V(y, x) for the light whose window is faces[first..first + count], x on patch j (normal
// n): 1 unless a surface of the window's item buffer around the direction of x lies on the
// segment between them. Fields are read one by one: a CPU adapter loads every field of a
// whole-struct read.
//
// A directional light's window is one parallel view (VIEW_ORTHOGRAPHIC) and y is the point
// of its plane behind the scene from which the light reaches x: the texels are those around
// x's own projection. There a triangle test alone would not do: a sun lights rooms through
// their tessellated walls and roofs, whose triangle corners poke between texel centres
// everywhere (with triangles, light leaked through at every mesh vertex: tests/lights.rs
// test08). So a surface seen there blocks where the segment crosses its plane inside its
// triangle or a little past an edge it shares with a neighbour of its plane
// (`crosses_surface`), and not past its outline.
fn visible(y: vec3<f32>, first: u32, count: u32, j: u32, n: vec3<f32>, x: vec3<f32>) -> bool {
    let w = x - y;
    let f = window_face(w, first, count);
    let z = dot(w, faces[f].view.forward.xyz);
    let right = faces[f].view.right;
    let up = faces[f].view.up;
    var window = vec2<f32>(dot(w, right.xyz), dot(w, up.xyz)) / z - faces[f].view.jitter.zw;
    let sun = has_light(LIGHT_DIRECTIONAL) && faces[f].view.size.z == VIEW_ORTHOGRAPHIC;
    if (sun) {
        let rel = x - faces[f].view.eye.xyz;
        window = vec2<f32>(dot(rel, right.xyz), dot(rel, up.xyz));
    }
    let ndc = clamp(window / vec2<f32>(right.w, up.w), vec2<f32>(-1.0), vec2<f32>(1.0));
    let side = faces[f].view.size.x;
    let tile = faces[f].tile;
    let pixel = vec2<f32>(0.5 * (ndc.x + 1.0), 0.5 * (1.0 - ndc.y)) * f32(side);
    if (z <= 0.0 || pixel.y >= f32(tile.z)) {
        // Outside the window (below an area light's plane): nothing reaches x.
        return false;
    }
    let last = vec2<i32>(i32(side) - 1, i32(tile.z) - 1);
    let origin = vec2<i32>(tile.xy);
    if (!sun) {
        // The 3 x 3 texels around the one that holds the direction, each surface tested
        // exactly against the segment. The 2 x 2 whose centres surround the direction
        // missed a triangle whose corner pokes between them without covering a centre: the
        // Sierpinski scene's direct light was 0.81 % off Mitsuba's, 93 % of it too bright;
        // 0.59 % with 3 x 3, 0.55 % with 4 x 4, for about 8 % more time per direct pass.
        let centre = vec2<i32>(floor(pixel));
        // A texel's side at x's depth (the face spans 2 right.w per unit of depth).
        let texel_at_x = 2.0 * right.w / f32(side) * z;
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let at = clamp(centre + vec2<i32>(dx, dy), vec2<i32>(0), last);
                if (blocks(atlas_id(tile.w, origin + at), j, n, y, x, false, 0.0, texel_at_x)) {
                    return false;
                }
            }
        }
        return true;
    }
    // A sun: the 2 x 2 texels whose centres surround x's projection, clamped to the view;
    // each distinct surface among them is tested once, by its plane (a wider neighbourhood
    // would widen the band along an occluder's outline that its plane darkens).
    let lo = clamp(vec2<i32>(floor(pixel - vec2<f32>(0.5))), vec2<i32>(0), last);
    let hi = min(lo + vec2<i32>(1), last);
    let a = atlas_id(tile.w, origin + lo);
    let b = atlas_id(tile.w, origin + vec2<i32>(hi.x, lo.y));
    let c = atlas_id(tile.w, origin + vec2<i32>(lo.x, hi.y));
    let d = atlas_id(tile.w, origin + hi);
    // A texel's side in the scene (the view is orthographic, 2 right.w across).
    let texel = 2.0 * right.w / f32(side);
    if (blocks(a, j, n, y, x, true, texel, 0.0)) {
        return false;
    }
    if (b != a && blocks(b, j, n, y, x, true, texel, 0.0)) {
        return false;
    }
    if (c != a && c != b && blocks(c, j, n, y, x, true, texel, 0.0)) {
        return false;
    }
    return d == a || d == b || d == c || !blocks(d, j, n, y, x, true, texel, 0.0);
}

// Multiple importance sampling of an emitting shape's light (docs/ALGORITHM.md 6): the
// share D takes of light arriving from a point of the shape at distance^2 r2 and cos_L, by
// the balance heuristic between the densities, per unit solid angle at x, of D's points
// (r^2 / (cos_L T A_t)) and of the gather's directions (1 / (2 pi)). G takes the rest.
fn light_share(r2: f32, cos_l: f32, pick_area: f32) -> f32 {
    let p_light = r2 / max(cos_l * pick_area, 1e-30);
    let p_gather = 1.0 / (2.0 * PI);
    return p_light / (p_light + p_gather);
}

// G's share of the emission of patch m, seen from x along `toward` (m's front faces x): none
// unless m belongs to a first-shot emitting shape (whose emission the iteration leaves out)
// and the image gathers.
fn emitted_share(m: u32, x: vec3<f32>, toward: vec3<f32>) -> vec3<f32> {
    if (!MIS || params.mis == 0u) {
        return vec3<f32>(0.0);
    }
    let pick_area = patches_at(m).light_pick_area;
    let plane = patches_at(m).normal;
    let cos_l = -dot(plane.xyz, toward);
    if (pick_area <= 0.0 || cos_l <= 0.0) {
        return vec3<f32>(0.0);
    }
    let t = abs((plane.w - dot(plane.xyz, x)) / cos_l);
    return patches_at(m).emission.rgb * (1.0 - light_share(t * t, cos_l, pick_area));
}

// Whether x, a point of patch j's plane (normal n), sees all of area light i past every
// occluder: patch j's bit i (`unshadowed`), where x lies on the patch itself (a pixel's point
// may lie a little past its patch's edge, and a sender's point farther: those cast their ray).
fn sees_whole(j: u32, i: u32, x: vec3<f32>, n: vec3<f32>) -> bool {
    if (!SHADOW_SHAFTS || i >= 32u || ((unshadowed[j] >> i) & 1u) == 0u) {
        return false;
    }
    // Inside the triangle, edges included: x on the inner side of each edge (the corners
    // run counter-clockwise about n).
    let a = patches_at(j).v0.xyz;
    let b = patches_at(j).v1.xyz;
    let c = patches_at(j).v2.xyz;
    return dot(cross(b - a, x - a), n) >= 0.0 && dot(cross(c - b, x - b), n) >= 0.0 && dot(cross(a - c, x - c), n) >= 0.0;
}

// D(x, w_out): every light's direct radiance reflected at x on patch j toward w_out.
fn direct_light(j: u32, x: vec3<f32>, n: vec3<f32>, m: Material, w_out: vec3<f32>) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < params.light_count; i++) {
        let kind = lights[i].kind;
        let sun = has_light(LIGHT_DIRECTIONAL) && kind == LIGHT_DIRECTIONAL;
        var y = lights[i].position.xyz;
        if (sun) {
            // The sun's light reaches x from the plane of its parallel view, straight back
            // along its direction of travel d.
            let d = lights[i].normal.xyz;
            y = x - d * dot(x - faces[lights[i].first_face].view.eye.xyz, d);
        }
        let to_light = y - x;
        let r2 = dot(to_light, to_light);
        var w_in = to_light * inverseSqrt(r2);
        if (sun) {
            w_in = -lights[i].normal.xyz;
        }
        let cos_x = dot(n, w_in);
        if (cos_x <= 0.0 || r2 <= 0.0) {
            continue;
        }
        var g = cos_x / r2;
        if (sun) {
            // Irradiance on a surface facing the light: no distance falloff.
            g = cos_x;
        }
        if (has_light(LIGHT_SPOT) && kind == LIGHT_SPOT) {
            g *= spot_falloff(dot(lights[i].normal.xyz, -w_in), lights[i].cone.x, lights[i].cone.y);
        }
        if (has_light(LIGHT_AREA) && kind == LIGHT_AREA) {
            let cos_l = max(0.0, dot(lights[i].normal.xyz, -w_in));
            g *= cos_l;
            if (MIS && params.mis != 0u && lights[i].normal.w > 0.0) {
                g *= light_share(r2, cos_l, lights[i].normal.w);
            }
        }
        var lit = g > 0.0;
        if (lit) {
            if (SHADOW_RAYS && has_light(LIGHT_AREA) && kind == LIGHT_AREA) {
                lit = sees_whole(j, i, x, n) || !occluded(y, lights[i].normal.xyz, x, n);
            } else {
                lit = visible(y, lights[i].first_face, lights[i].faces, j, n, x);
            }
        }
        if (lit) {
            sum += lights[i].strength.rgb * g * brdf(m, n, w_in, w_out);
        }
    }
    return sum;
}

// The point y where x's ray toward `toward` meets the plane of sender m (m's front faces x)
// and its distance t from x, or, where the ray meets that plane at a grazing angle or not
// ahead of x (the line and the ray on two sides of an edge), m's centre with t = 0.
fn sender_point(m: u32, x: vec3<f32>, toward: vec3<f32>) -> vec4<f32> {
    let plane = patches_at(m).normal;
    let t = (plane.w - dot(plane.xyz, x)) / dot(plane.xyz, toward);
    if (-dot(plane.xyz, toward) > 1e-3 && t > 0.0) {
        return vec4<f32>(x + t * toward, t);
    }
    return vec4<f32>(patch_centre(patches_at(m)), 0.0);
}

// A sender is near where x's ray meets it within NEAR_SENDER of its patch's width
// (sqrt(area)). There the patch-level Lfs_m, which averages the light over m (the first
// shot's visibility is m's share seen from each light sample, its geometry m's centre's),
// differs from the light at the point x sees by about that patch's own variation: beside a
// contact or a crease x gathers from the few points of m next to it (a block's foot on a
// floor it shades; a wall's crease where the neighbour's mean outshines the corner). A far
// sender fills a small solid angle over which x's weight barely changes, so its mean is what
// x gathers from it to first order in width / distance.
const NEAR_SENDER: f32 = 2.0;

// What x receives along `toward` (= s d): `radiance`, what the sender's patch sends the image
// (`ImageSender::outgoing`, with G's share of an emitting shape's light), black or the
// environment; `decided` false where `own_received` leaves it to `nearest_received`;
// `sender` the patch id (index + 1) whose front sends it, NO_PATCH if none.
struct Received {
    radiance: vec3<f32>,
    decided: bool,
    sender: u32,
}

fn received_from(m: u32, x: vec3<f32>, toward: vec3<f32>) -> Received {
    return Received(image_senders_at(m).outgoing.rgb + emitted_share(m, x, toward), true, m + 1u);
}

fn received_const(radiance: vec3<f32>, decided: bool) -> Received {
    return Received(radiance, decided, NO_PATCH);
}

// Whether x's sender is near (where the host asks for first bounces per point): x's ray
// meets its plane within NEAR_SENDER of its patch's width.
fn is_near_sender(received: Received, x: vec3<f32>, toward: vec3<f32>) -> bool {
    if (!FIRST_BOUNCE_PER_POINT || received.sender == NO_PATCH) {
        return false;
    }
    let m = received.sender - 1u;
    let t = sender_point(m, x, toward).w;
    return t * t < NEAR_SENDER * NEAR_SENDER * patches_at(m).v0.w;
}

// Lists `pixel` for `gather_first_bounce` (near_senders: [0] the count, then pixel and sender
// id a pair) where the host asks for first bounces per point and x's sender is near.
fn list_near_sender(received: Received, x: vec3<f32>, toward: vec3<f32>, pixel: u32) {
    if (is_near_sender(received, x, toward)) {
        let listed = atomicAdd(&near_senders[0], 1u);
        atomicStore(&near_senders[2u * listed + 1u], pixel);
        atomicStore(&near_senders[2u * listed + 2u], received.sender);
    }
}

// Whether patch m is of patch j's piece (`piece`, j's Patch::piece): a patch of the same
// split piece of a source triangle, in its plane, facing its way, with no contact line
// between the two (Rust: scene::Piece).
fn in_piece(m: u32, j: u32, piece: u32) -> bool {
    let step = select(1u, 2u, (piece & PIECE_TWINS) != 0u);
    let first = j - ((piece >> PIECE_BEFORE_SHIFT) & PIECE_REACH) * step;
    let last = j + (piece & PIECE_REACH) * step;
    return m >= first && m <= last && ((m - j) & (step - 1u)) == 0u;
}

// `found`, or fragment k + 1 of the line [begin, end) if it belongs to j's piece (`in_piece`).
fn own_fragment(found: u32, k: u32, range: vec2<u32>, j: u32, piece: u32) -> u32 {
    if (found != NO_PATCH || k < range.x || k >= range.y || !in_piece(fragments[k].y & ~FRAGMENT_FRONT_BIT, j, piece)) {
        return found;
    }
    return k + 1u;
}

struct Candidate {
    t: f32,
    patch_id: u32,
}

// The two nearest candidates among a line's fragments ahead of x: `hit`, the nearest whose
// triangle x's own ray x + t toward hits (Moller-Trumbore), and `plane`, the nearest facing
// x by the exact distance along that ray to its plane.
struct Nearest {
    hit: Candidate,
    plane: Candidate,
    // A candidate ahead of x faces away from it (the line passes through a solid).
    blocked: bool,
}

// `n` with fragment k of the line [begin, end) considered for both (one load of its patch
// serves both tests). Wrapped indices (below begin) are out of range.
fn consider(n: Nearest, k: u32, range: vec2<u32>, j: u32, x: vec3<f32>, toward: vec3<f32>, eps: f32) -> Nearest {
    if (k < range.x || k >= range.y) {
        return n;
    }
    let m = fragments[k].y & ~FRAGMENT_FRONT_BIT;
    let plane = patches_at(m).normal;
    // Distance from x to m's plane: ~0 for j's twin and the patches beside j in its plane,
    // which are not ahead of x whatever f32 rounding says.
    let dist = plane.w - dot(plane.xyz, x);
    if (m == j || abs(dist) <= eps) {
        return n;
    }
    var out = n;
    let denom = dot(plane.xyz, toward);
    // Only a surface facing x can be the plane candidate (of back-to-back twins, at the same
    // t, the one facing x); one facing away marks the line `blocked`.
    if (abs(denom) >= 1e-6) {
        let t = dist / denom;
        if (denom < 0.0 && t > 0.0 && t < n.plane.t - eps) {
            out.plane = Candidate(t, m + 1u);
        }
        if (denom > 0.0 && t > 0.0) {
            out.blocked = true;
        }
    }
    let a = patches_at(m).v0.xyz;
    let e1 = patches_at(m).v1.xyz - a;
    let e2 = patches_at(m).v2.xyz - a;
    let p = cross(toward, e2);
    let det = dot(e1, p);
    if (abs(det) < 1e-30) {
        return out;
    }
    let inv = 1.0 / det;
    let o = x - a;
    let u = dot(o, p) * inv;
    let q = cross(o, e1);
    let v = dot(toward, q) * inv;
    let t = dot(e2, q) * inv;
    let tie = abs(t - n.hit.t) <= eps && denom < 0.0;
    if (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0 && (t < n.hit.t - eps || tie)) {
        out.hit = Candidate(t, m + 1u);
    }
    return out;
}

// Where x lies on this step's bundle: its line's sorted fragments [begin, end) and `lo`,
// the first at or past x's depth (less a pixel's slack) in the direction of travel s d;
// `outside` when x projects off the grid.
struct OnLine {
    begin: u32,
    end: u32,
    lo: u32,
    outside: bool,
    // The line's width in fine lines: 1, or a wide line's `wide`.
    spacing: f32,
}

// Where x falls on this step's grid, in fine lines (the cell is its integer part); negative
// or past the resolution when x projects off the grid.
fn cell_of(x: vec3<f32>) -> vec2<f32> {
    let rel = x - this_bundle.centre.xyz;
    let clip = vec2<f32>(dot(rel, this_bundle.axis_u.xyz) + this_bundle.axis_u.w, dot(rel, this_bundle.axis_v.xyz) + this_bundle.axis_v.w);
    return vec2<f32>(0.5 * (clip.x + 1.0), 0.5 * (1.0 - clip.y)) * f32(this_bundle.resolution);
}

// The line through fine cell `cell` with `lo` at its start (`search` sets it): the fine line
// inside the fine window, the wide line that holds the cell outside it (a grid of two
// levels, `bundle_visibility`); `outside` off the grid.
fn line_at(cell: vec2<i32>) -> OnLine {
    let r = i32(this_bundle.resolution);
    if (any(cell < vec2<i32>(0)) || any(cell >= vec2<i32>(r))) {
        return OnLine(0u, 0u, 0u, true, 1.0);
    }
    let c = vec2<u32>(cell);
    let rect = this_bundle.fine_rect;
    var line: u32;
    var spacing = 1.0;
    if (all(c >= rect.xy) && all(c < rect.xy + rect.zw)) {
        let local = c - rect.xy;
        line = this_bundle.wide_lines + local.y * rect.z + local.x;
    } else {
        let k = this_bundle.wide;
        line = (c.y / k) * (this_bundle.resolution / k) + c.x / k;
        spacing = f32(k);
    }
    // The line's sorted surfaces: its bucket, or past LINE_BUCKET its own slice
    // (bundle_transfer).
    let count = counts[line];
    var begin = line * LINE_BUCKET;
    var end = begin + count;
    if (count > LINE_BUCKET) {
        let slice = slices[line];
        begin = slice.x;
        end = slice.y;
    }
    return OnLine(begin, end, begin, false, spacing);
}

// x's line with `lo` at its start (`on_line` searches it).
fn line_of(x: vec3<f32>) -> OnLine {
    return line_at(vec2<i32>(floor(cell_of(x))));
}

// One halving of a lower-bound search for `key` over the n fragments from `base`, applied
// four times (enough for n <= 8): (base, n) of the part that still holds the first fragment
// at or past key.
fn halve(at: vec2<u32>, key: f32) -> vec2<u32> {
    let base = at.x;
    let n = at.y;
    let half = n / 2u;
    if (n > 0u && bitcast<f32>(fragments[base + half].x) < key) {
        return vec2<u32>(base + half + 1u, n - half - 1u);
    }
    return vec2<u32>(base, half);
}

fn lower_half(base: u32, n: u32, key: f32) -> vec2<u32> {
    return halve(halve(halve(halve(vec2<u32>(base, n), key), key), key), key);
}

fn on_line(x: vec3<f32>, s: f32) -> OnLine {
    return search(line_of(x), x, s);
}

// `line` with `lo` at x's place on it (`on_line`).
fn search(line_in: OnLine, x: vec3<f32>, s: f32) -> OnLine {
    var line = line_in;
    if (line.outside) {
        return line;
    }
    let depth = dot(x - this_bundle.centre.xyz, this_bundle.direction.xyz);
    // The line's fragments lie at depths taken at its centre, up to a pixel's half diagonal
    // from x's ray: a surface within `slack` of x along the line may still be ahead of it.
    let slack = 0.75 * sqrt(this_bundle.direction.w) * line.spacing;
    let start_depth = depth - s * slack;
    // First fragment at or past start_depth in the direction of travel (binary search over
    // the sorted line). A line within its bucket (LINE_BUCKET = 8 places, nearly every line)
    // takes four fixed halvings: a CPU adapter runs a data-dependent loop over storage many
    // times slower.
    let n = line.end - line.begin;
    if (n <= LINE_BUCKET) {
        line.lo = lower_half(line.begin, n, start_depth).x;
        return line;
    }
    var lo = line.begin;
    var hi = line.end;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (bitcast<f32>(fragments[mid].x) < start_depth) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    line.lo = lo;
    return line;
}

// What x (on patch j) receives from direction `toward` (= s d) where a fragment of j's piece
// lies on x's line; not `decided` where none does (x near its piece's edge), which
// `gather_edges` then decides.
fn own_received(j: u32, x: vec3<f32>, toward: vec3<f32>, line: OnLine) -> Received {
    if (line.outside) {
        return received_const(this_bundle.environment.rgb, true);
    }
    let begin = line.begin;
    let end = line.end;
    let lo = line.lo;
    // Where x's own patch j lies on the line (its fragment within two places of x's depth),
    // x receives what j receives there in the transfer: from the next fragment in j's front
    // direction, O if that one's front faces back, black if its back does, the environment
    // past the line's end. Then the gather agrees with the patch state J_j it refines, also
    // at contacts, where the line's centre and x's own ray can pass on different sides.
    // Another patch of j's piece on the line serves as well: it lies in x's plane, facing
    // its way, within a line of x, with no contact line between (the cuts bound the pieces),
    // so what leaves it along the line is what leaves x. Without it, every pixel within
    // about half a line of its own patch's edge went to `gather_edges`, a third of them
    // where patches are a few lines wide.
    let range = vec2<u32>(begin, end);
    let piece = patches_at(j).piece;
    var own = NO_PATCH;
    own = own_fragment(own, lo - 2u, range, j, piece);
    own = own_fragment(own, lo - 1u, range, j, piece);
    own = own_fragment(own, lo, range, j, piece);
    own = own_fragment(own, lo + 1u, range, j, piece);
    own = own_fragment(own, lo + 2u, range, j, piece);
    if (own != NO_PATCH) {
        let k = own - 1u;
        let front = (fragments[k].y & FRAGMENT_FRONT_BIT) != 0u;
        if ((front && k + 1u >= end) || (!front && k == begin)) {
            return received_const(this_bundle.environment.rgb, true);
        }
        let other = fragments[select(k - 1u, k + 1u, front)].y;
        if (((other & FRAGMENT_FRONT_BIT) != 0u) != front) {
            let m = other & ~FRAGMENT_FRONT_BIT;
            return received_from(m, x, toward);
        }
        return received_const(vec3<f32>(0.0), true);
    }
    return received_const(vec3<f32>(0.0), false);
}

// What x receives where j's own fragment is on neither x's line nor the lines beside it
// (`gather_edges`: j crossed by no line near x, a patch about a line wide or less): the line
// may pass through a surface x's ray misses or beside one x's ray hits. The next four
// fragments in the direction of travel are the candidates. Whatever x's ray hits first faces
// x (x is on a surface, outside every solid), so a candidate that faces away is never the
// answer: it only says the line passes through a solid x's ray may miss. Answering black
// there lost light wherever patches are small against the lines (a closed furnace around a
// Sierpinski tetrahedron of triangles 1.4 lines wide came out 1.1-1.7 % dark, single
// pixels 11-14 %; tests/per_pixel.rs test13). Unrolled: a CPU adapter runs a data-dependent loop over
// storage many times slower. Only the pixels `gather` lists in `edges` get here: run among
// the others, this branch made every vector of 8 pixels that held one such pixel pay for it.
//
// Not `decided` where nothing lies ahead on the line: `gather_edges` then looks at the lines
// beside.
fn nearest_received(j: u32, x: vec3<f32>, toward: vec3<f32>, s: f32, line: OnLine) -> Received {
    let range = vec2<u32>(line.begin, line.end);
    let lo = line.lo;
    let eps = 1e-5 / this_bundle.centre.w;
    let none = Candidate(3.4e38, NO_PATCH);
    var n = Nearest(none, none, false);
    if (s > 0.0) {
        n = consider(n, lo, range, j, x, toward, eps);
        n = consider(n, lo + 1u, range, j, x, toward, eps);
        n = consider(n, lo + 2u, range, j, x, toward, eps);
        n = consider(n, lo + 3u, range, j, x, toward, eps);
    } else {
        n = consider(n, lo - 1u, range, j, x, toward, eps);
        n = consider(n, lo - 2u, range, j, x, toward, eps);
        n = consider(n, lo - 3u, range, j, x, toward, eps);
        n = consider(n, lo - 4u, range, j, x, toward, eps);
    }
    // First, the nearest whose triangle x's own ray hits: the surface x really sees that
    // way, wherever it is on the line too. A back face as the nearest hit says the ray
    // entered a solid through a face the line missed (x's ray and the line on two sides of
    // its edge): that entry is not on the line, so the plane rule below decides, as it does
    // where the ray hits nothing the line holds.
    let hit = n.hit;
    if (hit.patch_id != NO_PATCH && dot(patches_at(hit.patch_id - 1u).normal.xyz, toward) < 0.0) {
        let m = hit.patch_id - 1u;
        return received_from(m, x, toward);
    }
    // Failing that, the nearest facing x by the exact distance from x along the ray to its
    // plane. With none, the environment where nothing lies ahead on the line; where only
    // surfaces facing away do (the line inside a solid or outside the scene's walls), x's
    // ray still meets something the line does not show: the mean radiance j receives,
    // Lbar_j, stands in for it.
    let best = n.plane;
    if (best.patch_id == NO_PATCH && !n.blocked) {
        return received_const(vec3<f32>(0.0), false);
    }
    if (best.patch_id == NO_PATCH) {
        return received_const(image_senders_at(j).mean_radiance.rgb, true);
    }
    let m = best.patch_id - 1u;
    return received_from(m, x, toward);
}

// `nearest_received` on the line of grid cell `cell`, by the same rules as on x's own line:
// not decided off the grid or where nothing lies ahead of x there either. (Asked by x's ray
// alone, without the plane rule, the lines beside still let the sky reach single crease
// pixels of a closed room, up to 13 % of it: there the beside line's crossing of the other
// wall and x's ray's lie in two of its patches.)
fn beside_nearest(j: u32, x: vec3<f32>, toward: vec3<f32>, s: f32, cell: vec2<i32>) -> Received {
    let line = line_at(cell);
    if (line.outside) {
        return received_const(vec3<f32>(0.0), false);
    }
    return nearest_received(j, x, toward, s, search(line, x, s));
}

// The surface point a camera pixel sees in this pass: x on patch j (normal n) with w_out
// toward the eye; `kind` says whether there is one (SEEN_SURFACE), the pixel sees the
// environment (SEEN_NOTHING) or a surface's back (SEEN_BACK, black).
const SEEN_NOTHING: u32 = 0u;
const SEEN_SURFACE: u32 = 1u;
const SEEN_BACK: u32 = 2u;

struct Seen {
    kind: u32,
    j: u32,
    x: vec3<f32>,
    n: vec3<f32>,
    w_out: vec3<f32>,
}

fn seen(pixel: vec2<u32>) -> Seen {
    let id = textureLoad(item_buffer, camera_texel(camera, pixel), 0).x;
    var out = Seen(SEEN_NOTHING, 0u, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    if (id == NO_PATCH || id > params.patch_count) {
        return out;
    }
    let j = id - 1u;
    // Field by field: a CPU adapter loads every field of a whole-struct read.
    let plane = patches_at(j).normal;
    let n = plane.xyz;
    // The ray through this pass's sample point of the pixel.
    let dir = normalize(pixel_direction(camera, pixel));
    out.kind = SEEN_BACK;
    if (dot(n, -dir) > 0.0) {
        let t = (plane.w - dot(n, camera.eye.xyz)) / dot(n, dir);
        out = Seen(SEEN_SURFACE, j, camera.eye.xyz + t * dir, n, -dir);
    }
    return out;
}

// D: the direct light of every first-shot light, or the environment, added to the first half
// of the image sum; with the emission Le when the image does not gather
// (params.seen_in_gather = 0), else `gather` adds Le on every step.
@compute @workgroup_size(8, 8)
fn direct(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = camera.size.xy;
    // This band's rows: its image_sum holds them alone, from params.first_row on.
    let xy = vec2<u32>(gid.x, gid.y + params.first_row);
    let pixel = gid.y * size.x + gid.x;
    if (gid.x >= size.x || xy.y >= size.y || pixel >= arrayLength(&image_sum)) {
        return;
    }
    let at = seen(xy);
    var radiance = params.environment.rgb;
    if (at.kind == SEEN_BACK) {
        radiance = vec3<f32>(0.0);
    }
    if (at.kind == SEEN_SURFACE) {
        let m = materials[patches_at(at.j).material];
        radiance = direct_light(at.j, at.x, at.n, m, at.w_out);
        if (params.seen_in_gather == 0u) {
            radiance += patches_at(at.j).emission.rgb;
        }
    }
    image_sum[pixel] = image_sum[pixel] + vec4<f32>(radiance, 1.0);
}

// The glossy lobe's directional albedo for ks = 1 at cos theta = mu on material k: its table
// (scene::brdf::glossy_albedo_table), linear in sqrt(mu) between the samples.
fn lobe_albedo(k: u32, mu: f32) -> f32 {
    let t = sqrt(clamp(mu, 0.0, 1.0)) * f32(GLOSSY_ALBEDO_SAMPLES - 1u);
    let i = min(u32(t), GLOSSY_ALBEDO_SAMPLES - 2u);
    let at = k * GLOSSY_ALBEDO_SAMPLES + i;
    return mix(glossy_albedo[at], glossy_albedo[at + 1u], t - f32(i));
}

// G at x from what it receives from `toward` (= s d, density 1 / (2 pi) on x's hemisphere).
fn gather_radiance(at: Seen, incoming: vec3<f32>, toward: vec3<f32>) -> vec3<f32> {
    let k = patches_at(at.j).material;
    let m = materials[k];
    let cos_d = abs(dot(at.n, toward));
    // The diffuse part with the control variate of the state's K_j (bundle_finalize):
    // 2 pi (kd / pi) (|n . d| L - (|n . d| - 1/2) Lbar_j) has the mean of
    // 2 pi (kd / pi) |n . d| L, because |n . d| has mean 1/2 over x's hemisphere and
    // Lbar_j was drawn before d; where L is near Lbar_j (the bulk of the indirect light)
    // it has almost none of the variance of the factor |n . d|.
    let mean = image_senders_at(at.j).mean_radiance.rgb;
    var radiance = 2.0 * m.diffuse.rgb * (cos_d * incoming - (cos_d - 0.5) * mean);
    if (GLOSSY && m.kind == MATERIAL_PHONG) {
        // The glossy part likewise: 2 pi |n . d| f_glossy(-s d, w_out) has the mean
        // ks S(n . w_out) over x's hemisphere (the lobe's albedo, by reciprocity the same at
        // exitance), so 2 pi (L - c Lbar_j) |n . d| f_glossy + c Lbar_j ks S keeps the mean of
        // 2 pi L |n . d| f_glossy while the lobe's shape, which a uniform direction samples
        // badly, leaves only (L - c Lbar_j) to vary.
        // c = m.glossy_control: 1 for a broad lobe, 1/2 for a sharp one
        // (scene::brdf::glossy_control_weight says why).
        let base = m.glossy_control * mean;
        if (dot(at.n, toward) > 0.0) {
            radiance += 2.0 * PI * (incoming - base) * cos_d * brdf_glossy(m, at.n, toward, at.w_out);
        }
        radiance += base * m.specular.rgb * lobe_albedo(k, dot(at.n, at.w_out));
    }
    return radiance;
}

// The pixel of block `block` (of pixel_stride x pixel_stride pixels) that gathers through
// this bundle: the one at offset (pixel_class + h) mod 4 in the block (x first), h a hash of
// the block and the image's pixel_shuffle. The four bundles of a step take the four offsets
// of every block; which takes which changes from block to block, so that the classes'
// errors, each smooth over the image, show as noise rather than as a fixed 2 x 2 pattern,
// and not from step to step, so that a pixel's directions are one bundle's stratified set
// (rng::image_direction).
fn class_pixel(block: vec2<u32>) -> vec2<u32> {
    let stride = this_bundle.pixel_stride;
    if (stride == 1u) {
        return block;
    }
    var h = (block.x * 0x8da6b343u) ^ (block.y * 0xd8163841u) ^ this_bundle.pixel_shuffle;
    h = (h ^ (h >> 16u)) * 0x7feb352du;
    h = (h ^ (h >> 15u)) * 0x846ca68bu;
    h = h ^ (h >> 16u);
    let offset = (this_bundle.pixel_class + (h >> 30u)) & 3u;
    return block * 2u + vec2<u32>(offset & 1u, offset >> 1u);
}

// What x receives along `toward` by its line (without SKY_RAYS): what x's patch receives
// there (`own_received`), else, fused, by the lines beside and the nearest candidates
// (`edge_received`); split, the pixel is listed for `gather_edges` (with x's place on its
// line, so that it need not search it again), its Le added here with a count of 0 (Le in
// that pass's loop made it twice as slow on lavapipe), and the answer left undecided.
fn line_received(at: Seen, toward: vec3<f32>, s: f32, pixel: u32, emitted: vec3<f32>) -> Received {
    let line = on_line(at.x, s);
    let received = own_received(at.j, at.x, toward, line);
    if (received.decided) {
        return received;
    }
    if (FUSED_GATHER) {
        return edge_received(at, toward, s, line.lo);
    }
    let listed = atomicAdd(&edges[0], 1u);
    atomicStore(&edges[2u * listed + 1u], pixel);
    atomicStore(&edges[2u * listed + 2u], line.lo);
    image_sum[pixel] = image_sum[pixel] + vec4<f32>(emitted, 0.0);
    return received;
}

// G: the indirect light gathered through this step's bundle, added to the second half of
// the image sum (bound here as image_sum). A pixel whose patch has no fragment of its own
// near x on x's line is listed in `edges` instead (edges[0] counts them, the host clears
// it before the pass; then pixel and `lo` a pair) and left to `gather_edges`.
@compute @workgroup_size(8, 8)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    this_bundle = bundle;
    let size = camera.size.xy;
    // Only this bundle's pixels, one of each stride x stride block of the image (with four
    // bundles a step, each pixel of a 2 x 2 block gathers through its own): one invocation
    // per block, the host dispatching the blocks that meet this band's rows.
    let xy = class_pixel(vec2<u32>(gid.x, gid.y + params.first_row / this_bundle.pixel_stride));
    // This band's rows: its image_sum holds them alone, from params.first_row on.
    let pixel = (xy.y - params.first_row) * size.x + xy.x;
    if (xy.x >= size.x || xy.y >= size.y || xy.y < params.first_row || pixel >= arrayLength(&image_sum)) {
        return;
    }
    let at = seen(xy);
    var radiance = vec3<f32>(0.0);
    if (SEEN_IN_GATHER && at.kind == SEEN_SURFACE) {
        radiance = patches_at(at.j).emission.rgb;
    }
    if (at.kind == SEEN_SURFACE) {
        let d = this_bundle.direction.xyz;
        let s = bundle_side(at.n, d);
        let toward = s * d;
        var received: Received;
        if (SKY_RAYS) {
            received = ray_received(at, toward);
        } else {
            received = line_received(at, toward, s, pixel, radiance);
            if (!received.decided) {
                // Listed for gather_edges, which adds G and the count.
                return;
            }
        }
        if (FUSED_GATHER) {
            if (is_near_sender(received, at.x, toward)) {
                radiance += first_bounce_correction(at, received.sender - 1u, toward);
            }
        } else {
            list_near_sender(received, at.x, toward, pixel);
        }
        radiance += gather_radiance(at, received.radiance, toward);
    }
    image_sum[pixel] = image_sum[pixel] + vec4<f32>(radiance, 1.0);
}

// `own_received` on the line of grid cell `cell` (not decided off the grid or where j has
// no fragment near x's depth there).
fn beside_received(j: u32, x: vec3<f32>, toward: vec3<f32>, s: f32, cell: vec2<i32>) -> Received {
    let line = line_at(cell);
    if (line.outside) {
        return received_const(vec3<f32>(0.0), false);
    }
    return own_received(j, x, toward, search(line, x, s));
}

// What x receives where its own line did not decide (`own_received`): the lines beside x's
// own, then the candidates on x's line (its place on it `lo`), then the lines beside again,
// then the environment. `gather_edges` for the pixels `gather` listed, or `gather` itself
// (FUSED_GATHER).
fn edge_received(at: Seen, toward: vec3<f32>, s: f32, lo: u32) -> Received {
    // The lines beside x's own toward x's point in its cell, the nearer first, then the
    // diagonal one: where one holds j's own fragment near x's depth, x receives what j
    // receives there, as `gather` does on x's own line (a point of j at most a line and a
    // half from x). Only where none does (j crossed by no line near x: a patch smaller
    // than a line), the candidates on x's own line decide (`nearest_received`).
    // In x's own line's width: a wide line's neighbours are a wide line away.
    let cell = cell_of(at.x);
    let base = vec2<i32>(floor(cell));
    let own = line_at(base);
    let width = own.spacing;
    let scaled = cell / width;
    let f = scaled - floor(scaled);
    let step = i32(width);
    let side = vec2<i32>(select(-step, step, f.x >= 0.5), select(-step, step, f.y >= 0.5));
    var first = vec2<i32>(side.x, 0);
    var second = vec2<i32>(0, side.y);
    if (abs(f.y - 0.5) > abs(f.x - 0.5)) {
        first = vec2<i32>(0, side.y);
        second = vec2<i32>(side.x, 0);
    }
    var received = beside_received(at.j, at.x, toward, s, base + first);
    if (!received.decided) {
        received = beside_received(at.j, at.x, toward, s, base + second);
    }
    if (!received.decided) {
        received = beside_received(at.j, at.x, toward, s, base + side);
    }
    if (!received.decided) {
        var line = own;
        line.lo = lo;
        received = nearest_received(at.j, at.x, toward, s, line);
    }
    // Nothing ahead on x's own line: it may pass outside the surfaces right beside x, as
    // past a room's crease, where x's ray meets the other wall at once but the line, half
    // a line off x, misses both walls and leaves the scene. Answering the environment
    // there lit every crease of a closed room with the sky outside it (its pixels up to
    // 18 % of the sky). So the lines beside x decide, by the same rules; only where
    // nothing lies ahead on them either does x see the environment.
    // A loop, not three calls: each inlined copy of the search grows the kernel, and with
    // the paged accessors of a large scene three copies took lavapipe minutes to compile
    // (tests/scale.rs from 20 s to over 3 minutes). Few pixels get here.
    let beside = array<vec2<i32>, 3>(base + first, base + second, base + side);
    for (var c = 0u; c < 3u && !received.decided; c++) {
        received = beside_nearest(at.j, at.x, toward, s, beside[c]);
    }
    if (!received.decided) {
        received = received_const(this_bundle.environment.rgb, true);
    }
    return received;
}

// `gather_edges` and `gather_first_bounce` run on a fixed grid of workgroups of 64 (the
// lists' lengths are known only on the GPU; the host picks the grid for its adapter,
// `image_estimate::list_workgroups`): each invocation takes every (64 x workgroups)-th pixel
// listed.

// G of the pixels `gather` listed in `edges`, by the nearest surface ahead of x among the
// candidates on x's line (`nearest_received`).
@compute @workgroup_size(64)
fn gather_edges(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    this_bundle = bundle;
    let size = camera.size.xy;
    let listed = atomicLoad(&edges[0]);
    for (var i = gid.x; i < listed; i += groups.x * 64u) {
        let pixel = atomicLoad(&edges[2u * i + 1u]);
        let at = seen(vec2<u32>(pixel % size.x, pixel / size.x + params.first_row));
        let d = this_bundle.direction.xyz;
        let s = bundle_side(at.n, d);
        let toward = s * d;
        let received = edge_received(at, toward, s, atomicLoad(&edges[2u * i + 2u]));
        list_near_sender(received, at.x, toward, pixel);
        image_sum[pixel] = image_sum[pixel] + vec4<f32>(gather_radiance(at, received.radiance, toward), 1.0);
    }
}

// The patch-level Lfs_m that bundle_reflect packed into the w slots of image_senders'
// outgoing (`top`) and mean_radiance (`rest`): `pack_first_bounce` there.
fn unpack_first_bounce(top: f32, rest: f32) -> vec3<f32> {
    let bits = u32(rest);
    let others = vec2<f32>(f32((bits >> 11u) & 2047u), f32(bits & 2047u)) * (top / 2047.0);
    switch (bits >> 22u) {
        case 0u: {
            return vec3<f32>(top, others.x, others.y);
        }
        case 1u: {
            return vec3<f32>(others.x, top, others.y);
        }
        default: {
            return vec3<f32>(others.x, others.y, top);
        }
    }
}

// G's weight of radiance arriving at x along `toward`: 2 pi |n . d| f(-toward, w_out), the
// part of `gather_radiance` that is linear in what arrives.
fn gather_weight(at: Seen, toward: vec3<f32>) -> vec3<f32> {
    let m = materials[patches_at(at.j).material];
    let cos_d = abs(dot(at.n, toward));
    var weight = 2.0 * m.diffuse.rgb * cos_d;
    if (GLOSSY && m.kind == MATERIAL_PHONG && dot(at.n, toward) > 0.0) {
        weight += 2.0 * PI * cos_d * brdf_glossy(m, at.n, toward, at.w_out);
    }
    return weight;
}

// What G gains at x (seen `at`, receiving along `toward`) from near sender m's first
// reflection of the lights at the point y its ray meets, D(y, -toward), in place of the
// patch-level Lfs_m: G is linear in what arrives, so the difference times G's weight.
fn first_bounce_correction(at: Seen, m: u32, toward: vec3<f32>) -> vec3<f32> {
    let y = sender_point(m, at.x, toward).xyz;
    let n = patches_at(m).normal.xyz;
    let per_point = direct_light(m, y, n, materials[patches_at(m).material], -toward);
    let lfs = unpack_first_bounce(image_senders_at(m).outgoing.w, image_senders_at(m).mean_radiance.w);
    return gather_weight(at, toward) * (per_point - lfs);
}

// For the pixels `gather` and `gather_edges` listed in `near_senders` (a near sender m):
// G with m's first reflection of the lights at the point y that x's ray meets, with y's own
// visibility of each light, D(y, -toward), in place of the patch-level Lfs_m that `gather`
// took with image_senders (docs/ALGORITHM.md 6, "Near senders' first bounce per point").
// G is linear in what arrives, so the difference times G's weight is added, with no count.
// Its own pass: inlined in the gather, the direct light's code made every pixel's gather
// three times as long on lavapipe, though few pixels need it.
@compute @workgroup_size(64)
fn gather_first_bounce(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    this_bundle = bundle;
    let size = camera.size.xy;
    let listed = atomicLoad(&near_senders[0]);
    for (var i = gid.x; i < listed; i += groups.x * 64u) {
        let pixel = atomicLoad(&near_senders[2u * i + 1u]);
        let m = atomicLoad(&near_senders[2u * i + 2u]) - 1u;
        let at = seen(vec2<u32>(pixel % size.x, pixel / size.x + params.first_row));
        let toward = bundle_side(at.n, this_bundle.direction.xyz) * this_bundle.direction.xyz;
        image_sum[pixel] = image_sum[pixel] + vec4<f32>(first_bounce_correction(at, m, toward), 0.0);
    }
}
