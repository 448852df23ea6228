//! Surfaces -> patches; lights -> light samples (DESIGN.md section 1).
//!
//! To be implemented: see `tessellate`.

use super::{Rgb, Scene};
use crate::Result;
use glam::DVec3;

/// What a patch is part of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PatchKind {
    /// A triangle of a `[[shapes]]` entry.
    Surface { surface: u32 },
    /// A triangle of an area light's n x n grid: it emits `radiance` on its front, reflects
    /// nothing (black material) and occludes like any surface.
    AreaLight { light: u32 },
}

/// One triangular patch: the unit of the finite-element radiance representation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    /// Counter-clockwise seen from the front.
    pub vertices: [DVec3; 3],
    /// Unit front normal, normalize((v1 - v0) x (v2 - v0)).
    pub normal: DVec3,
    /// Exact area of the triangle.
    pub area: f64,
    /// Index into `Scene::materials`; `None` for area-light patches (black).
    pub material: Option<u32>,
    /// Diffuse emitted radiance on the front side.
    pub emission: Rgb,
    pub kind: PatchKind,
    /// This patch has a back-to-back twin (a `two_sided` shape): where both are seen at the
    /// same depth, only the one whose front faces the viewer counts.
    pub twin: bool,
}

/// One light sample y_i of the first shot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    pub position: DVec3,
    /// `None` for a point light (full cube window); the area light's unit normal otherwise
    /// (hemicube window above it).
    pub normal: Option<DVec3>,
    /// S_i: the power of a point light, the radiance of an area light.
    pub strength: Rgb,
    /// w_i: for an area-light vertex, (area of the light triangles sharing it) / 3; 1 for a
    /// point light.
    pub weight: f64,
    /// Index into `Scene::lights`.
    pub light: u32,
}

/// The tessellated scene.
#[derive(Debug, Clone, Default)]
pub struct Patches {
    pub patches: Vec<Patch>,
    pub samples: Vec<LightSample>,
}

/// Tessellates every surface into triangles whose longest edge is at most `patch_size`
/// (a two-sided surface into back-to-back pairs), and meshes every area light into its
/// n x n grid: 2 n^2 patches and (n+1)^2 samples with trapezoid weights.
pub fn tessellate(_scene: &Scene, _patch_size: f64) -> Result<Patches> {
    Ok(Patches::default())
}
