//! TOML (+ OBJ) -> `Scene`, with every check of docs/SCENE_FORMAT.md.
//!
//! The TOML is walked by hand rather than through serde: every accessor carries the key
//! path that led to it (`shapes[3].vertices[1]`), so each refusal names its key and says
//! what was expected, and unknown keys are refused with the list of allowed ones.

use super::brdf::max_directional_albedo;
use super::shapes::{self, LIGHT_PLANARITY, MAX_SIERPINSKI_LEVEL, POLYGON_PLANARITY, Transform};
use super::{Camera, Light, Material, MaterialKind, NamedCamera, Rgb, Scene, Settings, Surface, Triangle};
use crate::{Error, Result};
use glam::DVec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The largest image or item-buffer edge, in pixels.
pub const MAX_RESOLUTION: i64 = 16384;
/// The largest `subdivisions` of an area light (2 n^2 patches, (n+1)^2 light samples).
pub const MAX_SUBDIVISIONS: i64 = 64;

const TOP_KEYS: &[&str] = &["format", "camera", "cameras", "environment", "settings", "materials", "shapes", "lights"];
const CAMERA_KEYS: &[&str] = &["position", "look_at", "up", "fov_y", "width", "height"];
const NAMED_CAMERA_KEYS: &[&str] = &["name", "position", "look_at", "up", "fov_y", "width", "height"];
const ENVIRONMENT_KEYS: &[&str] = &["radiance"];
const SETTINGS_KEYS: &[&str] =
    &["patch_size", "hemicube_resolution", "bundle_resolution", "bundles_per_step", "iterations", "seed"];
const TRANSFORM_KEYS: &[&str] = &["scale", "rotate", "translate"];
const SHAPE_TYPES: &str = "\"quad\", \"triangle\", \"mesh\", \"gltf\", \"box\" or \"sierpinski\"";

/// Loads and validates a scene file: TOML, or glTF 2.0 by its extension (`.gltf`, `.glb`).
/// Errors name the file, the key and what was expected.
pub fn load(path: &Path) -> Result<Scene> {
    let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if matches!(extension.as_deref(), Some("gltf" | "glb")) {
        return super::gltf::load_scene(path);
    }
    let bytes = crate::files::read_named_input(path)?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..at].iter().filter(|&&b| b == b'\n').count();
        Error::scene(path, format!("line {line}"), "not UTF-8 text")
    })?;
    load_str(&text, path)
}

/// Loads a scene from its text. `source` names the file in errors and in `Scene::source`,
/// and mesh paths are relative to its folder.
pub fn load_str(text: &str, source: &Path) -> Result<Scene> {
    let root = parse_toml(text, source)?;
    let cx = Context { file: source };
    let root = Tbl { cx: &cx, key: String::new(), table: &root };

    // `format` first: a scene of another format should hear that, not about unknown keys.
    let format = root.req("format", "format = 1")?.integer(i64::MIN, i64::MAX)?;
    if format != 1 {
        return Err(cx.err("format", format!("unsupported format {format}: this build reads format 1")));
    }
    root.only(TOP_KEYS)?;

    let cameras = cameras(&root)?;
    let camera = cameras[0].camera;
    let environment = match root.get("environment") {
        Some(e) => {
            let e = e.table()?;
            e.only(ENVIRONMENT_KEYS)?;
            e.get("radiance").map_or(Ok([0.0; 3]), |r| r.rgb())?
        }
        None => [0.0; 3],
    };
    let settings = match root.get("settings") {
        Some(s) => settings(&s.table()?)?,
        None => Settings::default(),
    };
    let mut materials = match root.get("materials") {
        Some(m) => materials(&m.table()?)?,
        None => Vec::new(),
    };
    // Materials that meshes bring along (MTL libraries, glTF files), appended after the
    // [materials] ones, and what those files hold that is not rendered.
    let mut imported = Imported::default();
    let surfaces = match root.get("shapes") {
        Some(s) => {
            let names: HashMap<&str, u32> = materials.iter().zip(0..).map(|(m, i)| (m.name.as_str(), i)).collect();
            let known = Materials { by_name: &names, list: &materials };
            let mut surfaces = Vec::new();
            for t in s.tables("[[shapes]] tables")? {
                surfaces.extend(shape(&t, &known, &mut imported)?);
            }
            surfaces
        }
        None => Vec::new(),
    };
    materials.extend(imported.materials);
    let mut notes = imported.notes;
    notes.extend(materials.iter().filter_map(|m| sharp_lobe_note(source, m)));
    let lights = match root.get("lights") {
        Some(l) => l.tables("[[lights]] tables")?.iter().map(light).collect::<Result<Vec<_>>>()?,
        None => Vec::new(),
    };

    if surfaces.iter().all(|s| s.triangles.is_empty()) {
        return Err(cx.err("shapes", "the scene has no surfaces: add at least one [[shapes]] entry"));
    }
    let glows = |c: &Rgb| c.iter().any(|&x| x > 0.0);
    let emits = lights.iter().any(|l| match l {
        Light::Point { power, .. } => glows(power),
        Light::Area { radiance, .. } => glows(radiance),
        Light::Directional { irradiance, .. } => glows(irradiance),
        Light::Spot { intensity, .. } => glows(intensity),
    }) || surfaces.iter().any(|s| glows(&s.emission))
        || glows(&environment);
    if !emits {
        return Err(cx.err(
            "lights",
            "the scene has no emitter: add a [[lights]] entry with non-zero power or \
             radiance, an `emission` on a shape, or a non-black [environment] radiance",
        ));
    }

    let mut scene = Scene {
        source: source.to_path_buf(),
        camera,
        cameras,
        environment,
        settings,
        materials,
        surfaces,
        lights,
        notes,
        file_origin: DVec3::ZERO,
    };
    scene.recentre();
    scene.check_extent()?;
    Ok(scene)
}

