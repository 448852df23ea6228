// Light windows (docs/ALGORITHM.md 6): the item buffers of the lights' windows for the per-pixel
// direct light, every face a tile of one atlas texture. Each draw renders every patch into
// one face: the instance index picks the face's view, the host sets the viewport to its tile
// and the scissor to the rows inside the window.
//
// Render pass. Vertex input: the rasterised triangles (location 0 position, location 1 the
// first patch id with VERTEX_TWIN_BIT, location 2 the lattice word: `lattice_patch`).
// Target: R32Uint patch index + 1 (NO_PATCH where nothing), Depth32Float reversed-z (greater
// is nearer, cleared to 0). No culling: a surface seen from its back still occludes.
// Invariant: a face's pixel (i, j) holds the surface seen through its centre, as for the
// camera (`camera_item_buffer.wgsl`), so `image_estimate` can find the texels around any
// direction. Host: src/stages/light_window.rs. Its `SPEC` is the one statement of the
// bindings; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<storage, read> faces: array<WindowFace>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) patch_id: u32,
    @location(1) @interpolate(flat) lattice_word: u32,
    @location(2) lattice: vec2<f32>,
}

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    @location(1) patch_id: u32,
    @location(2) lattice_word: u32,
    @builtin(instance_index) face: u32,
) -> VertexOut {
    var out: VertexOut;
    // Faces sample their texel centres (jitter 0.5); a directional light's face is a
    // parallel projection.
    out.clip = view_clip(faces[face].view, position);
    out.patch_id = patch_id;
    out.lattice_word = lattice_word;
    out.lattice = lattice_corner(lattice_word);
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) u32 {
    // Of two back-to-back twins at the same depth only the one facing the light counts.
    if (!front && (in.patch_id & VERTEX_TWIN_BIT) != 0u) {
        discard;
    }
    return lattice_patch(in.patch_id & ~VERTEX_TWIN_BIT, in.lattice_word, in.lattice) + 1u;
}
