//! The WGSL BRDF (`wgsl/common/brdf.wgsl`, run through `stages::brdf_probe`) against the
//! host's `scene::brdf::eval`, the f64 reading of SCENE_FORMAT.md's max-Phong, over seeded
//! random direction pairs: above and below the surface, near the mirror direction and at
//! grazing angles.
//!
//! Agreement is 1e-5 relative where the formula is well conditioned in f32. Where it is not
//! (n = 200 turns cos psi's rounding, ~1e-7, into 2e-5 of f; at grazing 1 / max(cos theta)
//! does the same with cos theta's), the allowance grows by exactly how far f moves when the
//! GPU's cosines move by their f32 error bounds: that is f32, not a different formula.

mod common;

use firstshot::gpu::scene_buffers::gpu_materials;
use firstshot::scene::{Material, MaterialKind, brdf};
use firstshot::stages::brdf_probe::{BrdfQuery, evaluate};
use glam::{DVec3, Vec3};
use std::f64::consts::PI;

/// PCG32 (O'Neill's XSH-RR), written out so that the directions never change with a crate.
struct Pcg32 {
    state: u64,
}

impl Pcg32 {
    const MULTIPLIER: u64 = 6364136223846793005;
    const INCREMENT: u64 = 1442695040888963407;

    fn new(seed: u64) -> Pcg32 {
        let mut rng = Pcg32 { state: seed.wrapping_add(Self::INCREMENT) };
        rng.next_u32();
        rng
    }

    fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(Self::MULTIPLIER).wrapping_add(Self::INCREMENT);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        f64::from(self.next_u32()) / 4294967296.0
    }

    fn on_sphere(&mut self) -> DVec3 {
        let z = 2.0 * self.uniform() - 1.0;
        let phi = 2.0 * PI * self.uniform();
        let r = ((1.0 - z) * (1.0 + z)).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// A unit direction at `cos_theta` from the unit `axis`, turned by `phi` about it.
fn around(axis: DVec3, cos_theta: f64, phi: f64) -> DVec3 {
    let (t, b) = axis.any_orthonormal_pair();
    let sin_theta = ((1.0 - cos_theta) * (1.0 + cos_theta)).max(0.0).sqrt();
    (cos_theta * axis + sin_theta * (phi.cos() * t + phi.sin() * b)).normalize()
}

/// One query in both precisions: the GPU gets the f32 directions, the host evaluates the
/// very same (f32-rounded) numbers in f64, so only the arithmetic differs.
struct Case {
    what: &'static str,
    n: Vec3,
    w_in: Vec3,
    w_out: Vec3,
}

fn f32s(v: DVec3) -> Vec3 {
    v.as_vec3()
}

/// The directions of one test: several kinds, `per_kind` of each, from `seed`.
fn cases(seed: u64, per_kind: usize) -> Vec<Case> {
    let mut rng = Pcg32::new(seed);
    let mut out = Vec::new();
    for _ in 0..per_kind {
        let n = rng.on_sphere();
        let phi = |rng: &mut Pcg32| 2.0 * PI * rng.uniform();
        // Kept away from the horizon by more than f32 can resolve, so that both sides agree
        // on which side of the surface each direction is.
        let above = |rng: &mut Pcg32| 1e-4 + (1.0 - 1e-4) * rng.uniform();
        let below = |rng: &mut Pcg32| -(1e-4 + (1.0 - 1e-4) * rng.uniform());
        let grazing = |rng: &mut Pcg32| 10f64.powf(-4.0 + 3.0 * rng.uniform());

        let (a, b) = (rng.on_sphere(), rng.on_sphere());
        if n.dot(a).abs() > 1e-4 && n.dot(b).abs() > 1e-4 {
            out.push(Case { what: "anywhere", n: f32s(n), w_in: f32s(a), w_out: f32s(b) });
        }

        let w_in = around(n, above(&mut rng), phi(&mut rng));
        let w_out = around(n, above(&mut rng), phi(&mut rng));
        out.push(Case { what: "above", n: f32s(n), w_in: f32s(w_in), w_out: f32s(w_out) });

        // Within 1e-5 to 0.5 radians of the mirror direction, where the narrow lobes live.
        let w_in = around(n, above(&mut rng), phi(&mut rng));
        let mirror = 2.0 * n.dot(w_in) * n - w_in;
        let psi = 0.5 * 10f64.powf(-5.0 * rng.uniform());
        let w_out = around(mirror, psi.cos(), phi(&mut rng));
        if n.dot(w_out).abs() > 1e-4 {
            out.push(Case { what: "near mirror", n: f32s(n), w_in: f32s(w_in), w_out: f32s(w_out) });
        }

        let w_in = around(n, grazing(&mut rng), phi(&mut rng));
        let w_out = around(n, above(&mut rng), phi(&mut rng));
        let (w_in, w_out) = if rng.uniform() < 0.5 { (w_in, w_out) } else { (w_out, w_in) };
        out.push(Case { what: "grazing", n: f32s(n), w_in: f32s(w_in), w_out: f32s(w_out) });

        // Both grazing, near the mirror direction: the largest values of the lobe.
        let w_in = around(n, grazing(&mut rng), phi(&mut rng));
        let mirror = 2.0 * n.dot(w_in) * n - w_in;
        let w_out = around(mirror, (1e-3 * rng.uniform()).cos(), phi(&mut rng));
        if n.dot(w_out) > 1e-4 {
            out.push(Case { what: "grazing mirror", n: f32s(n), w_in: f32s(w_in), w_out: f32s(w_out) });
        }

        let w_in = around(n, below(&mut rng), phi(&mut rng));
        let w_out = around(n, if rng.uniform() < 0.5 { above(&mut rng) } else { below(&mut rng) }, phi(&mut rng));
        let (w_in, w_out) = if rng.uniform() < 0.5 { (w_in, w_out) } else { (w_out, w_in) };
        out.push(Case { what: "below", n: f32s(n), w_in: f32s(w_in), w_out: f32s(w_out) });
    }
    // Exactly in the tangent plane, where f32 and f64 agree that the cosine is 0.
    let tangent = [(Vec3::Z, Vec3::X, Vec3::Z), (Vec3::Z, Vec3::Z, Vec3::Y), (Vec3::Y, Vec3::X, Vec3::NEG_Z)];
    for (n, w_in, w_out) in tangent {
        out.push(Case { what: "horizon", n, w_in, w_out });
    }
    // Exactly at the mirror direction, and normal incidence and exit.
    let w = Vec3::new(0.6, 0.0, 0.8);
    out.push(Case { what: "exact mirror", n: Vec3::Z, w_in: w, w_out: Vec3::new(-0.6, 0.0, 0.8) });
    out.push(Case { what: "normal", n: Vec3::Z, w_in: Vec3::Z, w_out: Vec3::Z });
    out
}

fn materials() -> Vec<Material> {
    let phong =
        |shininess: f32| MaterialKind::Phong { diffuse: [0.18, 0.06, 0.12], specular: [0.45, 0.3, 0.15], shininess };
    let mut kinds = vec![MaterialKind::Diffuse { albedo: [0.2, 0.5, 0.9] }];
    kinds.extend([0.0, 0.5, 1.0, 3.0, 20.0, 200.0].map(phong));
    // A lobe in one channel only, and no diffuse part.
    kinds.push(MaterialKind::Phong { diffuse: [0.0; 3], specular: [0.0, 0.6, 0.0], shininess: 7.5 });
    kinds.into_iter().enumerate().map(|(i, kind)| Material { name: format!("m{i}"), kind }).collect()
}

/// Unit roundoff of f32.
const U: f64 = f32::EPSILON as f64 / 2.0;
/// The GPU's f32 cos theta (a 3-term dot product of unit vectors) is within 3u of the exact
/// value of its inputs; 4u leaves a margin.
const COS_ERROR: f64 = 4.0 * U;
/// Its cos psi dots w_out with a mirror direction that is itself rounded (2 cos_in n - w_in
/// adds about 2 COS_ERROR + 2u per component): 16u bounds the sum.
const COS_PSI_ERROR: f64 = 16.0 * U;
/// What the GPU's arithmetic after the cosines (pow, the division, kd / pi, the f32 result)
/// may add: the brief's 1e-5, 100 times f32's rounding of one operation.
const RELATIVE: f64 = 1e-5;
/// Below 1e-6 of the material's largest value at normal incidence (kd / pi + ks), f32's
/// rounding of pow near 0 dominates and nothing visible depends on the digits.
const FLOOR: f64 = 1e-6;

/// How far f may move, per channel, when the three cosines move by their f32 errors: the
/// f32 conditioning of the formula at these directions (n = 200 near the mirror amplifies
/// cos psi's error 200-fold; at grazing, 1 / max(cos) amplifies cos theta's).
fn conditioning(kind: &MaterialKind, n: DVec3, w_in: DVec3, w_out: DVec3) -> [f64; 3] {
    let MaterialKind::Phong { specular, shininess, .. } = *kind else { return [0.0; 3] };
    let (cos_in, cos_out) = (n.dot(w_in), n.dot(w_out));
    let cos_psi = 2.0 * cos_in * cos_out - w_in.dot(w_out);
    let power = |c: f64| if shininess == 0.0 { 1.0 } else { c.max(0.0).powf(f64::from(shininess)) };
    let largest = cos_in.max(cos_out);
    let lobe = power(cos_psi) / largest;
    let high = power(cos_psi + COS_PSI_ERROR) / (largest - COS_ERROR);
    let low = power(cos_psi - COS_PSI_ERROR) / (largest + COS_ERROR);
    specular.map(|ks| f64::from(ks) * (high - lobe).max(lobe - low))
}

/// kd / pi + ks per channel, the scale of the material's values.
fn scale(kind: &MaterialKind) -> f64 {
    let per_channel: [f64; 3] = match *kind {
        MaterialKind::Diffuse { albedo } => albedo.map(|a| f64::from(a) / PI),
        MaterialKind::Phong { diffuse, specular, .. } => {
            std::array::from_fn(|c| f64::from(diffuse[c]) / PI + f64::from(specular[c]))
        }
    };
    per_channel.into_iter().fold(0.0, f64::max)
}

#[test]
fn test01_wgsl_brdf_matches_the_host() {
    let Some(ctx) = common::gpu() else { return };
    let mut scene = common::bare_scene();
    scene.materials = materials();
    let table = gpu_materials(&scene);
    let cases = cases(1, 500);
    // Every case with every material, and with the black material that gpu_materials
    // appends for area lights.
    let mut queries = Vec::new();
    for m in 0..table.len() {
        for c in &cases {
            queries.push(BrdfQuery { material: m as u32, normal: c.n, w_in: c.w_in, w_out: c.w_out });
        }
    }
    let gpu = evaluate(&ctx, &table, &queries).expect("the probe runs");
    assert_eq!(gpu.len(), queries.len());

    let mut failures = Vec::new();
    let (mut tight, mut above) = (0usize, 0usize);
    let mut worst = vec![0.0f64; table.len()];
    for (i, (q, f)) in queries.iter().zip(&gpu).enumerate() {
        let case = &cases[i % cases.len()];
        let (n, w_in, w_out) = (q.normal.as_dvec3(), q.w_in.as_dvec3(), q.w_out.as_dvec3());
        let Some(material) = scene.materials.get(q.material as usize) else {
            assert_eq!(*f, [0.0; 3], "the black material reflects ({})", case.what);
            continue;
        };
        let kind = &material.kind;
        let host = brdf::eval(kind, n, w_in, w_out);
        if n.dot(w_in) <= 0.0 || n.dot(w_out) <= 0.0 {
            // The cases keep clear of the horizon (or sit exactly on it), so both sides
            // agree which side a direction is on, and below it f is exactly 0.
            assert_eq!(*f, [0.0; 3], "m{}: {} case below the surface", q.material, case.what);
            continue;
        }
        above += 1;
        let spread = conditioning(kind, n, w_in, w_out);
        let floor = FLOOR * scale(kind);
        let mut is_tight = true;
        for c in 0..3 {
            let (g, h) = (f64::from(f[c]), host[c]);
            let allowed = RELATIVE * h.abs() + floor + spread[c];
            is_tight &= spread[c] <= RELATIVE * h.abs() + floor;
            worst[q.material as usize] = worst[q.material as usize].max((g - h).abs() / allowed);
            // Written so that a NaN from either side fails.
            let agrees = (g - h).abs() <= allowed;
            if !agrees {
                failures.push(format!(
                    "m{} {:?} {} channel {c}: gpu {g:e} host {h:e} (allowed +-{allowed:e}); n {} w_in {} w_out {}",
                    q.material, kind, case.what, q.normal, q.w_in, q.w_out
                ));
            }
        }
        tight += is_tight as usize;
    }
    for (m, w) in worst.iter().enumerate() {
        eprintln!("m{m}: largest error {w:.3} of the allowed");
    }
    eprintln!("{tight} of {above} evaluations above the surface are well conditioned (held to 1e-5 alone)");
    assert!(failures.is_empty(), "{} of {} disagree:\n{}", failures.len(), queries.len(), failures.join("\n"));
    // Most pairs are held to RELATIVE alone; the conditioning widens only those at grazing
    // or near a narrow mirror lobe, two of the six kinds of case.
    assert!(tight * 3 >= above * 2, "only {tight} of {above} are well conditioned: the check lost its teeth");
}