/// Parses the TOML text, keeping the toml crate's line and column in the key.
pub(super) fn parse_toml(text: &str, source: &Path) -> Result<Table> {
    text.parse::<Table>().map_err(|e| {
        let shown = e.to_string();
        let message = e.message().trim();
        // The toml crate's text is "TOML parse error at line L, column C", a snippet with a
        // caret, then the message; the snippet is kept, the message moved to the front.
        match shown.split_once('\n') {
            Some((head, rest)) if head.starts_with("TOML parse error at ") => {
                let snippet = rest.trim_end();
                let snippet = snippet.strip_suffix(message).unwrap_or(snippet).trim_end();
                Error::scene(
                    source,
                    head.trim_start_matches("TOML parse error at "),
                    format!("TOML syntax error: {message}\n{snippet}"),
                )
            }
            _ => Error::scene(source, "syntax", shown.trim_end()),
        }
    })
}

/// `[camera]` (required, named "camera") and the `[[cameras]]` entries, in that order.
fn cameras(root: &Tbl) -> Result<Vec<NamedCamera>> {
    let main = root.req("camera", "a [camera] table")?.table()?;
    main.only(CAMERA_KEYS)?;
    let mut list = vec![NamedCamera { name: "camera".into(), camera: camera(&main)? }];
    if let Some(cs) = root.get("cameras") {
        for t in cs.tables("[[cameras]] tables, each with a name")? {
            t.only(NAMED_CAMERA_KEYS)?;
            let name_item = t.req("name", "a name, e.g. name = \"door\"")?;
            let name = name_item.string()?.to_string();
            if name.is_empty() {
                return Err(name_item.err("must not be empty"));
            }
            if list.iter().any(|c: &NamedCamera| c.name == name) {
                return Err(name_item.err(format!(
                    "camera \"{name}\" is named twice (the [camera] table is named \"camera\"): give each a name of its own"
                )));
            }
            list.push(NamedCamera { name, camera: camera(&t)? });
        }
    }
    Ok(list)
}

/// The keys of one camera table (the caller has checked which keys it may have).
fn camera(t: &Tbl) -> Result<Camera> {
    let position = t.req("position", "3 numbers")?.vec3()?;
    let look_at = t.req("look_at", "3 numbers")?.vec3()?;
    let up_item = t.req("up", "3 numbers")?;
    let up = up_item.vec3()?;
    let fov_item = t.req("fov_y", "a number in (0, 180)")?;
    let fov_y = fov_item.number()?;
    let width = t.req("width", "an integer")?.integer(1, MAX_RESOLUTION)? as u32;
    let height = t.req("height", "an integer")?.integer(1, MAX_RESOLUTION)? as u32;

    if !(fov_y > 0.0 && fov_y < 180.0) {
        return Err(fov_item.err(format!("must be > 0 and < 180 (degrees), got {fov_y}")));
    }
    let Some(forward) = (look_at - position).try_normalize() else {
        return Err(t
            .cx
            .err(t.child("look_at"), format!("must differ from camera.position, both are {}", show(position))));
    };
    let Some(up_dir) = up.try_normalize() else {
        return Err(up_item.err("must not be zero"));
    };
    // Below this sine the image's right = forward x up has no reliable direction.
    if forward.cross(up_dir).length() < 1e-6 {
        return Err(up_item.err(format!(
            "must not be parallel to the view direction (look_at - position = {})",
            show(look_at - position)
        )));
    }
    Ok(Camera { position, look_at, up, fov_y, width, height })
}

fn settings(t: &Tbl) -> Result<Settings> {
    t.only(SETTINGS_KEYS)?;
    let mut s = Settings::default();
    if let Some(p) = t.get("patch_size") {
        s.patch_size = p.positive()?;
    }
    if let Some(r) = t.get("hemicube_resolution") {
        s.hemicube_resolution = r.resolution_or_auto()?;
    }
    if let Some(r) = t.get("bundle_resolution") {
        s.bundle_resolution = r.resolution_or_auto()?;
    }
    if let Some(b) = t.get("bundles_per_step") {
        s.bundles_per_step = match b.value.as_str() {
            Some("auto") => None,
            Some(_) => return Err(b.expected("1, 4 or \"auto\"")),
            None => {
                let n = b.integer(1, 4)? as u32;
                if !crate::iteration::BUNDLES_PER_STEP_CHOICES.contains(&n) {
                    return Err(b.expected("1, 4 or \"auto\""));
                }
                Some(n)
            }
        };
    }
    if let Some(i) = t.get("iterations") {
        // 0 is meaningful: first shot only.
        s.iterations = i.integer(0, u32::MAX.into())? as u32;
    }
    if let Some(seed) = t.get("seed") {
        s.seed = seed.integer(0, i64::MAX)? as u64;
    }
    Ok(s)
}

