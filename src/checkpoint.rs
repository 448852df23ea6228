//! Checkpoints: the complete state of an iteration, so that a run stopped at step k and
//! resumed gives exactly the image of an uninterrupted run. The state is J_j and win_j of
//! every patch, the image sum and the step count: step k's random numbers depend only on
//! (seed, k), so no generator state needs saving.
//!
//! File layout (little endian): magic "FSCKPT01", fingerprint u64, step u32, state length
//! u64, image-sum length u64, the two byte arrays, then an FNV-1a 64 checksum of all that
//! precedes it.

use crate::{Error, Result};
use std::path::Path;

const MAGIC: &[u8; 8] = b"FSCKPT01";

/// The iteration state after `step` steps.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Checkpoint {
    /// Identifies the scene and every option that changes the result (`fingerprint`).
    pub fingerprint: u64,
    pub step: u32,
    /// The `GpuPatchState` buffer, byte for byte.
    pub state: Vec<u8>,
    /// The image sum (vec4<f32> per pixel), byte for byte.
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

    pub fn read(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
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
}
