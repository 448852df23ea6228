//! Checkpoints: the complete state of an iteration, so that a run stopped at step k and
//! resumed gives exactly the image of an uninterrupted run. The state is `GpuPatchState` of
//! every patch, the image sum (its two halves) and the step count: step k's random numbers
//! depend only on (seed, k), so no generator state needs saving.
//!
//! File layout (little endian): magic "FSCKPT06" (01: before the state's running means and
//! the image sum's two halves; 02: before the state's glossy history; 03: before the
//! emission a pixel sees moved from the image sum's first half to its second; 04: before
//! the glossy history's six packed entries in place of three; 05: before its ten, with the
//! direction packed beside K_j), fingerprint u64, step u32, state length u64, image-sum
//! length u64, the two byte arrays, then an FNV-1a 64 checksum of all that precedes it.

use crate::{Error, Result};
use std::path::Path;

const MAGIC: &[u8; 8] = b"FSCKPT06";
/// Earlier versions' magics, refused with a word on why.
const OLDER_MAGICS: [&[u8; 8]; 5] = [b"FSCKPT01", b"FSCKPT02", b"FSCKPT03", b"FSCKPT04", b"FSCKPT05"];

/// The iteration state after `step` steps.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Checkpoint {
    /// Identifies the scene and every option that changes the result (`fingerprint`).
    pub fingerprint: u64,
    pub step: u32,
    /// The `GpuPatchState` buffer, byte for byte.
    pub state: Vec<u8>,
    /// The image sum (vec4<f32> per pixel), byte for byte; with several views
    /// (`--all-cameras`) their sums one after another, in the order of the views.
    pub image_sum: Vec<u8>,
}

/// FNV-1a, 64 bits: small, portable and stable across versions.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn corrupt(path: &Path, what: &str) -> Error {
    Error::Usage(format!("{}: not a usable checkpoint ({what}); delete it or run without --resume", path.display()))
}

