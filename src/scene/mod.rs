//! Scenes: what `load` reads from a TOML file (format 1, docs/SCENE_FORMAT.md) and what
//! `tessellate` turns into patches and light samples.
//!
//! Geometry is kept in f64 on the host so that tessellation preserves areas to far better
//! than the 1e-6 the contract asks; it becomes f32 only when it is uploaded.

pub mod brdf;
pub mod camera_path;
pub mod contact;
pub mod gltf;
pub mod load;
pub mod mtl;
pub mod shapes;
pub mod tessellate;

use glam::DVec3;
use std::path::PathBuf;

pub use load::load;
pub use tessellate::{Lattice, LightSample, Patch, PatchKind, Patches, Piece, SampleKind, tessellate};

/// Linear RGB, one value per channel.
pub type Rgb = [f32; 3];

/// A loaded, validated scene. Every value here has passed the checks of docs/SCENE_FORMAT.md.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene file it came from (errors and stats name it).
    pub source: PathBuf,
    /// The camera this run renders: `[camera]`, or the one picked by name with
    /// `select_camera` (`--camera NAME`).
    pub camera: Camera,
    /// Every camera of the scene, in file order: `[camera]` first (named "camera"), then
    /// the `[[cameras]]` entries. Never empty.
    pub cameras: Vec<NamedCamera>,
    /// Radiance arriving from outside the scene (`[environment] radiance`).
    pub environment: Rgb,
    pub settings: Settings,
    pub materials: Vec<Material>,
    /// Every `[[shapes]]` entry, already turned into triangles in scene space.
    pub surfaces: Vec<Surface>,
    pub lights: Vec<Light>,
    /// What the loader read but does not render (a glTF texture, an MTL transparency, a
    /// Ks scaled down to conserve energy) and each glossy lobe sharper than the method
    /// samples well (`load::SHARP_LOBE_SHININESS`): one line each, printed as `note: ...`.
    pub notes: Vec<String>,
    /// The point of the file's coordinates that is this scene's origin: zero, unless the
    /// loader moved a scene that lies far from the file's origin to its own (`recentre`).
    /// Every position above (surfaces, lights, cameras) is the file's minus this; what the
    /// user reads back (the viewer's camera) is in the file's coordinates again.
    pub file_origin: DVec3,
}

/// A scene whose centre lies farther than this many of its radii from the origin of its
/// file is moved to it (`Scene::recentre`).
pub const RECENTRE_RADII: f64 = 4.0;

/// The sizes of scene the GPU's f32 arithmetic renders: the radius of the bounding sphere of
/// the surfaces and lights (after `Scene::recentre`), and the distance of every camera from
/// its centre, in scene units (`Scene::check_extent`). The kernels multiply up to three or
/// four lengths (areas, squared distances, cosines to the third over distances), which
/// overflow f32 (2^128) beyond a radius of about 2^42 and fall below its normal range (2^-126)
/// under about 2^-31. Measured (2026-11-30): cornell_point and the Sierpinski scene scaled by
/// powers of two (a point light's power by the square) render the same image to the bit from
/// radius 2^-28 to 2^42; at 2^-38 and 2^49 their errors against it were 0.27-0.48, and a
/// glowing quad of radius 7e-17 came out black and one of 7e20 with NaN pixels. These bounds
/// keep a margin of 16 to 64 times inside what was measured.
pub const EXTENT_RANGE: (f64, f64) = (1e-7, 1e10);

/// A pinhole camera (right-handed; image right = normalize(forward x up)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub position: DVec3,
    pub look_at: DVec3,
    pub up: DVec3,
    /// Full vertical field of view in degrees, 0 < fov_y < 180.
    pub fov_y: f64,
    pub width: u32,
    pub height: u32,
}

/// A camera with the name a user picks it by (`--camera NAME`).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedCamera {
    pub name: String,
    pub camera: Camera,
}

impl Scene {
    /// Moves a scene that lies far from the origin of its coordinates to it, exactly (by a
    /// multiple of a power of two near its radius, which every coordinate's last place
    /// divides), and keeps the move in `file_origin`. The GPU holds positions in f32, whose
    /// spacing grows with the distance from the origin: at 1e5 units it is 2^-7, a fifth of
    /// the Sierpinski scene's smallest triangles moved there, and every kernel (the camera's
    /// rays, the bundles' depths, the shadow rays) rounded to it. Centred, the scene keeps
    /// the precision of its own size wherever the file puts it. Only beyond RECENTRE_RADII
    /// radii: nearer, f32 holds positions to within a few 1e-7 of the scene's size already,
    /// and scenes modelled around their origin keep their exact numbers.
    pub fn recentre(&mut self) {
        let Some((centre, radius)) = self.extent() else {
            return;
        };
        if !(radius > 0.0 && radius.is_finite() && centre.length() > RECENTRE_RADII * radius) {
            return;
        }
        // A power of two: the coordinates near `centre` are multiples of their last place,
        // which is far below it, so subtracting a multiple of it is exact in f64.
        let grid = 2f64.powi(radius.log2().floor() as i32);
        self.translate(-(centre / grid).round() * grid);
    }

