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
/// The burn-in's steps take these; an image's steps take `image_direction` where the image
/// knows how many steps it averages.
pub fn stratified_direction(seed: u64, step: u64) -> glam::DVec3 {
    let block = step / DIRECTION_BLOCK;
    let mut rng = StepRng::new(seed, BLOCK_STREAM - block);
    let shift = [rng.uniform(), rng.uniform()];
    let v = shuffled(&mut rng, DIRECTION_BLOCK, step % DIRECTION_BLOCK);
    r2_direction(shift, v)
}

/// Point `v` of the R2 sequence shifted by `shift` (each point then uniform on the unit
/// square), mapped to the sphere by the area-preserving map (z, phi).
fn r2_direction(shift: [f64; 2], v: u64) -> glam::DVec3 {
    let [u1, u2] = r2_point(shift, v);
    let z = 1.0 - 2.0 * u1;
    let phi = 2.0 * std::f64::consts::PI * u2;
    let r = (1.0 - z * z).max(0.0).sqrt();
    glam::DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Point `v` of the first two dimensions of the Sobol sequence (a (0, 2)-sequence in base 2:
/// every run of 2^k points from a multiple of 2^k puts one point in each of the 2^k
/// intervals of either coordinate, and in each elementary box of area 2^-k), its 32-bit
/// coordinates xor-ed with `shift` (a random digital shift: each point then uniform on the
/// square, the runs as even as before). Dimension 1 is the van der Corput sequence (the bits
/// of `v` reversed); dimension 2 has the direction numbers v_0 = 2^31, v_k = v_(k-1) xor
/// (v_(k-1) >> 1) (the polynomial x + 1).
fn sobol_2d(shift: [u32; 2], v: u64) -> [f64; 2] {
    let v = v as u32;
    let x = v.reverse_bits();
    let (mut y, mut direction) = (0u32, 1u32 << 31);
    for bit in 0..32 {
        if v >> bit & 1 == 1 {
            y ^= direction;
        }
        direction ^= direction >> 1;
    }
    let unit = |bits: u32| (bits >> 8) as f64 * (1.0 / 16_777_216.0);
    [unit(x ^ shift[0]), unit(y ^ shift[1])]
}

/// Point `v` of the R2 sequence on the unit square, shifted by `shift` (mod 1).
fn r2_point(shift: [f64; 2], v: u64) -> [f64; 2] {
    // The sequence's increments, 1 / g and 1 / g^2 for the plastic number g; their products
    // with v are reduced mod 1 exactly enough (v < 2^34: 18 bits left of a 52-bit mantissa).
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_3;
    let v = v as f64;
    [(shift[0] + (v * A1).fract()).fract(), (shift[1] + (v * A2).fract()).fract()]
}

/// The steps of one image whose bundle directions form their own stratified set
/// (`image_direction`): the image starts at step `start` and averages `steps` steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageDirections {
    pub start: u64,
    pub steps: u64,
}

/// Generator streams of the images' direction sets, apart from the steps' and the blocks'.
const IMAGE_STREAM: u64 = u64::MAX / 8 * 3;

/// The direction of bundle `bundle` (of `per_step`) of an image's step `image_step` (counted
/// from the image's first step). The image's bundles take the first `per_step x
/// image.steps` points of the R2 sequence shifted by one random offset for the image (as
/// `stratified_direction`'s blocks are): bundle q takes the run of `image.steps` points
/// from q x image.steps on, in a random order of its own. So whatever the image's length,
/// its directions together cover the sphere as evenly as the R2 points do, and so do each
/// bundle's alone (a run of a Kronecker sequence is as even as its start); a pixel gathers
/// through the same bundle at every step of an image (`iteration::bundle_of_step`'s
/// `pixel_shuffle`), and a block of 2 x 2 pixels through all of them. The run's blocks of
/// `DIRECTION_BLOCK` gave an image of fewer steps (or one starting inside a block, after the
/// burn-in) a random part of a block, spread no better than independent directions. The
/// orders are random and each bundle's its own, so the directions that follow one another
/// in the iteration (a step's bundles, then the next step's) are as good as independent, as
/// its two-bounce estimates need. A step past the image's length (not asked for) takes a
/// set of the same size of its own.
pub fn image_direction(seed: u64, image: ImageDirections, bundle: u32, per_step: u32, image_step: u64) -> glam::DVec3 {
    let n = image.steps.max(1);
    let key = splitmix64(image.start ^ splitmix64(image_step / n));
    let mut rng = StepRng::new(seed ^ key, IMAGE_STREAM);
    let shift = [rng.uniform(), rng.uniform()];
    let order = splitmix64(((rng.0.next_u32() as u64) << 32 | rng.0.next_u32() as u64) ^ bundle as u64);
    let v = bundle.min(per_step.max(1) - 1) as u64 * n + permuted(image_step % n, n, order);
    r2_direction(shift, v)
}

/// Element `index` of a random permutation of 0..len chosen by `key`, in constant expected
/// time and memory whatever len: a bijection of the numbers of as many bits as len - 1
/// needs, applied until it lands below len (cycle walking, as in Kensler's correlated
/// multi-jittered sampling, 2013). Each round is invertible on those bits: xor with a
/// constant, multiplication by an odd one, xor with the number shifted right.
fn permuted(index: u64, len: u64, key: u64) -> u64 {
    if len <= 1 {
        return 0;
    }
    let bits = 64 - (len - 1).leading_zeros();
    let mask = if bits == 64 { u64::MAX } else { (1u64 << bits) - 1 };
    let rounds: [(u64, u64); 4] = std::array::from_fn(|r| {
        let k = splitmix64(key ^ (r as u64) << 56);
        (k & mask, (splitmix64(k) | 1) & mask)
    });
    let shift = bits / 2 + 1;
    let mut x = index;
    loop {
        for (xor, odd) in rounds {
            x ^= xor;
            x = x.wrapping_mul(odd) & mask;
            x ^= x >> shift;
        }
        if x < len {
            return x;
        }
    }
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
/// The generator stream of the seed's shift of the camera samples' offsets: one past the
/// blocks' streams (which count down from PIXEL_STREAM).
const PIXEL_OFFSET_STREAM: u64 = PIXEL_STREAM + 1;

/// The camera's sample inside every pixel at one image step (`stratified_pixel_sample`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelSample {
    /// The stratum of the PIXEL_STRATA x PIXEL_STRATA grid (x right, y down).
    pub cell: [u32; 2],
    /// The offset inside the stratum, in strata, each in [0, 1): the same for every step of
    /// a block.
    pub offset: [f64; 2],
}

impl PixelSample {
    /// The sample's position inside the pixel (x right, y down), each in [0, 1).
    pub fn position(&self) -> [f64; 2] {
        let n = PIXEL_STRATA as f64;
        [(self.cell[0] as f64 + self.offset[0]) / n, (self.cell[1] as f64 + self.offset[1]) / n]
    }
}

/// The camera's sample inside every pixel at image step `image_step`: uniform over the
/// pixel, and stratified over blocks of PIXEL_STRATA^2 image steps, which visit the strata
/// of a PIXEL_STRATA x PIXEL_STRATA grid once each in the block's random order, every step
/// of a block at the same offset inside its stratum. The blocks' offsets are the points of
/// a two-dimensional Sobol sequence (`sobol_2d`), one per block, under one random digital
/// shift for the seed (so that each is uniform): along a geometric edge
/// a pixel's value converges as a quasi-Monte Carlo mean of the share each side covers, its
/// error falling about as 1 / blocks, where independent offsets a block left it falling as
/// 1 / sqrt(blocks) (with every pixel sharing a step's offset, an image of 500 steps showed
/// a bright light's outline shifted by 0.02 pixels, most of its error; docs/PERFORMANCE.md,
/// "Outlines converge faster"). The random order keeps the samples independent of the other
/// stratified sequences (the bundle directions, the area lights' points), so that no pairing
/// of them repeats. The shared offset lets one camera raster at PIXEL_STRATA times the
/// resolution serve a whole block (`camera_item_buffer::camera_supersample`).
pub fn stratified_pixel_sample(seed: u64, image_step: u64) -> PixelSample {
    let cells = PIXEL_STRATA * PIXEL_STRATA;
    let block = image_step / cells;
    let mut rng = StepRng::new(seed, PIXEL_STREAM - block);
    let cell = shuffled(&mut rng, cells, image_step % cells);
    let mut shift = StepRng::new(seed, PIXEL_OFFSET_STREAM);
    let offset = sobol_2d([shift.0.next_u32(), shift.0.next_u32()], block);
    PixelSample { cell: [(cell % PIXEL_STRATA) as u32, (cell / PIXEL_STRATA) as u32], offset }
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
    fn permuted_is_a_permutation_for_every_length() {
        for len in 1..=100u64 {
            for key in [0, 1, 0xdead_beef, u64::MAX] {
                let mut seen = vec![false; len as usize];
                for i in 0..len {
                    let p = permuted(i, len, key);
                    assert!(p < len && !seen[p as usize], "len {len}, key {key}: {i} -> {p} twice or out of range");
                    seen[p as usize] = true;
                }
            }
        }
        // A length far past any list a test could hold: still in range and distinct.
        let len = 3_000_000_019;
        let mut some: Vec<u64> = (0..2000).map(|i| permuted(i * 1_000_003, len, 7)).collect();
        assert!(some.iter().all(|&p| p < len));
        some.sort_unstable();
        some.dedup();
        assert_eq!(some.len(), 2000);
        // Other keys, other orders.
        let order = |key: u64| (0..64).map(|i| permuted(i, 64, key)).collect::<Vec<_>>();
        assert_ne!(order(1), order(2));
    }

    /// Squared deviation of the octant counts of `d` from an even split, summed over the
    /// octants: about n 7/8 for independent directions.
    fn octant_deviation(d: &[glam::DVec3]) -> f64 {
        let mut octants = [0.0f64; 8];
        for v in d {
            octants[(v.x > 0.0) as usize + 2 * (v.y > 0.0) as usize + 4 * (v.z > 0.0) as usize] += 1.0;
        }
        let even = d.len() as f64 / 8.0;
        octants.iter().map(|c| (c - even).powi(2)).sum()
    }

    #[test]
    fn an_images_directions_cover_the_sphere_evenly_for_any_length() {
        let image = |start: u64, steps: u64| ImageDirections { start, steps };
        // Over many images, every (bundle, step) is uniform: mean 0 and E[z^2] = 1/3.
        let (mut mean, mut z2, mut count) = (glam::DVec3::ZERO, 0.0, 0.0);
        for start in 0..400 {
            for i in 0..29 {
                for q in 0..4 {
                    let d = image_direction(3, image(start, 29), q, 4, i);
                    assert!((d.length() - 1.0).abs() < 1e-12);
                    mean += d;
                    z2 += d.z * d.z;
                    count += 1.0;
                }
            }
        }
        assert!((mean / count).length() < 0.01 && (z2 / count - 1.0 / 3.0).abs() < 0.01, "{mean} {z2}");
        // Each bundle's steps, and a step's bundles together, split evenly over the octants:
        // summed over 64 images, the deviation is a small part of independent directions'
        // (n 7/8 an image); before, an image of fewer steps than a block took a random part
        // of it and deviated as much as independent directions.
        for (steps, per_step) in [(13u64, 1u32), (29, 1), (64, 1), (29, 4), (100, 4)] {
            let (mut own, mut together) = (0.0, 0.0);
            for start in 0..64 {
                let d = |q: u32, i: u64| image_direction(11, image(40 + 1000 * start, steps), q, per_step, i);
                for q in 0..per_step {
                    own += octant_deviation(&(0..steps).map(|i| d(q, i)).collect::<Vec<_>>());
                }
                let all: Vec<_> = (0..steps).flat_map(|i| (0..per_step).map(move |q| d(q, i))).collect();
                together += octant_deviation(&all);
            }
            let independent = |n: u64| 64.0 * n as f64 * 7.0 / 8.0;
            let own = own / per_step as f64;
            assert!(own < 0.4 * independent(steps), "{steps} steps: {own} against {}", independent(steps));
            let n = steps * per_step as u64;
            assert!(together < 0.4 * independent(n), "{steps} x {per_step}: {together} against {}", independent(n));
        }
        // One direction after another in the iteration (a step's bundles, then the next
        // step's first) is as good as independent: E|d . d'| = 1/2 (standard error about
        // 0.29 / sqrt(n)), where consecutive points of a stratified set would be apart.
        let (mut sum, mut n) = (0.0, 0.0);
        for start in 0..100 {
            let seq: Vec<_> =
                (0..50).flat_map(|i| (0..4).map(move |q| image_direction(5, image(start, 50), q, 4, i))).collect();
            for w in seq.windows(2) {
                sum += w[0].dot(w[1]).abs();
                n += 1.0;
            }
        }
        assert!((sum / n - 0.5).abs() < 0.02, "E|d . d'| = {}", sum / n);
        // The image's start (a walkthrough's frame) and the seed choose other sets.
        assert_ne!(image_direction(5, image(40, 29), 0, 1, 3), image_direction(5, image(69, 29), 0, 1, 3));
        assert_ne!(image_direction(5, image(40, 29), 0, 1, 3), image_direction(6, image(40, 29), 0, 1, 3));
    }

    #[test]
    fn pixel_samples_fill_each_stratum_once_a_block() {
        let cells = PIXEL_STRATA * PIXEL_STRATA;
        let mut sum = [0.0; 2];
        let blocks = 64;
        for block in 0..blocks {
            let mut seen = vec![0; cells as usize];
            let first = stratified_pixel_sample(3, block * cells);
            for i in 0..cells {
                let step = block * cells + i;
                let sample = stratified_pixel_sample(3, step);
                let p = sample.position();
                assert!(p.iter().all(|&c| (0.0..1.0).contains(&c)), "{p:?}");
                // One offset inside the strata for the whole block.
                assert_eq!(sample.offset, first.offset, "block {block}, step {step}");
                let n = PIXEL_STRATA as f64;
                assert_eq!([(p[0] * n) as u32, (p[1] * n) as u32], sample.cell);
                seen[(sample.cell[1] as u64 * PIXEL_STRATA + sample.cell[0] as u64) as usize] += 1;
                sum[0] += p[0];
                sum[1] += p[1];
            }
            assert!(seen.iter().all(|&c| c == 1), "block {block}: {seen:?}");
        }
        // Uniform: the mean of 1024 stratified points (64 offsets) is 1/2 within about
        // 0.29 / (4 sqrt(64)) = 0.009 (the offsets' spread over the strata); 0.03 is three of them.
        let n = (blocks * cells) as f64;
        assert!((sum[0] / n - 0.5).abs() < 0.03 && (sum[1] / n - 0.5).abs() < 0.03, "{sum:?}");
        // The order and the offset differ from block to block and from seed to seed.
        let first = |seed: u64, block: u64| -> Vec<[u32; 2]> {
            (0..cells).map(|i| stratified_pixel_sample(seed, block * cells + i).cell).collect()
        };
        assert_ne!(first(3, 0), first(3, 1));
        assert_ne!(first(3, 0), first(4, 0));
        assert_ne!(stratified_pixel_sample(3, 0).offset, stratified_pixel_sample(3, cells).offset);
        assert_ne!(stratified_pixel_sample(3, 0).offset, stratified_pixel_sample(4, 0).offset);
    }

    /// The blocks' offsets: any 2^k consecutive blocks from a multiple of 2^k put one offset
    /// in each of the 2^k intervals of either coordinate (and of each elementary box), whatever
    /// the seed's shift; so the camera samples of an image of B blocks cover each pixel to
    /// about 1 / (4 B) along either axis, where random offsets left it near 0.29 / (4 sqrt B).
    #[test]
    fn pixel_offsets_are_stratified_at_every_scale() {
        assert_eq!(
            (0..4).map(|v| sobol_2d([0, 0], v)).collect::<Vec<_>>(),
            vec![[0.0, 0.0], [0.5, 0.5], [0.25, 0.75], [0.75, 0.25]]
        );
        let cells = PIXEL_STRATA * PIXEL_STRATA;
        for seed in [3, 11] {
            let offset = |block: u64| stratified_pixel_sample(seed, block * cells).offset;
            for k in 0..=8u32 {
                let n = 1u64 << k;
                for first in [0, n, 5 * n] {
                    for axis in 0..2 {
                        let mut seen = vec![0; n as usize];
                        for b in first..first + n {
                            seen[(offset(b)[axis] * n as f64) as usize] += 1;
                        }
                        assert!(seen.iter().all(|&c| c == 1), "seed {seed}, {n} blocks from {first}, axis {axis}");
                    }
                    // Elementary boxes of 2^i x 2^(k - i) intervals.
                    for i in 0..=k {
                        let (nx, ny) = (1u64 << i, 1u64 << (k - i));
                        let mut seen = vec![0; n as usize];
                        for b in first..first + n {
                            let o = offset(b);
                            seen[((o[1] * ny as f64) as u64 * nx + (o[0] * nx as f64) as u64) as usize] += 1;
                        }
                        assert!(seen.iter().all(|&c| c == 1), "seed {seed}, {n} blocks, boxes {nx} x {ny}");
                    }
                }
            }
        }
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
