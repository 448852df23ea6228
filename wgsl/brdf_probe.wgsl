// BRDF probe: evaluates `brdf` (wgsl/common/brdf.wgsl) for a list of queries, so that a test
// can compare it with the host's `scene::brdf::eval`. Test instrument, not part of a render.
//
// Compute, one invocation per query: queries holds 4 vec4 per query (n, w_in, w_out,
// (material, 0, 0, 0)), results the rgb f of each.
// Host: src/stages/brdf_probe.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<storage, read> materials: array<Material>;
@group(0) @binding(1) var<storage, read> queries: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> results: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let q = gid.x;
    if (q >= arrayLength(&results)) {
        return;
    }
    let n = queries[4u * q].xyz;
    let w_in = queries[4u * q + 1u].xyz;
    let w_out = queries[4u * q + 2u].xyz;
    let m = materials[u32(queries[4u * q + 3u].x)];
    results[q] = vec4<f32>(brdf(m, n, w_in, w_out), 0.0);
}
