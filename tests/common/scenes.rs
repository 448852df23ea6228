//! Scene text for tests: the smallest scene that loads, edits of it, the shipped scenes.

use std::path::PathBuf;

/// The smallest scene that loads: one floor quad of one white material, lit by one point
/// light.
pub const MINIMAL: &str = r#"
format = 1

[camera]
position = [0, 1, -5]
look_at = [0, 1, 0]
up = [0, 1, 0]
fov_y = 40
width = 64
height = 48

[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[[shapes]]
type = "quad"
vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1]]
material = "white"

[[lights]]
type = "point"
position = [0, 3, 0]
power = [10, 10, 10]
"#;

/// A closed furnace: a 2 x 2 x 2 room whose walls emit 1 and reflect `albedo` on both sides,
/// so the radiance is exactly 1 / (1 - albedo) everywhere, seen from inside by a 32 x 32
/// camera; with `inner_box`, a box standing on the floor that emits and reflects as the room
/// (the radiance stays the same, also at the contact).
pub fn closed_furnace(albedo: f64, bundle_resolution: u32, inner_box: bool) -> String {
    let mut text = format!(
        r#"
format = 1
[camera]
position = [0.1, 0.6, -0.9]
look_at = [0.0, -0.4, 0.5]
up = [0.0, 1.0, 0.0]
fov_y = 70.0
width = 32
height = 32
[settings]
patch_size = 0.4
bundle_resolution = {bundle_resolution}
hemicube_resolution = 128
[materials.wall]
type = "diffuse"
albedo = [{albedo}, {albedo}, {albedo}]
[[shapes]]
type = "box"
min = [-1.0, -1.0, -1.0]
max = [1.0, 1.0, 1.0]
material = "wall"
two_sided = true
emission = [1.0, 1.0, 1.0]
"#
    );
    if inner_box {
        text.push_str(
            r#"
[[shapes]]
type = "box"
min = [-0.3, -1.0, -0.3]
max = [0.3, 0.2, 0.3]
material = "wall"
emission = [1.0, 1.0, 1.0]
"#,
        );
    }
    text
}

/// The furnace of albedo one half (radiance 2) at bundle resolution 128.
pub fn half_furnace(inner_box: bool) -> String {
    closed_furnace(0.5, 128, inner_box)
}

/// MINIMAL with each `(from, to)` replaced once (each `from` must occur).
pub fn edited(edits: &[(&str, &str)]) -> String {
    let mut text = MINIMAL.to_string();
    for (from, to) in edits {
        assert!(text.contains(from), "{from:?} is not in the scene");
        text = text.replacen(from, to, 1);
    }
    text
}

/// `scenes/<name>.toml` of the checkout.
pub fn shipped(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes").join(format!("{name}.toml"))
}

/// The glTF model scenes/engine_room.toml places: the Khronos sample "2CylinderEngine" as
/// Debian's assimp-testmodels installs it (`.ci/run` does).
pub const ENGINE_MODEL: &str = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";

/// The shipped engine_room scene when its model is installed. Without it: a failure under
/// `FIRSTSHOT_REQUIRE_SAMPLES` (CI), else `None` and a line that says what is left out.
pub fn engine_room() -> Option<PathBuf> {
    if std::path::Path::new(ENGINE_MODEL).is_file() {
        return Some(shipped("engine_room"));
    }
    assert!(
        std::env::var("FIRSTSHOT_REQUIRE_SAMPLES").is_err(),
        "FIRSTSHOT_REQUIRE_SAMPLES is set but {ENGINE_MODEL} is missing (apt-get install assimp-testmodels)"
    );
    eprintln!("SKIPPED: {ENGINE_MODEL} is missing (apt-get install assimp-testmodels)");
    None
}

/// Writes `text` as `scene.toml` in a scratch folder of its own (`group`/`test`) and loads
/// it; the folder lives as long as the returned `Scratch` (meshes beside it may be written
/// there too).
pub fn load_text(group: &str, test: &str, text: &str) -> (super::scratch::Scratch, firstshot::scene::Scene) {
    let scratch = super::scratch::Scratch::new(group, test);
    let path = scratch.join("scene.toml");
    super::scratch::write(&path, text);
    let scene = firstshot::scene::load(&path).unwrap();
    (scratch, scene)
}

/// `text` with every point moved by `offset`: the triples of the `position`, `look_at`,
/// `vertices`, `center` (a Sierpinski shape's), `min` and `max` (a box's) keys (directions,
/// `up` and colours stay).
pub fn moved(text: &str, offset: glam::DVec3) -> String {
    let shift = |triple: &str| -> String {
        let v: Vec<f64> = triple.split(',').map(|x| x.trim().parse().expect("a number")).collect();
        format!("[{}, {}, {}]", v[0] + offset.x, v[1] + offset.y, v[2] + offset.z)
    };
    text.lines()
        .map(|line| {
            let Some((key, value)) = line.split_once(" = ") else { return line.to_string() };
            if !matches!(key, "position" | "look_at" | "vertices" | "center" | "min" | "max") {
                return line.to_string();
            }
            // The innermost brackets hold the triples: each ']' closes the last '[' before it.
            let mut out = String::new();
            let mut rest = value;
            while let Some(close) = rest.find(']') {
                let Some(open) = rest[..close].rfind('[') else { break };
                out += &rest[..open];
                out += &shift(&rest[open + 1..close]);
                rest = &rest[close + 1..];
            }
            format!("{key} = {out}{rest}")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// `text` (a scene of quads, boxes, Sierpinski shapes and point, spot or area lights, no
/// meshes) in units `factor` times smaller: every position and length times `factor`, a
/// point light's power and a spot's intensity times its square, so that every irradiance and
/// radiance, and so the image, stays the same.
pub fn scaled(text: &str, factor: f64) -> String {
    let times = |value: &str, by: f64| -> String {
        let mut out = String::new();
        let mut number = String::new();
        let flush = |number: &mut String, out: &mut String| {
            if !number.is_empty() {
                let x: f64 = number.parse().expect("a number");
                *out += &format!("{:e}", x * by);
                number.clear();
            }
        };
        for c in value.chars() {
            if c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E') {
                number.push(c);
            } else {
                flush(&mut number, &mut out);
                out.push(c);
            }
        }
        flush(&mut number, &mut out);
        out
    };
    text.lines()
        .map(|line| {
            let Some((key, value)) = line.split_once(" = ") else { return line.to_string() };
            let (value, comment) = value.split_once('#').map_or((value, ""), |(v, c)| (v, c));
            let by = match key {
                "position" | "look_at" | "vertices" | "center" | "min" | "max" | "size" | "patch_size" => factor,
                "power" | "intensity" => factor * factor,
                _ => return line.to_string(),
            };
            let comment = if comment.is_empty() { String::new() } else { format!("#{comment}") };
            format!("{key} = {}{comment}", times(value, by))
        })
        .collect::<Vec<_>>()
        .join("\n")
}
