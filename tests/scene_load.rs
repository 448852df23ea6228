//! `scene::load` against SCENE_FORMAT.md: what loads, what is refused (with which key), and
//! that no input makes it panic.

mod common;

use common::scenes::{MINIMAL, edited};
use common::scratch::{Scratch, write};
use firstshot::Error;
use firstshot::scene::load::load_str;
use firstshot::scene::{Light, MaterialKind, Scene, Settings, brdf, load};
use glam::DVec3;
use proptest::prelude::*;
use std::path::Path;

/// Rounding tolerance for areas and positions of unit-sized f64 geometry.
const EPS: f64 = 1e-9;

fn source() -> &'static Path {
    Path::new("memory/scene.toml")
}

/// Asserts that `text` is refused with `key`, and returns the message.
fn refused(text: &str, key: &str) -> String {
    refused_at(load_str(text, source()), key)
}

fn refused_at(result: firstshot::Result<Scene>, key: &str) -> String {
    match result {
        Err(Error::Scene { key: k, message, .. }) => {
            assert_eq!(k, key, "refused with another key: {message}");
            message
        }
        Err(e) => panic!("refused, but not as a scene error: {e}"),
        Ok(_) => panic!("loaded, but should be refused with key {key}"),
    }
}

fn assert_contains(message: &str, part: &str) {
    assert!(message.contains(part), "{message:?} lacks {part:?}");
}

fn triangle_area(t: &[DVec3; 3]) -> f64 {
    (t[1] - t[0]).cross(t[2] - t[0]).length() / 2.0
}

#[test]
fn test01_cornell_box_loads() {
    let path = common::scenes::shipped("cornell_box");
    let scene = load(&path).unwrap();
    assert_eq!(scene.source, path);
    assert_eq!(scene.materials.len(), 3);
    assert_eq!(scene.surfaces.len(), 15);
    let triangles: usize = scene.surfaces.iter().map(|s| s.triangles.len()).sum();
    assert_eq!(triangles, 30);
    assert_eq!(scene.surfaces[0].origin, "shapes[0] (quad)");
    assert_eq!(scene.camera.width, 512);
    assert_eq!(scene.camera.fov_y, 39.3077);
    assert_eq!(scene.environment, [0.0; 3]);
    assert_eq!(
        scene.settings,
        Settings {
            patch_size: 40.0,
            hemicube_resolution: None,
            bundle_resolution: None,
            iterations: 1000,
            seed: 1,
            bundles_per_step: None,
        }
    );
    let [Light::Area { radiance, subdivisions, .. }] = scene.lights[..] else {
        panic!("expected one area light: {:?}", scene.lights);
    };
    assert_eq!(radiance, [18.387, 13.9873, 6.75357]);
    assert_eq!(subdivisions, 2);
    // The right wall is green.
    let green = scene.materials.iter().position(|m| m.name == "green");
    assert_eq!(Some(scene.surfaces[3].triangles[0].material as usize), green);
    // The floor is 552.8 x 559.2 less a sliver: measured corners, two triangles.
    let floor: f64 = scene.surfaces[0].triangles.iter().map(|t| triangle_area(&t.vertices)).sum();
    assert!((floor - 0.5 * (552.8 * 559.2 + 549.6 * 559.2)).abs() < 1e-6);
}

#[test]
fn test02_defaults() {
    let scene = load_str(MINIMAL, source()).unwrap();
    assert_eq!(scene.settings, Settings::default());
    assert_eq!(scene.environment, [0.0; 3]);
    assert!(!scene.surfaces[0].two_sided);
    assert_eq!(scene.surfaces[0].emission, [0.0; 3]);
    let area = edited(&[(
        "type = \"point\"\nposition = [0, 3, 0]\npower = [10, 10, 10]",
        "type = \"area\"\nvertices = [[0, 3, 0], [1, 3, 0], [1, 3, 1], [0, 3, 1]]\nradiance = [1, 1, 1]",
    )]);
    let scene = load_str(&area, source()).unwrap();
    assert!(matches!(scene.lights[0], Light::Area { subdivisions: 1, .. }));
}

