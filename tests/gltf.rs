//! glTF 2.0 scenes (docs/SCENE_FORMAT.md, "glTF 2.0") against oracles that share no code
//! with the loader: files written by `common::gltf_writer` from the specification, the same
//! scene written in TOML, our own albedo check for the material mapping, and a real-world
//! model no one here wrote.

mod common;

use common::gltf_writer::GltfWriter;
use common::scratch::{Scratch, write};
use firstshot::Error;
use firstshot::render::{RenderOptions, render};
use firstshot::scene::{self, Light, MaterialKind, Scene, brdf};
use glam::DVec3;
use serde_json::json;
use std::path::Path;

fn refused(result: firstshot::Result<Scene>, key_part: &str, message_part: &str) {
    match result {
        Err(Error::Scene { key, message, .. }) => {
            assert!(key.contains(key_part), "key {key:?} lacks {key_part:?} ({message})");
            assert!(message.contains(message_part), "{message:?} lacks {message_part:?}");
        }
        Err(e) => panic!("refused, but not as a scene error: {e}"),
        Ok(_) => panic!("loaded, but should be refused at {key_part}"),
    }
}

#[test]
fn test01_metallic_roughness_never_gains_energy_and_rough_dielectric_is_diffuse() {
    let bases = [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0], [1.0, 0.0, 0.0], [0.9, 0.5, 0.1], [0.2, 1.0, 0.7]];
    let levels = [0.0, 0.25, 0.5, 0.75, 1.0];
    let roughnesses = [0.0, 0.05, 0.2, 0.5, 0.8, 1.0];
    for base in bases {
        for metallic in levels {
            for roughness in roughnesses {
                let kind = scene::gltf::metallic_roughness(base, metallic, roughness);
                let albedo = brdf::max_directional_albedo(&kind);
                assert!(
                    albedo.iter().all(|&a| a <= 1.0),
                    "base {base:?} metallic {metallic} roughness {roughness}: albedo {albedo:?} ({kind:?})"
                );
                if let MaterialKind::Phong { diffuse, specular, shininess } = kind {
                    assert!(diffuse.iter().chain(&specular).all(|&x| x >= 0.0) && shininess >= 0.0, "{kind:?}");
                }
            }
        }
        // Metallic 0, roughness 1: exactly the diffuse base colour.
        assert_eq!(scene::gltf::metallic_roughness(base, 0.0, 1.0), MaterialKind::Diffuse { albedo: base });
    }
    // A white, smooth metal is a mirror-like lobe that reflects (nearly) everything.
    let MaterialKind::Phong { diffuse, shininess, .. } = scene::gltf::metallic_roughness([1.0; 3], 1.0, 0.0) else {
        panic!("a smooth metal must be glossy");
    };
    assert_eq!(diffuse, [0.0; 3]);
    assert_eq!(shininess, 1e4);
}

/// A closed box of f32-exact coordinates lit by an emitting quad in its ceiling: (corners,
/// material, emission) per quad. Materials: 0 white, 1 red, 2 green, 3 black.
fn box_quads() -> Vec<([[f32; 3]; 4], usize, [f32; 3])> {
    let (s, h) = (8.0, 8.0);
    let none = [0.0; 3];
    vec![
        ([[0.0, 0.0, 0.0], [0.0, 0.0, s], [s, 0.0, s], [s, 0.0, 0.0]], 0, none), // floor, up
        ([[0.0, h, 0.0], [s, h, 0.0], [s, h, s], [0.0, h, s]], 0, none),         // ceiling, down
        ([[0.0, 0.0, 0.0], [s, 0.0, 0.0], [s, h, 0.0], [0.0, h, 0.0]], 0, none), // back, +z
        ([[s, 0.0, 0.0], [s, 0.0, s], [s, h, s], [s, h, 0.0]], 2, none),         // right, -x
        ([[0.0, 0.0, s], [0.0, 0.0, 0.0], [0.0, h, 0.0], [0.0, h, s]], 1, none), // left, +x
        ([[0.0, 0.0, s], [0.0, h, s], [s, h, s], [s, 0.0, s]], 0, none),         // front, -z
        ([[3.0, 7.5, 3.0], [5.0, 7.5, 3.0], [5.0, 7.5, 5.0], [3.0, 7.5, 5.0]], 3, [16.0, 12.0, 8.0]), // lamp, down
        // A triangle, stored as a quad whose last corner repeats its first (`is_triangle`).
        ([[2.0, 2.0, 4.0], [2.0, 0.5, 2.5], [5.5, 1.0, 3.0], [2.0, 2.0, 4.0]], 0, none),
    ]
}

