// Camera item buffer: which patch each camera pixel sees (docs/ALGORITHM.md 4), for this pass's
// sub-pixel sample position.
//
// Render pass. Vertex input: the rasterised triangles (location 0 position, location 1 the
// first patch id with VERTEX_TWIN_BIT, location 2 the lattice word: `lattice_patch`).
// Target: R32Uint patch index + 1 (NO_PATCH where nothing), Depth32Float reversed-z
// (greater is nearer, cleared to 0). No culling: a back face is black but still occludes.
// Invariant: the sample point (pixel + camera.jitter) lands on the rasteriser's pixel
// centre, so `image_estimate` can rebuild the exact ray of every pixel. The first shot's
// faces use it too, a directional light's as a parallel projection (`view_clip`).
// Host: src/stages/camera_item_buffer.rs. Its `SPEC` is the one statement of the bindings
// (names, kinds, access); tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> camera: Camera;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) patch_id: u32,
    @location(1) @interpolate(flat) lattice_word: u32,
    @location(2) lattice: vec2<f32>,
}

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) patch_id: u32, @location(2) lattice_word: u32) -> VertexOut {
    var out: VertexOut;
    out.clip = view_clip(camera, position);
    out.patch_id = patch_id;
    out.lattice_word = lattice_word;
    out.lattice = lattice_corner(lattice_word);
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) u32 {
    // Of two back-to-back twins at the same depth only the one facing the camera counts.
    if (!front && (in.patch_id & VERTEX_TWIN_BIT) != 0u) {
        discard;
    }
    return lattice_patch(in.patch_id & ~VERTEX_TWIN_BIT, in.lattice_word, in.lattice) + 1u;
}
