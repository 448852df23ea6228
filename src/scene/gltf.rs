//! glTF 2.0 (`.gltf` with its buffers, `.glb`, data URIs) -> our scene: triangles under the
//! node hierarchy, materials, point lights, cameras (docs/SCENE_FORMAT.md, "glTF 2.0").
//!
//! The mapping never gains energy (`metallic_roughness`), and everything the file holds that
//! is not rendered (textures, morph targets, skins, other lights, unknown extensions) is
//! either refused or named in a note, one line each. Errors and notes name the file and the
//! glTF object by its JSON path (`meshes[2] "Piston" primitives[0]`).

use super::brdf::max_directional_albedo;
use super::mtl::fit_specular;
use super::shapes::{self, POLYGON_PLANARITY, PolygonProblem};
use super::{Camera, Light, Material, MaterialKind, NamedCamera, Rgb, Scene, Settings, Surface, Triangle};
use crate::{Error, Result};
use base64::Engine as _;
use glam::{DMat4, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::khr_lights_punctual::Kind as LightKind;
use std::collections::HashSet;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Extensions this loader reads; a file that requires any other is refused, one that merely
/// uses another gets a note.
const SUPPORTED_EXTENSIONS: &[&str] = &["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// The image edge of a glTF camera along its longer side (`--width` / `--height` override).
pub const CAMERA_PIXELS: u32 = 512;

/// The largest max-Phong exponent a roughness maps to: roughness 0 (a perfect mirror) would
/// be infinite. 10^4 is a lobe about half a degree wide.
pub const MAX_SHININESS: f64 = 1e4;

/// The vertical field of view of the default camera of a glTF scene without one, degrees.
pub const DEFAULT_FOV_Y: f64 = 40.0;

/// Nodes nested deeper than this are refused (a cycle, or a file made to exhaust the stack).
const MAX_NODE_DEPTH: usize = 256;

/// metallic-roughness -> max-Phong, conserving energy (docs/SCENE_FORMAT.md):
///
/// - specular colour F = 0.04 (1 - m) + c m (glTF's F0), glossiness t = 1 - r;
/// - specular albedo A = t F, given to a lobe of exponent n = 1 / (2 r^4) - 1/2 (at most
///   `MAX_SHININESS`) with ks = A / L(n), L(n) the lobe's largest albedo over all angles;
/// - kd = (1 - m) c (1 - A) + m r c: the base colour less what the specular takes, and the
///   share of a metal's reflection that roughness spreads over the hemisphere.
///
/// kd + A <= 1 - m t (1 - F) <= 1 for c <= 1, so the largest albedo is at most 1; rounding
/// is caught by `fit_specular`. Metallic 0, roughness 1 is exactly `Diffuse { c }`.
pub fn metallic_roughness(base: Rgb, metallic: f32, roughness: f32) -> MaterialKind {
    let (m, r) = (f64::from(metallic.clamp(0.0, 1.0)), f64::from(roughness.clamp(0.0, 1.0)));
    let c = base.map(|x| f64::from(x.clamp(0.0, 1.0)));
    let t = 1.0 - r;
    let specular_albedo = c.map(|c| t * (0.04 * (1.0 - m) + c * m));
    let diffuse: Rgb = std::array::from_fn(|i| ((1.0 - m) * c[i] * (1.0 - specular_albedo[i]) + m * r * c[i]) as f32);
    if specular_albedo.iter().all(|&a| a == 0.0) {
        return MaterialKind::Diffuse { albedo: diffuse };
    }
    let shininess = if r > 0.0 { (0.5 / r.powi(4) - 0.5).min(MAX_SHININESS) } else { MAX_SHININESS } as f32;
    let lobe =
        f64::from(max_directional_albedo(&MaterialKind::Phong { diffuse: [0.0; 3], specular: [1.0; 3], shininess })[0]);
    let specular = specular_albedo.map(|a| (a / lobe) as f32);
    let (specular, _) = fit_specular(diffuse, specular, shininess);
    MaterialKind::Phong { diffuse, specular, shininess }
}

/// What a glTF file holds, in scene space, with material indices counted from
/// `first_material`.
pub struct Model {
    pub surfaces: Vec<Surface>,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    pub cameras: Vec<NamedCamera>,
    pub notes: Vec<String>,
}

/// How the model is placed and dressed by the scene that reads it.
pub struct Placement {
    /// Applied after the glTF node transforms: the `gltf` shape's transform.
    pub transform: DMat4,
    /// A `material` override: every primitive gets it (and the file's materials are unused).
    pub material: Option<u32>,
    /// The index the model's first material will have in `Scene::materials`.
    pub first_material: u32,
    /// Prefix of surface origins (`shapes[2] (gltf "lamp.glb")`).
    pub origin: String,
}

/// Loads a glTF file as a whole scene (`firstshot scene.glb`): default settings, black
/// environment, its cameras (or a default one), lights and emissive materials.
pub fn load_scene(path: &Path) -> Result<Scene> {
    let placement = Placement {
        transform: DMat4::IDENTITY,
        material: None,
        first_material: 0,
        origin: path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()),
    };
    let model = read(path, &placement)?;
    let err = |key: &str, message: &str| Error::scene(path, key, message);
    if model.surfaces.iter().all(|s| s.triangles.is_empty()) {
        return Err(err("meshes", "the glTF scene has no triangles to render"));
    }
    let glows = |c: &Rgb| c.iter().any(|&x| x > 0.0);
    let emits = model.surfaces.iter().any(|s| glows(&s.emission))
        || model.lights.iter().any(|l| matches!(l, Light::Point { power, .. } if glows(power)));
    if !emits {
        return Err(err(
            "lights",
            "the glTF scene has no light: give it a KHR_lights_punctual light (point, directional or spot) or an emissive material, \
             or place the model in a TOML scene with a `gltf` shape (docs/SCENE_FORMAT.md)",
        ));
    }
    let mut notes = model.notes;
    let cameras = if model.cameras.is_empty() {
        notes.push(format!(
            "{}: no perspective camera: the default camera looks at the model's bounding box along -z, fov_y {DEFAULT_FOV_Y}",
            path.display()
        ));
        vec![NamedCamera { name: "default".into(), camera: default_camera(&model.surfaces) }]
    } else {
        model.cameras
    };
    let mut scene = Scene {
        source: path.to_path_buf(),
        camera: cameras[0].camera,
        cameras,
        environment: [0.0; 3],
        settings: Settings::default(),
        materials: model.materials,
        surfaces: model.surfaces,
        lights: model.lights,
        notes,
        file_origin: DVec3::ZERO,
    };
    scene.recentre();
    scene.check_extent()?;
    Ok(scene)
}

/// From the +z side of the bounding box, at the distance where its bounding sphere fills
/// the field of view.
fn default_camera(surfaces: &[Surface]) -> Camera {
    let points = surfaces.iter().flat_map(|s| s.triangles.iter().flat_map(|t| t.vertices));
    let (lo, hi) = super::bounding_box(points).unwrap_or((DVec3::INFINITY, DVec3::NEG_INFINITY));
    let center = (lo + hi) / 2.0;
    let radius = ((hi - lo).length() / 2.0).max(1e-6);
    let distance = radius / (DEFAULT_FOV_Y.to_radians() / 2.0).sin();
    Camera {
        position: center + DVec3::Z * distance,
        look_at: center,
        up: DVec3::Y,
        fov_y: DEFAULT_FOV_Y,
        width: CAMERA_PIXELS,
        height: CAMERA_PIXELS,
    }
}

/// Reads a glTF file: its default scene (else its first), every node under it.
pub fn read(path: &Path, placement: &Placement) -> Result<Model> {
    let bytes = crate::files::read_named_input(path)?;
    let err = |key: &str, message: String| Error::scene(path, key, message);
    let file = gltf::Gltf::from_slice_without_validation(&bytes)
        .map_err(|e| err("glTF", format!("not a glTF 2.0 file (JSON .gltf or binary .glb): {e}")))?;
    let mut notes = Vec::new();
    let note = |notes: &mut Vec<String>, key: &str, message: String| {
        notes.push(format!("{}: {key}: {message}", path.display()))
    };
    for required in file.extensions_required() {
        if !SUPPORTED_EXTENSIONS.contains(&required) {
            return Err(err(
                "extensionsRequired",
                format!(
                    "the file requires the extension {required}, which this loader does not read (it reads {})",
                    SUPPORTED_EXTENSIONS.join(", ")
                ),
            ));
        }
    }
    for used in file.extensions_used() {
        if !SUPPORTED_EXTENSIONS.contains(&used) {
            note(&mut notes, "extensionsUsed", format!("extension {used} is ignored"));
        }
    }
    let gltf::Gltf { document, blob } = file;
    let document = gltf::Document::from_json(document.into_json()).map_err(|e| match e {
        gltf::Error::Validation(errors) => {
            let (at, what) = &errors[0];
            err(&at.to_string(), format!("invalid glTF: {what}"))
        }
        e => err("glTF", format!("invalid glTF: {e}")),
    })?;
    let buffers = read_buffers(path, &document, blob)?;
    if document.animations().next().is_some() {
        note(&mut notes, "animations", "animations are ignored (the scene is rendered at rest)".into());
    }

    let mut reader = Reader {
        path,
        placement,
        buffers,
        notes,
        surfaces: Vec::new(),
        materials: Vec::new(),
        material_slots: vec![None; document.materials().len() + 1],
        lights: Vec::new(),
        cameras: Vec::new(),
    };
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        return Err(err("scenes", "the file has no scene to render".into()));
    };
    let mut on_path = HashSet::new();
    for node in scene.nodes() {
        reader.node(&node, placement.transform, &mut on_path, 0)?;
    }
    Ok(Model {
        surfaces: reader.surfaces,
        materials: reader.materials,
        lights: reader.lights,
        cameras: reader.cameras,
        notes: reader.notes,
    })
}

