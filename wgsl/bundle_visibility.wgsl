// Bundle visibility (docs/ALGORITHM.md 2.3): every patch projected in parallel along the bundle's
// direction onto its grid; every surface crossing a pixel's line is kept, not only the
// nearest, in one pass. Each line owns LINE_BUCKET slots of the fragment list; its first
// LINE_BUCKET surfaces go there, the rest to the spill list, chained per line from `heads`
// (node + 1, 0 ends the chain), and the line is listed in `long_lines`. bundle_transfer
// gathers a listed line into one slice and sorts every line by depth: the order here is
// whatever the rasteriser produced.
//
// Render pass, no culling, no depth test, a depth-only attachment that nothing reads.
// Vertex input: the rasterised triangles (position, first patch id, lattice word:
// `lattice_patch`). A spill node past the capacity sets `overflow`: the host
// grows the spill list and redoes the steps.
// Host: src/stages/bundle_visibility.rs. Its `SPEC` is the one statement of the bindings
// (names, kinds, access); tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> bundle: Bundle;
@group(0) @binding(1) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read_write> heads: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> fragments: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> spill: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> tally: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> overflow: atomic<u32>;
@group(0) @binding(7) var<storage, read_write> long_lines: array<u32>;
@group(0) @binding(8) var<storage, read> outgoing: array<vec4<f32>>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) depth: f32,
    // The patch | FRAGMENT_FRONT_BIT when its front faces +d: the facing travels with the
    // fragment, so sorting and transfer need not look up the patch, and it is looked up
    // once a vertex, not once a fragment: all patches of a lattice share its plane.
    @location(1) @interpolate(flat) patch_id: u32,
    @location(2) @interpolate(flat) lattice_word: u32,
    @location(3) lattice: vec2<f32>,
    @location(4) @interpolate(flat) level: u32,
}

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    @location(1) patch_id: u32,
    @location(2) lattice_word: u32,
    @builtin(instance_index) instance: u32,
) -> VertexOut {
    let rel = position - bundle.centre.xyz;
    let depth = dot(rel, bundle.direction.xyz);
    var out: VertexOut;
    let clip = vec2<f32>(dot(rel, bundle.axis_u.xyz) + bundle.axis_u.w, dot(rel, bundle.axis_v.xyz) + bundle.axis_v.w);
    // Instance 0 draws the wide lines: the whole grid in a viewport of resolution / wide
    // pixels. Instance 1 the fine lines: the whole grid's, the scissor keeping the fine
    // window's (one level: instance 1 alone, whose window is the whole grid). The same clip
    // coordinates in both, as with one level: the rasteriser then interpolates the same
    // depth for back-to-back twins, which the transfer's order needs.
    out.clip = vec4<f32>(clip, clamp(0.5 + 0.49 * depth * bundle.centre.w, 0.0, 1.0), 1.0);
    out.depth = depth;
    let id = patch_id & ~VERTEX_TWIN_BIT;
    out.patch_id = id | select(0u, FRAGMENT_FRONT_BIT, outgoing_at(id).w > 0.0);
    out.lattice_word = lattice_word;
    out.lattice = lattice_corner(lattice_word);
    out.level = instance;
    return out;
}

@fragment
fn fs_fill(in: VertexOut) {
    let pixel = vec2<u32>(in.clip.xy);
    var line: u32;
    let rect = bundle.fine_rect;
    let size = rect.zw;
    if (in.level == 1u) {
        // A fine line, inside the fine window (the scissor).
        let local = pixel - rect.xy;
        if (any(pixel < rect.xy) || any(local >= size)) {
            return;
        }
        line = bundle.wide_lines + local.y * size.x + local.x;
    } else {
        // A wide line, unless the fine window covers it.
        let k = bundle.wide;
        let low = rect.xy / k;
        let high = (rect.xy + size) / k;
        if (all(pixel >= low) && all(pixel < high)) {
            return;
        }
        line = pixel.y * (bundle.resolution / k) + pixel.x;
    }
    let front = in.patch_id & FRAGMENT_FRONT_BIT;
    let patch_id = lattice_patch(in.patch_id & ~FRAGMENT_FRONT_BIT, in.lattice_word, in.lattice) | front;
    let fragment = vec2<u32>(bitcast<u32>(in.depth), patch_id);
    let slot = atomicAdd(&counts[line], 1u);
    if (slot < LINE_BUCKET) {
        fragments[line * LINE_BUCKET + slot] = fragment;
        return;
    }
    if (slot == LINE_BUCKET) {
        // The line's first surface past its bucket lists the line, once.
        let listed = atomicAdd(&tally[TALLY_LONG_LINES], 1u);
        if (listed < bundle.capacity) {
            long_lines[listed] = line;
        }
    }
    let node = atomicAdd(&tally[TALLY_SPILLED], 1u);
    if (node < bundle.capacity) {
        spill[node] = vec4<u32>(fragment, atomicExchange(&heads[line], node + 1u), 0u);
    } else {
        atomicMax(&overflow, 1u);
    }
}