/// The example of SCENE_FORMAT.md, every key of the contract, loads as written.
#[test]
fn test03_the_contract_example_loads() {
    let dir = Scratch::new("scene-load", "contract");
    write(&dir.join("meshes/bunny.obj"), "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
    let text = r#"
format = 1
[camera]
position = [278.0, 273.0, -800.0]
look_at  = [278.0, 273.0, 0.0]
up       = [0.0, 1.0, 0.0]
fov_y    = 39.3077
width    = 512
height   = 512
[environment]
radiance = [0.0, 0.0, 0.0]
[settings]
patch_size = 40.0
hemicube_resolution = 512
bundle_resolution = 512
iterations = 500
seed = 1
[materials.white]
type = "diffuse"
albedo = [0.73, 0.73, 0.73]
[materials.gloss]
type = "phong"
diffuse = [0.18, 0.06, 0.12]
specular = [0.6, 0.6, 0.6]
shininess = 3.0
[[shapes]]
type = "quad"
vertices = [[0,0,0], [0,0,1], [1,0,1], [1,0,0]]
material = "white"
[[shapes]]
type = "triangle"
vertices = [[0,0,0], [0,0,1], [1,0,1]]
material = "white"
two_sided = true
emission = [1.0, 2.0, 3.0]
[[shapes]]
type = "mesh"
file = "meshes/bunny.obj"
material = "white"
transform = { scale = 1.0, rotate = [0.0, 1.0, 0.0, 30.0], translate = [0.0, 0.0, 0.0] }
[[shapes]]
type = "box"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
material = "white"
transform = { rotate = [0.0, 1.0, 0.0, -17.0] }
[[shapes]]
type = "sierpinski"
center = [0.0, 0.0, 0.0]
size = 1.0
level = 4
material = "gloss"
[[lights]]
type = "point"
position = [278.0, 500.0, 279.0]
power = [50.0, 50.0, 50.0]
[[lights]]
type = "area"
vertices = [[343.0, 548.7, 227.0], [343.0, 548.7, 332.0], [213.0, 548.7, 332.0], [213.0, 548.7, 227.0]]
radiance = [17.0, 12.0, 4.0]
subdivisions = 2
"#;
    let path = dir.join("scene.toml");
    write(&path, text);
    let scene = load(&path).unwrap();
    let counts: Vec<usize> = scene.surfaces.iter().map(|s| s.triangles.len()).collect();
    assert_eq!(counts, [2, 1, 2, 12, 4usize.pow(5)]);
    assert!(scene.surfaces[1].two_sided);
    assert_eq!(scene.surfaces[1].emission, [1.0, 2.0, 3.0]);
    assert_eq!(scene.settings.iterations, 500);
    assert_eq!(scene.lights.len(), 2);
    let gloss = &scene.materials[scene.surfaces[4].triangles[0].material as usize];
    assert_eq!(gloss.name, "gloss");
    assert_eq!(
        gloss.kind,
        MaterialKind::Phong { diffuse: [0.18, 0.06, 0.12], specular: [0.6, 0.6, 0.6], shininess: 3.0 }
    );
}

#[test]
fn test04_shape_triangles_areas_and_normals() {
    let shapes = r#"
[[shapes]]
type = "triangle"
vertices = [[0, 0, 0], [2, 0, 0], [0, 0, -3]]
material = "white"
[[shapes]]
type = "box"
min = [-1, 0, 2]
max = [1, 3, 6]
material = "white"
[[shapes]]
type = "sierpinski"
center = [0, 5, 0]
size = 2
level = 2
material = "white"
"#;
    let scene = load_str(&format!("{MINIMAL}{shapes}"), source()).unwrap();
    let area = |s: usize| -> f64 { scene.surfaces[s].triangles.iter().map(|t| triangle_area(&t.vertices)).sum() };
    let normal = |t: &[DVec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]).normalize();
    let counts: Vec<usize> = scene.surfaces.iter().map(|s| s.triangles.len()).collect();
    assert_eq!(counts, [2, 1, 12, 64]);
    assert!((area(0) - 4.0).abs() < EPS);
    assert!(normal(&scene.surfaces[0].triangles[0].vertices).distance(DVec3::Y) < EPS);
    assert!((area(1) - 3.0).abs() < EPS);
    assert!(normal(&scene.surfaces[1].triangles[0].vertices).distance(DVec3::Y) < EPS);
    assert!((area(2) - 2.0 * (2.0 * 3.0 + 3.0 * 4.0 + 4.0 * 2.0)).abs() < EPS);
    let middle = DVec3::new(0.0, 1.5, 4.0);
    for t in &scene.surfaces[2].triangles {
        let v = t.vertices;
        assert!(normal(&v).dot(v[0] + v[1] + v[2] - 3.0 * middle) > 0.0);
    }
    // A regular tetrahedron of edge a has area sqrt(3) a^2; level 2 has 16 of edge a / 4.
    assert!((area(3) - 16.0 * 3.0f64.sqrt() * 0.25).abs() < EPS);
}

#[test]
fn test05_transform_order_scale_rotate_translate() {
    let shapes = r#"
[[shapes]]
type = "box"
min = [0, 0, 0]
max = [1, 1, 1]
material = "white"
transform = { scale = [2, 1, 1], rotate = [0, 0, 1, 90], translate = [10, 0, 0] }
"#;
    let scene = load_str(&format!("{MINIMAL}{shapes}"), source()).unwrap();
    let points: Vec<DVec3> = scene.surfaces[1].triangles.iter().flat_map(|t| t.vertices).collect();
    let lo = points.iter().fold(DVec3::INFINITY, |a, &b| a.min(b));
    let hi = points.iter().fold(DVec3::NEG_INFINITY, |a, &b| a.max(b));
    // x in [0, 2] after scaling, turned onto y in [0, 2]; y in [0, 1] onto x in [-1, 0].
    assert!(lo.distance(DVec3::new(9.0, 0.0, 0.0)) < EPS, "{lo}");
    assert!(hi.distance(DVec3::new(10.0, 2.0, 1.0)) < EPS, "{hi}");
}

#[test]
fn test06_obj_polygons_negative_indices_and_usemtl() {
    let dir = Scratch::new("scene-load", "obj");
    write(
        &dir.join("meshes/thing.obj"),
        "\
# a unit quad, a pentagon of area 1.25 and a triangle
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 1
f 1/1/1 2/1/1 3/1/1 4/1/1
usemtl red
v 0 0 1
v 1 0 1
v 1.5 0.5 1
v 1 1 1
v 0 1 1
f -5//1 -4//1 -3//1 -2//1 -1//1
g other
usemtl white
f 1 2 -1
",
    );
    let text = edited(&[(
        "[[shapes]]",
        "[materials.red]\ntype = \"diffuse\"\nalbedo = [0.5, 0, 0]\n\n[[shapes]]\ntype = \"mesh\"\n\
         file = \"meshes/thing.obj\"\nmaterial = \"white\"\ntransform = { translate = [0, 0, 5] }\n\n[[shapes]]",
    )]);
    let path = dir.join("scene.toml");
    write(&path, &text);
    let scene = load(&path).unwrap();
    let mesh = &scene.surfaces[0];
    assert_eq!(mesh.origin, "shapes[0] (mesh \"meshes/thing.obj\")");
    assert_eq!(mesh.triangles.len(), 2 + 3 + 1);
    let name = |t: usize| scene.materials[mesh.triangles[t].material as usize].name.as_str();
    let names: Vec<&str> = (0..6).map(name).collect();
    assert_eq!(names, ["white", "white", "red", "red", "red", "white"]);
    let area: f64 = mesh.triangles[2..5].iter().map(|t| triangle_area(&t.vertices)).sum();
    assert!((area - 1.25).abs() < EPS);
    assert!(mesh.triangles.iter().flat_map(|t| t.vertices).all(|v| v.z >= 5.0));
}