fn materials(t: &Tbl) -> Result<Vec<Material>> {
    let mut out = Vec::with_capacity(t.table.len());
    for name in t.table.keys() {
        let m = t.req(name, "a table")?.table()?;
        let kind_item = m.req("type", "\"diffuse\" or \"phong\"")?;
        let kind = match kind_item.string()? {
            "diffuse" => {
                m.only(&["type", "albedo"])?;
                let albedo_item = m.req("albedo", "3 numbers in [0, 1]")?;
                let albedo = albedo_item.rgb()?;
                if albedo.iter().any(|&a| a > 1.0) {
                    return Err(albedo_item.err(format!(
                        "must be <= 1 in every channel (a diffuse albedo above 1 creates energy), got {}",
                        show_rgb(albedo)
                    )));
                }
                MaterialKind::Diffuse { albedo }
            }
            "phong" => {
                m.only(&["type", "diffuse", "specular", "shininess"])?;
                let diffuse = m.req("diffuse", "3 numbers >= 0")?.rgb()?;
                let specular = m.req("specular", "3 numbers >= 0")?.rgb()?;
                let shininess_item = m.req("shininess", "a number >= 0")?;
                let shininess = shininess_item.number()?;
                if shininess < 0.0 {
                    return Err(shininess_item.err(format!("must be >= 0, got {shininess}")));
                }
                MaterialKind::Phong { diffuse, specular, shininess: shininess as f32 }
            }
            other => {
                return Err(
                    kind_item.err(format!("unknown material type \"{other}\": expected \"diffuse\" or \"phong\""))
                );
            }
        };
        let albedo = max_directional_albedo(&kind);
        if albedo.iter().any(|&a| a.is_nan() || a > 1.0) {
            let largest = albedo.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            return Err(t.cx.err(
                &m.key,
                format!(
                    "gains energy: its largest directional albedo is {largest} (per channel {}), \
                     it must be <= 1 in every channel at every incident angle",
                    show_rgb(albedo)
                ),
            ));
        }
        out.push(Material { name: name.clone(), kind });
    }
    Ok(out)
}

/// Shininess above which a max-Phong lobe is sharper than the iteration samples well: each
/// step estimates the lobe's reflection from uniformly drawn directions, whose relative
/// variance grows about as the shininess ((n + 2)^2 / (2 n + 1): about 100 at 200). Measured,
/// a glossy floor at 200 had 2.4 times the error after 400 steps that it had at 60
/// (cornell_point's sharpest), so about 5.7 times the steps for the same error
/// (docs/ALGORITHM.md 6, "Sharp lobes").
pub const SHARP_LOBE_SHININESS: f32 = 200.0;

/// A lobe that reflects less than this share at normal incidence (every channel) is too dim
/// to show its noise, however sharp.
const SHARP_LOBE_ALBEDO: f64 = 0.05;

/// A note for a max-Phong material whose lobe is sharper than `SHARP_LOBE_SHININESS` and
/// reflects a visible share of the light: it renders right, but its speckles fade slowly.
fn sharp_lobe_note(source: &Path, m: &Material) -> Option<String> {
    let MaterialKind::Phong { diffuse, shininess, .. } = m.kind else { return None };
    if shininess <= SHARP_LOBE_SHININESS {
        return None;
    }
    // Only for a sharp lobe: the albedo is a quadrature, and every max-Phong material loads.
    let at_normal = super::brdf::directional_albedo(&m.kind, 1.0);
    let lobe = (0..3).map(|c| at_normal[c] - f64::from(diffuse[c])).fold(0.0, f64::max);
    if lobe < SHARP_LOBE_ALBEDO {
        return None;
    }
    // Half the lobe's peak at psi = acos(2^(-1 / n)) from the mirror direction.
    let half_width = 0.5f64.powf(1.0 / f64::from(shininess)).acos().to_degrees();
    Some(format!(
        "{}: material \"{}\": shininess {shininess} (a glossy lobe that reflects {lobe:.2} of the light \
         at normal incidence and falls to half within {half_width:.1} degrees of the mirror direction) is \
         sharper than the iteration's uniformly drawn directions sample well (above {SHARP_LOBE_SHININESS}): \
         it renders right on average, but its bright and dark speckles fade slowly, the error after a \
         given number of steps growing about as the square root of the shininess \
         (docs/ALGORITHM.md 6, \"Sharp lobes\")",
        source.display(),
        m.name
    ))
}

