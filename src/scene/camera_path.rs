//! Camera paths (walkthroughs, docs/CAMERA_PATH.md): a TOML file of keyframes, each a
//! position and a point looked at (and optionally an up direction and a field of view,
//! else the scene camera's), and the camera of every frame, interpolated between them.
//!
//! Interpolation is a uniform Catmull-Rom spline through the keyframes (the end keyframes
//! repeated as their own outer neighbours), of position, look_at, up and fov_y alike: it
//! passes through every keyframe with a continuous first derivative, so the camera moves
//! without jerks at the keyframes. Frame f of N sits at f (K - 1) / (N - 1) keyframe
//! intervals from the first (K keyframes): the first frame is the first keyframe, the last
//! the last one.

use super::Camera;
use super::load::{Context, Tbl, parse_toml, show};
use crate::{Error, Result};
use glam::DVec3;
use std::path::{Path, PathBuf};

const TOP_KEYS: &[&str] = &["format", "keyframes"];
const KEYFRAME_KEYS: &[&str] = &["position", "look_at", "up", "fov_y"];

/// One keyframe of a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keyframe {
    pub position: DVec3,
    pub look_at: DVec3,
    pub up: DVec3,
    /// Full vertical field of view, degrees.
    pub fov_y: f64,
}

/// A loaded, checked camera path.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraPath {
    /// The file it came from (errors name it).
    pub source: PathBuf,
    /// At least one.
    pub keyframes: Vec<Keyframe>,
}

/// Loads a path file; `up` and `fov_y` default to `camera`'s. Errors name the file, the key
/// and what was expected, as the scene loader's.
pub fn load_path(path: &Path, camera: &Camera) -> Result<CameraPath> {
    let bytes = crate::files::read_named_input(path)?;
    let text = String::from_utf8(bytes).map_err(|_| Error::scene(path, "file", "not UTF-8 text"))?;
    load_path_str(&text, path, camera)
}

/// As `load_path`, from the text; `source` names the file in errors.
pub fn load_path_str(text: &str, source: &Path, camera: &Camera) -> Result<CameraPath> {
    let root = parse_toml(text, source)?;
    let cx = Context { file: source };
    let root = Tbl { cx: &cx, key: String::new(), table: &root };
    let format = root.req("format", "format = 1")?.integer(i64::MIN, i64::MAX)?;
    if format != 1 {
        return Err(cx.err("format", format!("unsupported format {format}: this build reads camera paths of format 1")));
    }
    root.only(TOP_KEYS)?;
    let tables = root.req("keyframes", "[[keyframes]] tables, each with position and look_at")?;
    let tables = tables.tables("[[keyframes]] tables, each with position and look_at")?;
    if tables.is_empty() {
        return Err(cx.err("keyframes", "required: at least one [[keyframes]] table"));
    }
    let mut keyframes = Vec::with_capacity(tables.len());
    for t in &tables {
        t.only(KEYFRAME_KEYS)?;
        let position = t.req("position", "3 numbers")?.vec3()?;
        let look_at_item = t.req("look_at", "3 numbers")?;
        let look_at = look_at_item.vec3()?;
        let up = match t.get("up") {
            Some(u) => {
                let up = u.vec3()?;
                if up.try_normalize().is_none() {
                    return Err(u.err("must not be zero"));
                }
                up
            }
            None => camera.up,
        };
        let fov_y = match t.get("fov_y") {
            Some(f) => {
                let fov = f.number()?;
                if !(fov > 0.0 && fov < 180.0) {
                    return Err(f.err(format!("must be > 0 and < 180 (degrees), got {fov}")));
                }
                fov
            }
            None => camera.fov_y,
        };
        let key = Keyframe { position, look_at, up, fov_y };
        if let Err(message) = check(&key) {
            return Err(look_at_item.err(message));
        }
        keyframes.push(key);
    }
    Ok(CameraPath { source: source.to_path_buf(), keyframes })
}

