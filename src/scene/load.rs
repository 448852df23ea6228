//! TOML (+ OBJ) -> `Scene`, with every check of SCENE_FORMAT.md.
//!
//! To be implemented: see `load`.

use super::Scene;
use crate::{Error, Result};
use std::path::Path;

/// Loads and validates a scene file. Errors name the file, the key and what was expected.
pub fn load(path: &Path) -> Result<Scene> {
    Err(Error::scene(path, "format", "scene loading is not written yet"))
}
