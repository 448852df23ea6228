//! The BRDFs on the host (tests, oracles, material validation). Their WGSL twin is
//! `wgsl/common/brdf.wgsl`; a GPU test keeps the two in step.
//!
//! Convention: `n` is the unit front normal; `w_in` (toward the light) and `w_out` (toward
//! the viewer) are unit vectors pointing away from the surface. Below the surface (either
//! cosine <= 0) a BRDF is 0.
//!
//! max-Phong (docs/SCENE_FORMAT.md): `f = kd / pi + ks max(0, cos psi)^n / max(cos theta_in,
//! cos theta_out)`, psi the angle between `w_out` and the mirror direction of `w_in`.
//! `max(0, cos psi)^0` is 1 everywhere, as `powf` and the WGSL twin have it.

use super::{MaterialKind, Rgb};
use glam::DVec3;
use std::f64::consts::{FRAC_PI_2, PI};
use std::sync::OnceLock;

/// f(w_in, w_out) per channel, in 1/sr.
pub fn eval(kind: &MaterialKind, n: DVec3, w_in: DVec3, w_out: DVec3) -> [f64; 3] {
    let cos_in = n.dot(w_in);
    let cos_out = n.dot(w_out);
    if cos_in <= 0.0 || cos_out <= 0.0 {
        return [0.0; 3];
    }
    match *kind {
        MaterialKind::Diffuse { albedo } => albedo.map(|a| f64::from(a) / PI),
        MaterialKind::Phong { diffuse, specular, shininess } => {
            // (2 cos_in n - w_in) . w_out, written so that swapping the two directions gives
            // the same float: reciprocity holds bit for bit.
            let cos_psi = 2.0 * cos_in * cos_out - w_in.dot(w_out);
            let lobe = cos_psi.max(0.0).powf(f64::from(shininess)) / cos_in.max(cos_out);
            std::array::from_fn(|c| f64::from(diffuse[c]) / PI + f64::from(specular[c]) * lobe)
        }
    }
}

/// The directional albedo: the fraction of the light arriving at `cos_theta_in` that is
/// reflected into the whole hemisphere, integral of f cos(theta_out) over w_out.
///
/// `cos_theta_in` is clamped to [0, 1]; at 0 (grazing) the value is the limit from above.
/// The diffuse part is exactly kd; the specular part is a deterministic quadrature, accurate
/// to about 1e-9 relative for any shininess up to 10^4 and beyond.
pub fn directional_albedo(kind: &MaterialKind, cos_theta_in: f64) -> [f64; 3] {
    match *kind {
        MaterialKind::Diffuse { albedo } => albedo.map(f64::from),
        MaterialKind::Phong { diffuse, specular, shininess } => {
            let lobe = lobe_albedo(f64::from(shininess), cos_theta_in);
            std::array::from_fn(|c| f64::from(diffuse[c]) + f64::from(specular[c]) * lobe)
        }
    }
}

/// The glossy lobe's directional albedo for ks = 1 (`lobe_albedo`, the same at incidence and
/// exitance by reciprocity) at cos theta = (i / (N - 1))^2, i = 0..N, N =
/// `layout::GLOSSY_ALBEDO_SAMPLES`: the gather's control variate needs it at every pixel
/// (docs/ALGORITHM.md 6), where the quadrature is far too slow. The samples are dense toward
/// grazing, where a sharp lobe's albedo changes fastest; linear interpolation in
/// sqrt(cos theta) (`glossy_albedo_lookup`, as the WGSL does) stays within 6e-4 of the
/// quadrature for shininess 0 to 10^4.
pub fn glossy_albedo_table(shininess: f64) -> Vec<f32> {
    let n = crate::layout::GLOSSY_ALBEDO_SAMPLES as usize;
    (0..n)
        .map(|i| {
            let t = i as f64 / (n - 1) as f64;
            lobe_albedo(shininess, t * t) as f32
        })
        .collect()
}