fn is_triangle(q: &[[f32; 3]; 4]) -> bool {
    q[3] == q[0]
}

const COLOURS: [[f32; 3]; 4] = [[0.75, 0.75, 0.75], [0.75, 0.25, 0.25], [0.25, 0.75, 0.25], [0.0, 0.0, 0.0]];
const CAMERA_AT: [f32; 3] = [4.0, 4.0, 7.75];
const YFOV: f32 = 1.5;

fn box_toml() -> String {
    let fov_y = f64::from(YFOV).to_degrees();
    let [x, y, z] = CAMERA_AT;
    let mut t = format!(
        "format = 1\n[camera]\nposition = [{x}, {y}, {z}]\nlook_at = [{x}, {y}, {}]\nup = [0, 1, 0]\nfov_y = {fov_y:?}\nwidth = 512\nheight = 512\n",
        z - 1.0
    );
    for (i, c) in COLOURS.iter().enumerate() {
        t += &format!("[materials.m{i}]\ntype = \"diffuse\"\nalbedo = [{}, {}, {}]\n", c[0], c[1], c[2]);
    }
    for (q, m, e) in box_quads() {
        let n = if is_triangle(&q) { 3 } else { 4 };
        let vertices: Vec<String> = q[..n].iter().map(|v| format!("[{}, {}, {}]", v[0], v[1], v[2])).collect();
        t += &format!(
            "[[shapes]]\ntype = \"{}\"\nvertices = [{}]\nmaterial = \"m{m}\"\n",
            if n == 3 { "triangle" } else { "quad" },
            vertices.join(", ")
        );
        if e != [0.0; 3] {
            t += &format!("emission = [{}, {}, {}]\n", e[0], e[1], e[2]);
        }
    }
    t
}

/// The same box in glTF, exercising what the loader must get right: node translations
/// (the mesh data shifted back), a mirroring node (the data mirrored and wound the other
/// way), indexed and non-indexed primitives, emissive strength, and a camera node.
fn box_gltf() -> GltfWriter {
    let mut w = GltfWriter::default();
    for (i, c) in COLOURS.iter().enumerate() {
        let mut m = json!({"pbrMetallicRoughness": {"baseColorFactor": [c[0], c[1], c[2], 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}});
        if i == 3 {
            // Emission 16 x [1, 0.75, 0.5]: exact in f32, as the TOML's [16, 12, 8].
            m["emissiveFactor"] = json!([1.0, 0.75, 0.5]);
            m["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": 16.0}});
        }
        w.material(m);
    }
    for (k, (q, m, _)) in box_quads().into_iter().enumerate() {
        let n = if is_triangle(&q) { 3 } else { 4 };
        let fan: Vec<u32> = if n == 3 { vec![0, 1, 2] } else { vec![0, 1, 2, 0, 2, 3] };
        let node = match k % 3 {
            // Under a parent (x + 1) with its own translation (y + 2): the data moved back.
            0 => {
                let data: Vec<[f32; 3]> = q[..n].iter().map(|v| [v[0] - 1.0, v[1] - 2.0, v[2]]).collect();
                let mesh = w.mesh(&data, Some(&fan), Some(m));
                let child = w.node(json!({"mesh": mesh, "translation": [0.0, 2.0, 0.0]}), false);
                json!({"name": "parent", "translation": [1.0, 0.0, 0.0], "children": [child]})
            }
            // Mirrored in x: the data mirrored, and each triangle wound the other way.
            1 => {
                let data: Vec<[f32; 3]> = q[..n].iter().map(|v| [-v[0], v[1], v[2]]).collect();
                let wound: Vec<u32> = fan.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
                let mesh = w.mesh(&data, Some(&wound), Some(m));
                json!({"mesh": mesh, "scale": [-1.0, 1.0, 1.0]})
            }
            // Non-indexed: the fan's vertices written out.
            _ => {
                let data: Vec<[f32; 3]> = fan.iter().map(|&i| q[i as usize]).collect();
                let mesh = w.mesh(&data, None, Some(m));
                json!({"mesh": mesh})
            }
        };
        w.node(node, true);
    }
    w.cameras.push(json!({"name": "front", "type": "perspective", "perspective": {"yfov": YFOV, "aspectRatio": 1.0, "znear": 0.1}}));
    w.node(json!({"camera": 0, "translation": CAMERA_AT}), true);
    w
}

