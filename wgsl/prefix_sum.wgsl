// Exclusive prefix sum of u32 counts, in levels: `scan_blocks` scans blocks of BLOCK values
// and writes each block's total to `block_sums`; the host scans those recursively, then
// `add_block_offsets` adds each block's scanned total back. Integer sums: exact and
// independent of thread order.
//
// Compute, workgroup PREFIX_SUM_WORKGROUP, PREFIX_SUM_PER_THREAD values per invocation
// (both from src/layout.rs): long runs per thread keep the barrier-bound workgroup scan a
// small share of the work on CPU adapters.
// Invariant: dispatches cover ceil(n / BLOCK) workgroups (2D when above 65535).
// Host: src/stages/prefix_sum.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

// PREFIX_SUM_WORKGROUP and PREFIX_SUM_PER_THREAD come from the generated header.
const WORKGROUP: u32 = PREFIX_SUM_WORKGROUP;
const PER_THREAD: u32 = PREFIX_SUM_PER_THREAD;
const BLOCK: u32 = WORKGROUP * PER_THREAD;

@group(0) @binding(0) var<uniform> params: vec4<u32>;
@group(0) @binding(1) var<storage, read> values: array<u32>;
@group(0) @binding(2) var<storage, read_write> scanned: array<u32>;
@group(0) @binding(3) var<storage, read_write> block_sums: array<u32>;

var<workgroup> partial: array<u32, PREFIX_SUM_WORKGROUP>;

fn block_index(wg: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wg.x + wg.y * groups.x;
}

@compute @workgroup_size(PREFIX_SUM_WORKGROUP)
fn scan_blocks(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let block = block_index(wg, groups);
    let n = params.x;
    let base = block * BLOCK + lid * PER_THREAD;
    var local: array<u32, PREFIX_SUM_PER_THREAD>;
    var total = 0u;
    for (var k = 0u; k < PER_THREAD; k++) {
        local[k] = total;
        if (base + k < n) {
            total += values[base + k];
        }
    }
    partial[lid] = total;
    workgroupBarrier();
    // Hillis-Steele inclusive scan of the per-thread totals.
    for (var offset = 1u; offset < WORKGROUP; offset *= 2u) {
        var add = 0u;
        if (lid >= offset) {
            add = partial[lid - offset];
        }
        workgroupBarrier();
        partial[lid] += add;
        workgroupBarrier();
    }
    let before = partial[lid] - total;
    for (var k = 0u; k < PER_THREAD; k++) {
        if (base + k < n) {
            scanned[base + k] = before + local[k];
        }
    }
    if (lid == WORKGROUP - 1u && block * BLOCK < n) {
        block_sums[block] = partial[lid];
    }
}

@compute @workgroup_size(PREFIX_SUM_WORKGROUP)
fn add_block_offsets(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
                     @builtin(local_invocation_index) lid: u32) {
    let block = block_index(wg, groups);
    let n = params.x;
    let add = block_sums[block];
    for (var k = 0u; k < PER_THREAD; k++) {
        let i = block * BLOCK + lid * PER_THREAD + k;
        if (i < n) {
            scanned[i] += add;
        }
    }
}