/// Whether a keyframe (or an interpolated camera) gives a view: look_at apart from the
/// position, up not along the view direction, fov_y in (0, 180).
fn check(k: &Keyframe) -> std::result::Result<(), String> {
    let Some(forward) = (k.look_at - k.position).try_normalize() else {
        return Err(format!("must differ from position, both are {}", show(k.position)));
    };
    let Some(up) = k.up.try_normalize() else {
        return Err("the up direction is zero".into());
    };
    // As the scene's cameras (load.rs): below this sine right = forward x up has no
    // reliable direction.
    if forward.cross(up).length() < 1e-6 {
        return Err(format!(
            "the view direction (look_at - position = {}) is parallel to up {}",
            show(k.look_at - k.position),
            show(k.up)
        ));
    }
    if !(k.fov_y > 0.0 && k.fov_y < 180.0) {
        return Err(format!("the field of view {} is not in (0, 180) degrees", k.fov_y));
    }
    Ok(())
}

/// The uniform Catmull-Rom segment from `p1` (t = 0) to `p2` (t = 1).
fn catmull_rom<T>(p0: T, p1: T, p2: T, p3: T, t: f64) -> T
where
    T: std::ops::Mul<f64, Output = T> + std::ops::Add<Output = T> + std::ops::Sub<Output = T> + Copy,
{
    let (t2, t3) = (t * t, t * t * t);
    (p1 * 2.0 + (p2 - p0) * t + (p0 * 2.0 - p1 * 5.0 + p2 * 4.0 - p3) * t2 + (p1 * 3.0 - p0 - p2 * 3.0 + p3) * t3) * 0.5
}

impl CameraPath {
    /// The path with every keyframe's position and look_at moved by `by`: into a scene's
    /// own coordinates, `-Scene::file_origin` (the file's are the scene file's).
    pub fn moved(mut self, by: DVec3) -> Self {
        for k in &mut self.keyframes {
            k.position += by;
            k.look_at += by;
        }
        self
    }

    /// The keyframe at `u` keyframe intervals from the first (0 <= u <= K - 1).
    pub fn at(&self, u: f64) -> Keyframe {
        let k = &self.keyframes;
        let last = k.len() - 1;
        if last == 0 {
            return k[0];
        }
        let u = u.clamp(0.0, last as f64);
        let i = (u.floor() as usize).min(last - 1);
        let t = u - i as f64;
        let pick = |j: isize| k[j.clamp(0, last as isize) as usize];
        let [a, b, c, d] = [-1, 0, 1, 2].map(|o| pick(i as isize + o));
        Keyframe {
            position: catmull_rom(a.position, b.position, c.position, d.position, t),
            look_at: catmull_rom(a.look_at, b.look_at, c.look_at, d.look_at, t),
            up: catmull_rom(a.up, b.up, c.up, d.up, t),
            fov_y: catmull_rom(a.fov_y, b.fov_y, c.fov_y, d.fov_y, t),
        }
    }

