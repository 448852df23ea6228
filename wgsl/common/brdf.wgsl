// The max-Phong BRDF of docs/SCENE_FORMAT.md, the WGSL twin of `src/scene/brdf.rs`
// (`tests/brdf_gpu.rs` compares the two on the GPU to 1e-5, widened only by how far f32
// rounding of the three cosines moves f: at grazing and near a narrow lobe's mirror direction).
// Directions point away from the surface: w_in toward the light, w_out toward the viewer.

// False where the scene has no glossy material (every `Material::kind` MATERIAL_DIFFUSE):
// the host then builds the image estimate's kernels without the glossy code
// (`SceneBuffers::constants`; bundle_reflect keeps the default, see its host). On a CPU
// adapter a branch that no invocation takes still costs a good part of its code, for every
// pixel (docs/PERFORMANCE.md, "Branches cost both sides on the CPU adapter").
override GLOSSY: bool = true;

fn brdf(m: Material, n: vec3<f32>, w_in: vec3<f32>, w_out: vec3<f32>) -> vec3<f32> {
    let cos_in = dot(n, w_in);
    let cos_out = dot(n, w_out);
    if (cos_in <= 0.0 || cos_out <= 0.0) {
        return vec3<f32>(0.0);
    }
    return m.diffuse.rgb / PI + brdf_glossy(m, n, w_in, w_out);
}

// The glossy lobe of the BRDF alone (zero for a diffuse material), for w_in and w_out both
// above the surface: f = diffuse / pi + brdf_glossy.
fn brdf_glossy(m: Material, n: vec3<f32>, w_in: vec3<f32>, w_out: vec3<f32>) -> vec3<f32> {
    if (!GLOSSY || m.kind != MATERIAL_PHONG) {
        return vec3<f32>(0.0);
    }
    let cos_in = dot(n, w_in);
    let cos_out = dot(n, w_out);
    let shininess = m.specular.w;
    let mirror = 2.0 * cos_in * n - w_in;
    let cos_psi = dot(mirror, w_out);
    // max(0, cos psi)^n with 0^0 = 1, as Rust's powf gives.
    var lobe = select(0.0, 1.0, shininess == 0.0);
    if (cos_psi > 0.0) {
        lobe = pow(cos_psi, shininess);
    }
    return m.specular.rgb * lobe / max(cos_in, cos_out);
}