#[test]
fn test02_a_gltf_box_renders_bit_identically_to_the_same_box_in_toml() {
    let dir = Scratch::new("gltf", "box");
    let toml = dir.join("box.toml");
    write(&toml, box_toml());
    let writer = box_gltf();
    let embedded = dir.join("box.gltf");
    write(&embedded, writer.gltf_embedded());
    let (text, bin) = writer.gltf_with_bin("box data.bin");
    write(&dir.join("split.gltf"), text.replace("box data.bin", "box%20data.bin"));
    std::fs::write(dir.join("box data.bin"), bin).unwrap();
    let glb = dir.join("box.glb");
    std::fs::write(&glb, writer.glb()).unwrap();

    let reference = scene::load(&toml).unwrap();
    let loaded: Vec<Scene> = [embedded, dir.join("split.gltf"), glb].iter().map(|p| scene::load(p).unwrap()).collect();
    let triangles = |s: &Scene| -> Vec<[DVec3; 3]> {
        s.surfaces.iter().flat_map(|x| x.triangles.iter().map(|t| t.vertices)).collect()
    };
    for s in &loaded {
        assert!(s.notes.is_empty(), "{:?}", s.notes);
        assert_eq!(triangles(s), triangles(&reference), "the same triangles, wound the same way");
        assert_eq!(s.camera, reference.camera);
        assert_eq!(s.cameras[0].name, "front");
        let emissions: Vec<_> = s.surfaces.iter().map(|x| x.emission).collect();
        assert_eq!(emissions, reference.surfaces.iter().map(|x| x.emission).collect::<Vec<_>>());
    }

    let Some(ctx) = common::gpu() else { return };
    let run = |s: &Scene| {
        let mut options = RenderOptions::from_scene(s);
        (options.width, options.height) = (24, 24);
        options.iterations = 8;
        options.hemicube_resolution = Some(64);
        options.bundle_resolution = Some(48);
        options.patch_size = 2.0;
        let patches = scene::tessellate(s, options.patch_size).unwrap();
        render(&ctx, s, &patches, &options).unwrap().image
    };
    let expected = run(&reference);
    assert!(expected.pixels.iter().any(|p| p[0] > 0.0), "the reference is black");
    for s in &loaded {
        let image = run(s);
        assert!(image.pixels == expected.pixels, "{} differs from the TOML scene", s.source.display());
    }
}

fn one_triangle(material: serde_json::Value) -> GltfWriter {
    let mut w = GltfWriter::default();
    let m = w.material(material);
    let mesh = w.mesh(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], Some(&[0, 1, 2]), Some(m));
    w.node(json!({"name": "tri", "mesh": mesh}), true);
    w
}

fn load_written(dir: &Path, name: &str, text: &str) -> firstshot::Result<Scene> {
    let path = dir.join(name);
    write(&path, text);
    scene::load(&path)
}