    /// The centre and radius of the sphere around the bounding box of the surfaces and the
    /// lights' points; `None` with neither.
    fn extent(&self) -> Option<(DVec3, f64)> {
        let surfaces = self.surfaces.iter().flat_map(|s| &s.triangles).flat_map(|t| t.vertices);
        let (low, high) = bounding_box(surfaces.chain(self.lights.iter().flat_map(|l| l.points().iter().copied())))?;
        Some((0.5 * (low + high), 0.5 * (high - low).length()))
    }

    /// Refuses a scene too large or too small for the GPU's f32 arithmetic (`EXTENT_RANGE`),
    /// which would otherwise render black or with NaN pixels, naming the fix: the same scene
    /// in other units (every position and size times a factor, a point or spot light's power
    /// or intensity times its square) renders the same image.
    pub fn check_extent(&self) -> crate::Result<()> {
        let (low, high) = EXTENT_RANGE;
        let Some((centre, radius)) = self.extent() else {
            return Ok(());
        };
        let rescale = "multiply every position and size in the scene (and its meshes) by a factor that brings it \
                       into that range, a point or spot light's power or intensity by the factor's square: the image \
                       stays the same";
        if !(low..=high).contains(&radius) && radius > 0.0 {
            let gltf = self
                .source
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"));
            return Err(crate::Error::scene(
                &self.source,
                if gltf { "meshes, lights" } else { "shapes, lights" },
                format!(
                    "they fit in a sphere of radius {radius:.3e} units; the renderer's f32 arithmetic holds scenes of \
                     radius {low:e} to {high:e} units (beyond, products of lengths overflow or vanish and the image \
                     comes out black or with NaN pixels): {rescale}"
                ),
            ));
        }
        for view in &self.cameras {
            let distance = view.camera.position.distance(centre);
            if distance > high {
                let key = if view.name == "camera" {
                    "camera.position".to_string()
                } else {
                    format!("cameras \"{}\" position", view.name)
                };
                return Err(crate::Error::scene(
                    &self.source,
                    key,
                    format!(
                        "the camera is {distance:.3e} units from the scene's centre, beyond the {high:e} that the \
                         renderer's f32 arithmetic holds: move it nearer, or {rescale}"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Moves everything with a position (surfaces, lights, cameras) by `by`; `file_origin`
    /// keeps where the file's coordinates then lie.
    pub fn translate(&mut self, by: DVec3) {
        for t in self.surfaces.iter_mut().flat_map(|s| &mut s.triangles) {
            t.vertices = t.vertices.map(|v| v + by);
        }
        for p in self.lights.iter_mut().flat_map(Light::points_mut) {
            *p += by;
        }
        let moved = |c: &mut Camera| {
            c.position += by;
            c.look_at += by;
        };
        moved(&mut self.camera);
        self.cameras.iter_mut().for_each(|c| moved(&mut c.camera));
        self.file_origin -= by;
    }

    /// Makes the camera called `name` the one this run renders. The error lists the names.
    pub fn select_camera(&mut self, name: &str) -> std::result::Result<(), String> {
        match self.cameras.iter().find(|c| c.name == name) {
            Some(c) => {
                self.camera = c.camera;
                Ok(())
            }
            None => {
                let names: Vec<String> = self.cameras.iter().map(|c| format!("\"{}\"", c.name)).collect();
                Err(format!("the scene has no camera \"{name}\"; its cameras are {}", names.join(", ")))
            }
        }
    }
}

/// `[settings]`: defaults that command-line flags override.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    pub patch_size: f64,
    /// `None`: chosen from the patches the light samples see (`first_shot::auto_resolution`).
    pub hemicube_resolution: Option<u32>,
    /// `None`: chosen from the patches and the image (`iteration::auto_bundle_resolution`).
    pub bundle_resolution: Option<u32>,
    pub iterations: u32,
    pub seed: u64,
    /// Bundles a step draws, 1 or 4; `None`: chosen from the patches and the image
    /// (`iteration::auto_bundles_per_step`).
    pub bundles_per_step: Option<u32>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            patch_size: f64::INFINITY,
            hemicube_resolution: None,
            bundle_resolution: None,
            iterations: 100,
            seed: 1,
            bundles_per_step: None,
        }
    }
}

/// A named material (`[materials.NAME]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    pub kind: MaterialKind,
}

/// The two BRDFs of the format. `brdf.rs` evaluates them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MaterialKind {
    /// Lambertian, f = albedo / pi.
    Diffuse { albedo: Rgb },
    /// max-Phong: f = kd / pi + ks max(0, cos psi)^n / max(cos theta_in, cos theta_out).
    Phong { diffuse: Rgb, specular: Rgb, shininess: f32 },
}

/// One triangle of a shape, counter-clockwise seen from its front.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangle {
    pub vertices: [DVec3; 3],
    /// Index into `Scene::materials` (meshes may set it per face through `usemtl`).
    pub material: u32,
}

