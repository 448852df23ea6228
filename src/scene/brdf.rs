//! The BRDFs on the host (tests, oracles, material validation). Their WGSL twin is
//! `wgsl/common/brdf.wgsl`; a GPU test keeps the two in step.
//!
//! To be implemented: evaluation, directional albedo, the energy check.

use super::{MaterialKind, Rgb};

/// The largest directional albedo over all incident angles, per channel. A material whose
/// value exceeds 1 in any channel gains energy and is refused by the loader.
pub fn max_directional_albedo(_kind: &MaterialKind) -> Rgb {
    [0.0; 3]
}