#[test]
fn test03_lights_cameras_and_what_is_ignored() {
    let dir = Scratch::new("gltf", "lights");
    let mut w = one_triangle(json!({
        "name": "wood",
        "doubleSided": true,
        "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.4, 0.3, 1.0], "baseColorTexture": {"index": 0}},
    }));
    w.extra.push(("textures".into(), json!([{"source": 0}])));
    w.extra.push(("images".into(), json!([{"uri": "wood.png"}])));
    w.lights.push(json!({"name": "bulb", "type": "point", "intensity": 10.0, "color": [1.0, 0.5, 0.25]}));
    w.lights.push(json!({"name": "sun", "type": "directional", "intensity": 3.0, "color": [1.0, 0.5, 0.25]}));
    w.lights.push(json!({"name": "cone", "type": "spot", "intensity": 7.0,
        "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.5}}));
    w.node(json!({"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0.0, 0.0, 2.0]}), true);
    // The sun's node turns its -z onto -y (a quarter turn about +x): it shines straight down.
    let q = std::f32::consts::FRAC_1_SQRT_2;
    w.node(json!({"extensions": {"KHR_lights_punctual": {"light": 1}}, "rotation": [-q, 0.0, 0.0, q]}), true);
    w.node(json!({"extensions": {"KHR_lights_punctual": {"light": 2}}, "translation": [1.0, 2.0, 3.0]}), true);
    w.cameras.push(
        json!({"name": "wide", "type": "perspective", "perspective": {"yfov": 1.0, "aspectRatio": 2.0, "znear": 0.1}}),
    );
    w.cameras.push(
        json!({"name": "tall", "type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 0.5, "znear": 0.1}}),
    );
    w.cameras
        .push(json!({"type": "orthographic", "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.1, "zfar": 9.0}}));
    // "tall" looks along -x: its node turns -z onto -x (a quarter turn about +y).
    let h = std::f32::consts::FRAC_1_SQRT_2;
    w.node(json!({"camera": 0, "translation": [0.0, 0.0, 5.0]}), true);
    w.node(json!({"camera": 1, "translation": [5.0, 0.0, 0.0], "rotation": [0.0, h, 0.0, h]}), true);
    w.node(json!({"camera": 2}), true);
    let mut scene = load_written(&dir, "lit.gltf", &w.gltf_embedded()).unwrap();

    let [
        Light::Point { position, power },
        Light::Directional { direction, irradiance },
        Light::Spot { position: spot_at, direction: axis, intensity, inner_angle, outer_angle },
    ] = scene.lights[..]
    else {
        panic!("{:?}", scene.lights)
    };
    // Lux read as W/m^2 times the colour; the direction is the node's -z.
    assert_eq!(irradiance, [3.0, 1.5, 0.75]);
    assert!(direction.distance(DVec3::NEG_Y) < 1e-6, "{direction}");
    // Candela read as W/sr; radians to degrees; the node's -z.
    assert_eq!(intensity, [7.0; 3]);
    assert_eq!((spot_at, axis), (DVec3::new(1.0, 2.0, 3.0), DVec3::NEG_Z));
    assert!((inner_angle - 0.25f64.to_degrees()).abs() < 1e-5 && (outer_angle - 0.5f64.to_degrees()).abs() < 1e-5);
    assert_eq!(position, DVec3::new(0.0, 0.0, 2.0));
    let expected = [1.0, 0.5, 0.25].map(|c| 4.0 * std::f64::consts::PI * 10.0 * c);
    for c in 0..3 {
        assert!((f64::from(power[c]) - expected[c]).abs() <= 1e-6 * expected[c], "{power:?} against {expected:?}");
    }
    assert!(scene.surfaces[0].two_sided);
    assert_eq!(scene.materials[0].kind, MaterialKind::Diffuse { albedo: [0.5, 0.4, 0.3] });
    let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["wide", "tall"]);
    assert_eq!((scene.camera.width, scene.camera.height), (512, 256));
    assert!((scene.camera.fov_y - 1f64.to_degrees()).abs() < 1e-12);
    scene.select_camera("tall").unwrap();
    assert_eq!((scene.camera.width, scene.camera.height), (256, 512));
    assert!((scene.camera.look_at - scene.camera.position).distance(DVec3::NEG_X) < 1e-6, "{:?}", scene.camera);
    // One line each for the texture and the orthographic camera.
    let notes = scene.notes.join("\n");
    assert_eq!(scene.notes.len(), 2, "{notes}");
    for part in ["materials[0] \"wood\": baseColorTexture is ignored", "orthographic"] {
        assert!(notes.contains(part), "{notes}");
    }
    assert!(scene.notes.iter().all(|n| n.contains("lit.gltf")), "{notes}");

    // Without camera: the documented default, framing the model from +z.
    let mut plain = one_triangle(json!({"emissiveFactor": [1.0, 1.0, 1.0]}));
    plain.roots.truncate(1);
    let scene = load_written(&dir, "plain.gltf", &plain.gltf_embedded()).unwrap();
    assert_eq!(scene.cameras[0].name, "default");
    assert!(scene.camera.position.z > 1.0 && scene.camera.look_at.z == 0.0);
    assert_eq!(scene.surfaces[0].emission, [1.0; 3]);
}

#[test]
fn test04_refusals_name_the_file_and_the_gltf_object() {
    let dir = Scratch::new("gltf", "refusals");
    let lit = json!({"emissiveFactor": [1.0, 1.0, 1.0]});
    // No light of any kind.
    let dark = one_triangle(json!({})).gltf_embedded();
    refused(load_written(&dir, "dark.gltf", &dark), "lights", "no light");
    // A required extension we do not read.
    let mut draco = one_triangle(lit.clone());
    draco.extra.push(("extensionsUsed".into(), json!(["KHR_draco_mesh_compression"])));
    draco.extra.push(("extensionsRequired".into(), json!(["KHR_draco_mesh_compression"])));
    refused(
        load_written(&dir, "draco.gltf", &draco.gltf_embedded()),
        "extensionsRequired",
        "KHR_draco_mesh_compression",
    );
    // An index past the vertices.
    let mut bad = GltfWriter::default();
    let m = bad.material(lit.clone());
    let mesh = bad.mesh(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], Some(&[0, 1, 7]), Some(m));
    bad.node(json!({"mesh": mesh}), true);
    refused(
        load_written(&dir, "index.gltf", &bad.gltf_embedded()),
        "meshes[0] primitives[0] accessors[1]",
        "index 2 is 7",
    );
    // A buffer file that is not there.
    let (text, _) = one_triangle(lit.clone()).gltf_with_bin("gone.bin");
    refused(load_written(&dir, "gone.gltf", &text), "buffers[0]", "does not exist");
    // A buffer shorter than the accessors read.
    let text = one_triangle(lit.clone()).gltf_embedded().replace("\"byteLength\":42", "\"byteLength\":40");
    assert!(load_written(&dir, "short.gltf", &text).is_err());
    // Out-of-range factors, a node cycle, a non-glTF file.
    let metal =
        one_triangle(json!({"emissiveFactor": [1.0, 1.0, 1.0], "pbrMetallicRoughness": {"metallicFactor": 1.5}}));
    refused(
        load_written(&dir, "metal.gltf", &metal.gltf_embedded()),
        "materials[0]",
        "metallicFactor must be in [0, 1]",
    );
    let mut cycle = one_triangle(lit.clone());
    cycle.nodes[0]["children"] = json!([0]);
    assert!(load_written(&dir, "cycle.gltf", &cycle.gltf_embedded()).is_err());
    refused(load_written(&dir, "junk.glb", "not a model"), "glTF", "not a glTF 2.0 file");
    // Lines and points are reported, not rendered: with nothing else, no triangles remain.
    let mut lines = one_triangle(lit);
    lines.meshes[0]["primitives"][0]["mode"] = json!(1);
    refused(load_written(&dir, "lines.gltf", &lines.gltf_embedded()), "meshes", "no triangles");
    // A model too large for f32 (scene::EXTENT_RANGE): a triangle 1e12 across.
    let mut huge = GltfWriter::default();
    let m = huge.material(json!({"emissiveFactor": [1.0, 1.0, 1.0]}));
    let mesh = huge.mesh(&[[0.0, 0.0, 0.0], [1e12, 0.0, 0.0], [0.0, 1e12, 0.0]], None, Some(m));
    huge.node(json!({"mesh": mesh}), true);
    refused(load_written(&dir, "huge.gltf", &huge.gltf_embedded()), "meshes, lights", "radius 1e-7 to 1e10");
}

#[test]
fn test05_a_gltf_shape_in_a_toml_room_with_transform_and_material_override() {
    let dir = Scratch::new("gltf", "shape");
    let mut w = one_triangle(
        json!({"name": "gold", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.8, 0.3, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.3}}),
    );
    w.lights.push(json!({"type": "point", "intensity": 1.0}));
    w.node(json!({"extensions": {"KHR_lights_punctual": {"light": 0}}}), true);
    std::fs::write(dir.join("model.glb"), w.glb()).unwrap();
    let shape =
        "[[shapes]]\ntype = \"gltf\"\nfile = \"model.glb\"\ntransform = { scale = 2.0, translate = [0, 1, 0] }\n";
    let text = common::scenes::edited(&[("[[shapes]]", &format!("{shape}\n[[shapes]]"))]);
    let scene = load_written(&dir, "room.toml", &text).unwrap();
    let model = &scene.surfaces[0];
    assert_eq!(model.origin, "shapes[0] (gltf \"model.glb\") nodes[0] \"tri\" meshes[0] primitives[0]");
    assert_eq!(
        model.triangles[0].vertices,
        [DVec3::new(0.0, 1.0, 0.0), DVec3::new(2.0, 1.0, 0.0), DVec3::new(0.0, 3.0, 0.0)]
    );
    let gold = &scene.materials[model.triangles[0].material as usize];
    assert!(matches!(gold.kind, MaterialKind::Phong { .. }), "{gold:?}");
    assert!(scene.notes.iter().any(|n| n.contains("lights") && n.contains("ignored")), "{:?}", scene.notes);
    // `material` overrides every primitive's.
    let text = common::scenes::edited(&[("[[shapes]]", &format!("{shape}material = \"white\"\n\n[[shapes]]"))]);
    let scene = load_written(&dir, "room.toml", &text).unwrap();
    assert_eq!(scene.materials[scene.surfaces[0].triangles[0].material as usize].name, "white");
    assert_eq!(scene.materials.len(), 1);
}

/// A real-world model no one here wrote: the Khronos sample "2CylinderEngine" (donated by
/// Okino Computer Graphics, CC-BY 4.0) as Debian's assimp-testmodels ships it (.ci/run
/// installs it; scenes/LICENSES.md). It is placed in a lit TOML room and rendered.
#[test]
fn test06_a_real_world_gltf_loads_and_renders() {
    let Some(engine_room) = common::scenes::engine_room() else { return };
    let scene = scene::load(&engine_room).unwrap();
    let triangles: usize = scene.surfaces.iter().map(|s| s.triangles.len()).sum();
    assert!(triangles > 50_000, "{triangles} triangles");
    let Some(ctx) = common::gpu() else { return };
    let mut options = RenderOptions::from_scene(&scene);
    (options.width, options.height) = (48, 36);
    options.iterations = 4;
    options.hemicube_resolution = Some(64);
    options.bundle_resolution = Some(64);
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    let image = render(&ctx, &scene, &patches, &options).unwrap().image;
    let lit = image.pixels.iter().filter(|p| p.iter().all(|&c| c.is_finite()) && p[1] > 0.0).count();
    assert!(lit > image.pixels.len() / 2, "{lit} of {} pixels lit", image.pixels.len());
}
