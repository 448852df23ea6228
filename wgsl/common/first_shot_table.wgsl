// The first-shot table (bind group 1) and the reflected first-shot radiance, for the
// kernels that evaluate it (image_estimate, bundle_reflect). Built by src/first_shot.rs.
// Bindings: `FIRST_SHOT_TABLE_GROUP` in src/gpu/scene_buffers.rs, group 1 of those kernels'
// `SPEC`s (tests/kernel_bindings.rs holds them against this file).

@group(1) @binding(0) var<storage, read> fs_offsets: array<u32>;       // row starts, patches + 1
@group(1) @binding(1) var<storage, read> fs_entries: array<vec2<u32>>; // (sample, bits of r_ij)
@group(1) @binding(2) var<storage, read> samples: array<LightSample>;
@group(1) @binding(3) var<storage, read> fs_irradiance: array<vec4<f32>>; // sum_i S_i r_ij

// Lfs_j(x, w_out) = sum_i S_i r_ij f_j(w'_i(x), x, w_out), w'_i(x) from y_i to x (a
// directional light's own direction of travel).
fn first_shot_radiance(j: u32, x: vec3<f32>, n: vec3<f32>, m: Material, w_out: vec3<f32>) -> vec3<f32> {
    if (dot(n, w_out) <= 0.0) {
        return vec3<f32>(0.0);
    }
    // A diffuse BRDF is kd / pi for every pair of directions above the surface, and every
    // stored sample lies above it (only front faces received), so the row's sum suffices.
    if (m.kind == MATERIAL_DIFFUSE) {
        return fs_irradiance_at(j).rgb * m.diffuse.rgb / PI;
    }
    var sum = vec3<f32>(0.0);
    for (var e = fs_offsets[j]; e < fs_offsets[j + 1u]; e++) {
        let entry = fs_entries[e];
        // Field by field: a CPU adapter loads every field of a whole-struct read.
        let i = entry.x;
        var w_in = normalize(samples[i].position.xyz - x);
        if (samples[i].kind == LIGHT_DIRECTIONAL) {
            w_in = -samples[i].normal.xyz;
        }
        sum += samples[i].strength.rgb * bitcast<f32>(entry.y) * brdf(m, n, w_in, w_out);
    }
    return sum;
}
