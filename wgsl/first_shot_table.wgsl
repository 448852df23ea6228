// First-shot table: the appended (patch, sample, r_ij) pairs into compressed rows by patch.
// `fill_rows` places each pair in its patch's row (row starts from the prefix sum of the
// row counts); `sort_rows` orders each row by sample index, so the table does not depend
// on the order in which the pairs were appended; `row_irradiance` sums S_i r_ij over each
// row, which is all a diffuse patch needs (its BRDF does not depend on the directions).
//
// Compute. fill_rows: one invocation per pair; sort_rows, row_irradiance: one per patch
// (2D dispatch past 65535 workgroups). The cursor is zeroed before fill_rows.
// Host: src/stages/first_shot_table.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> params: vec4<u32>;
@group(0) @binding(1) var<storage, read> pairs: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> cursor: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> entries: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read> samples: array<LightSample>;
@group(0) @binding(6) var<storage, read_write> irradiance: array<vec4<f32>>;

@compute @workgroup_size(64)
fn fill_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = gid.x + gid.y * groups.x * 64u;
    if (k >= params.x) {
        return;
    }
    let pair = pairs_at(k);
    let slot = offsets[pair.x] + atomicAdd(&cursor[pair.x], 1u);
    entries[slot] = pair.yz;
}

@compute @workgroup_size(64)
fn sort_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = gid.x + gid.y * groups.x * 64u;
    if (j >= params.y) {
        return;
    }
    let begin = offsets[j];
    let end = offsets[j + 1u];
    // Rows hold at most one entry per light sample: short, so insertion sort.
    for (var a = begin + 1u; a < end; a++) {
        let item = entries[a];
        var b = a;
        while (b > begin && entries[b - 1u].x > item.x) {
            entries[b] = entries[b - 1u];
            b--;
        }
        entries[b] = item;
    }
}

@compute @workgroup_size(64)
fn row_irradiance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = gid.x + gid.y * groups.x * 64u;
    if (j >= params.y) {
        return;
    }
    var sum = vec3<f32>(0.0);
    for (var e = offsets[j]; e < offsets[j + 1u]; e++) {
        sum += samples[entries[e].x].strength.rgb * bitcast<f32>(entries[e].y);
    }
    irradiance_set(j, vec4<f32>(sum, 0.0));
}