/// The value `table` (`glossy_albedo_table`) gives at cos theta = `mu`, interpolated as the
/// WGSL's `lobe_albedo` does.
pub fn glossy_albedo_lookup(table: &[f32], mu: f64) -> f64 {
    let t = mu.clamp(0.0, 1.0).sqrt() * (table.len() - 1) as f64;
    let i = (t as usize).min(table.len() - 2);
    let f = t - i as f64;
    f64::from(table[i]) * (1.0 - f) + f64::from(table[i + 1]) * f
}

/// The weight c of the glossy lobe's control variate c Lbar_j in the image's gather
/// (docs/ALGORITHM.md 6): 1 for a broad lobe, 1/2 for a sharp one.
///
/// Why: where the lobe weights incoming radiance L_m on average, a step's variance scales
/// with (L_m - c Lbar_j)^2, least at c = L_m / Lbar_j. A broad lobe averages L over much of
/// the hemisphere, as Lbar_j does, so L_m is close to Lbar_j and c = 1 takes away nearly all
/// the variance the lobe's shape adds; a sharp lobe sees the light of a few directions, often
/// well below the mean (a dark mirror direction), where c = 1 would add variance and c = 1/2
/// hedges (it adds some only below a quarter of the mean). The measure of breadth is the
/// lobe's effective share of the hemisphere at normal view, E[g]^2 / E[g^2] for the
/// weight g = cos^(n + 1) under uniform directions, (2n + 3) / (n + 2)^2, against the
/// cosine lobe's 3 / 4: a lobe is broad at a third of that or more (n <= 5). Measured
/// (docs/PERFORMANCE.md, "The glossy control variate's weight"): with c = 1 the Sierpinski
/// scene (n = 3) had 0.61-0.70 of the squared error of c = 1/2 after 10-50 steps (0.99
/// after 200), cornell_point (n = 20, 60) 1.02 and the glossy gallery (n = 10, 60)
/// 1.14-1.17. Either value keeps the gather unbiased: only its variance depends on c.
pub fn glossy_control_weight(shininess: f64) -> f64 {
    let n = shininess.max(0.0);
    let share = (2.0 * n + 3.0) / ((n + 2.0) * (n + 2.0));
    if share >= 0.75 / 3.0 { 1.0 } else { 0.5 }
}

/// The largest directional albedo over all incident angles, per channel. A material whose
/// value exceeds 1 in any channel gains energy and is refused by the loader.
pub fn max_directional_albedo(kind: &MaterialKind) -> Rgb {
    match *kind {
        MaterialKind::Diffuse { albedo } => albedo,
        MaterialKind::Phong { diffuse, specular, shininess } => {
            let lobe = max_lobe_albedo(f64::from(shininess));
            std::array::from_fn(|c| (f64::from(diffuse[c]) + f64::from(specular[c]) * lobe) as f32)
        }
    }
}

