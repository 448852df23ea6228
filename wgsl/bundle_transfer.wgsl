// Bundle transfer (docs/ALGORITHM.md 2.3-2.4): for every line of the grid, its surfaces sorted by
// depth along d; each patch receives from the next surface along its front direction s_j d:
// that surface's O if its front faces back (s_m = -s_j), black if its back does, the
// environment if there is none. Received radiance is added to the patch's exact 64-bit
// signed fixed-point sums (scaled so the step's largest magnitude fits in 30 bits), so the result
// does not depend on thread order and needs no float atomics.
//
// Two compute entry points. `gather_long_lines` (a fixed grid striding over bundle_visibility's
// list of lines past their bucket, a few in a thousand) gathers each such line's bucket and
// spill chain into a slice of its own past the buckets and records it in `slices`; a slice
// past the capacity sets `overflow` (the host grows the lists and redoes the steps). Then
// `main`, one invocation per line (2D dispatch past 65535 workgroups), sorts the line's
// slice (its bucket, or its slice in `slices` when its count exceeds LINE_BUCKET) in place
// and transfers along it. The image's gather finds the lines the same way.
// Host: src/stages/bundle_transfer.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> bundle: Bundle;
@group(0) @binding(1) var<storage, read> counts: array<u32>;
@group(0) @binding(2) var<storage, read> heads: array<u32>;
@group(0) @binding(3) var<storage, read_write> fragments: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> spill: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> tally: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> overflow: atomic<u32>;
@group(0) @binding(7) var<storage, read_write> slices: array<vec2<u32>>;
@group(0) @binding(8) var<storage, read> long_lines: array<u32>;
@group(0) @binding(9) var<storage, read> outgoing: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> sums: array<atomic<u32>>;
@group(0) @binding(11) var<storage, read> max_bits: array<u32>;

// Fixed-point scale 2^(30 - e) with largest magnitude < 2^e (a rounded value stays below
// 2^30, a sign bit to spare): shared with bundle_finalize.
fn transfer_scale(bits: u32) -> f32 {
    let e = i32((bits >> 23u) & 0xffu) - 126;
    return exp2(f32(30 - e));
}

// Sort key order: depth, then the surface facing -d first (back-to-back twins lie at the
// same depth; this order lets each see past the other), then patch index. The facing bit
// is the top bit of y, so the last two compare as one integer.
fn before(a: vec2<u32>, b: vec2<u32>) -> bool {
    let da = bitcast<f32>(a.x);
    let db = bitcast<f32>(b.x);
    if (da != db) {
        return da < db;
    }
    return a.y < b.y;
}

fn add_fixed(index: u32, value: i32) {
    let low = bitcast<u32>(value);
    let old = sums_add(index, low);
    // The high word gets the carry of the low one and the sign extension of the value.
    let high = select(0u, 1u, old > 0xffffffffu - low) + select(0u, 0xffffffffu, value < 0);
    if (high != 0u) {
        sums_add(index + 1u, high);
    }
}

// Dispatched as LONG_LINES_WORKGROUPS workgroups: each invocation takes every
// LONG_LINES_INVOCATIONS-th line of the list.
const LONG_LINES_INVOCATIONS: u32 = LONG_LINES_WORKGROUPS * 64u;

@compute @workgroup_size(64)
fn gather_long_lines(@builtin(global_invocation_id) gid: vec3<u32>) {
    let listed = min(atomicLoad(&tally[TALLY_LONG_LINES]), bundle.capacity);
    let buckets = bundle.line_capacity * LINE_BUCKET;
    for (var i = gid.x; i < listed; i += LONG_LINES_INVOCATIONS) {
        let line = long_lines[i];
        let n = counts[line];
        let base = atomicAdd(&tally[TALLY_LONG], n);
        if (base + n > bundle.capacity) {
            atomicMax(&overflow, 1u);
            slices[line] = vec2<u32>(0u, 0u);
            continue;
        }
        let begin = buckets + base;
        for (var k = 0u; k < LINE_BUCKET; k++) {
            fragments[begin + k] = fragments[line * LINE_BUCKET + k];
        }
        var end = begin + LINE_BUCKET;
        // The chain is short of n only when the spill list overflowed (the steps are redone).
        var node = heads[line];
        while (node != 0u && end < begin + n) {
            let s = spill[node - 1u];
            fragments[end] = s.xy;
            node = s.z;
            end++;
        }
        slices[line] = vec2<u32>(begin, end);
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let line = gid.x + gid.y * groups.x * 64u;
    if (line >= bundle.line_count) {
        return;
    }
    let n = counts[line];
    if (n == 0u) {
        return;
    }
    var begin = line * LINE_BUCKET;
    var end = begin + n;
    if (n > LINE_BUCKET) {
        let slice = slices[line];
        begin = slice.x;
        end = slice.y;
    }
    for (var a = begin + 1u; a < end; a++) {
        let item = fragments[a];
        var b = a;
        while (b > begin && before(item, fragments[b - 1u])) {
            fragments[b] = fragments[b - 1u];
            b--;
        }
        fragments[b] = item;
    }
    // A wide line samples wide^2 fine lines' squares: its radiance counts that many
    // times. The scale leaves room for it (bundle_finalize divides by the same).
    let fine_scale = transfer_scale(max_bits[0]) / f32(bundle.wide * bundle.wide);
    let scale = select(fine_scale, transfer_scale(max_bits[0]), line < bundle.wide_lines);
    for (var k = begin; k < end; k++) {
        let j = fragments[k].y & ~FRAGMENT_FRONT_BIT;
        let front = (fragments[k].y & FRAGMENT_FRONT_BIT) != 0u;
        var received = bundle.environment.rgb;
        var neighbour = -1;
        if (front) {
            if (k + 1u < end) {
                neighbour = i32(k + 1u);
            }
        } else if (k > begin) {
            neighbour = i32(k - 1u);
        }
        if (neighbour >= 0) {
            let other = fragments[u32(neighbour)].y;
            let other_front = (other & FRAGMENT_FRONT_BIT) != 0u;
            // Its front must face back toward this patch: the opposite facing.
            received = select(vec3<f32>(0.0), outgoing_at(other & ~FRAGMENT_FRONT_BIT).rgb, other_front != front);
        }
        for (var c = 0u; c < 3u; c++) {
            let value = i32(round(received[c] * scale));
            if (value != 0) {
                add_fixed(6u * j + 2u * c, value);
            }
        }
    }
}