/// The bytes of every buffer: the GLB binary chunk, a data URI or a file beside the glTF.
fn read_buffers(path: &Path, document: &gltf::Document, mut blob: Option<Vec<u8>>) -> Result<Vec<Vec<u8>>> {
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let key = format!("buffers[{}]", buffer.index());
        let err = |message: String| Error::scene(path, &key, message);
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => {
                blob.take().ok_or_else(|| err("refers to the GLB binary chunk, which the file does not have".into()))?
            }
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let Some((_, payload)) = uri.split_once(";base64,") else {
                    return Err(err("a data URI must be base64 (data:...;base64,...)".into()));
                };
                base64::engine::general_purpose::STANDARD
                    .decode(payload)
                    .map_err(|e| err(format!("the data URI is not valid base64: {e}")))?
            }
            gltf::buffer::Source::Uri(uri) => {
                if uri.contains("://") {
                    return Err(err(format!(
                        "\"{uri}\" is not a file beside the glTF: only relative paths and data URIs are read"
                    )));
                }
                let file =
                    path.parent().map_or_else(|| PathBuf::from(percent_decoded(uri)), |d| d.join(percent_decoded(uri)));
                crate::files::read_input(&file).map_err(|e| {
                    let why = match e {
                        crate::files::ReadError::Io(e) if e.kind() == std::io::ErrorKind::NotFound => {
                            "does not exist".to_string()
                        }
                        crate::files::ReadError::NotAFile(what) => format!("is {what}"),
                        crate::files::ReadError::Io(e) => format!("cannot be read: {e}"),
                    };
                    err(format!("buffer file {} {why}", file.display()))
                })?
            }
        };
        if data.len() < buffer.length() {
            return Err(err(format!("holds {} bytes, fewer than its byteLength {}", data.len(), buffer.length())));
        }
        // Accessors must stay within the declared length, whatever follows it.
        let mut data = data;
        data.truncate(buffer.length());
        out.push(data);
    }
    Ok(out)
}