    /// The cameras of `frames` frames (frame f at f (K - 1) / (frames - 1) intervals), at
    /// `width` x `height`. An interpolated camera that gives no view (the spline passes
    /// look_at through the position between two keyframes) is an error naming the frame
    /// and the keyframes around it.
    pub fn cameras(&self, frames: u32, width: u32, height: u32) -> Result<Vec<Camera>> {
        let intervals = (self.keyframes.len() - 1) as f64;
        (0..frames)
            .map(|f| {
                let u = if frames <= 1 { 0.0 } else { f as f64 * intervals / (frames - 1) as f64 };
                let k = self.at(u);
                check(&k).map_err(|message| {
                    let i = (u.floor() as usize).min(self.keyframes.len().saturating_sub(2));
                    Error::scene(
                        &self.source,
                        format!("keyframes[{i}] to keyframes[{}]", i + 1),
                        format!("frame {f} of {frames}: {message}; move these keyframes apart or add one between them"),
                    )
                })?;
                Ok(Camera { position: k.position, look_at: k.look_at, up: k.up, fov_y: k.fov_y, width, height })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> Camera {
        Camera { position: DVec3::ZERO, look_at: DVec3::Z, up: DVec3::Y, fov_y: 40.0, width: 8, height: 8 }
    }

    #[test]
    fn test01_frames_pass_through_the_keyframes_and_defaults_come_from_the_scene() {
        let text = "format = 1\n[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\n\
                    [[keyframes]]\nposition = [1, 0, 0]\nlook_at = [1, 0, 1]\nfov_y = 60\n\
                    [[keyframes]]\nposition = [3, 1, 0]\nlook_at = [3, 0, 1]\nup = [0, 0, -1]\n";
        let path = load_path_str(text, Path::new("p.toml"), &base()).unwrap();
        assert_eq!(path.keyframes.len(), 3);
        assert_eq!((path.keyframes[0].up, path.keyframes[0].fov_y), (DVec3::Y, 40.0));
        assert_eq!((path.keyframes[2].up, path.keyframes[2].fov_y), (DVec3::new(0.0, 0.0, -1.0), 40.0));
        // 5 frames over 2 intervals: frames 0, 2, 4 are the keyframes exactly.
        let cams = path.cameras(5, 8, 8).unwrap();
        for (f, k) in [(0, 0), (2, 1), (4, 2)] {
            assert!((cams[f].position - path.keyframes[k].position).length() < 1e-12, "frame {f}");
            assert!((cams[f].fov_y - path.keyframes[k].fov_y).abs() < 1e-12, "frame {f}");
        }
        // Between keyframes, on the spline: frame 1 between positions 0 and 1.
        assert!(cams[1].position.x > 0.0 && cams[1].position.x < 1.0, "{:?}", cams[1].position);
    }

    #[test]
    fn test02_the_spline_is_smooth_across_keyframes() {
        let keyframes: Vec<Keyframe> = [0.0, 1.0, 3.0, 3.5]
            .iter()
            .map(|&x| Keyframe {
                position: DVec3::new(x, x * x, 0.0),
                look_at: DVec3::Z * 5.0,
                up: DVec3::Y,
                fov_y: 40.0,
            })
            .collect();
        let path = CameraPath { source: "p".into(), keyframes };
        for knot in [1.0, 2.0] {
            let h = 1e-6;
            let left = (path.at(knot).position - path.at(knot - h).position) / h;
            let right = (path.at(knot + h).position - path.at(knot).position) / h;
            assert!((left - right).length() < 1e-3, "velocity jumps at keyframe {knot}: {left} against {right}");
        }
    }

    #[test]
    fn test03_refusals_name_the_file_and_the_key() {
        let cases = [
            ("[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\n", "format"),
            ("format = 1\n", "keyframes"),
            ("format = 1\nkeyframes = []\n", "keyframes"),
            ("format = 1\n[[keyframes]]\nposition = [0, 0, 0]\n", "keyframes[0].look_at"),
            ("format = 1\n[[keyframes]]\nposition = [0, 0]\nlook_at = [0, 0, 1]\n", "keyframes[0].position"),
            ("format = 1\n[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 0, 0]\n", "keyframes[0].look_at"),
            (
                "format = 1\n[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nfov_y = 180\n",
                "keyframes[0].fov_y",
            ),
            (
                "format = 1\n[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nup = [0, 0, 0]\n",
                "keyframes[0].up",
            ),
            ("format = 1\n[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nroll = 3\n", "keyframes[0].roll"),
            ("format = 1\n[[keyframes]]\nposition = [0, 0, 0]\nlook_at = [0, 1, 0]\n", "keyframes[0].look_at"),
        ];
        for (text, key) in cases {
            let e = load_path_str(text, Path::new("walk.toml"), &base()).expect_err(text).to_string();
            assert!(e.starts_with("walk.toml: ") && e.contains(key), "{text}: {e}");
        }
    }
}