/// A `[[shapes]]` entry after loading: its triangles in scene space.
#[derive(Debug, Clone)]
pub struct Surface {
    /// Where it came from, for messages: `shapes[3] (mesh "meshes/bunny.obj")`.
    pub origin: String,
    pub triangles: Vec<Triangle>,
    /// Diffuse emitted radiance on the front side (black when absent).
    pub emission: Rgb,
    /// Both sides reflect (and emit) with the same material.
    pub two_sided: bool,
}

/// A `[[lights]]` entry: the sources that the first shot handles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Isotropic point light; intensity = power / (4 pi).
    Point { position: DVec3, power: Rgb },
    /// One-sided diffuse planar convex quad, meshed into `subdivisions` x `subdivisions` cells.
    Area { vertices: [DVec3; 4], radiance: Rgb, subdivisions: u32 },
    /// A sun: parallel light travelling along `direction` (unit), of `irradiance` on a
    /// surface facing it (E = irradiance cos theta on one at angle theta).
    Directional { direction: DVec3, irradiance: Rgb },
    /// A point light at `position` whose intensity (W/sr) is `intensity` on its axis
    /// `direction` (unit) and falls off with the glTF KHR_lights_punctual cone between
    /// `inner_angle` and `outer_angle` (degrees from the axis, 0 <= inner < outer <= 90):
    /// `SpotCone`.
    Spot { position: DVec3, direction: DVec3, intensity: Rgb, inner_angle: f64, outer_angle: f64 },
}

impl Light {
    /// The points that place the light: a point or spot light's position, an area light's
    /// corners; none for a directional light.
    pub fn points(&self) -> &[DVec3] {
        match self {
            Light::Point { position, .. } | Light::Spot { position, .. } => std::slice::from_ref(position),
            Light::Area { vertices, .. } => vertices,
            Light::Directional { .. } => &[],
        }
    }

    /// The same, to move them.
    pub fn points_mut(&mut self) -> &mut [DVec3] {
        match self {
            Light::Point { position, .. } | Light::Spot { position, .. } => std::slice::from_mut(position),
            Light::Area { vertices, .. } => vertices,
            Light::Directional { .. } => &mut [],
        }
    }
}

/// The axis-aligned box (lowest and highest corner) of `points`; `None` when there are none.
pub fn bounding_box(points: impl IntoIterator<Item = DVec3>) -> Option<(DVec3, DVec3)> {
    let (low, high) = points
        .into_iter()
        .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.min(p), hi.max(p)));
    (low.x <= high.x).then_some((low, high))
}

/// A spot light's cone as glTF KHR_lights_punctual defines its falloff: with cd the cosine
/// of the angle between the spot's axis and the direction to the lit point,
///
///     factor = clamp(cd * scale + offset, 0, 1)^2,
///     scale = 1 / max(0.001, cos(inner) - cos(outer)),  offset = -cos(outer) * scale,
///
/// 1 inside the inner cone, 0 outside the outer one, smooth between.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpotCone {
    /// 1 / max(0.001, cos(inner) - cos(outer)).
    pub scale: f64,
    /// -cos(outer) scale.
    pub offset: f64,
}

impl SpotCone {
    /// The cone between `inner` and `outer` (degrees from the axis).
    pub fn new(inner_angle: f64, outer_angle: f64) -> SpotCone {
        let (cos_inner, cos_outer) = (inner_angle.to_radians().cos(), outer_angle.to_radians().cos());
        let scale = 1.0 / (cos_inner - cos_outer).max(0.001);
        SpotCone { scale, offset: -cos_outer * scale }
    }

    /// The falloff factor for a direction at cosine `cd` to the axis.
    pub fn falloff(&self, cd: f64) -> f64 {
        (cd * self.scale + self.offset).clamp(0.0, 1.0).powi(2)
    }
}