/// What shapes bring in from their files: materials (indexed after `Materials::list`) and
/// notes about what is not rendered.
#[derive(Default)]
pub(super) struct Imported {
    pub(super) materials: Vec<Material>,
    pub(super) notes: Vec<String>,
}

/// The materials a shape may name.
pub(super) struct Materials<'a> {
    by_name: &'a HashMap<&'a str, u32>,
    list: &'a [Material],
}

impl Materials<'_> {
    fn find(&self, name: &str) -> Result<u32, String> {
        self.by_name.get(name).copied().ok_or_else(|| {
            if self.list.is_empty() {
                format!("unknown material \"{name}\": the scene defines no [materials]")
            } else {
                let names: Vec<&str> = self.list.iter().map(|m| m.name.as_str()).collect();
                format!("unknown material \"{name}\": [materials] defines {}", names.join(", "))
            }
        })
    }
}

/// One `[[shapes]]` entry: one surface, or for meshes one per emission their materials give.
fn shape(t: &Tbl, materials: &Materials, imported: &mut Imported) -> Result<Vec<Surface>> {
    let type_item = t.req("type", SHAPE_TYPES)?;
    let kind = type_item.string()?;
    let specific: &[&str] = match kind {
        "quad" | "triangle" => &["vertices"],
        "mesh" | "gltf" => &["file", "transform"],
        "box" => &["min", "max", "transform"],
        "sierpinski" => &["center", "size", "level", "transform"],
        other => {
            return Err(type_item.err(format!("unknown shape type \"{other}\": expected {SHAPE_TYPES}")));
        }
    };
    let mut allowed = vec!["type", "material", "emission", "two_sided"];
    allowed.extend_from_slice(specific);
    if t.table.contains_key("transform") && !allowed.contains(&"transform") {
        return Err(t.cx.err(
            t.child("transform"),
            format!("a {kind} takes no transform (only mesh, gltf, box and sierpinski do)"),
        ));
    }
    t.only(&allowed)?;

    let material = match t.get("material") {
        Some(m) => {
            let name = m.string()?;
            Some(materials.find(name).map_err(|msg| m.err(msg))?)
        }
        None if kind == "mesh" || kind == "gltf" => None,
        None => {
            return Err(t.cx.err(t.child("material"), "required: a [materials] name"));
        }
    };
    let emission_key = t.get("emission").map(|e| e.rgb()).transpose()?;
    let emission = emission_key.unwrap_or([0.0; 3]);
    let two_sided = t.get("two_sided").map_or(Ok(false), |b| b.boolean())?;
    let transform = match t.get("transform") {
        Some(tr) => transform(&tr.table()?)?,
        None => Transform::IDENTITY,
    };
    // Every kind but mesh has its `material` (required above): `unwrap_or(0)` below never
    // falls back.
    let with = |m: u32| move |vertices: [DVec3; 3]| Triangle { vertices, material: m };

    let (origin, triangles): (String, Vec<Triangle>) = match kind {
        "quad" | "triangle" => {
            let n = if kind == "quad" { 4 } else { 3 };
            let vertices_item = t.req("vertices", &format!("{n} points"))?;
            let vertices = vertices_item.points(n)?;
            shapes::check_polygon(&vertices, POLYGON_PLANARITY)
                .map_err(|p| vertices_item.err(format!("this {kind} is {p}")))?;
            let m = material.unwrap_or(0);
            let triangles = shapes::fan(&vertices).map(with(m)).collect();
            (format!("{} ({kind})", t.key), triangles)
        }
        "box" => {
            let min = t.req("min", "3 numbers")?.vec3()?;
            let max_item = t.req("max", "3 numbers")?;
            let max = max_item.vec3()?;
            if !(max.cmpgt(min).all()) {
                return Err(max_item.err(format!(
                    "must be greater than min on every axis (a flat box has zero-area faces), \
                     got min {} and max {}",
                    show(min),
                    show(max)
                )));
            }
            let m = material.unwrap_or(0);
            let triangles = shapes::box_triangles(min, max)
                .into_iter()
                .map(|tri| transform.apply_triangle(tri))
                .map(with(m))
                .collect();
            (format!("{} (box)", t.key), triangles)
        }
        "sierpinski" => {
            let center = t.req("center", "3 numbers")?.vec3()?;
            let size = t.req("size", "a number > 0")?.positive()?;
            let level = t.req("level", "an integer from 0 to 8")?.integer(0, MAX_SIERPINSKI_LEVEL.into())? as u32;
            let m = material.unwrap_or(0);
            let triangles = shapes::sierpinski(center, size, level)
                .into_iter()
                .map(|tri| transform.apply_triangle(tri))
                .map(with(m))
                .collect();
            (format!("{} (sierpinski level {level})", t.key), triangles)
        }
        "gltf" => {
            let file_item = t.req("file", "the path of a glTF file (.gltf or .glb)")?;
            let written = file_item.string()?;
            let path = t.cx.file.parent().map_or_else(|| PathBuf::from(written), |dir| dir.join(written));
            if !path.is_file() {
                return Err(file_item.err(format!("glTF file {} does not exist or is not a file", path.display())));
            }
            let placement = super::gltf::Placement {
                transform: glam::DMat4::from_scale_rotation_translation(
                    transform.scale,
                    transform.rotation,
                    transform.translation,
                ),
                material,
                first_material: (materials.list.len() + imported.materials.len()) as u32,
                origin: format!("{} (gltf \"{written}\")", t.key),
            };
            let model = super::gltf::read(&path, &placement)?;
            imported.materials.extend(model.materials);
            imported.notes.extend(model.notes);
            if !model.lights.is_empty() || !model.cameras.is_empty() {
                imported.notes.push(format!(
                    "{}: the {} lights and {} cameras of a glTF placed as a shape are ignored: give the TOML scene its own",
                    t.key,
                    model.lights.len(),
                    model.cameras.len()
                ));
            }
            let mut surfaces = model.surfaces;
            for s in &mut surfaces {
                s.emission = emission_key.unwrap_or(s.emission);
                s.two_sided |= two_sided;
            }
            return Ok(surfaces);
        }
        _ => {
            let file_item = t.req("file", "the path of an OBJ file")?;
            let written = file_item.string()?;
            let origin = format!("{} (mesh \"{written}\")", t.key);
            let faces = mesh(t, &file_item, written, material, &transform, materials, imported)?;
            // Faces that emit (MTL Ke) become surfaces of their own, one per emission; a
            // shape's `emission` key sets every face's.
            let mut surfaces: Vec<Surface> = Vec::new();
            for (triangle, ke) in faces {
                let emission = emission_key.unwrap_or(ke);
                match surfaces.iter_mut().find(|s| s.emission == emission) {
                    Some(s) => s.triangles.push(triangle),
                    None => {
                        let origin = if emission == [0.0; 3] {
                            origin.clone()
                        } else {
                            format!("{origin} emitting {}", show_rgb(emission))
                        };
                        surfaces.push(Surface { origin, triangles: vec![triangle], emission, two_sided });
                    }
                }
            }
            return Ok(surfaces);
        }
    };

    // Quads and triangles were checked as written; the rest after their transform, which a
    // tiny or huge scale can make degenerate or overflow.
    if matches!(kind, "box" | "sierpinski") {
        for tri in &triangles {
            shapes::check_polygon(&tri.vertices, POLYGON_PLANARITY)
                .map_err(|p| t.cx.err(&t.key, format!("after its transform, a triangle of this {kind} is {p}")))?;
        }
    }

    Ok(vec![Surface { origin, triangles, emission, two_sided }])
}