/// The specular albedo for ks = 1:
/// `S(mu) = integral over the hemisphere of max(0, cos psi)^n cos(theta_out)
///          / max(mu, cos theta_out) dw_out`, mu = cos(theta_in).
///
/// Integrated in polar coordinates (psi, phi) about the mirror direction, where the lobe
/// depends on psi alone. The ring over phi at each psi has a closed form (piecewise between
/// the horizon and the kink of the max()); what is left is smooth in psi between the angles
/// where those two appear: psi = pi/2 - theta_in (the horizon cuts the ring) and psi = 2
/// theta_in (the kink reaches phi = pi). Gauss-Legendre on those pieces, with pieces no
/// wider than the lobe, converges fast.
fn lobe_albedo(shininess: f64, mu: f64) -> f64 {
    let mu = mu.clamp(0.0, 1.0);
    if shininess == 0.0 {
        // The lobe is 1 over the whole hemisphere: 2 pi * integral of c / max(mu, c) dc.
        return 2.0 * PI * (1.0 - 0.5 * mu);
    }
    let sin_in = ((1.0 - mu) * (1.0 + mu)).sqrt();
    let theta_in = mu.acos();

    // Where w_out = cos psi r + sin psi (cos phi t + sin phi b), r the mirror direction and t
    // the unit vector perpendicular to r in the plane of incidence pointing away from n,
    // cos theta_out = a - b cos phi with a = mu cos psi, b = sin_in sin psi. Over phi the
    // integrand is 0 below the horizon, cos theta_out / mu up to the kink of the max() and 1
    // past it; cos theta_out rises with phi in [0, pi], so each piece is one interval and
    // its integral has a closed form (the start-up evaluated each ring by Gauss-Legendre:
    // 48 cosines a ring, a tenth of a second per glossy material on one core).
    let ring = |psi: f64| {
        let (sin_psi, cos_psi) = psi.sin_cos();
        let (a, b) = (mu * cos_psi, sin_in * sin_psi);
        if b <= 0.0 {
            let cos_out = a.max(0.0);
            return 2.0 * PI * if cos_out > 0.0 { cos_out / mu.max(cos_out) } else { 0.0 };
        }
        // Above the horizon where cos phi < a / b; past the kink where cos phi < (a - mu) / b
        // = -tan(psi / 2) mu / sin_in (no cancellation near psi = 0).
        let horizon = if a < b { (a / b).acos() } else { 0.0 };
        let kink = (-(0.5 * psi).tan() * mu / sin_in).max(-1.0).acos().max(horizon);
        // Integral of (a - b cos phi) / mu from the horizon to the kink (empty at mu = 0,
        // where the kink is the horizon), then of 1 from the kink to pi. The difference of
        // the sines as a product: both are near 1 at grazing incidence.
        let width = kink - horizon;
        let sines = 2.0 * (0.5 * (kink + horizon)).cos() * (0.5 * width).sin();
        let below = if width > 0.0 { (a * width - b * sines) / mu } else { 0.0 };
        2.0 * (below + (PI - kink))
    };

    // The lobe cos^n psi sin psi has width ~ 1 / sqrt(n); beyond 12 widths it is below
    // exp(-72 n / (n + 1)) of its peak.
    let width = 1.0 / (shininess + 1.0).sqrt();
    let end = FRAC_PI_2.min(12.0 * width);
    let mut breaks = vec![0.0, end, FRAC_PI_2 - theta_in, 2.0 * theta_in];
    if end == FRAC_PI_2 && shininess.fract() != 0.0 {
        // cos^n psi ~ (pi/2 - psi)^n is not smooth at the end for a fractional n: pieces
        // shrinking geometrically towards it keep the convergence exponential.
        breaks.extend((1..=30).map(|j| FRAC_PI_2 - width.min(1.0) * 0.5f64.powi(j)));
    }
    breaks.retain(|&x| (0.0..=end).contains(&x));
    breaks.sort_by(f64::total_cmp);
    breaks.dedup();
    let integrand = |psi: f64| {
        let (sin_psi, cos_psi) = psi.sin_cos();
        cos_psi.max(0.0).powf(shininess) * sin_psi * ring(psi)
    };
    breaks
        .windows(2)
        .map(|w| {
            let pieces = ((w[1] - w[0]) / width).ceil().max(1.0);
            let step = (w[1] - w[0]) / pieces;
            (0..pieces as usize)
                .map(|i| {
                    let from = w[0] + step * i as f64;
                    gauss_legendre(from, from + step, integrand)
                })
                .sum::<f64>()
        })
        .sum()
}