impl Checkpoint {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(40 + self.state.len() + self.image_sum.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&self.fingerprint.to_le_bytes());
        out.extend_from_slice(&self.step.to_le_bytes());
        out.extend_from_slice(&(self.state.len() as u64).to_le_bytes());
        out.extend_from_slice(&(self.image_sum.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.state);
        out.extend_from_slice(&self.image_sum);
        let sum = fnv1a(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    /// Parses a checkpoint; `path` only names it in errors.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Checkpoint> {
        const HEADER: usize = 8 + 8 + 4 + 8 + 8;
        if bytes.len() >= 8 && OLDER_MAGICS.iter().any(|m| &bytes[..8] == *m) {
            return Err(corrupt(
                path,
                "it was written by an older firstshot whose iteration state this one cannot continue",
            ));
        }
        if bytes.len() < HEADER + 8 || &bytes[..8] != MAGIC {
            return Err(corrupt(path, "no firstshot checkpoint header"));
        }
        let (body, sum) = bytes.split_at(bytes.len() - 8);
        if fnv1a(body).to_le_bytes() != sum {
            return Err(corrupt(path, "checksum mismatch: the file is truncated or damaged"));
        }
        let u64_at = |i: usize| u64::from_le_bytes(body[i..i + 8].try_into().unwrap_or([0; 8]));
        let fingerprint = u64_at(8);
        let step = u32::from_le_bytes(body[16..20].try_into().unwrap_or([0; 4]));
        let (state_len, image_len) = (u64_at(20) as usize, u64_at(28) as usize);
        if Some(body.len()) != HEADER.checked_add(state_len).and_then(|n| n.checked_add(image_len)) {
            return Err(corrupt(path, "lengths do not match the file size"));
        }
        Ok(Checkpoint {
            fingerprint,
            step,
            state: body[HEADER..HEADER + state_len].to_vec(),
            image_sum: body[HEADER + state_len..].to_vec(),
        })
    }

    /// Checks what the checksum cannot (it is as easy to recompute as to forge): that the
    /// numbers are those of a run resumed after `burn_in` steps of the iteration, whose first
    /// n image steps hold `direct_estimates(n)` estimates of the direct light. Every number
    /// of the state and of the image sum must be finite, and every pixel's weights (the
    /// fourth component of its two sums, `stages::image_estimate`) must be those direct-light
    /// estimates and the `step - burn_in` image steps. `view_pixels`: the pixels of each
    /// view, whose image sums follow one another; `None`, a single view of any size. A
    /// refusal names the file (exit status 2), instead of a GPU failure later.
    pub fn check_numbers(
        &self,
        path: &Path,
        burn_in: u32,
        direct_estimates: &dyn Fn(u32) -> u32,
        view_pixels: Option<&[u64]>,
    ) -> Result<()> {
        use crate::layout::GpuPatchState;
        if !self.state.len().is_multiple_of(size_of::<GpuPatchState>()) || !self.image_sum.len().is_multiple_of(16) {
            return Err(corrupt(path, "its arrays are not whole numbers"));
        }
        let floats = |bytes: &[u8]| -> Vec<f32> {
            bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        // The state's float fields; the direction and the glossy history's entries are packed
        // bits, which read as floats may look like anything.
        // Patch by patch from the bytes (a copy of the whole state would double a large
        // scene's memory at resume).
        let finite = |bytes: &[u8]| {
            let s: GpuPatchState = bytemuck::pod_read_unaligned(bytes);
            [s.incoming, s.mean_radiance, s.diffuse_sum].iter().flatten().chain(&s.diffuse).all(|v| v.is_finite())
        };
        if !self.state.chunks_exact(size_of::<GpuPatchState>()).all(finite) {
            return Err(corrupt(path, "its iteration state holds numbers that are not finite"));
        }
        let Some(image_steps) = self.step.checked_sub(burn_in).filter(|&n| n > 0) else {
            return Err(corrupt(path, &format!("step {} is not past the burn-in of {burn_in} steps", self.step)));
        };
        let sum = floats(&self.image_sum);
        if sum.iter().any(|v| !v.is_finite()) {
            return Err(corrupt(path, "its image holds numbers that are not finite"));
        }
        let one_view = [sum.len() as u64 / 8];
        let view_pixels = view_pixels.unwrap_or(&one_view);
        if view_pixels.iter().map(|p| p * 8).sum::<u64>() != sum.len() as u64 {
            return Err(corrupt(path, "its images are not of this run's cameras and sizes"));
        }
        let direct_passes = direct_estimates(image_steps);
        let mut rest = &sum[..];
        for &pixels in view_pixels {
            let (view, after) = rest.split_at(pixels as usize * 8);
            rest = after;
            let (direct, gathered) = view.split_at(view.len() / 2);
            if direct.chunks_exact(4).any(|p| p[3] != direct_passes as f32)
                || gathered.chunks_exact(4).any(|p| p[3] != image_steps as f32)
            {
                return Err(corrupt(
                    path,
                    &format!(
                        "its image's weights are not those of the {image_steps} image steps of step {}",
                        self.step
                    ),
                ));
            }
        }
        Ok(())
    }

    pub fn read(path: &Path) -> Result<Checkpoint> {
        let bytes = crate::files::read_named_input(path)?;
        Checkpoint::from_bytes(path, &bytes)
    }

    /// Writes through a temporary file and a rename: a reader sees the old or the new
    /// checkpoint, never half of one.
    pub fn write(&self, path: &Path) -> Result<()> {
        crate::image::write_atomically(path, &self.to_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_every_corruption_is_refused() {
        let c = Checkpoint { fingerprint: 42, step: 17, state: (0..64).collect(), image_sum: (0..=255).collect() };
        let bytes = c.to_bytes();
        let p = Path::new("x.checkpoint");
        assert_eq!(Checkpoint::from_bytes(p, &bytes).unwrap(), c);
        for cut in [0, 7, 40, bytes.len() - 1] {
            assert!(Checkpoint::from_bytes(p, &bytes[..cut]).is_err(), "truncated at {cut}");
        }
        for flip in [0, 9, 17, 30, 50, bytes.len() - 3] {
            let mut b = bytes.clone();
            b[flip] ^= 0x10;
            assert!(Checkpoint::from_bytes(p, &b).is_err(), "bit flipped at {flip}");
        }
    }

    /// A forged checkpoint (its checksum recomputed) with numbers no run writes.
    #[test]
    fn numbers_a_run_cannot_write_are_refused() {
        let p = Path::new("x.checkpoint");
        let pixel = |rgb: f32, w: f32| [rgb, rgb, rgb, w].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>();
        // One patch's state: finite floats, and a glossy history of packed bits that read as
        // floats would be NaN (a run writes such bits: they are not floats).
        let patch = crate::layout::GpuPatchState {
            incoming: [0.5; 4],
            diffuse: [0.5; 3],
            direction: 0xffff_ffff,
            mean_radiance: [0.5; 4],
            diffuse_sum: [1.0; 4],
            earlier: [[0x7fc0_0001, 0xffff_ffff]; crate::layout::GLOSSY_HISTORY],
        };
        let good = Checkpoint {
            fingerprint: 1,
            step: 12,
            state: bytemuck::bytes_of(&patch).to_vec(),
            image_sum: [pixel(0.25, 2.0), pixel(3.0, 2.0)].concat(),
        };
        good.check_numbers(p, 10, &|n| n, None).unwrap();
        let refused = |c: &Checkpoint, burn_in: u32, part: &str| {
            let e = c.check_numbers(p, burn_in, &|n| n, None).expect_err(part).to_string();
            assert!(e.contains("x.checkpoint") && e.contains(part), "{e}");
            assert!(Checkpoint::from_bytes(p, &c.to_bytes()).is_ok(), "the checksum alone passes it");
        };
        refused(&good, 12, "burn-in");
        refused(&good, 11, "weights");
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut c = good.clone();
            c.state[4..8].copy_from_slice(&bad.to_le_bytes());
            refused(&c, 10, "iteration state");
            let mut c = good.clone();
            c.image_sum = [pixel(bad, 2.0), pixel(3.0, 2.0)].concat();
            refused(&c, 10, "image holds");
            let mut c = good.clone();
            c.image_sum = [pixel(0.25, bad), pixel(3.0, 2.0)].concat();
            refused(&c, 10, "image holds");
        }
        let mut c = good.clone();
        c.state.pop();
        refused(&c, 10, "whole numbers");
    }
}