/// Reads, parses and triangulates an OBJ mesh: its triangles, each with the emission (MTL
/// `Ke`) of its material. Errors inside the file name the mesh file and
/// `<path as written> line N`; inside an MTL library, the library and its line.
fn mesh(
    t: &Tbl,
    file_item: &Item,
    written: &str,
    material: Option<u32>,
    transform: &Transform,
    materials: &Materials,
    imported: &mut Imported,
) -> Result<Vec<(Triangle, Rgb)>> {
    let path = t.cx.file.parent().map_or_else(|| PathBuf::from(written), |dir| dir.join(written));
    let bytes = crate::files::read_input(&path).map_err(|e| match e {
        crate::files::ReadError::Io(e) if e.kind() == std::io::ErrorKind::NotFound => {
            file_item.err(format!("mesh file {} does not exist", path.display()))
        }
        crate::files::ReadError::NotAFile(what) => {
            file_item.err(format!("mesh file {} is {what}; give the path of an OBJ file", path.display()))
        }
        crate::files::ReadError::Io(e) => file_item.err(format!("mesh file {} cannot be read: {e}", path.display())),
    })?;
    // Lossy: stray bytes in comments or names must not hide the line of a real problem.
    let text = String::from_utf8_lossy(&bytes);
    let at_line = |line: usize, message: String| {
        Error::scene(&path, format!("{written} line {line}"), format!("{message} (mesh of {})", t.key))
    };
    let library = mtl_libraries(t, &path, written, &text, &at_line)?;
    // `usemtl NAME`: a [materials] entry of the scene if there is one by that name (so a
    // scene can restyle a model), else the libraries' material, imported on first use.
    let mut emission_of: HashMap<u32, Rgb> = HashMap::new();
    let base = materials.list.len();
    let obj = shapes::parse_obj(&text, |name| {
        if let Ok(index) = materials.find(name) {
            return Ok(index);
        }
        let Some(m) = library.iter().find(|m| m.name == name) else {
            return Err(match library.is_empty() {
                true => materials.find(name).unwrap_err(),
                false => {
                    format!("unknown material \"{name}\": neither [materials] nor the file's MTL libraries define it")
                }
            });
        };
        let full_name = format!("{written}: {name}");
        if let Some(i) = imported.materials.iter().position(|x| x.name == full_name) {
            return Ok((base + i) as u32);
        }
        let index = (base + imported.materials.len()) as u32;
        imported.materials.push(Material { name: full_name, kind: m.kind });
        imported.notes.extend(m.notes.iter().map(|n| format!("{} (mesh \"{written}\"): {n}", t.key)));
        emission_of.insert(index, m.emission);
        Ok(index)
    })
    .map_err(|e| at_line(e.line, e.message))?;
    if obj.faces.is_empty() {
        return Err(file_item.err(format!("mesh file {} has no faces", path.display())));
    }

    let positions: Vec<DVec3> = obj.positions.iter().map(|&p| transform.apply(p)).collect();
    let mut triangles = Vec::with_capacity(obj.indices.len());
    let mut polygon = Vec::new();
    for face in &obj.faces {
        let Some(m) = face.material.or(material) else {
            return Err(at_line(
                face.line,
                format!("this face has no `usemtl` above it and {} sets no `material`", t.key),
            ));
        };
        polygon.clear();
        polygon.extend(obj.face_indices(face).iter().map(|&i| positions[i]));
        shapes::check_polygon(&polygon, POLYGON_PLANARITY)
            .map_err(|p| at_line(face.line, format!("this face is {p}")))?;
        let emission = emission_of.get(&m).copied().unwrap_or([0.0; 3]);
        triangles.extend(shapes::fan(&polygon).map(|vertices| (Triangle { vertices, material: m }, emission)));
    }
    Ok(triangles)
}

