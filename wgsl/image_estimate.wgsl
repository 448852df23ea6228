// Image estimate (DESIGN.md 2.5): for every camera pixel, the radiance that leaves the
// point it sees toward the eye, added to the running sum of the image:
//   E = Le_j + Lfs_j(x, w_e) + 2 pi J_j f_j(win_j, x, w_e)
// with x the pixel's own surface point (the camera ray through this pass's sample hits the
// plane of patch j there), the environment where no surface is, black on a back side.
//
// Compute, one invocation per pixel: the only writer of its image_sum.
// Group 1: the first-shot table (wgsl/common/first_shot_table.wgsl).
// Host: src/stages/image_estimate.rs. Its `SPEC` is the one statement of the bindings (names,
// kinds, access) and workgroup sizes; tests/kernel_bindings.rs holds it against this file.

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<uniform> params: EstimateParams;
@group(0) @binding(2) var item_buffer: texture_2d<u32>;
@group(0) @binding(3) var<storage, read> patches: array<Patch>;
@group(0) @binding(4) var<storage, read> materials: array<Material>;
@group(0) @binding(5) var<storage, read> state: array<PatchState>;
@group(0) @binding(6) var<storage, read_write> image_sum: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = camera.size.xy;
    if (gid.x >= size.x || gid.y >= size.y) {
        return;
    }
    let id = textureLoad(item_buffer, vec2<i32>(gid.xy), 0).x;
    var radiance = params.environment.rgb;
    if (id != NO_PATCH && id <= params.patch_count) {
        let j = id - 1u;
        // Field by field: a CPU adapter loads every field of a whole-struct read.
        let plane = patches[j].normal;
        let n = plane.xyz;
        // The ray through this pass's sample point of the pixel.
        let dir = normalize(pixel_direction(camera, gid.xy));
        let w_out = -dir;
        radiance = vec3<f32>(0.0);
        let facing = dot(n, w_out);
        if (facing > 0.0) {
            let t = (plane.w - dot(n, camera.eye.xyz)) / dot(n, dir);
            let x = camera.eye.xyz + t * dir;
            let m = materials[patches[j].material];
            radiance = patches[j].emission.rgb + first_shot_radiance(j, x, n, m, w_out);
            if (params.use_state != 0u) {
                let s = state[j];
                radiance += 2.0 * PI * s.incoming.rgb * brdf(m, n, -s.direction.xyz, w_out);
            }
        }
    }
    let pixel = gid.y * size.x + gid.x;
    image_sum[pixel] = image_sum[pixel] + vec4<f32>(radiance, 1.0);
}
