//! Random numbers. Every step draws from its own generator, seeded from (run seed, step
//! index) alone, so a step's directions do not depend on how the run was split, paused or
//! resumed: the iteration state needs no generator state, and seeded shards merge exactly.

use rand_core::RngCore;
use rand_pcg::Pcg32;

/// SplitMix64 (Steele, Lea, Flood 2014): a bijective 64-bit mixing function.
pub fn splitmix64(mut z: u64) -> u64 {
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

/// Steps per block of stratified bundle directions.
pub const DIRECTION_BLOCK: u64 = 256;
/// Generator streams of the blocks: (seed, BLOCK_STREAM - block), apart from the steps'.
const BLOCK_STREAM: u64 = u64::MAX / 4;

/// The bundle direction of step `step`: uniform on the sphere, and stratified over blocks of
/// `DIRECTION_BLOCK` steps. A block's directions are the points of the R2 sequence (Roberts
/// 2018) shifted by the block's random offset (Cranley-Patterson rotation, so each is
/// uniform), mapped to the sphere by an area-preserving map, and visited in the block's
/// random order, so that consecutive steps' directions are as good as independent (the
/// iteration's two-bounce estimates pair them) while a block covers the sphere evenly.
pub fn stratified_direction(seed: u64, step: u64) -> glam::DVec3 {
    let block = step / DIRECTION_BLOCK;
    let mut rng = StepRng::new(seed, BLOCK_STREAM - block);
    let shift = [rng.uniform(), rng.uniform()];
    let v = shuffled(&mut rng, DIRECTION_BLOCK, step % DIRECTION_BLOCK) as f64;
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_3;
    let (u1, u2) = ((shift[0] + v * A1).fract(), (shift[1] + v * A2).fract());
    let z = 1.0 - 2.0 * u1;
    let phi = 2.0 * std::f64::consts::PI * u2;
    let r = (1.0 - z * z).max(0.0).sqrt();
    glam::DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Points per block of a progressive stream (a power of two).
pub const PROGRESSIVE_BLOCK: u64 = 256;
/// Independent progressive streams the image's steps alternate between.
pub const PROGRESSIVE_STREAMS: u64 = 2;
/// Generator streams of the progressive blocks, apart from the steps', the direction blocks'
/// and the camera samples' blocks.
const PROGRESSIVE_STREAM: u64 = u64::MAX / 4 * 3;

/// The bundle direction of image step `index` of an image whose first step is step `start`
/// of the run: uniform on the sphere, like `stratified_direction`, but stratified for any
/// number of image steps, not only for whole blocks of the run's steps (of which the image's
/// first 20 or 50 steps got a random part, barely better than independent directions).
///
/// The image's steps alternate between `PROGRESSIVE_STREAMS` independent streams, so that
/// consecutive steps, which the iteration's two-bounce estimates pair, are independent: one
/// stream alone made them anti-correlated and biased the state (the Cornell box's image 3 %
/// dark after 20 steps, docs/PERFORMANCE.md "Where the image's error lies"). A stream's
/// blocks are a 2D Sobol' (0, 2)-sequence (van der Corput and its Pascal-matrix partner)
/// with a random digital shift and a uniform offset inside each point's finest cell, so
/// each point is uniform on the unit square and the stream's first 2^k points form a
/// (0, k, 2)-net (one point in every elementary cell of area 2^-k); mapped to the
/// hemisphere of line directions (d and -d make the same lines) by z = u1, phi = 2 pi u2
/// (area-preserving), with a random sign. A stream's point 0 comes first, then each
/// doubling [2^k, 2^(k+1)) in the block's random order. The block's numbers depend on
/// (seed, `start`, stream, block), so that the frames of a walkthrough, each an image of
/// its own, do not repeat their directions.
pub fn progressive_direction(seed: u64, start: u64, index: u64) -> glam::DVec3 {
    let (stream, element) = (index % PROGRESSIVE_STREAMS, index / PROGRESSIVE_STREAMS);
    let (block, i) = (element / PROGRESSIVE_BLOCK, element % PROGRESSIVE_BLOCK);
    let key = splitmix64(splitmix64(start ^ (stream << 48)) ^ block);
    let mut rng = StepRng::new(seed, PROGRESSIVE_STREAM - key);
    let bits = PROGRESSIVE_BLOCK.trailing_zeros();
    let shift = [rng.0.next_u32() >> (32 - bits), rng.0.next_u32() >> (32 - bits)];
    // The Sobol' index of point i: 0, then each doubling's indices in its own random order
    // (every doubling's permutation is drawn, so that it depends on the block alone).
    let mut sobol = 0;
    for k in 0..bits {
        let len = 1u64 << k;
        let pick = shuffled(&mut rng, len, i.wrapping_sub(len) % len);
        if i >= len && i < 2 * len {
            sobol = len + pick;
        }
    }
    let mut jitter = StepRng::new(seed, PROGRESSIVE_STREAM - splitmix64(key ^ splitmix64(i)) - 1);
    let cell = (1u64 << bits) as f64;
    let vdc = ((sobol as u32).reverse_bits() >> (32 - bits)) ^ shift[0];
    let pascal = (sobol_pascal(sobol as u32) >> (32 - bits)) ^ shift[1];
    let (u1, u2) = ((vdc as f64 + jitter.uniform()) / cell, (pascal as f64 + jitter.uniform()) / cell);
    let sign = if jitter.uniform() < 0.5 { -1.0 } else { 1.0 };
    let z = u1;
    let phi = 2.0 * std::f64::consts::PI * u2;
    let r = (1.0 - z * z).max(0.0).sqrt();
    sign * glam::DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// The second dimension of the Sobol' sequence (generator matrix the Pascal matrix mod 2;
/// Kollig and Keller 2002), in the high bits.
fn sobol_pascal(mut i: u32) -> u32 {
    let (mut r, mut v) = (0u32, 1u32 << 31);
    while i != 0 {
        if i & 1 != 0 {
            r ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    r
}

/// Element `index` of a random permutation of 0..len drawn from `rng` (Fisher-Yates, drawn
/// in full so that it depends on the generator alone, not on `index`).
fn shuffled(rng: &mut StepRng, len: u64, index: u64) -> u64 {
    let mut order: Vec<u64> = (0..len).collect();
    for i in (1..order.len()).rev() {
        let pick = ((rng.uniform() * (i + 1) as f64) as usize).min(i);
        order.swap(i, pick);
    }
    order[index as usize]
}

/// Side of the grid of strata of the camera's sample inside a pixel: a block of
/// PIXEL_STRATA^2 image steps puts one sample in each stratum.
pub const PIXEL_STRATA: u64 = 4;
/// Generator streams of the camera samples' blocks, apart from the steps' and the
/// directions' blocks.
const PIXEL_STREAM: u64 = u64::MAX / 2;

/// The camera's sample inside every pixel (x right, y down, in [0, 1)) at image step
/// `image_step`, from the step's uniforms `u`: uniform over the pixel, and stratified over
/// blocks of PIXEL_STRATA^2 image steps, which visit the strata of a PIXEL_STRATA x
/// PIXEL_STRATA grid once each in the block's random order, with `u` placing the sample
/// within its stratum. Along a geometric edge a pixel's value then converges as a
/// stratified mean (the share of the pixel each side covers) instead of a random one; the
/// random order keeps the samples independent of the other stratified sequences (the
/// bundle directions, the area lights' points), so that no pairing of them repeats.
pub fn stratified_pixel_sample(seed: u64, image_step: u64, u: [f64; 2]) -> [f64; 2] {
    let cells = PIXEL_STRATA * PIXEL_STRATA;
    let mut rng = StepRng::new(seed, PIXEL_STREAM - image_step / cells);
    let cell = shuffled(&mut rng, cells, image_step % cells);
    let n = PIXEL_STRATA as f64;
    [((cell % PIXEL_STRATA) as f64 + u[0]) / n, ((cell / PIXEL_STRATA) as f64 + u[1]) / n]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stratified_directions_are_uniform_and_cover_each_block_evenly() {
        // Uniform: mean 0 and E[z^2] = 1/3 over many blocks (standard error ~0.002 for 65k,
        // less for stratified points; 0.01 is five of them).
        let n = 256 * DIRECTION_BLOCK;
        let d: Vec<glam::DVec3> = (0..n).map(|k| stratified_direction(5, k)).collect();
        let mean = d.iter().sum::<glam::DVec3>() / n as f64;
        let z2 = d.iter().map(|v| v.z * v.z).sum::<f64>() / n as f64;
        assert!(mean.length() < 0.01 && (z2 - 1.0 / 3.0).abs() < 0.01, "mean {mean}, E[z^2] {z2}");
        // Even: within one block every octant holds its share to within a few points (a
        // random set of 256 would stray by ~sqrt(32) = 6 points per octant).
        for block in 0..4 {
            let mut octants = [0i32; 8];
            for k in 0..DIRECTION_BLOCK {
                let v = stratified_direction(9, block * DIRECTION_BLOCK + k);
                octants[(v.x > 0.0) as usize + 2 * (v.y > 0.0) as usize + 4 * (v.z > 0.0) as usize] += 1;
            }
            assert!(octants.iter().all(|&c| (c - 32).abs() <= 4), "block {block}: {octants:?}");
        }
        // Another seed, other directions.
        assert_ne!(stratified_direction(5, 3), stratified_direction(6, 3));
    }

    #[test]
    fn progressive_directions_are_uniform_and_every_doubling_is_a_net() {
        // Uniform on the sphere: mean 0, E[z^2] = 1/3, over many blocks (as above).
        let n = 128 * PROGRESSIVE_BLOCK * PROGRESSIVE_STREAMS;
        let d: Vec<glam::DVec3> = (0..n).map(|i| progressive_direction(5, 41, i)).collect();
        let mean = d.iter().sum::<glam::DVec3>() / n as f64;
        let z2 = d.iter().map(|v| v.z * v.z).sum::<f64>() / n as f64;
        assert!(mean.length() < 0.01 && (z2 - 1.0 / 3.0).abs() < 0.01, "mean {mean}, E[z^2] {z2}");
        // Each stream's first 2^k points of a block, as points (|z|, phi / 2 pi) of the unit
        // square, hold one point in every elementary cell of area 2^-k (every split of k
        // into a halvings of u1 and k - a of u2): a (0, k, 2)-net, in every block.
        for (stream, block) in [(0, 0), (1, 0), (0, 1), (1, 2)] {
            let points: Vec<[f64; 2]> = (0..PROGRESSIVE_BLOCK)
                .map(|i| {
                    let index = (block * PROGRESSIVE_BLOCK + i) * PROGRESSIVE_STREAMS + stream;
                    let v = progressive_direction(9, 100, index);
                    let v = if v.z < 0.0 { -v } else { v };
                    [v.z, v.y.atan2(v.x).rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU]
                })
                .collect();
            for k in 0..=PROGRESSIVE_BLOCK.trailing_zeros() {
                let prefix = &points[..1 << k];
                for a in 0..=k {
                    let mut cells = vec![0; 1 << k];
                    for p in prefix {
                        let (x, y) = ((p[0] * (1u64 << a) as f64) as usize, (p[1] * (1u64 << (k - a)) as f64) as usize);
                        cells[(x << (k - a)) + y.min((1 << (k - a)) - 1)] += 1;
                    }
                    let first = 1 << k;
                    assert!(
                        cells.iter().all(|&c| c == 1),
                        "stream {stream} block {block}, first {first}, {a} halvings of z: {cells:?}"
                    );
                }
            }
        }
        // Consecutive image steps come from independent streams: over many blocks, steps
        // 0 and 1, where one stream alone puts its points 0 and 1 in opposite cells, are as
        // far apart as two random directions (E|d . d'| = 1/2), and so are steps later on.
        for offset in [0, 2 * 130] {
            let blocks = 4000;
            let cos: f64 = (0..blocks)
                .map(|b| {
                    let i = b * PROGRESSIVE_BLOCK * PROGRESSIVE_STREAMS + offset;
                    progressive_direction(3, 7, i).dot(progressive_direction(3, 7, i + 1)).abs()
                })
                .sum::<f64>()
                / blocks as f64;
            assert!((cos - 0.5).abs() < 0.02, "steps {offset}, {}: E|d . d'| = {cos}, 1/2 if independent", offset + 1);
        }
        // Another start (another frame of a walkthrough), other directions.
        assert_ne!(progressive_direction(5, 41, 3), progressive_direction(5, 42, 3));
    }

    #[test]
    fn pixel_samples_fill_each_stratum_once_a_block() {
        let cells = PIXEL_STRATA * PIXEL_STRATA;
        let mut sum = [0.0; 2];
        let blocks = 64;
        for block in 0..blocks {
            let mut seen = vec![0; cells as usize];
            for i in 0..cells {
                let step = block * cells + i;
                let mut r = StepRng::new(3, step);
                let p = stratified_pixel_sample(3, step, [r.uniform(), r.uniform()]);
                assert!(p.iter().all(|&c| (0.0..1.0).contains(&c)), "{p:?}");
                let n = PIXEL_STRATA as f64;
                seen[((p[1] * n) as u64 * PIXEL_STRATA + (p[0] * n) as u64) as usize] += 1;
                sum[0] += p[0];
                sum[1] += p[1];
            }
            assert!(seen.iter().all(|&c| c == 1), "block {block}: {seen:?}");
        }
        // Uniform: the mean of 1024 stratified points is 1/2 within a few 1e-3.
        let n = (blocks * cells) as f64;
        assert!((sum[0] / n - 0.5).abs() < 0.005 && (sum[1] / n - 0.5).abs() < 0.005, "{sum:?}");
        // The order differs from block to block and from seed to seed.
        let first = |seed: u64, block: u64| -> Vec<u64> {
            (0..cells)
                .map(|i| {
                    let p = stratified_pixel_sample(seed, block * cells + i, [0.5, 0.5]);
                    (p[1] * 4.0) as u64 * 4 + (p[0] * 4.0) as u64
                })
                .collect()
        };
        assert_ne!(first(3, 0), first(3, 1));
        assert_ne!(first(3, 0), first(4, 0));
    }

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