/// Reads the MTL libraries an OBJ file names (`mtllib`), relative to its folder.
fn mtl_libraries(
    t: &Tbl,
    obj_path: &Path,
    written: &str,
    text: &str,
    at_line: &dyn Fn(usize, String) -> Error,
) -> Result<Vec<super::mtl::MtlMaterial>> {
    let mut out: Vec<super::mtl::MtlMaterial> = Vec::new();
    for (line, name) in shapes::obj_material_libraries(text) {
        let path = obj_path.parent().map_or_else(|| PathBuf::from(&name), |dir| dir.join(&name));
        let bytes = crate::files::read_input(&path).map_err(|e| {
            let why = match e {
                crate::files::ReadError::Io(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    "does not exist".to_string()
                }
                crate::files::ReadError::NotAFile(what) => format!("is {what}"),
                crate::files::ReadError::Io(e) => format!("cannot be read: {e}"),
            };
            at_line(
                line,
                format!(
                    "material library {} {why}: give the MTL file beside the OBJ, or remove the `mtllib` line",
                    path.display()
                ),
            )
        })?;
        let mtl = super::mtl::parse_mtl(&String::from_utf8_lossy(&bytes)).map_err(|e| {
            Error::scene(
                &path,
                format!("{name} line {}", e.line),
                format!("{} (material library of {}, {written})", e.message, t.key),
            )
        })?;
        for m in mtl {
            // The first library that defines a name wins, as in other OBJ readers.
            if !out.iter().any(|o| o.name == m.name) {
                out.push(m);
            }
        }
    }
    Ok(out)
}

fn transform(t: &Tbl) -> Result<Transform> {
    t.only(TRANSFORM_KEYS)?;
    let mut out = Transform::IDENTITY;
    if let Some(s) = t.get("scale") {
        out.scale = match s.value {
            Value::Array(_) => {
                let [x, y, z] = s.fixed::<3>("3 numbers > 0 [x, y, z], or one number")?;
                DVec3::new(x.positive()?, y.positive()?, z.positive()?)
            }
            _ => DVec3::splat(s.positive()?),
        };
    }
    if let Some(r) = t.get("rotate") {
        let [x, y, z, degrees] = r.fixed::<4>("4 numbers [axis_x, axis_y, axis_z, degrees]")?;
        let axis = DVec3::new(x.number()?, y.number()?, z.number()?);
        out.rotation = Transform::rotation(axis, degrees.number()?)
            .ok_or_else(|| r.err("the rotation axis (the first 3 numbers) must not be zero"))?;
    }
    if let Some(tr) = t.get("translate") {
        out.translation = tr.vec3()?;
    }
    Ok(out)
}

const LIGHT_TYPES: &str = "\"point\", \"area\", \"directional\" or \"spot\"";

