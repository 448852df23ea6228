// First-shot reduction (docs/ALGORITHM.md 1). `reduce_face` adds, for every pixel of one face of a
// light sample's window, the pixel's weight cos^3(theta_p) (times cos(theta_L) for an
// area-light vertex, times the cone's falloff for a spot light; 1 for the parallel view of a
// directional light) to the sum of the patch seen there, if the patch's front faces the
// sample. `append_sample` then turns each non-zero sum into r_ij and appends the pair
// (patch, sample, r_ij) to a list, clearing the sum for the next sample.
//
// Sums are exact 64-bit integers (weights in [0, 1] times FIXED_POINT_SCALE, split over two
// u32 atomics), so the result does not depend on thread order and needs no float atomics.
//
// Compute. reduce_face: one invocation per run of FIRST_SHOT_RUN pixels of a face row. append_sample: one invocation per
// patch (2D dispatch past 65535 workgroups), the only writer of its row count. The pair
// count may exceed the capacity: then the host grows the list and runs the first shot again.
// Host: src/stages/first_shot_reduce.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> face: Camera;
@group(0) @binding(1) var<uniform> params: FaceParams;
@group(0) @binding(2) var item_buffer: texture_2d<u32>;
@group(0) @binding(3) var<storage, read> patches: array<Patch>;
@group(0) @binding(4) var<storage, read> samples: array<LightSample>;
@group(0) @binding(5) var<storage, read_write> sums: array<atomic<u32>>;
@group(0) @binding(6) var<uniform> append: AppendParams;
@group(0) @binding(7) var<storage, read_write> row_counts: array<u32>;
@group(0) @binding(8) var<storage, read_write> pairs: array<vec4<u32>>;
@group(0) @binding(9) var<storage, read_write> pair_count: atomic<u32>;

// Adds a run's sum (lo, hi: 64 bits) to patch j's; the carry of the low word into the high.
fn add_to_sum(j: u32, lo: u32, hi: u32) {
    if ((lo | hi) == 0u) {
        return;
    }
    var carry = hi;
    if (lo != 0u) {
        let old = atomicAdd(&sums[2u * j], lo);
        if (old > 0xffffffffu - lo) {
            carry += 1u;
        }
    }
    if (carry != 0u) {
        atomicAdd(&sums[2u * j + 1u], carry);
    }
}

// The weight of the face pixel whose direction from the sample is `v` (at focal distance 1)
// for a patch of plane `n` (xyz normal, w offset), 0 if the patch's back faces the sample,
// as a fixed-point integer.
fn pixel_weight(n: vec4<f32>, s: LightSample, v: vec3<f32>) -> u32 {
    var weight = 1.0;
    if (s.kind == LIGHT_DIRECTIONAL) {
        // A parallel projection: every pixel has the same area dP (in the host's factor).
        // Only front faces receive: the light must travel against the patch's normal.
        if (dot(n.xyz, s.normal.xyz) >= 0.0) {
            return 0u;
        }
    } else {
        // Only front faces receive: the sample must lie on the front side of the patch's plane.
        if (dot(n.xyz, s.position.xyz) - n.w <= 0.0) {
            return 0u;
        }
        // The face's normal is `forward` (unit) at focal distance 1, so cos(theta_p) = 1 / |v|.
        let inv = inverseSqrt(dot(v, v));
        weight = inv * inv * inv;
        if (s.kind == LIGHT_AREA) {
            weight *= max(dot(v, s.normal.xyz) * inv, 0.0);
        }
        if (s.kind == LIGHT_SPOT) {
            weight *= spot_falloff(dot(v, s.normal.xyz) * inv, s.cone_scale, s.cone_offset);
        }
    }
    return u32(min(weight, 1.0) * FIXED_POINT_SCALE + 0.5);
}

// One invocation per run of FIRST_SHOT_RUN pixels of a row: neighbouring pixels mostly see
// the same patch, so the run adds up each patch's pixels in registers (exact 64-bit integer
// sums, as the atomics are) and adds them to the patch's sum once per change of patch.
@compute @workgroup_size(8, 8)
fn reduce_face(@builtin(global_invocation_id) gid: vec3<u32>) {
    let first = gid.x * FIRST_SHOT_RUN;
    if (first >= face.size.x || gid.y >= params.rows) {
        return;
    }
    let s = samples[params.sample];
    let end = min(first + FIRST_SHOT_RUN, face.size.x);
    var current = NO_PATCH;
    var n = vec4<f32>(0.0);
    var lo = 0u;
    var hi = 0u;
    // The direction of the run's first pixel, and its step along the row: the directions are
    // linear in the pixel, and one inverse square root a pixel instead of a square root and
    // two divisions took the first shot's reduction from about 100 to 75 ms on lavapipe
    // (Sierpinski, 45 faces of 544).
    let v = pixel_direction(face, vec2<u32>(first, gid.y));
    let step = pixel_direction(face, vec2<u32>(first + 1u, gid.y)) - v;
    for (var x = first; x < end; x++) {
        let id = textureLoad(item_buffer, vec2<i32>(i32(x), i32(gid.y)), 0).x;
        if (id == NO_PATCH || id > params.patch_count) {
            continue;
        }
        if (id != current) {
            if (current != NO_PATCH) {
                add_to_sum(current - 1u, lo, hi);
            }
            current = id;
            n = patches_at(id - 1u).normal;
            lo = 0u;
            hi = 0u;
        }
        let fixed = pixel_weight(n, s, v + f32(x - first) * step);
        let before = lo;
        lo += fixed;
        if (lo < before) {
            hi += 1u;
        }
    }
    if (current != NO_PATCH) {
        add_to_sum(current - 1u, lo, hi);
    }
}

@compute @workgroup_size(64)
fn append_sample(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = gid.x + gid.y * groups.x * 64u;
    if (j >= append.patch_count) {
        return;
    }
    let lo = atomicLoad(&sums[2u * j]);
    let hi = atomicLoad(&sums[2u * j + 1u]);
    if ((lo | hi) == 0u) {
        return;
    }
    atomicStore(&sums[2u * j], 0u);
    atomicStore(&sums[2u * j + 1u], 0u);
    let sum = f32(hi) * 4294967296.0 + f32(lo);
    let r = sum * append.factor / patches_at(j).v0.w;
    row_counts[j] += 1u;
    let slot = atomicAdd(&pair_count, 1u);
    if (slot < append.capacity) {
        pairs_set(slot, vec4<u32>(j, append.sample, bitcast<u32>(r), 0u));
    }
}