/// The largest `lobe_albedo` over incident angles. It is at normal incidence for most
/// shininesses but at grazing for n = 0, so: a grid in theta_in, denser towards both ends,
/// then a golden-section search in the best grid cell.
fn max_lobe_albedo(shininess: f64) -> f64 {
    let lobe = |theta: f64| lobe_albedo(shininess, theta.cos());
    let mut grid: Vec<f64> = (0..=64).map(|i| FRAC_PI_2 * i as f64 / 64.0).collect();
    for offset in [1e-6, 1e-4, 1e-3, 1e-2] {
        grid.extend([offset, FRAC_PI_2 - offset]);
    }
    grid.sort_by(f64::total_cmp);
    let values: Vec<f64> = grid.iter().map(|&t| lobe(t)).collect();
    let best = (0..grid.len()).max_by(|&i, &j| values[i].total_cmp(&values[j])).unwrap_or(0);
    let (mut lo, mut hi) = (grid[best.saturating_sub(1)], grid[(best + 1).min(grid.len() - 1)]);
    // Golden-section search: each round keeps one of its two inner points, so it costs one
    // new quadrature.
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
    let (mut f1, mut f2) = (lobe(x1), lobe(x2));
    let mut best_value = values[best].max(f1).max(f2);
    for _ in 0..40 {
        if f1 >= f2 {
            (hi, x2, f2) = (x2, x1, f1);
            x1 = hi - ratio * (hi - lo);
            f1 = lobe(x1);
            best_value = best_value.max(f1);
        } else {
            (lo, x1, f1) = (x1, x2, f2);
            x2 = lo + ratio * (hi - lo);
            f2 = lobe(x2);
            best_value = best_value.max(f2);
        }
    }
    best_value
}

/// Gauss-Legendre nodes and weights on [-1, 1], by Newton's method on P_N.
fn gauss_legendre_rule() -> &'static [(f64, f64)] {
    const N: usize = 24;
    static RULE: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    RULE.get_or_init(|| {
        (0..N)
            .map(|i| {
                let mut x = (PI * (i as f64 + 0.75) / (N as f64 + 0.5)).cos();
                let mut derivative = 0.0;
                for _ in 0..100 {
                    let (mut p, mut p_prev) = (1.0, 0.0);
                    for k in 1..=N {
                        let k = k as f64;
                        (p, p_prev) = (((2.0 * k - 1.0) * x * p - (k - 1.0) * p_prev) / k, p);
                    }
                    derivative = N as f64 * (x * p - p_prev) / (x * x - 1.0);
                    let dx = p / derivative;
                    x -= dx;
                    if dx.abs() < 1e-16 {
                        break;
                    }
                }
                (x, 2.0 / ((1.0 - x * x) * derivative * derivative))
            })
            .collect()
    })
}