#[test]
fn test07_mesh_material_is_optional_only_if_every_face_has_usemtl() {
    let dir = Scratch::new("scene-load", "usemtl");
    let mesh = "[[shapes]]\ntype = \"mesh\"\nfile = \"meshes/m.obj\"\n\n[[shapes]]";
    let path = dir.join("scene.toml");
    write(&path, edited(&[("[[shapes]]", mesh)]));
    write(&dir.join("meshes/m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl white\nf 1 2 3\n");
    assert!(load(&path).is_ok());
    write(&dir.join("meshes/m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let message = refused_at(load(&path), "meshes/m.obj line 4");
    assert_contains(&message, "no `usemtl`");
}

#[test]
fn test08_obj_errors_name_the_mesh_file_and_line() {
    let dir = Scratch::new("scene-load", "obj_errors");
    let path = dir.join("scene.toml");
    write(
        &path,
        edited(&[(
            "[[shapes]]",
            "[[shapes]]\ntype = \"mesh\"\nfile = \"meshes/bad.obj\"\nmaterial = \"white\"\n\n[[shapes]]",
        )]),
    );
    let cases = [
        ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", 4, "zero area"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3 4\n", 5, "not convex"),
        ("v 0 0 0\nv 1 0 0\nv 1 1 1\nv 0 1 0\nf 1 2 3 4\n", 5, "not planar"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl gold\nf 1 2 3\n", 4, "unknown material \"gold\""),
        ("v 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n", 3, "finite"),
        ("v 0 0 0\nf 1 2 3\n", 2, "does not exist"),
    ];
    for (obj, line, part) in cases {
        write(&dir.join("meshes/bad.obj"), obj);
        match load(&path) {
            Err(Error::Scene { file, key, message }) => {
                assert_eq!(file, dir.join("meshes/bad.obj"));
                assert_eq!(key, format!("meshes/bad.obj line {line}"), "{message}");
                assert_contains(&message, part);
                assert_contains(&message, "shapes[0]");
            }
            other => panic!("{obj:?}: {other:?}"),
        }
    }
    write(&dir.join("meshes/bad.obj"), "# nothing\nv 0 0 0\n");
    assert_contains(&refused_at(load(&path), "shapes[0].file"), "no faces");
}

#[test]
fn test09_missing_mesh_file() {
    let dir = Scratch::new("scene-load", "missing_mesh");
    let path = dir.join("scene.toml");
    write(
        &path,
        edited(&[(
            "[[shapes]]",
            "[[shapes]]\ntype = \"mesh\"\nfile = \"meshes/nowhere.obj\"\nmaterial = \"white\"\n\n[[shapes]]",
        )]),
    );
    let message = refused_at(load(&path), "shapes[0].file");
    assert_contains(&message, "does not exist");
    assert_contains(&message, "nowhere.obj");
}

#[test]
fn test10_scene_file_problems() {
    let missing = load(Path::new("/nonexistent/firstshot/scene.toml"));
    // The user's to fix (exit status 2), naming the file.
    assert!(matches!(&missing, Err(e @ Error::Input { .. }) if e.is_usage()), "{missing:?}");
    let dir = Scratch::new("scene-load", "bytes");
    let path = dir.join("scene.toml");
    write(&path, b"format = 1\n\xff\xfe\n");
    assert_contains(&refused_at(load(&path), "line 2"), "UTF-8");
    let message = refused("format = 1\n\n[camera\nwidth = 3\n", "line 3, column 8");
    assert_contains(&message, "TOML syntax error");
    assert_contains(&message, "[camera");
    refused("format = 1\nformat = 1\n", "line 2, column 1");
}

#[test]
fn test11_format_and_camera_refusals() {
    refused(&edited(&[("format = 1", "")]), "format");
    assert_contains(&refused(&edited(&[("format = 1", "format = 2")]), "format"), "format 1");
    refused(&edited(&[("format = 1", "format = \"1\"")]), "format");
    refused("format = 1", "camera");
    for (from, to, key, part) in [
        ("width = 64", "width = 0", "camera.width", "from 1 to 16384, got 0"),
        ("width = 64", "width = 16385", "camera.width", "16384"),
        ("height = 48", "height = 48.0", "camera.height", "expected an integer"),
        ("fov_y = 40", "fov_y = 0", "camera.fov_y", "got 0"),
        ("fov_y = 40", "fov_y = 180", "camera.fov_y", "< 180"),
        ("fov_y = 40", "", "camera.fov_y", "required"),
        ("look_at = [0, 1, 0]", "look_at = [0, 1, -5]", "camera.look_at", "camera.position"),
        ("up = [0, 1, 0]", "up = [0, 0, 2]", "camera.up", "parallel"),
        ("up = [0, 1, 0]", "up = [0, 0, 0]", "camera.up", "zero"),
        ("up = [0, 1, 0]", "up = [0, 1]", "camera.up", "expected 3 numbers"),
        ("up = [0, 1, 0]", "up = [0, \"1\", 0]", "camera.up[1]", "expected a number"),
        ("position = [0, 1, -5]", "position = [0, nan, -5]", "camera.position[1]", "finite"),
        ("position = [0, 1, -5]", "position = [0, 1, -inf]", "camera.position[2]", "finite"),
        ("position = [0, 1, -5]", "position = [0, 1e39, -5]", "camera.position[1]", "range"),
    ] {
        let message = refused(&edited(&[(from, to)]), key);
        assert_contains(&message, part);
    }
}

/// MINIMAL with `[[cameras]]` entries appended (each a name and the keys of MINIMAL's camera,
/// moved back along z by its index).
fn with_cameras(names: &[&str]) -> String {
    let mut text = MINIMAL.to_string();
    for (i, name) in names.iter().enumerate() {
        text += &format!(
            "\n[[cameras]]\nname = \"{name}\"\nposition = [0, 1, {}]\nlook_at = [0, 1, 0]\nup = [0, 1, 0]\nfov_y = 30\nwidth = 32\nheight = 16\n",
            -6 - i as i64
        );
    }
    text
}

#[test]
fn test11b_more_cameras_load_in_order_and_are_picked_by_name() {
    let mut scene = load_str(&with_cameras(&["door", "top"]), source()).unwrap();
    let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["camera", "door", "top"]);
    assert_eq!(scene.camera, scene.cameras[0].camera, "[camera] is the default view");
    assert_eq!(scene.camera.width, 64);
    scene.select_camera("top").unwrap();
    assert_eq!(scene.camera.position, DVec3::new(0.0, 1.0, -7.0));
    assert_eq!((scene.camera.width, scene.camera.height, scene.camera.fov_y), (32, 16, 30.0));
    let message = scene.select_camera("side").unwrap_err();
    assert_contains(&message, "\"side\"");
    assert_contains(&message, "\"camera\", \"door\", \"top\"");

    assert_contains(&refused(&with_cameras(&["door", "door"]), "cameras[1].name"), "named twice");
    assert_contains(&refused(&with_cameras(&["camera"]), "cameras[0].name"), "named twice");
    refused(&with_cameras(&[""]), "cameras[0].name");
    refused(&with_cameras(&["a"]).replace("name = \"a\"\n", ""), "cameras[0].name");
    refused(&with_cameras(&["a"]).replace("fov_y = 30", "fov_y = 200"), "cameras[0].fov_y");
    assert_contains(&refused(&with_cameras(&["a"]).replace("fov_y = 30", "fov = 30"), "cameras[0].fov"), "fov_y");
    // [camera] stays required: more cameras do not replace it.
    let without_main = with_cameras(&["a"]).replacen("[camera]", "[nothing]", 1);
    assert!(load_str(&without_main, source()).is_err());
}

#[test]
fn test12_settings_and_environment_refusals() {
    let with = |settings: &str| format!("{MINIMAL}\n[settings]\n{settings}\n");
    assert_contains(&refused(&with("patch_size = -1"), "settings.patch_size"), "must be > 0, got -1");
    refused(&with("patch_size = 0"), "settings.patch_size");
    refused(&with("patch_size = inf"), "settings.patch_size");
    refused(&with("hemicube_resolution = 0"), "settings.hemicube_resolution");
    refused(&with("hemicube_resolution = 16385"), "settings.hemicube_resolution");
    assert_contains(&refused(&with("hemicube_resolution = \"fine\""), "settings.hemicube_resolution"), "\"auto\"");
    assert_eq!(load_str(&with("hemicube_resolution = \"auto\""), source()).unwrap().settings.hemicube_resolution, None);
    assert_eq!(load_str(&with("hemicube_resolution = 96"), source()).unwrap().settings.hemicube_resolution, Some(96));
    refused(&with("bundle_resolution = 0"), "settings.bundle_resolution");
    refused(&with("bundle_resolution = 1e9"), "settings.bundle_resolution");
    assert_contains(&refused(&with("bundle_resolution = \"fine\""), "settings.bundle_resolution"), "\"auto\"");
    assert_eq!(load_str(&with("bundle_resolution = \"auto\""), source()).unwrap().settings.bundle_resolution, None);
    assert_eq!(load_str(&with("bundle_resolution = 96"), source()).unwrap().settings.bundle_resolution, Some(96));
    assert_contains(&refused(&with("bundles_per_step = 2"), "settings.bundles_per_step"), "1, 4 or");
    refused(&with("bundles_per_step = 0"), "settings.bundles_per_step");
    refused(&with("bundles_per_step = \"four\""), "settings.bundles_per_step");
    assert_eq!(load_str(&with("bundles_per_step = 1"), source()).unwrap().settings.bundles_per_step, Some(1));
    assert_eq!(load_str(&with("bundles_per_step = \"auto\""), source()).unwrap().settings.bundles_per_step, None);
    refused(&with("iterations = -1"), "settings.iterations");
    refused(&with("seed = -1"), "settings.seed");
    let scene = load_str(&with("iterations = 0\nseed = 7\npatch_size = 0.5"), source()).unwrap();
    assert_eq!(scene.settings.iterations, 0);
    assert_eq!(scene.settings.seed, 7);
    assert_eq!(scene.settings.patch_size, 0.5);
    let env = format!("{MINIMAL}\n[environment]\nradiance = [1, -1, 1]\n");
    assert_contains(&refused(&env, "environment.radiance"), ">= 0");
}

#[test]
fn test13_material_refusals() {
    let gloss = "[materials.gloss]\ntype = \"phong\"\ndiffuse = [0.1, 0.1, 0.1]\n\
                 specular = [0.2, 0.2, 0.2]\nshininess = 10\n";
    let with = |m: &str| format!("{MINIMAL}\n{m}");
    assert!(load_str(&with(gloss), source()).is_ok());
    for (from, to, key, part) in [
        ("shininess = 10", "shininess = -1", "materials.gloss.shininess", "must be >= 0, got -1"),
        ("specular = [0.2, 0.2, 0.2]", "specular = [0.2, -0.2, 0.2]", "materials.gloss.specular", "green"),
        ("diffuse = [0.1, 0.1, 0.1]", "diffuse = [-1, 0.1, 0.1]", "materials.gloss.diffuse", ">= 0"),
        ("diffuse = [0.1, 0.1, 0.1]", "", "materials.gloss.diffuse", "required"),
        ("type = \"phong\"", "type = \"glass\"", "materials.gloss.type", "\"diffuse\" or \"phong\""),
        ("shininess = 10", "shininess = 10\nalbedo = [1, 1, 1]", "materials.gloss.albedo", "unknown key"),
    ] {
        assert_contains(&refused(&with(&gloss.replace(from, to)), key), part);
    }
    let albedo = |a: &str| edited(&[("albedo = [0.5, 0.5, 0.5]", a)]);
    assert_contains(&refused(&albedo("albedo = [0.5, 1.5, 0.5]"), "materials.white.albedo"), "<= 1");
    assert_contains(&refused(&albedo("albedo = [0.5, -0.5, 0.5]"), "materials.white.albedo"), ">= 0");
    refused(&albedo("albedo = [0.5, 0.5, nan]"), "materials.white.albedo[2]");
    refused(&albedo("albedo = 0.5"), "materials.white.albedo");
    let quoted = with("[materials.\"my gloss\"]\ntype = \"diffuse\"\nalbedo = [2, 0, 0]\n");
    refused(&quoted, "materials.\"my gloss\".albedo");
}

/// Holds once `brdf::max_directional_albedo` is written; until then it says it skipped.
#[test]
fn test14_energy_gaining_material_is_refused() {
    let kind = MaterialKind::Phong { diffuse: [0.9, 0.9, 0.9], specular: [0.9, 0.9, 0.9], shininess: 0.0 };
    let albedo = brdf::max_directional_albedo(&kind);
    let text = format!(
        "{MINIMAL}\n[materials.hot]\ntype = \"phong\"\ndiffuse = [0.9, 0.9, 0.9]\n\
         specular = [0.9, 0.9, 0.9]\nshininess = 0\n"
    );
    if albedo.iter().any(|&a| a > 1.0) {
        let message = refused(&text, "materials.hot");
        let largest = albedo.iter().copied().fold(0.0f32, f32::max);
        assert_contains(&message, &largest.to_string());
    } else {
        eprintln!("skipped: max_directional_albedo gives {albedo:?} for kd = ks = 0.9, n = 0");
    }
}

#[test]
fn test15_shape_refusals() {
    let quad = "vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1]]";
    for (to, key, part) in [
        ("vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, 1]]", "shapes[0].vertices", "zero area"),
        ("vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, -1], [1, 0, 1]]", "shapes[0].vertices", "not convex"),
        ("vertices = [[-1, 0, -1], [-1, 0, 1], [1, 1, 1], [1, 0, -1]]", "shapes[0].vertices", "not planar"),
        ("vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, 1]]", "shapes[0].vertices", "expected 4 points"),
        ("vertices = [[-1, 0, -1], [-1, 0], [1, 0, 1], [1, 0, -1]]", "shapes[0].vertices[1]", "expected 3 numbers"),
        ("vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, nan], [1, 0, -1]]", "shapes[0].vertices[2][2]", "finite"),
        ("", "shapes[0].vertices", "required"),
    ] {
        assert_contains(&refused(&edited(&[(quad, to)]), key), part);
    }
    let triangle =
        |v: &str| format!("{MINIMAL}\n[[shapes]]\ntype = \"triangle\"\nvertices = {v}\nmaterial = \"white\"\n");
    assert_contains(&refused(&triangle("[[0, 0, 0], [1, 1, 1], [2, 2, 2]]"), "shapes[1].vertices"), "zero area");
    assert_contains(&refused(&triangle("[[0, 0, 0], [0, 0, 0], [0, 0, 0]]"), "shapes[1].vertices"), "zero area");

    let material = "material = \"white\"";
    assert_contains(
        &refused(&edited(&[(material, "material = \"whte\"")]), "shapes[0].material"),
        "unknown material \"whte\"",
    );
    assert_contains(&refused(&edited(&[(material, "")]), "shapes[0].material"), "required");
    assert_contains(
        &refused(&edited(&[(material, "material = \"white\"\nemission = [1, -2, 0]")]), "shapes[0].emission"),
        ">= 0",
    );
    refused(&edited(&[(material, "material = \"white\"\ntwo_sided = 1")]), "shapes[0].two_sided");
    assert_contains(
        &refused(&edited(&[(material, "material = \"white\"\ntransform = { scale = 2 }")]), "shapes[0].transform"),
        "only mesh, gltf, box and sierpinski",
    );
    assert_contains(&refused(&edited(&[("type = \"quad\"", "type = \"disc\"")]), "shapes[0].type"), "\"sierpinski\"");
    refused(&edited(&[("type = \"quad\"", "")]), "shapes[0].type");

    let shape = |body: &str| format!("{MINIMAL}\n[[shapes]]\nmaterial = \"white\"\n{body}\n");
    let cube = "type = \"box\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]";
    assert!(load_str(&shape(cube), source()).is_ok());
    assert_contains(
        &refused(&shape("type = \"box\"\nmin = [0, 0, 0]\nmax = [1, 0, 1]"), "shapes[1].max"),
        "greater than min",
    );
    let transformed = |t: &str| shape(&format!("{cube}\ntransform = {t}"));
    assert_contains(&refused(&transformed("{ scale = 0 }"), "shapes[1].transform.scale"), "must be > 0, got 0");
    assert_contains(
        &refused(&transformed("{ scale = [1, -1, 1] }"), "shapes[1].transform.scale[1]"),
        "must be > 0, got -1",
    );
    refused(&transformed("{ scale = [1, 1] }"), "shapes[1].transform.scale");
    assert_contains(&refused(&transformed("{ rotate = [0, 0, 0, 30] }"), "shapes[1].transform.rotate"), "axis");
    assert_contains(
        &refused(&transformed("{ rotate = [0, 1, 0] }"), "shapes[1].transform.rotate"),
        "expected 4 numbers",
    );
    refused(&transformed("{ translate = [0, 1, inf] }"), "shapes[1].transform.translate[2]");
    assert_contains(&refused(&transformed("{ shear = 1 }"), "shapes[1].transform.shear"), "scale, rotate, translate");
    // A legal but extreme transform that makes the geometry overflow or vanish.
    assert_contains(&refused(&transformed("{ scale = 1e38, translate = [3e38, 0, 0] }"), "shapes[1]"), "out of range");
    assert_contains(&refused(&transformed("{ scale = 1e-200 }"), "shapes[1]"), "zero area");

    let sierpinski = |level: &str, size: &str| {
        shape(&format!("type = \"sierpinski\"\ncenter = [0, 0, 0]\nsize = {size}\nlevel = {level}"))
    };
    assert!(load_str(&sierpinski("8", "1"), source()).is_ok());
    assert_contains(&refused(&sierpinski("9", "1"), "shapes[1].level"), "from 0 to 8, got 9");
    refused(&sierpinski("50", "1"), "shapes[1].level");
    refused(&sierpinski("-1", "1"), "shapes[1].level");
    refused(&sierpinski("9223372036854775807", "1"), "shapes[1].level");
    refused(&sierpinski("1", "0"), "shapes[1].size");
    refused(&sierpinski("1", "-2"), "shapes[1].size");
}

#[test]
fn test16_light_refusals() {
    let light = |body: &str| format!("{MINIMAL}\n[[lights]]\n{body}\n");
    let area = |vertices: &str, rest: &str| {
        light(&format!("type = \"area\"\nvertices = {vertices}\nradiance = [1, 1, 1]\n{rest}"))
    };
    let square = "[[0, 2, 0], [1, 2, 0], [1, 2, 1], [0, 2, 1]]";
    assert!(load_str(&area(square, "subdivisions = 64"), source()).is_ok());
    for (vertices, part) in [
        ("[[0, 2, 0], [1, 2, 0], [1, 2.001, 1], [0, 2, 1]]", "not planar"),
        ("[[0, 2, 0], [1, 2, 0], [0, 2, 1], [1, 2, 1]]", "not convex"),
        ("[[0, 2, 0], [1, 2, 0], [2, 2, 0], [3, 2, 0]]", "zero area"),
        ("[[0, 2, 0], [1, 2, 0], [1, 2, 1], [1, 2, 1]]", "zero area"),
        ("[[0, 2, 0], [1, 2, 0], [1, 2, 1]]", "expected 4 points"),
        ("[[0, 2, 0], [1, 2, 0], [1, 2, 1], [0, 2, 1], [0, 2, 0.5]]", "expected 4 points"),
    ] {
        assert_contains(&refused(&area(vertices, ""), "lights[1].vertices"), part);
    }
    // Planar within 1e-4 of its size (the diagonal, sqrt 2): any one vertex lifted by 0.7
    // of that passes, by 1.4 of it does not.
    for lifted in 0..4 {
        for (factor, ok) in [(0.7, true), (1.4, false)] {
            let lift = factor * 1e-4 * 2.0f64.sqrt();
            let vertices: Vec<String> = [[0, 0], [1, 0], [1, 1], [0, 1]]
                .iter()
                .enumerate()
                .map(|(k, [x, z])| {
                    let y = if k == lifted { 2.0 + lift } else { 2.0 };
                    format!("[{x}, {y}, {z}]")
                })
                .collect();
            let text = area(&format!("[{}]", vertices.join(", ")), "");
            if ok {
                assert!(load_str(&text, source()).is_ok(), "{text}");
            } else {
                assert_contains(&refused(&text, "lights[1].vertices"), "not planar");
            }
        }
    }
    for n in ["0", "65", "100000000000", "1.5", "-1"] {
        refused(&area(square, &format!("subdivisions = {n}")), "lights[1].subdivisions");
    }
    let message =
        refused(&area(square, "").replace("radiance = [1, 1, 1]", "radiance = [1, 1, -1]"), "lights[1].radiance");
    assert_contains(&message, "blue");
    refused(&light("type = \"point\"\nposition = [0, 1, 0]\npower = [-1, 1, 1]"), "lights[1].power");
    refused(&light("type = \"point\"\nposition = [0, 1, 0]"), "lights[1].power");
    refused(&light("type = \"laser\"\nposition = [0, 1, 0]"), "lights[1].type");
    assert_contains(
        &refused(
            &light("type = \"point\"\nposition = [0, 1, 0]\npower = [1, 1, 1]\nradiance = [1, 1, 1]"),
            "lights[1].radiance",
        ),
        "type, position, power",
    );
}

#[test]
fn test17_no_surfaces_and_no_emitters() {
    let no_shapes = MINIMAL.split("[[shapes]]").next().unwrap().to_string()
        + "[[lights]]\ntype = \"point\"\nposition = [0, 3, 0]\npower = [10, 10, 10]\n";
    assert_contains(&refused(&no_shapes, "shapes"), "no surfaces");
    assert_contains(&refused(&format!("shapes = []\n{no_shapes}"), "shapes"), "no surfaces");
    refused(&format!("shapes = 3\n{no_shapes}"), "shapes");

    let no_lights = MINIMAL.split("[[lights]]").next().unwrap();
    assert_contains(&refused(no_lights, "lights"), "no emitter");
    let black = edited(&[("power = [10, 10, 10]", "power = [0, 0, 0]")]);
    assert_contains(&refused(&black, "lights"), "no emitter");
    let black_env = format!("{no_lights}\n[environment]\nradiance = [0, 0, 0]\n");
    refused(&black_env, "lights");
    // Any one emitter is enough.
    let sky = format!("{no_lights}\n[environment]\nradiance = [0, 0, 0.1]\n");
    assert!(load_str(&sky, source()).is_ok());
    let glowing = no_lights.replace("material = \"white\"", "material = \"white\"\nemission = [0, 1, 0]");
    assert!(load_str(&glowing, source()).is_ok());
}

#[test]
fn test18_unknown_keys_are_refused_with_the_allowed_ones() {
    for (text, key, allowed) in [
        (format!("colour = 1\n{MINIMAL}"), "colour", "format, camera, cameras, environment"),
        (format!("fmt = 1\n{MINIMAL}"), "fmt", "format, camera"),
        (edited(&[("fov_y = 40", "fov_y = 40\nfov_x = 40")]), "camera.fov_x", "position, look_at, up, fov_y"),
        (format!("{MINIMAL}\n[settings]\nspp = 4\n"), "settings.spp", "patch_size, hemicube_resolution"),
        (format!("{MINIMAL}\n[environment]\ncolor = [1, 1, 1]\n"), "environment.color", "radiance"),
        (
            edited(&[("albedo = [0.5, 0.5, 0.5]", "albedo = [0.5, 0.5, 0.5]\nroughness = 1")]),
            "materials.white.roughness",
            "type, albedo",
        ),
        (
            edited(&[("material = \"white\"", "material = \"white\"\nname = \"floor\"")]),
            "shapes[0].name",
            "two_sided, vertices",
        ),
        (
            edited(&[("power = [10, 10, 10]", "power = [10, 10, 10]\nsubdivisions = 2")]),
            "lights[0].subdivisions",
            "position, power",
        ),
    ] {
        let message = refused(&text, key);
        assert_contains(&message, "unknown key");
        assert_contains(&message, allowed);
    }
}

/// Cornell box mutations: the kinds of mistakes (and malice) a scene file can carry.
fn mutation() -> impl Strategy<Value = (u8, usize, usize, &'static str)> {
    let replacement = prop::sample::select(vec![
        "1e300",
        "-1e300",
        "1e39",
        "nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "-0.0",
        "\"x\"",
        "[]",
        "[1, 2]",
        "{}",
        "true",
        "99999999999999999999",
        "9223372036854775807",
        "2",
        "64",
        "1979-05-27",
        "[[1, 2, 3]]",
    ]);
    (0u8..5, any::<usize>(), any::<usize>(), replacement)
}

fn mutate(text: &str, mutations: &[(u8, usize, usize, &'static str)]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for &(op, a, b, replacement) in mutations {
        if lines.is_empty() {
            break;
        }
        let i = a % lines.len();
        match op {
            0 => {
                lines.remove(i);
            }
            1 => {
                let line = lines[i].clone();
                lines.insert(b % (lines.len() + 1), line);
            }
            2 => {
                let j = b % lines.len();
                lines.swap(i, j);
            }
            _ => {
                // Replace the (b mod n)-th number of the line, if it has one.
                let line = lines[i].clone();
                let numbers: Vec<(usize, usize)> = number_spans(&line);
                if let Some(&(start, end)) = numbers.get(b % numbers.len().max(1)) {
                    lines[i] = format!("{}{replacement}{}", &line[..start], &line[end..]);
                } else {
                    lines[i] = format!("{line} {replacement}");
                }
            }
        }
    }
    lines.join("\n")
}

/// Byte spans of the number-like tokens of a line.
fn number_spans(line: &str) -> Vec<(usize, usize)> {
    let bytes = line.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() || bytes[i] == b'-' {
            let start = i;
            while i < bytes.len() && (bytes[i].is_ascii_digit() || b"-.eE".contains(&bytes[i])) {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}

/// A random shape entry, valid or not, mesh entries pointing at a random OBJ.
fn shape_entry() -> impl Strategy<Value = String> {
    let number = prop_oneof![
        4 => (-5.0f64..5.0).prop_map(|x| format!("{x}")),
        1 => prop::sample::select(vec!["0", "1e38", "-3e38", "1e-300", "nan", "9", "100"])
            .prop_map(str::to_string),
    ];
    let point = prop::array::uniform3(number.clone()).prop_map(|p| format!("[{}]", p.join(", ")));
    let kind = prop::sample::select(vec!["quad", "triangle", "box", "sierpinski", "mesh", "disc"]);
    let transform = prop_oneof![
        Just(String::new()),
        (number.clone(), point.clone(), number.clone(), point.clone()).prop_map(|(s, axis, angle, t)| {
            let axis = axis.trim_end_matches(']');
            format!("transform = {{ scale = {s}, rotate = {axis}, {angle}], translate = {t} }}")
        }),
    ];
    (
        kind,
        prop::collection::vec(point, 0..6),
        number.clone(),
        // Deep levels are slow to build and are covered once in test15.
        prop_oneof![0i64..4, Just(9), Just(-1)],
        transform,
    )
        .prop_map(|(kind, points, size, level, transform)| {
            let first = points.first().cloned().unwrap_or_else(|| "[0, 0, 0]".into());
            let last = points.last().cloned().unwrap_or_else(|| "[1, 1, 1]".into());
            let body = match kind {
                "quad" | "triangle" | "disc" => format!("vertices = [{}]", points.join(", ")),
                "box" => format!("min = {first}\nmax = {last}\n{transform}"),
                "sierpinski" => {
                    format!("center = {first}\nsize = {size}\nlevel = {level}\n{transform}")
                }
                _ => format!("file = \"meshes/fuzz.obj\"\n{transform}"),
            };
            format!("[[shapes]]\ntype = \"{kind}\"\nmaterial = \"white\"\n{body}\n")
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn test19_mutated_cornell_box_never_panics(
        mutations in prop::collection::vec(mutation(), 1..6)
    ) {
        let cornell = include_str!("../scenes/cornell_box.toml");
        let _ = load_str(&mutate(cornell, &mutations), source());
    }

    #[test]
    fn test20_random_text_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let text = String::from_utf8_lossy(&bytes);
        let _ = load_str(&text, source());
        // Also after a valid head, so that the walker, not only the parser, sees it.
        let _ = load_str(&format!("{MINIMAL}\n{text}"), source());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn test21_random_shapes_and_objs_never_panic(
        shapes in prop::collection::vec(shape_entry(), 1..4),
        obj in prop::collection::vec(
            prop_oneof![
                prop::array::uniform3(-3i32..3).prop_map(|v| format!("v {} {} {}", v[0], v[1], v[2])),
                prop::collection::vec(-6i64..7, 0..6).prop_map(|f| {
                    let f: Vec<String> = f.iter().map(i64::to_string).collect();
                    format!("f {}", f.join(" "))
                }),
                Just("usemtl white".to_string()),
                Just("usemtl gold".to_string()),
                "[ -~]{0,12}",
            ],
            0..20,
        ),
    ) {
        let dir = Scratch::new("scene-load", "fuzz");
        write(&dir.join("meshes/fuzz.obj"), obj.join("\n"));
        let text = format!("{MINIMAL}\n{}", shapes.join("\n"));
        if let Ok(scene) = load_str(&text, &dir.join("scene.toml")) {
            for t in scene.surfaces.iter().flat_map(|s| &s.triangles) {
                prop_assert!(triangle_area(&t.vertices) > 0.0);
                prop_assert!((t.material as usize) < scene.materials.len());
            }
        }
    }

    #[test]
    fn test22_random_bytes_through_the_file_never_panic(
        bytes in prop::collection::vec(any::<u8>(), 0..200)
    ) {
        let dir = Scratch::new("scene-load", "bytes_fuzz");
        let path = dir.join("scene.toml");
        write(&path, &bytes);
        let _ = load(&path);
    }
}

#[test]
fn test23_obj_mtl_materials_emission_and_refusals() {
    let dir = Scratch::new("scene-load", "mtl");
    write(
        &dir.join("meshes/lamp.mtl"),
        "\
newmtl white
Kd 0.2 0.2 0.2
newmtl shade
Kd 0.5 0.4 0.3
Ks 0.9 0.9 0.9
Ns 8
map_Kd shade.png
newmtl bulb
Kd 0 0 0
Ke 4 3 2
",
    );
    write(
        &dir.join("meshes/lamp.obj"),
        "\
mtllib lamp.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
usemtl shade
f 1 2 3
usemtl bulb
f 1 3 4
usemtl white
f 3 2 1
",
    );
    let path = dir.join("scene.toml");
    let mesh = "[[shapes]]\ntype = \"mesh\"\nfile = \"meshes/lamp.obj\"\n\n[[shapes]]";
    write(&path, edited(&[("[[shapes]]", mesh)]));
    let scene = load(&path).unwrap();
    // The emitting face is a surface of its own, with the bulb's Ke.
    assert_eq!(scene.surfaces.len(), 3, "{:?}", scene.surfaces.iter().map(|s| &s.origin).collect::<Vec<_>>());
    let (plain, lit) = (&scene.surfaces[0], &scene.surfaces[1]);
    assert_eq!(plain.emission, [0.0; 3]);
    assert_eq!(plain.triangles.len(), 2);
    assert_eq!(lit.emission, [4.0, 3.0, 2.0]);
    assert_eq!(lit.triangles.len(), 1);
    assert_contains(&lit.origin, "emitting");
    let material = |t: &firstshot::scene::Triangle| &scene.materials[t.material as usize];
    // `usemtl white` names the scene's [materials] white (0.5), not the library's (0.2).
    assert_eq!(material(&plain.triangles[1]).kind, MaterialKind::Diffuse { albedo: [0.5; 3] });
    // Kd 0.5 + Ks 0.9 with Ns 8 would reflect 0.5 + 0.9 * 2 pi / 10 > 1: Ks is scaled to fit.
    let shade = material(&plain.triangles[0]);
    assert_eq!(shade.name, "meshes/lamp.obj: shade");
    let MaterialKind::Phong { diffuse, specular, shininess } = shade.kind else { panic!("{shade:?}") };
    assert_eq!((diffuse, shininess), ([0.5, 0.4, 0.3], 8.0));
    assert!(specular[0] < 0.9 && specular[0] > 0.0 && specular[0] == specular[2], "{specular:?}");
    let albedo = brdf::max_directional_albedo(&shade.kind);
    assert!(albedo.iter().all(|&a| a <= 1.0) && albedo[0] > 0.9999, "{albedo:?}");
    // One note for the scaled Ks, one for the texture.
    assert_eq!(scene.notes.len(), 2, "{:?}", scene.notes);
    assert!(scene.notes.iter().any(|n| n.contains("Ks scaled by")));
    assert!(scene.notes.iter().any(|n| n.contains("map_Kd") && n.contains("line 7")));

    // A shape's `emission` key sets every face's, and so one surface.
    write(&path, edited(&[("[[shapes]]", &mesh.replace("lamp.obj\"", "lamp.obj\"\nemission = [1, 1, 1]"))]));
    let scene = load(&path).unwrap();
    assert_eq!(scene.surfaces[0].triangles.len(), 3);
    assert_eq!(scene.surfaces[0].emission, [1.0; 3]);

    // Refusals name the file and line: a missing library, an unknown material, a bad MTL line.
    write(&path, edited(&[("[[shapes]]", mesh)]));
    write(&dir.join("meshes/lamp.obj"), "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl shade\nf 1 2 3\n");
    assert_contains(&refused_at(load(&path), "meshes/lamp.obj line 1"), "nowhere.mtl does not exist");
    write(&dir.join("meshes/lamp.obj"), "mtllib lamp.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl gold\nf 1 2 3\n");
    assert_contains(&refused_at(load(&path), "meshes/lamp.obj line 5"), "unknown material \"gold\"");
    write(&dir.join("meshes/lamp.mtl"), "newmtl hot\nKd 1.2 0.5 0.5\n");
    write(&dir.join("meshes/lamp.obj"), "mtllib lamp.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl hot\nf 1 2 3\n");
    let message = refused_at(load(&path), "lamp.mtl line 1");
    assert_contains(&message, "Kd must be <= 1");
    assert_contains(&message, "shapes[0]");
}

#[test]
fn test24_sharp_glossy_lobes_get_a_note() {
    // A max-Phong material sharper than the iteration samples well (shininess above
    // SHARP_LOBE_SHININESS) and bright enough to show it gets a note naming the file, the
    // material, its shininess and where the docs explain it; a lobe of the shipped scenes'
    // kind (60), a sharp but dim one (reflecting 0.3 % at normal incidence) and the
    // threshold itself do not.
    let phong = |name: &str, ks: f64, n: f64| {
        format!(
            "[materials.{name}]\ntype = \"phong\"\ndiffuse = [0.2, 0.2, 0.2]\nspecular = [{ks}, {ks}, {ks}]\nshininess = {n}\n\n"
        )
    };
    // ks (n + 2) / (2 pi) keeps the lobe's albedo at normal incidence near 1/2.
    let half = |n: f64| 0.5 * (n + 2.0) / (2.0 * std::f64::consts::PI);
    let materials = [
        phong("broad", half(60.0), 60.0),
        phong("at_threshold", half(200.0), 200.0),
        phong("mirror", half(2000.0), 2000.0),
        phong("dim", 1.0, 2000.0),
    ]
    .concat();
    let text = edited(&[("[materials.white]", &format!("{materials}[materials.white]"))]);
    let scene = load_str(&text, source()).unwrap();
    assert_eq!(scene.notes.len(), 1, "{:?}", scene.notes);
    let note = &scene.notes[0];
    for part in ["memory/scene.toml", "material \"mirror\"", "shininess 2000", "reflects 0.5", "\"Sharp lobes\""] {
        assert_contains(note, part);
    }
    assert_eq!(firstshot::scene::load::SHARP_LOBE_SHININESS, 200.0);
    // None of the shipped scenes has such a lobe.
    for name in ["cornell_box", "cornell_point", "sierpinski", "sun_room", "cornell_emissive"] {
        let scene = load(&common::scenes::shipped(name)).unwrap();
        assert!(scene.notes.iter().all(|n| !n.contains("shininess")), "{name}: {:?}", scene.notes);
    }
}

#[test]
fn test25_a_scene_far_from_its_origin_is_moved_to_it_exactly() {
    // Around its origin (its centre 0.7 of its radius from it): where the file has it.
    let near = load_str(MINIMAL, source()).unwrap();
    assert_eq!(near.file_origin, DVec3::ZERO);
    // Far from it: moved to its own origin (`Scene::recentre`), by a multiple of a power of two
    // no larger than its radius, so that every position is the file's less `file_origin` to
    // the bit, the camera's and the light's included.
    let by = DVec3::new(3.0e6 + 0.25, -1.0e5, 7.0e5);
    let far = load_str(&common::scenes::moved(MINIMAL, by), source()).unwrap();
    let o = far.file_origin;
    assert!((o - by).length() <= 4.0, "moved by {o}");
    assert!(o.to_array().iter().all(|c| (c / 2.0).fract() == 0.0), "{o} is not a multiple of 2 (the radius is 2.06)");
    for (f, n) in far.surfaces[0].triangles.iter().zip(&near.surfaces[0].triangles) {
        for (v_far, v_near) in f.vertices.iter().zip(&n.vertices) {
            assert_eq!(*v_far + o, *v_near + by);
            assert!(v_far.length() < 4.0, "{v_far} is not near the origin");
        }
    }
    assert_eq!(far.camera.position + o, near.camera.position + by);
    assert_eq!(far.camera.look_at + o, near.camera.look_at + by);
    assert_eq!(far.cameras[0].camera, far.camera);
    assert_eq!(far.camera.up, near.camera.up);
    let (Light::Point { position: p_far, .. }, Light::Point { position: p_near, .. }) = (far.lights[0], near.lights[0])
    else {
        panic!("a point light")
    };
    assert_eq!(p_far + o, p_near + by);
    // The same patches, moved.
    let (patches_far, patches_near) =
        (firstshot::scene::tessellate(&far, 0.3).unwrap(), firstshot::scene::tessellate(&near, 0.3).unwrap());
    assert_eq!(patches_far.patches.len(), patches_near.patches.len());
    for (a, b) in patches_far.patches.iter().zip(&patches_near.patches) {
        assert!((a.area - b.area).abs() < 1e-12 && (a.vertices[0] + o - b.vertices[0] - by).length() < 1e-9);
    }
}
