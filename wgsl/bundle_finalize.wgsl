// Bundle finalize (docs/ALGORITHM.md 2.4): J_j = (dP / A_j) * (sum of received radiance) from the
// signed fixed-point sums, win_j = -s_j d, K_j = J_j with its control variate, the running
// mean Lbar_j and (past the burn-in) the sum of K_j for the image; the sums are cleared for
// the next step.
//
// Compute, one invocation per patch (2D dispatch past 65535 workgroups): each patch's 6
// sums and its state have one writer.
// Host: src/stages/bundle_finalize.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> bundle: Bundle;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;
@group(0) @binding(3) var<storage, read> max_bits: array<u32>;
@group(0) @binding(4) var<storage, read> outgoing: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> state: array<PatchState>;
@group(0) @binding(6) var<storage, read> materials: array<Material>;

// The weight of each step's estimate 2 K_j in Lbar_j (an exponential mean over about 8 steps).
const MEAN_RADIANCE_WEIGHT: f32 = 0.125;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = gid.x + gid.y * groups.x * 64u;
    if (j >= bundle.patch_count) {
        return;
    }
    let bits = max_bits[0];
    let e = i32((bits >> 23u) & 0xffu) - 126;
    // bundle_transfer's scale of a fine line's radiance (a wide line's counts wide^2 times).
    let scale = exp2(f32(30 - e)) / f32(bundle.wide * bundle.wide);
    var j_value = vec3<f32>(0.0);
    for (var c = 0u; c < 3u; c++) {
        let lo = sums_at(6u * j + 2u * c);
        let hi = sums_at(6u * j + 2u * c + 1u);
        // Two's complement: received radiance can be negative (see below).
        j_value[c] = (f32(bitcast<i32>(hi)) * 4294967296.0 + f32(lo)) / scale;
        sums_set(6u * j + 2u * c, 0u);
        sums_set(6u * j + 2u * c + 1u, 0u);
    }
    let factor = bundle.direction.w / patches_at(j).v0.w;
    let side = outgoing_at(j).w;
    let incoming = j_value * factor;
    // The control variate: J_j carries the projected-area factor |n . d| of the one
    // direction (the radiance along it times the share of the patch it covers), whose mean
    // over uniform directions is exactly 1/2. K_j = J_j - (|n . d| - 1/2) Lbar_j has J's
    // mean for any Lbar_j drawn before d, and where the incoming radiance is close to
    // Lbar_j (the bulk of indirect light) nearly none of the factor's variance, which
    // otherwise multiplies from step to step (unbounded variance once albedo > 0.87).
    // Field by field: a CPU adapter loads every field of a whole-struct read, and the
    // history's entries are only moved.
    let old_incoming = state_at(j).incoming;
    let old_mean_radiance = state_at(j).mean_radiance.rgb;
    let cos_d = abs(dot(patches_at(j).normal.xyz, bundle.direction.xyz));
    let diffuse = incoming - (cos_d - 0.5) * old_mean_radiance;
    // A patch smaller than a line's pixel (dP / A_j > 1) is crossed by no line or by one
    // weighing dP / A_j times its share: its J spikes. Its weight shrinks by A_j / dP, so
    // that a spike moves Lbar_j by a bounded amount (the weight times 2 dP / A_j times the
    // radiance: a quarter of the radiance) and Lbar_j averages over about as many crossings
    // as a large patch's. Lbar_j is only the control variates' coefficient, so any weight
    // keeps them unbiased; a spiked Lbar_j gave the image's first steps pixels of +-50 where
    // the radiance is 0.2 (a Cornell box sliver at bundle 64).
    // A patch that is not glossy may lie outside the fine window, where a wide line weighs
    // wide^2 fine lines (bundle_transfer): its spikes are that much taller.
    let material = patches_at(j).material;
    let glossy = materials[material].kind == MATERIAL_PHONG && any(materials[material].specular.rgb > vec3<f32>(0.0));
    let line_factor = select(factor * f32(bundle.wide * bundle.wide), factor, glossy);
    let weight = MEAN_RADIANCE_WEIGHT * min(1.0, 1.0 / line_factor);
    var mean_radiance = mix(old_mean_radiance, 2.0 * diffuse, weight);
    // An image whose directions are its own stratified set (rng::image_direction) keeps
    // Lbar_j as the burn-in left it: a direction of the set avoids the strata the set's
    // earlier ones took, so it is not independent of an Lbar_j made from them, and the
    // control variates here and in the gather would lose their zero mean (16-point sets
    // with a running Lbar_j put a sunlit glossy receiver 4.8 % high, tests/lights.rs
    // test10). The burn-in's directions are a stream of their own, so its Lbar_j is
    // independent of every image's.
    if (bundle.image_step == IMAGE_STEP_OWN_DIRECTIONS) {
        mean_radiance = old_mean_radiance;
    }
    // Past the burn-in, K joins the running sum whose mean the image's senders reflect.
    var sum = state_at(j).diffuse_sum;
    if (bundle.image_step != BURN_IN_STEP) {
        sum += vec4<f32>(diffuse, 1.0);
    }
    // The last steps' J_j move down the history (the oldest drops out): the image's senders
    // average the glossy reflections of these samples of win (docs/ALGORITHM.md 6). Step 0's
    // entry (the zero state) is shifted in too but never counted.
    // Only a glossy patch's history is read (bundle_reflect): the others' stays zero, which
    // saves moving it at every bundle (about 15 % of this kernel on the all-diffuse Cornell
    // box).
    let written = select(old_incoming.w, min(old_incoming.w + 1.0, f32(GLOSSY_HISTORY)), bundle.use_state != 0u);
    // The history written out, for GLOSSY_HISTORY entries, with no dynamic index.
    var next = PatchState(
        vec4<f32>(incoming, written),
        diffuse,
        octahedral_pack(-side * bundle.direction.xyz),
        vec4<f32>(mean_radiance, 0.0),
        sum,
        array<vec2<u32>, GLOSSY_HISTORY>());
    if (materials[material].kind == MATERIAL_PHONG) {
        let newest = vec2<u32>(pack_history_radiance(old_incoming.rgb), state_at(j).direction);
        next.earlier = array<vec2<u32>, GLOSSY_HISTORY>(
            newest, state_at(j).earlier[0], state_at(j).earlier[1], state_at(j).earlier[2], state_at(j).earlier[3],
            state_at(j).earlier[4], state_at(j).earlier[5], state_at(j).earlier[6], state_at(j).earlier[7],
            state_at(j).earlier[8]);
    }
    state_set(j, next);
}