fn light(t: &Tbl) -> Result<Light> {
    let type_item = t.req("type", LIGHT_TYPES)?;
    match type_item.string()? {
        "point" => {
            t.only(&["type", "position", "power"])?;
            Ok(Light::Point {
                position: t.req("position", "3 numbers")?.vec3()?,
                power: t.req("power", "3 numbers >= 0")?.rgb()?,
            })
        }
        "area" => {
            t.only(&["type", "vertices", "radiance", "subdivisions"])?;
            let vertices_item = t.req("vertices", "4 points")?;
            let points = vertices_item.points(4)?;
            shapes::check_polygon(&points, LIGHT_PLANARITY)
                .map_err(|p| vertices_item.err(format!("this area light is {p}")))?;
            let vertices = [points[0], points[1], points[2], points[3]];
            let radiance = t.req("radiance", "3 numbers >= 0")?.rgb()?;
            let subdivisions = match t.get("subdivisions") {
                Some(s) => s.integer(1, MAX_SUBDIVISIONS)? as u32,
                None => 1,
            };
            Ok(Light::Area { vertices, radiance, subdivisions })
        }
        "directional" => {
            t.only(&["type", "direction", "irradiance"])?;
            Ok(Light::Directional {
                direction: unit_direction(&t.req("direction", "3 numbers, the way the light travels")?)?,
                irradiance: t.req("irradiance", "3 numbers >= 0 (W/m^2 on a surface facing the light)")?.rgb()?,
            })
        }
        "spot" => {
            t.only(&["type", "position", "direction", "intensity", "inner_angle", "outer_angle"])?;
            let position = t.req("position", "3 numbers")?.vec3()?;
            let direction = unit_direction(&t.req("direction", "3 numbers, the spot's axis")?)?;
            let intensity = t.req("intensity", "3 numbers >= 0 (W/sr on the axis)")?.rgb()?;
            // glTF KHR_lights_punctual's defaults and bounds: 0 <= inner < outer <= 90 degrees.
            let angle = |key: &str, default: f64| -> Result<f64> {
                let Some(item) = t.get(key) else { return Ok(default) };
                let degrees = item.number()?;
                if !(0.0..=90.0).contains(&degrees) {
                    return Err(item.err(format!("must be from 0 to 90 (degrees from the axis), got {degrees}")));
                }
                Ok(degrees)
            };
            let inner_angle = angle("inner_angle", 0.0)?;
            let outer_angle = angle("outer_angle", 45.0)?;
            if inner_angle >= outer_angle {
                return Err(t.cx.err(
                    t.child("inner_angle"),
                    format!(
                        "must be less than outer_angle ({outer_angle} degrees{}), got {inner_angle}",
                        if t.get("outer_angle").is_some() { "" } else { ", its default" }
                    ),
                ));
            }
            Ok(Light::Spot { position, direction, intensity, inner_angle, outer_angle })
        }
        other => Err(type_item.err(format!("unknown light type \"{other}\": expected {LIGHT_TYPES}"))),
    }
}

/// A direction: 3 numbers, not all zero, normalised.
fn unit_direction(item: &Item) -> Result<DVec3> {
    let v = item.vec3()?;
    v.try_normalize().ok_or_else(|| item.err("must not be zero: it is a direction"))
}

/// The file being read, for errors.
pub(super) struct Context<'a> {
    pub(super) file: &'a Path,
}

impl Context<'_> {
    pub(super) fn err(&self, key: impl Into<String>, message: impl Into<String>) -> Error {
        Error::scene(self.file, key, message)
    }
}

/// A TOML table and the key path that leads to it ("" for the root).
pub(super) struct Tbl<'a> {
    pub(super) cx: &'a Context<'a>,
    pub(super) key: String,
    pub(super) table: &'a Table,
}

/// A TOML value and the key path that leads to it.
pub(super) struct Item<'a> {
    pub(super) cx: &'a Context<'a>,
    pub(super) key: String,
    pub(super) value: &'a Value,
}

impl<'a> Tbl<'a> {
    pub(super) fn child(&self, name: &str) -> String {
        let name = quote_key(name);
        if self.key.is_empty() { name } else { format!("{}.{name}", self.key) }
    }

    pub(super) fn get(&self, name: &str) -> Option<Item<'a>> {
        self.table.get(name).map(|value| Item { cx: self.cx, key: self.child(name), value })
    }

    pub(super) fn req(&self, name: &str, expected: &str) -> Result<Item<'a>> {
        self.get(name).ok_or_else(|| self.cx.err(self.child(name), format!("required: {expected}")))
    }

    /// Refuses any key not in `allowed`, naming the allowed ones.
    pub(super) fn only(&self, allowed: &[&str]) -> Result<()> {
        match self.table.keys().find(|k| !allowed.contains(&k.as_str())) {
            Some(unknown) => {
                Err(self.cx.err(self.child(unknown), format!("unknown key; allowed here: {}", allowed.join(", "))))
            }
            None => Ok(()),
        }
    }
}

impl<'a> Item<'a> {
    pub(super) fn err(&self, message: impl Into<String>) -> Error {
        self.cx.err(&self.key, message)
    }

    pub(super) fn expected(&self, what: &str) -> Error {
        self.err(format!("expected {what}, got {}", describe(self.value)))
    }

    pub(super) fn index(&self, i: usize, value: &'a Value) -> Item<'a> {
        Item { cx: self.cx, key: format!("{}[{i}]", self.key), value }
    }

    pub(super) fn table(&self) -> Result<Tbl<'a>> {
        match self.value {
            Value::Table(table) => Ok(Tbl { cx: self.cx, key: self.key.clone(), table }),
            _ => Err(self.expected("a table")),
        }
    }