/// `%20` -> ` ` (URIs in glTF are percent-encoded).
fn percent_decoded(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && let (Some(h), Some(l)) = (hex(bytes[i + 1]), hex(bytes[i + 2]))
        {
            out.push((h * 16 + l) as u8);
            i += 3;
            continue;
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Walks the node tree, collecting what it finds.
struct Reader<'a> {
    path: &'a Path,
    placement: &'a Placement,
    buffers: Vec<Vec<u8>>,
    notes: Vec<String>,
    surfaces: Vec<Surface>,
    materials: Vec<Material>,
    /// glTF material index (the last slot: the default material) -> index in `materials`
    /// and its emission, once used.
    material_slots: Vec<Option<(u32, Rgb)>>,
    lights: Vec<Light>,
    cameras: Vec<NamedCamera>,
}

/// `nodes[3] "Engine"`: a glTF object by index, with its name if it has one.
fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("{kind}[{index}] {n:?}"),
        None => format!("{kind}[{index}]"),
    }
}

impl Reader<'_> {
    fn note(&mut self, key: &str, message: impl Into<String>) {
        self.notes.push(format!("{}: {key}: {}", self.path.display(), message.into()));
    }

    fn err(&self, key: &str, message: impl Into<String>) -> Error {
        Error::scene(self.path, key, message)
    }

    fn node(&mut self, node: &gltf::Node, parent: DMat4, on_path: &mut HashSet<usize>, depth: usize) -> Result<()> {
        let key = named("nodes", node.index(), node.name());
        if !on_path.insert(node.index()) || depth > MAX_NODE_DEPTH {
            return Err(self.err(&key, "the node hierarchy has a cycle (a node is its own ancestor) or is too deep"));
        }
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if !world.is_finite() {
            return Err(self.err(&key, "its transform is not finite"));
        }
        if node.skin().is_some() {
            self.note(&key, "its skin is ignored (the mesh is rendered in its bind pose)");
        }
        if let Some(mesh) = node.mesh() {
            self.mesh(&key, &mesh, world)?;
        }
        if let Some(camera) = node.camera() {
            self.camera(&key, &camera, world)?;
        }
        if let Some(light) = node.light() {
            self.light(&key, &light, world);
        }
        for child in node.children() {
            self.node(&child, world, on_path, depth + 1)?;
        }
        on_path.remove(&node.index());
        Ok(())
    }

    fn mesh(&mut self, node_key: &str, mesh: &gltf::Mesh, world: DMat4) -> Result<()> {
        let mesh_key = format!("{node_key} {}", named("meshes", mesh.index(), mesh.name()));
        // A transform with a negative determinant mirrors: the triangles' winding flips with
        // it, so each is turned back to keep its front where the file had it.
        let mirrors = world.determinant() < 0.0;
        for primitive in mesh.primitives() {
            let key = format!("{mesh_key} primitives[{}]", primitive.index());
            if primitive.mode() != gltf::mesh::Mode::Triangles {
                self.note(&key, format!("mode {:?} is ignored (only triangles are rendered)", primitive.mode()));
                continue;
            }
            if primitive.morph_targets().next().is_some() {
                self.note(&key, "its morph targets are ignored (the base mesh is rendered)");
            }
            let Some(positions) = primitive.get(&gltf::Semantic::Positions) else {
                return Err(self.err(&key, "has no POSITION attribute"));
            };
            let positions: Vec<DVec3> =
                self.positions(&key, &positions)?.into_iter().map(|p| world.transform_point3(p)).collect();
            let indices = match primitive.indices() {
                Some(a) => self.indices(&key, &a, positions.len())?,
                None => (0..positions.len() as u32).collect(),
            };
            if !indices.len().is_multiple_of(3) {
                return Err(self.err(&key, format!("has {} indices, not a multiple of 3 (triangles)", indices.len())));
            }
            let (material, emission, two_sided) = self.material(&primitive.material())?;
            let mut triangles = Vec::with_capacity(indices.len() / 3);
            let mut degenerate = 0;
            for (k, t) in indices.chunks_exact(3).enumerate() {
                let mut v = [positions[t[0] as usize], positions[t[1] as usize], positions[t[2] as usize]];
                if mirrors {
                    v.swap(1, 2);
                }
                match shapes::check_polygon(&v, POLYGON_PLANARITY) {
                    Ok(()) => triangles.push(Triangle { vertices: v, material }),
                    // Exported models often carry slivers; they cover nothing.
                    Err(PolygonProblem::ZeroArea { .. }) => degenerate += 1,
                    Err(p) => return Err(self.err(&key, format!("triangle {k} (scene space) is {p}"))),
                }
            }
            if degenerate > 0 {
                self.note(&key, format!("{degenerate} zero-area triangles skipped"));
            }
            let origin = format!("{} {key}", self.placement.origin);
            self.surfaces.push(Surface { origin, triangles, emission, two_sided });
        }
        Ok(())
    }

    /// The accessor's elements as (offset in its buffer) after every bounds check.
    fn element_offsets(&self, key: &str, accessor: &gltf::Accessor, size: usize) -> Result<(usize, Vec<usize>)> {
        let akey = format!("{key} accessors[{}]", accessor.index());
        if accessor.sparse().is_some() {
            return Err(self.err(&akey, "sparse accessors are not supported"));
        }
        let Some(view) = accessor.view() else {
            return Err(self.err(&akey, "has no bufferView (all zeros); give it data"));
        };
        let buffer = view.buffer().index();
        let stride = view.stride().unwrap_or(size);
        let view_end = view.offset().checked_add(view.length());
        let fits = |offset: usize| {
            offset
                .checked_add(size)
                .is_some_and(|end| view_end.is_some_and(|v| end <= v) && end <= self.buffers[buffer].len())
        };
        let start = view.offset().checked_add(accessor.offset());
        let mut offsets = Vec::with_capacity(accessor.count());
        for i in 0..accessor.count() {
            let offset = start.and_then(|s| i.checked_mul(stride).and_then(|d| s.checked_add(d)));
            match offset {
                Some(o) if fits(o) => offsets.push(o),
                _ => return Err(self.err(&akey, format!("element {i} lies outside its bufferView or buffer"))),
            }
        }
        Ok((buffer, offsets))
    }

    fn positions(&self, key: &str, accessor: &gltf::Accessor) -> Result<Vec<DVec3>> {
        if accessor.dimensions() != Dimensions::Vec3 || accessor.data_type() != DataType::F32 || accessor.normalized() {
            return Err(self.err(
                &format!("{key} accessors[{}]", accessor.index()),
                format!(
                    "POSITION must be VEC3 of FLOAT, got {:?} of {:?} (quantized positions are not supported)",
                    accessor.dimensions(),
                    accessor.data_type()
                ),
            ));
        }
        let (buffer, offsets) = self.element_offsets(key, accessor, 12)?;
        let data = &self.buffers[buffer];
        let float = |o: usize| f64::from(f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]));
        Ok(offsets.into_iter().map(|o| DVec3::new(float(o), float(o + 4), float(o + 8))).collect())
    }

    fn indices(&self, key: &str, accessor: &gltf::Accessor, vertices: usize) -> Result<Vec<u32>> {
        let akey = format!("{key} accessors[{}]", accessor.index());
        let size = match (accessor.dimensions(), accessor.data_type()) {
            (Dimensions::Scalar, DataType::U8) => 1,
            (Dimensions::Scalar, DataType::U16) => 2,
            (Dimensions::Scalar, DataType::U32) => 4,
            (d, t) => {
                return Err(self.err(&akey, format!("indices must be SCALAR of unsigned integers, got {d:?} of {t:?}")));
            }
        };
        let (buffer, offsets) = self.element_offsets(key, accessor, size)?;
        let data = &self.buffers[buffer];
        let mut out = Vec::with_capacity(offsets.len());
        for (i, o) in offsets.into_iter().enumerate() {
            let index = match size {
                1 => u32::from(data[o]),
                2 => u32::from(u16::from_le_bytes([data[o], data[o + 1]])),
                _ => u32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]),
            };
            if index as usize >= vertices {
                return Err(self.err(&akey, format!("index {i} is {index}, but the primitive has {vertices} vertices")));
            }
            out.push(index);
        }
        Ok(out)
    }

    /// The primitive's material index in the scene, its emission and whether it is
    /// two-sided. Each glTF material is mapped once, on first use.
    fn material(&mut self, material: &gltf::Material) -> Result<(u32, Rgb, bool)> {
        let slot = material.index().unwrap_or(self.material_slots.len() - 1);
        let two_sided = material.double_sided();
        let mkey = match material.index() {
            Some(i) => named("materials", i, material.name()),
            None => "the default material".into(),
        };
        let (index, emission) = match self.material_slots[slot] {
            Some(done) => done,
            None => {
                let pbr = material.pbr_metallic_roughness();
                let [r, g, b, alpha] = pbr.base_color_factor();
                let (metallic, roughness) = (pbr.metallic_factor(), pbr.roughness_factor());
                for (what, x) in [
                    ("baseColorFactor", r),
                    ("baseColorFactor", g),
                    ("baseColorFactor", b),
                    ("metallicFactor", metallic),
                    ("roughnessFactor", roughness),
                ] {
                    if !(0.0..=1.0).contains(&x) {
                        return Err(self.err(&mkey, format!("{what} must be in [0, 1], got {x}")));
                    }
                }
                let strength = material.emissive_strength().unwrap_or(1.0);
                let emission = material.emissive_factor().map(|e| e * strength);
                if emission.iter().any(|&e| !e.is_finite() || e < 0.0) {
                    return Err(self.err(
                        &mkey,
                        format!("emissiveFactor x emissiveStrength must be finite and >= 0, got {emission:?}"),
                    ));
                }
                let textures = [
                    ("baseColorTexture", pbr.base_color_texture().is_some()),
                    ("metallicRoughnessTexture", pbr.metallic_roughness_texture().is_some()),
                    ("normalTexture", material.normal_texture().is_some()),
                    ("occlusionTexture", material.occlusion_texture().is_some()),
                    ("emissiveTexture", material.emissive_texture().is_some()),
                ];
                for (name, present) in textures {
                    if present {
                        self.note(&mkey, format!("{name} is ignored (its constant factor is used)"));
                    }
                }
                if alpha < 1.0 || material.alpha_mode() != gltf::material::AlphaMode::Opaque {
                    self.note(&mkey, "transparency (alpha) is ignored: rendered opaque");
                }
                if let Some(extensions) = material.extensions() {
                    for name in extensions.keys().filter(|k| !SUPPORTED_EXTENSIONS.contains(&k.as_str())) {
                        self.note(&mkey, format!("extension {name} is ignored"));
                    }
                }
                let index = match self.placement.material {
                    Some(m) => m,
                    None => {
                        let kind = metallic_roughness([r, g, b], metallic, roughness);
                        let name = format!("{} {mkey}", self.placement.origin);
                        self.materials.push(Material { name, kind });
                        self.placement.first_material + self.materials.len() as u32 - 1
                    }
                };
                self.material_slots[slot] = Some((index, emission));
                (index, emission)
            }
        };
        Ok((index, emission, two_sided))
    }

    fn camera(&mut self, node_key: &str, camera: &gltf::Camera, world: DMat4) -> Result<()> {
        let key = format!("{node_key} {}", named("cameras", camera.index(), camera.name()));
        let gltf::camera::Projection::Perspective(p) = camera.projection() else {
            self.note(&key, "orthographic cameras are ignored (only perspective ones are read)");
            return Ok(());
        };
        let fov_y = f64::from(p.yfov()).to_degrees();
        if !(fov_y > 0.0 && fov_y < 180.0) {
            return Err(self.err(&key, format!("yfov must be > 0 and < pi, got {}", p.yfov())));
        }
        let aspect = f64::from(p.aspect_ratio().unwrap_or(1.0));
        if !(aspect.is_finite() && aspect > 0.0) {
            return Err(self.err(&key, format!("aspectRatio must be > 0, got {aspect}")));
        }
        let pixels = f64::from(CAMERA_PIXELS);
        let (width, height) = if aspect >= 1.0 { (pixels, pixels / aspect) } else { (pixels * aspect, pixels) };
        let position = world.transform_point3(DVec3::ZERO);
        // A glTF camera looks down its local -z with +y up.
        let (Some(forward), Some(up)) =
            (world.transform_vector3(DVec3::NEG_Z).try_normalize(), world.transform_vector3(DVec3::Y).try_normalize())
        else {
            return Err(self.err(&key, "its node's transform collapses the view direction (zero scale)"));
        };
        let name = camera.name().map(str::to_string).unwrap_or_else(|| format!("camera{}", camera.index()));
        let name =
            if self.cameras.iter().any(|c| c.name == name) { format!("{name}#{}", self.cameras.len()) } else { name };
        self.cameras.push(NamedCamera {
            name,
            camera: Camera {
                position,
                look_at: position + forward,
                up,
                fov_y,
                width: width.round().max(1.0) as u32,
                height: height.round().max(1.0) as u32,
            },
        });
        Ok(())
    }

    fn light(&mut self, node_key: &str, light: &gltf::khr_lights_punctual::Light, world: DMat4) {
        let key = format!("{node_key} {}", named("KHR_lights_punctual.lights", light.index(), light.name()));
        match light.kind() {
            LightKind::Point => {
                // Intensity in candela, read as W/sr: an isotropic source of that intensity
                // emits 4 pi times it.
                let intensity = f64::from(light.intensity());
                let power = light.color().map(|c| (4.0 * PI * intensity * f64::from(c)) as f32);
                if power.iter().any(|p| !p.is_finite() || *p < 0.0) {
                    self.note(&key, format!("ignored: its power {power:?} is not finite and >= 0"));
                    return;
                }
                if light.range().is_some() {
                    self.note(&key, "its range is ignored (the light falls off with the inverse square everywhere)");
                }
                self.lights.push(Light::Point { position: world.transform_point3(DVec3::ZERO), power });
            }
            LightKind::Directional => {
                // Intensity in lux, read as W/m^2: the irradiance on a surface facing the
                // light. It shines along the node's local -z.
                let intensity = f64::from(light.intensity());
                let irradiance = light.color().map(|c| (intensity * f64::from(c)) as f32);
                if irradiance.iter().any(|p| !p.is_finite() || *p < 0.0) {
                    self.note(&key, format!("ignored: its irradiance {irradiance:?} is not finite and >= 0"));
                    return;
                }
                let Some(direction) = world.transform_vector3(DVec3::NEG_Z).try_normalize() else {
                    self.note(&key, "ignored: its node's transform collapses the light's direction");
                    return;
                };
                self.lights.push(Light::Directional { direction, irradiance });
            }
            LightKind::Spot { inner_cone_angle, outer_cone_angle } => {
                // Intensity in candela, read as W/sr, on the axis (the node's local -z); the
                // cone angles are radians in glTF, degrees in the scene.
                let intensity = f64::from(light.intensity());
                let intensity = light.color().map(|c| (intensity * f64::from(c)) as f32);
                let (inner, outer) =
                    (f64::from(inner_cone_angle).to_degrees(), f64::from(outer_cone_angle).to_degrees());
                if intensity.iter().any(|p| !p.is_finite() || *p < 0.0) {
                    self.note(&key, format!("ignored: its intensity {intensity:?} is not finite and >= 0"));
                    return;
                }
                if !(0.0 <= inner && inner < outer && outer <= 90.0) {
                    self.note(
                        &key,
                        format!("ignored: its cone angles ({inner:.3} and {outer:.3} degrees) are not 0 <= inner < outer <= 90"),
                    );
                    return;
                }
                let Some(direction) = world.transform_vector3(DVec3::NEG_Z).try_normalize() else {
                    self.note(&key, "ignored: its node's transform collapses the light's direction");
                    return;
                };
                if light.range().is_some() {
                    self.note(&key, "its range is ignored (the light falls off with the inverse square everywhere)");
                }
                let position = world.transform_point3(DVec3::ZERO);
                self.lights.push(Light::Spot {
                    position,
                    direction,
                    intensity,
                    inner_angle: inner,
                    outer_angle: outer,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decoded("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decoded("100%"), "100%");
        assert_eq!(percent_decoded("x%2"), "x%2");
        assert_eq!(percent_decoded("%zz"), "%zz");
    }
}
