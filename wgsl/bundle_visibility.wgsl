// Bundle visibility (docs/ALGORITHM.md 2.3): every patch projected in parallel along the bundle's
// direction onto its grid; every surface crossing a pixel's line is kept, not only the
// nearest. `fs_count` counts the surfaces per line; after a prefix sum of the counts,
// `fs_fill` writes (depth along d, patch) into each line's slice of the fragment list.
// The order inside a slice is whatever the rasteriser produced: bundle_transfer sorts it.
//
// Render pass, no culling, no depth test, a depth-only attachment that nothing reads.
// Vertex input: RasterVertex. A slot past the capacity sets `overflow`: the host grows the
// list and redoes the steps.
// Host: src/stages/bundle_visibility.rs. Its `SPEC` is the one statement of the bindings
// (names, kinds, access); tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> bundle: Bundle;
@group(0) @binding(1) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> cursor: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> fragments: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> overflow: atomic<u32>;
@group(0) @binding(6) var<storage, read> outgoing: array<vec4<f32>>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) depth: f32,
    @location(1) @interpolate(flat) patch_id: u32,
}

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) patch_id: u32) -> VertexOut {
    let rel = position - bundle.centre.xyz;
    let depth = dot(rel, bundle.direction.xyz);
    var out: VertexOut;
    out.clip = vec4<f32>(
        dot(rel, bundle.axis_u.xyz) + bundle.axis_u.w,
        dot(rel, bundle.axis_v.xyz) + bundle.axis_v.w,
        clamp(0.5 + 0.49 * depth * bundle.centre.w, 0.0, 1.0),
        1.0);
    out.depth = depth;
    out.patch_id = patch_id & ~VERTEX_TWIN_BIT;
    return out;
}

fn line_index(frag: vec4<f32>) -> u32 {
    let pixel = vec2<u32>(frag.xy);
    return pixel.y * bundle.resolution + pixel.x;
}

@fragment
fn fs_count(in: VertexOut) {
    atomicAdd(&counts[line_index(in.clip)], 1u);
}

@fragment
fn fs_fill(in: VertexOut) {
    let line = line_index(in.clip);
    let slot = offsets[line] + atomicAdd(&cursor[line], 1u);
    if (slot < bundle.capacity) {
        // The facing travels with the fragment, so sorting and transfer need not look up
        // the patch.
        let front = select(0u, FRAGMENT_FRONT_BIT, outgoing_at(in.patch_id).w > 0.0);
        fragments[slot] = vec2<u32>(bitcast<u32>(in.depth), in.patch_id | front);
    } else {
        atomicMax(&overflow, 1u);
    }
}