    /// An array of tables (`[[shapes]]`), each keyed `key[i]`.
    pub(super) fn tables(&self, what: &str) -> Result<Vec<Tbl<'a>>> {
        let Value::Array(items) = self.value else {
            return Err(self.expected(&format!("an array of {what}")));
        };
        items.iter().enumerate().map(|(i, v)| self.index(i, v).table()).collect()
    }

    /// An array of exactly N values.
    pub(super) fn fixed<const N: usize>(&self, what: &str) -> Result<[Item<'a>; N]> {
        let wrong = || self.expected(what);
        let Value::Array(items) = self.value else {
            return Err(wrong());
        };
        if items.len() != N {
            return Err(self.err(format!("expected {what}, got {} values", items.len())));
        }
        let items: Vec<Item<'a>> = items.iter().enumerate().map(|(i, v)| self.index(i, v)).collect();
        items.try_into().map_err(|_| wrong())
    }

    pub(super) fn string(&self) -> Result<&'a str> {
        self.value.as_str().ok_or_else(|| self.expected("a string"))
    }

    pub(super) fn boolean(&self) -> Result<bool> {
        self.value.as_bool().ok_or_else(|| self.expected("true or false"))
    }

    /// A resolution in pixels, or "auto" (`None`: the automatic choice).
    fn resolution_or_auto(&self) -> Result<Option<u32>> {
        match self.value.as_str() {
            Some("auto") => Ok(None),
            Some(_) => Err(self.expected("an integer or \"auto\"")),
            None => Ok(Some(self.integer(1, MAX_RESOLUTION)? as u32)),
        }
    }

    pub(super) fn integer(&self, min: i64, max: i64) -> Result<i64> {
        let Value::Integer(i) = *self.value else {
            return Err(self.expected("an integer"));
        };
        if i < min || i > max {
            return Err(self.err(format!("must be from {min} to {max}, got {i}")));
        }
        Ok(i)
    }

    /// A finite number within the f32 range (integers are numbers too).
    pub(super) fn number(&self) -> Result<f64> {
        let x = match *self.value {
            Value::Integer(i) => i as f64,
            Value::Float(x) => x,
            _ => return Err(self.expected("a number")),
        };
        if !x.is_finite() {
            return Err(self.err(format!("must be a finite number, got {x}")));
        }
        if x.abs() > shapes::MAX_COORDINATE {
            return Err(self.err(format!(
                "out of range: {x:e} is beyond ±{:e}, the f32 range the GPU works in",
                shapes::MAX_COORDINATE
            )));
        }
        Ok(x)
    }

    pub(super) fn positive(&self) -> Result<f64> {
        let x = self.number()?;
        if x > 0.0 { Ok(x) } else { Err(self.err(format!("must be > 0, got {x}"))) }
    }

    pub(super) fn vec3(&self) -> Result<DVec3> {
        let [x, y, z] = self.fixed::<3>("3 numbers [x, y, z]")?;
        Ok(DVec3::new(x.number()?, y.number()?, z.number()?))
    }

    /// A colour: 3 numbers, each >= 0.
    pub(super) fn rgb(&self) -> Result<Rgb> {
        let [r, g, b] = self.fixed::<3>("3 numbers [r, g, b]")?;
        let rgb = [r.number()?, g.number()?, b.number()?];
        if let Some(c) = rgb.iter().position(|&x| x < 0.0) {
            return Err(self.err(format!(
                "a colour must be >= 0 in every channel, got {} in channel {}",
                rgb[c],
                ["red", "green", "blue"][c]
            )));
        }
        Ok(rgb.map(|x| x as f32))
    }

    /// An array of exactly `n` points, each keyed `key[i]`.
    pub(super) fn points(&self, n: usize) -> Result<Vec<DVec3>> {
        let what = format!("{n} points [[x, y, z], ...]");
        let Value::Array(items) = self.value else {
            return Err(self.expected(&what));
        };
        if items.len() != n {
            return Err(self.err(format!("expected {what}, got {} values", items.len())));
        }
        items.iter().enumerate().map(|(i, v)| self.index(i, v).vec3()).collect()
    }
}

/// A key as TOML would need it written: bare if it can be, quoted otherwise.
fn quote_key(name: &str) -> String {
    let bare = !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare { name.to_string() } else { format!("{name:?}") }
}

/// What a value is, for "expected X, got Y".
fn describe(value: &Value) -> String {
    match value {
        Value::String(s) if s.len() <= 40 => format!("the string {s:?}"),
        Value::String(_) => "a string".into(),
        Value::Integer(i) => format!("the integer {i}"),
        Value::Float(x) => format!("the number {x}"),
        Value::Boolean(b) => format!("{b}"),
        Value::Datetime(d) => format!("the date-time {d}"),
        Value::Array(a) => format!("an array of {} values", a.len()),
        Value::Table(_) => "a table".into(),
    }
}

pub(super) fn show(v: DVec3) -> String {
    format!("[{}, {}, {}]", v.x, v.y, v.z)
}

fn show_rgb(c: Rgb) -> String {
    format!("[{}, {}, {}]", c[0], c[1], c[2])
}
