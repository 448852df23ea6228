//! firstshot: global illumination of glossy scenes on the GPU, after *Incoming First-Shot for
//! Non-Diffuse Global Illumination* (Szirmay-Kalos, Sbert, Martínez, Tobler, SCCG 2000).
//!
//! The pipeline, in the order `render.rs` runs it:
//! 1. `scene`: a TOML scene (+ OBJ meshes) is loaded and validated, then tessellated into
//!    triangular patches and light samples.
//! 2. `stages::first_shot_*`: item buffers around every light sample give one scalar r_ij per
//!    visible (patch, light sample) pair; their reflection is evaluated on the fly.
//! 3. `stages::bundle_*`: ray-bundle stochastic iteration transfers the remaining light along
//!    random global directions between all mutually visible patches.
//! 4. `stages::image_estimate`: every step adds an estimate of each camera pixel; the image is
//!    the running mean, written by `image` as EXR + PNG.
//!
//! `shard` and `merge` split one run into independent chains on many machines and add their
//! image sums exactly (docs/DISTRIBUTED.md).

pub mod burn_in;
pub mod checkpoint;
pub mod direct_light;
pub mod error;
pub mod files;
pub mod first_shot;
pub mod scene;
pub mod shadow_bvh;
pub mod shard;

pub use error::{Error, Result};
pub mod gpu;
pub mod image;
pub mod iteration;
pub mod layout;
pub mod memory;
pub mod merge;
pub mod render;
pub mod rng;
pub mod stages;

/// The result of a scoped thread, its panic raised again on the joining thread (the
/// renderer's host work beside the device's: the adapter's opening, the burn-in's walk, the
/// image's pipelines).
pub(crate) fn joined<T>(handle: std::thread::ScopedJoinHandle<'_, T>) -> T {
    handle.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}
