//! Random numbers. Every step draws from its own generator, seeded from (run seed, step
//! index) alone, so a step's directions do not depend on how the run was split, paused or
//! resumed: the iteration state needs no generator state, and seeded shards merge exactly.

use rand_core::RngCore;
use rand_pcg::Pcg32;

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The generator of step `step` of a run with seed `seed` (PCG32, a portable stream).
pub struct StepRng(Pcg32);

impl StepRng {
    pub fn new(seed: u64, step: u64) -> Self {
        StepRng(Pcg32::new(splitmix64(seed ^ splitmix64(step)), 0x0a02_bdbf_7bb3_c0a7))
    }

    /// Uniform in [0, 1) with 24 random bits (exactly representable as f32).
    pub fn uniform(&mut self) -> f64 {
        (self.0.next_u32() >> 8) as f64 * (1.0 / 16_777_216.0)
    }

    /// A direction uniform on the unit sphere.
    pub fn direction(&mut self) -> glam::DVec3 {
        let z = 1.0 - 2.0 * self.uniform();
        let phi = 2.0 * std::f64::consts::PI * self.uniform();
        let r = (1.0 - z * z).max(0.0).sqrt();
        glam::DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_and_step_give_the_same_stream() {
        let a: Vec<f64> = (0..8)
            .map({
                let mut r = StepRng::new(7, 3);
                move |_| r.uniform()
            })
            .collect();
        let b: Vec<f64> = (0..8)
            .map({
                let mut r = StepRng::new(7, 3);
                move |_| r.uniform()
            })
            .collect();
        let c: Vec<f64> = (0..8)
            .map({
                let mut r = StepRng::new(7, 4);
                move |_| r.uniform()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn directions_are_uniform_on_the_sphere() {
        // The mean of a uniform direction is 0 and E[z^2] = 1/3; 100k samples put the
        // standard error near 0.002, so 0.01 is five of them.
        let n = 100_000;
        let mut mean = glam::DVec3::ZERO;
        let mut z2 = 0.0;
        for step in 0..n {
            let d = StepRng::new(1, step).direction();
            assert!((d.length() - 1.0).abs() < 1e-12);
            mean += d;
            z2 += d.z * d.z;
        }
        mean /= n as f64;
        assert!(mean.length() < 0.01, "mean {mean}");
        assert!((z2 / n as f64 - 1.0 / 3.0).abs() < 0.01);
    }
}
