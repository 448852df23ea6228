// Bundle reflection (docs/ALGORITHM.md 2.2): the radiance every patch sends into this step's bundle,
//   O_j = Le_j + Lfs_j(c_j, s_j d) + 2 kd_j K_j + (1 / h) sum_i 2 pi J_j,i f_glossy_j(win_j,i, c_j, s_j d)
// (2 kd K = 2 pi K f_diffuse: K_j is J_j with its control variate, bundle_finalize; the
// glossy sum over the h <= GLOSSY_HISTORY + 1 latest J_j with their directions), with Le
// left out for first-shot lights (their first reflection replaces them); the same with the
// mean of K_j over the image steps in place of K_j, which the image gathers
// (`image_senders`, docs/ALGORITHM.md 6); where the image evaluates near senders' first
// bounce per point, Lfs_j alone (`pack_first_bounce`); and the largest |O| of the step (for
// the fixed-point scale of the transfer).
//
// Compute, one invocation per patch (2D dispatch past 65535 workgroups), the only writer
// of its `outgoing` (rgb O_j, w s_j). `max_bits` takes the largest O channel by its bits
// (positive floats order like their bits).
// Group 1: the first-shot table (wgsl/common/first_shot_table.wgsl).
// Host: src/stages/bundle_reflect.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

// The step's bundle as a storage buffer: as a uniform, lavapipe compiled this kernel again
// at every step of a new seed (src/stages/bundle_reflect.rs says why).
@group(0) @binding(0) var<storage, read> bundle: Bundle;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> materials: array<Material>;
@group(0) @binding(3) var<storage, read> state: array<PatchState>;
@group(0) @binding(4) var<storage, read_write> outgoing: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> max_bits: atomic<u32>;
@group(0) @binding(6) var<storage, read_write> image_senders: array<ImageSender>;

// True where the image's gather evaluates a near sender's first reflection of the
// first-shot lights per point (image_estimate's FIRST_BOUNCE_PER_POINT): it then needs the
// patch-level Lfs_j that image_senders' outgoing holds, to take it out. Lfs_j rides in the
// w slots of an ImageSender, which nothing else reads (`pack_first_bounce`): an array of its
// own took more storage bindings, past lavapipe's 32.
override IMAGE_FIRST_BOUNCE: bool = false;