fn gauss_legendre(from: f64, to: f64, f: impl Fn(f64) -> f64) -> f64 {
    let (mid, half) = (0.5 * (from + to), 0.5 * (to - from));
    half * gauss_legendre_rule().iter().map(|&(x, w)| w * f(mid + half * x)).sum::<f64>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_core::{RngCore, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn glossy_control_weight_is_one_for_broad_lobes_and_a_half_for_sharp_ones() {
        // The share (2n + 3) / (n + 2)^2 falls through a third of the cosine lobe's 3/4
        // between n = 5 (0.265) and n = 6 (0.234).
        for n in [0.0, 1.0, 3.0, 5.0] {
            assert_eq!(glossy_control_weight(n), 1.0, "n = {n}");
        }
        for n in [6.0, 10.0, 20.0, 60.0, 1e4] {
            assert_eq!(glossy_control_weight(n), 0.5, "n = {n}");
        }
        // The share is what a quadrature of the weight gives.
        for n in [0.0, 3.0, 20.0] {
            let steps = 20000;
            let (mut m1, mut m2) = (0.0, 0.0);
            for i in 0..steps {
                // Uniform over the hemisphere: cos theta uniform in [0, 1].
                let mu = (i as f64 + 0.5) / steps as f64;
                let g: f64 = mu.powf(n + 1.0);
                m1 += g / steps as f64;
                m2 += g * g / steps as f64;
            }
            let share = (2.0 * n + 3.0) / ((n + 2.0) * (n + 2.0));
            assert!((m1 * m1 / m2 - share).abs() < 1e-6, "n = {n}: {} against {share}", m1 * m1 / m2);
        }
    }

    /// The quadrature against closed forms: far below the 1e-4 the loader needs.
    const QUADRATURE: f64 = 1e-8;

    fn phong(kd: f32, ks: f32, n: f32) -> MaterialKind {
        MaterialKind::Phong { diffuse: [kd, 0.5 * kd, 0.0], specular: [ks, ks, 0.5 * ks], shininess: n }
    }

    fn uniform(rng: &mut Pcg64) -> f64 {
        (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    fn on_sphere(rng: &mut Pcg64) -> DVec3 {
        let z = 2.0 * uniform(rng) - 1.0;
        let phi = 2.0 * PI * uniform(rng);
        let r = (1.0 - z * z).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// A direction at `cos_theta` from `n`, turned by `phi` about it.
    fn around(n: DVec3, cos_theta: f64, phi: f64) -> DVec3 {
        let (t, b) = n.any_orthonormal_pair();
        let sin_theta = ((1.0 - cos_theta) * (1.0 + cos_theta)).max(0.0).sqrt();
        cos_theta * n + sin_theta * (phi.cos() * t + phi.sin() * b)
    }

    fn shininesses() -> [f64; 9] {
        [0.25, 1.0, 3.0, 10.0, 42.5, 100.0, 1000.0, 5000.0, 10_000.0]
    }

    #[test]
    fn test01_reciprocity() {
        let mut rng = Pcg64::seed_from_u64(1);
        let materials = [
            phong(0.18, 2.0 / PI as f32, 3.0),
            phong(0.0, 1.0, 0.0),
            phong(0.3, 0.5, 250.0),
            MaterialKind::Diffuse { albedo: [0.2, 0.5, 0.9] },
        ];
        let mut above = 0;
        for _ in 0..20_000 {
            let (n, a, b) = (on_sphere(&mut rng), on_sphere(&mut rng), on_sphere(&mut rng));
            for m in &materials {
                assert_eq!(eval(m, n, a, b), eval(m, n, b, a));
            }
            if n.dot(a) > 0.0 && n.dot(b) > 0.0 {
                above += 1;
            }
        }
        assert!(above > 4000, "the pairs cover the interesting case");
    }

    #[test]
    fn test02_zero_below_the_surface() {
        let m = phong(0.5, 0.5, 3.0);
        let n = DVec3::Z;
        let up = DVec3::new(0.3, 0.0, 0.9).normalize();
        let down = DVec3::new(0.3, 0.0, -0.9).normalize();
        let grazing = DVec3::X;
        for (a, b) in [(up, down), (down, up), (down, down), (grazing, up), (up, grazing)] {
            assert_eq!(eval(&m, n, a, b), [0.0; 3]);
        }
        assert!(eval(&m, n, up, up)[0] > 0.0);
    }

    #[test]
    fn test03_eval_matches_the_formula() {
        // Exact in f32, so that the material holds these very numbers.
        let (kd, ks, n_exp) = (0.25f64, 0.75f64, 5.0f64);
        let m = phong(kd as f32, ks as f32, n_exp as f32);
        let n = DVec3::Z;
        let w_in = around(n, 0.8, 0.0);
        let mirror = 2.0 * n.dot(w_in) * n - w_in;
        let w_out = around(n, 0.5, 2.8);
        let expected = kd / PI + ks * mirror.dot(w_out).max(0.0).powf(n_exp) / n.dot(w_in).max(n.dot(w_out));
        assert!((eval(&m, n, w_in, w_out)[0] - expected).abs() < 1e-12);
        // Exactly at the mirror direction the lobe is ks / max(cos, cos) = ks / cos.
        let at_mirror = eval(&m, n, w_in, mirror)[0];
        assert!((at_mirror - (kd / PI + ks / 0.8)).abs() < 1e-6);
    }

    #[test]
    fn test04_diffuse_albedo_is_kd_exactly() {
        let diffuse = MaterialKind::Diffuse { albedo: [0.1, 0.5, 0.9] };
        for mu in [0.0, 0.3, 1.0] {
            assert_eq!(directional_albedo(&diffuse, mu), [0.1f32, 0.5, 0.9].map(f64::from));
        }
        assert_eq!(max_directional_albedo(&diffuse), [0.1, 0.5, 0.9]);
        let no_lobe = phong(0.4, 0.0, 30.0);
        assert_eq!(directional_albedo(&no_lobe, 0.7), [0.4f32, 0.2, 0.0].map(f64::from));
    }

    #[test]
    fn test05_normal_incidence_is_2_pi_over_n_plus_2() {
        // max(cos, cos) = 1 and psi = theta_out: ks * integral of cos^(n+1) = 2 pi / (n + 2).
        for n in shininesses().into_iter().chain([0.0]) {
            let exact = 2.0 * PI / (n + 2.0);
            let s = lobe_albedo(n, 1.0);
            assert!((s - exact).abs() <= QUADRATURE * exact, "n = {n}: {s} vs {exact}");
        }
    }

    #[test]
    fn test06_grazing_incidence_is_pi_over_n_plus_1() {
        // mu -> 0: max(mu, cos theta_out) = cos theta_out and the horizon halves the lobe.
        for n in shininesses() {
            let exact = PI / (n + 1.0);
            let s = lobe_albedo(n, 0.0);
            assert!((s - exact).abs() <= QUADRATURE * exact, "n = {n}: {s} vs {exact}");
            let near = lobe_albedo(n, 1e-9);
            assert!((near - exact).abs() <= 1e-6 * exact, "continuous at grazing");
        }
        // n = 0: the lobe is 1 everywhere, 2 pi * integral of c / max(mu, c) dc.
        assert!((lobe_albedo(0.0, 0.0) - 2.0 * PI).abs() < 1e-15);
    }

    /// Monte Carlo over w_out with `eval` itself (not the quadrature's own parametrisation):
    /// uniform on the hemisphere for broad lobes, cos^n psi around the mirror for narrow
    /// ones. Returns the estimate of channel 0 and its standard error.
    fn monte_carlo(m: &MaterialKind, mu: f64, samples: usize, seed: u64) -> (f64, f64) {
        let MaterialKind::Phong { shininess, .. } = *m else { unreachable!() };
        let shininess = f64::from(shininess);
        let mut rng = Pcg64::seed_from_u64(seed);
        let n = DVec3::new(0.2, -0.4, 0.9).normalize();
        let w_in = around(n, mu, 1.0);
        let mirror = 2.0 * mu * n - w_in;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..samples {
            let (u, v) = (uniform(&mut rng), uniform(&mut rng));
            let (w_out, pdf) = if shininess < 20.0 {
                (around(n, u, 2.0 * PI * v), 1.0 / (2.0 * PI))
            } else {
                let cos_psi = u.powf(1.0 / (shininess + 1.0));
                let pdf = (shininess + 1.0) / (2.0 * PI) * cos_psi.powf(shininess);
                (around(mirror, cos_psi, 2.0 * PI * v), pdf)
            };
            let x = eval(m, n, w_in, w_out)[0] * n.dot(w_out).max(0.0) / pdf;
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / samples as f64;
        let variance = (sum2 / samples as f64 - mean * mean) / (samples as f64 - 1.0);
        (mean, variance.sqrt())
    }

    #[test]
    fn test09_the_glossy_albedo_table_interpolates_the_quadrature() {
        // Between the samples, over the shininesses a scene may use, including the sharp
        // lobes whose albedo drops within a few degrees of grazing.
        for n in [0.0, 0.5, 1.0, 3.0, 10.0, 60.0, 100.0, 1000.0, 10_000.0] {
            let table = glossy_albedo_table(n);
            assert_eq!(table.len(), crate::layout::GLOSSY_ALBEDO_SAMPLES as usize);
            let worst = (0..4000)
                .map(|k| {
                    let mu = (k as f64 + 0.5) / 4000.0;
                    let exact = lobe_albedo(n, mu);
                    ((glossy_albedo_lookup(&table, mu) - exact) / exact).abs()
                })
                .fold(0.0, f64::max);
            assert!(worst < 1e-3, "shininess {n}: interpolation {worst:.2e} off the quadrature");
            // The ends are the closed forms (for n > 0; n = 0 is 2 pi (1 - mu / 2)): 2 pi /
            // (n + 2) at normal incidence, pi / (n + 1) at grazing, to f32 rounding.
            let ends = if n > 0.0 { [PI / (n + 1.0), 2.0 * PI / (n + 2.0)] } else { [2.0 * PI, PI] };
            for (mu, end) in [0.0, 1.0].into_iter().zip(ends) {
                assert!((glossy_albedo_lookup(&table, mu) / end - 1.0).abs() < 1e-6, "shininess {n}, mu {mu}");
            }
        }
    }

    #[test]
    fn test07_monte_carlo_agrees_with_the_quadrature() {
        let cases = [
            (0.0, 0.3),
            (3.0, 0.9),
            (3.0, 0.4),
            (3.0, 0.05),
            (12.0, 0.6),
            (300.0, 0.7),
            (10_000.0, 0.5),
            (10_000.0, 0.02),
        ];
        for (seed, (n, mu)) in cases.into_iter().enumerate() {
            let m = phong(0.0, 1.0, n as f32);
            let (estimate, error) = monte_carlo(&m, mu, 200_000, seed as u64);
            let quadrature = directional_albedo(&m, mu)[0];
            // Seeded, so this is deterministic; 4 standard errors would be exceeded by chance
            // once in 16 000 seeds.
            assert!(
                (estimate - quadrature).abs() <= 4.0 * error,
                "n = {n}, mu = {mu}: {estimate} +- {error} vs {quadrature}"
            );
            assert!(error < 0.01 * quadrature, "the check has teeth");
        }
    }

    #[test]
    fn test08_papers_material_reflects_98_percent_at_most() {
        let m = MaterialKind::Phong { diffuse: [0.18, 0.06, 0.12], specular: [2.0 / PI as f32; 3], shininess: 3.0 };
        let max = max_directional_albedo(&m);
        assert!((max[0] - 0.98).abs() < 1e-6, "{max:?}");
        assert!(max.iter().all(|&a| a <= 1.0));
        let mut mu = 0.0;
        while mu <= 1.0 {
            assert!(directional_albedo(&m, mu)[0] <= f64::from(max[0]) + 1e-7);
            mu += 0.01;
        }
        #[allow(clippy::approx_constant, reason = "the rounded value in scenes/sierpinski.toml")]
        let file_value = MaterialKind::Phong { diffuse: [0.18, 0.06, 0.12], specular: [0.63662; 3], shininess: 3.0 };
        assert!(max_directional_albedo(&file_value)[0] < 1.0);
    }

    #[test]
    fn test09_energy_gaining_materials_exceed_1() {
        let bright = MaterialKind::Phong { diffuse: [0.0; 3], specular: [1.0; 3], shininess: 3.0 };
        let max = max_directional_albedo(&bright)[0];
        assert!((f64::from(max) - 2.0 * PI / 5.0).abs() < 1e-6, "{max}");
        assert!(max > 1.0);
        // n = 0 peaks at grazing, 2 pi ks: the search must not assume normal incidence.
        let flat = phong(0.0, 0.2, 0.0);
        let max = f64::from(max_directional_albedo(&flat)[0]);
        assert!((max - 0.2 * 2.0 * PI).abs() < 1e-6, "{max}");
        assert!(max > 1.0);
    }

    #[test]
    fn test10_max_is_the_largest_of_a_fine_scan() {
        for n in [0.1, 0.5, 1.0, 2.0, 3.0, 20.0, 1000.0] {
            let max = max_lobe_albedo(n);
            let scan = (0..=400).map(|i| lobe_albedo(n, (FRAC_PI_2 * i as f64 / 400.0).cos())).fold(0.0, f64::max);
            assert!(max >= scan - 1e-12 && max <= scan * (1.0 + 1e-4), "n = {n}");
        }
    }
}