// Lfs (non-negative) as two floats: its largest channel exactly, and, as an integer below
// 2^24 (exact in f32), which channel that is (2 bits) and the other two in channel order as
// 11-bit fractions of it, rounded: within 1 / 4094 of the largest channel.
// `unpack_first_bounce` in wgsl/image_estimate.wgsl reads it.
fn pack_first_bounce(l: vec3<f32>) -> vec2<f32> {
    let top = max(l.r, max(l.g, l.b));
    if (top <= 0.0) {
        return vec2<f32>(0.0);
    }
    var which = 2u;
    var others = l.rg;
    if (l.r == top) {
        which = 0u;
        others = l.gb;
    } else if (l.g == top) {
        which = 1u;
        others = l.rb;
    }
    let q = vec2<u32>(round(clamp(others / top, vec2<f32>(0.0), vec2<f32>(1.0)) * 2047.0));
    return vec2<f32>(top, f32((which << 22u) | (q.x << 11u) | q.y));
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = gid.x + gid.y * groups.x * 64u;
    if (j == 0u) {
        let env = bundle.environment.rgb;
        atomicMax(&max_bits, bitcast<u32>(max(env.r, max(env.g, env.b))));
    }
    if (j >= bundle.patch_count) {
        return;
    }
    let p = patches_at(j);
    let n = p.normal.xyz;
    let d = bundle.direction.xyz;
    let side = bundle_side(n, d);
    let w_out = side * d;
    var o = vec3<f32>(0.0);
    if ((p.flags & PATCH_FIRST_SHOT_LIGHT) == 0u) {
        o = p.emission.rgb;
    }
    let m = materials[p.material];
    let c = patch_centre(p);
    let first_bounce = first_shot_radiance(j, c, n, m, w_out);
    o += first_bounce;
    // What the image gathers from j: its diffuse reflection of the mean J of the image steps
    // so far (a direction-free estimate with none of the chain's step-to-step noise).
    var image_o = o;
    var mean_radiance = vec3<f32>(0.0);
    if (bundle.use_state != 0u) {
        // Field by field, and the glossy history only for a glossy patch: a CPU adapter loads
        // every field of a whole-struct read.
        mean_radiance = state_at(j).mean_radiance.rgb;
        let diffuse = state_at(j).diffuse.rgb;
        let diffuse_sum = state_at(j).diffuse_sum;
        // The glossy part, in the transport and the image alike: the mean of the glossy
        // reflections of the last steps' J, each an independent sample of win drawn before
        // this step's d, so the mean is as unbiased as one sample (docs/ALGORITHM.md 2.2).
        // One sample alone multiplies J by up to 2 pi |n . d| f_glossy (3.2 at the peak of
        // Sierpinski's lobe, more on sharper ones) at every glossy bounce: chains of such
        // gains made a few patches hundreds of times too bright for some steps. The mean
        // spreads one step's spike over as many steps at a fraction of its weight.
        var glossy = vec3<f32>(0.0);
        if (m.kind == MATERIAL_PHONG) {
            let incoming = state_at(j).incoming;
            glossy = glossy_reflection(m, n, incoming.rgb, -octahedral_unpack(state_at(j).direction), w_out);
            // Unrolled, for GLOSSY_HISTORY entries: a CPU adapter runs a data-dependent loop
            // many times slower.
            let written = u32(incoming.w);
            if (written > 0u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[0], w_out);
            }
            if (written > 1u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[1], w_out);
            }
            if (written > 2u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[2], w_out);
            }
            if (written > 3u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[3], w_out);
            }
            if (written > 4u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[4], w_out);
            }
            if (written > 5u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[5], w_out);
            }
            if (written > 6u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[6], w_out);
            }
            if (written > 7u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[7], w_out);
            }
            if (written > 8u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[8], w_out);
            }
            if (written > 9u) {
                glossy += earlier_glossy(m, n, state_at(j).earlier[9], w_out);
            }
            glossy /= f32(1u + written);
        }
        o += 2.0 * m.diffuse.rgb * diffuse + glossy;
        var mean = diffuse;
        if (diffuse_sum.w > 0.0) {
            mean = diffuse_sum.rgb / diffuse_sum.w;
        }
        image_o += 2.0 * m.diffuse.rgb * mean + glossy;
    }
    outgoing_set(j, vec4<f32>(o, side));
    var packed = vec2<f32>(side, 0.0);
    if (IMAGE_FIRST_BOUNCE) {
        packed = pack_first_bounce(first_bounce);
    }
    // With Lbar_j as it stands before this step's d (finalize updates it with this step's J):
    // the gather's control variate at j's own pixels.
    image_senders_set(j, ImageSender(vec4<f32>(image_o, packed.x), vec4<f32>(mean_radiance, packed.y)));
    let largest = abs(o);
    atomicMax(&max_bits, bitcast<u32>(max(largest.r, max(largest.g, largest.b))));
}

// The glossy reflection toward w_out of radiance J arriving from w_in (unit, away from the
// surface), one sample of a uniform hemisphere (density 1 / (2 pi)).
fn glossy_reflection(m: Material, n: vec3<f32>, j: vec3<f32>, w_in: vec3<f32>, w_out: vec3<f32>) -> vec3<f32> {
    if (dot(n, w_in) > 0.0 && dot(n, w_out) > 0.0) {
        return 2.0 * PI * j * brdf_glossy(m, n, w_in, w_out);
    }
    return vec3<f32>(0.0);
}

// The same for an entry of the state's history (PatchState::earlier).
fn earlier_glossy(m: Material, n: vec3<f32>, e: vec2<u32>, w_out: vec3<f32>) -> vec3<f32> {
    return glossy_reflection(m, n, unpack_history_radiance(e.x), -octahedral_unpack(e.y), w_out);
}
