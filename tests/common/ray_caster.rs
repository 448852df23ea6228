//! A small CPU ray caster over the loaded scene's triangles: the tests' independent oracle
//! of visibility and of direct light. It shares no code with the product's GPU path (only
//! the loaded scene, its input).

use firstshot::scene::{Camera, Light, MaterialKind, Scene};
use glam::DVec3;

/// One triangle: vertices, unit front normal, grey diffuse albedo (0 for a light's own).
pub struct Tri {
    pub v: [DVec3; 3],
    pub n: DVec3,
    pub albedo: f64,
}

pub struct Caster {
    pub tris: Vec<Tri>,
}

impl Caster {
    /// Every surface triangle (diffuse, grey albedo taken from the red channel) and every
    /// area light's quad (black, it reflects nothing).
    pub fn new(scene: &Scene) -> Caster {
        let mut tris = Vec::new();
        for s in &scene.surfaces {
            for t in &s.triangles {
                let albedo = match scene.materials[t.material as usize].kind {
                    MaterialKind::Diffuse { albedo } => albedo[0] as f64,
                    MaterialKind::Phong { .. } => panic!("the ray caster knows diffuse materials only"),
                };
                let n = (t.vertices[1] - t.vertices[0]).cross(t.vertices[2] - t.vertices[0]).normalize();
                tris.push(Tri { v: t.vertices, n, albedo });
            }
        }
        for l in &scene.lights {
            if let Light::Area { vertices: [a, b, c, d], .. } = *l {
                for v in [[a, b, c], [a, c, d]] {
                    tris.push(Tri { v, n: (v[1] - v[0]).cross(v[2] - v[0]).normalize(), albedo: 0.0 });
                }
            }
        }
        Caster { tris }
    }

    /// The nearest triangle hit by origin + t dir, t in (t_min, t_max).
    pub fn hit(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<(f64, usize)> {
        let mut best: Option<(f64, usize)> = None;
        for (i, tri) in self.tris.iter().enumerate() {
            let e1 = tri.v[1] - tri.v[0];
            let e2 = tri.v[2] - tri.v[0];
            let p = dir.cross(e2);
            let det = e1.dot(p);
            if det.abs() < 1e-300 {
                continue;
            }
            let s = origin - tri.v[0];
            let u = s.dot(p) / det;
            let q = s.cross(e1);
            let v = dir.dot(q) / det;
            let t = e2.dot(q) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > t_min && t < t_max && best.is_none_or(|b| t < b.0) {
                best = Some((t, i));
            }
        }
        best
    }

    /// Whether anything lies strictly between a and b (leaving out 1e-9 of the segment at
    /// each end, where a and b lie on surfaces themselves).
    pub fn occluded(&self, a: DVec3, b: DVec3) -> bool {
        self.hit(a, b - a, 1e-9, 1.0 - 1e-9).is_some()
    }
}

/// The ray through image point (px, py) (pixels, from the top-left corner) of the camera,
/// as SCENE_FORMAT defines it: right = forward x up, top = up made orthogonal.
pub fn camera_ray(camera: &Camera, width: u32, height: u32, px: f64, py: f64) -> (DVec3, DVec3) {
    let forward = (camera.look_at - camera.position).normalize();
    let right = forward.cross(camera.up).normalize();
    let up = right.cross(forward);
    let tan_y = (camera.fov_y.to_radians() / 2.0).tan();
    let tan_x = tan_y * width as f64 / height as f64;
    let x = (2.0 * px / width as f64 - 1.0) * tan_x;
    let y = (1.0 - 2.0 * py / height as f64) * tan_y;
    (camera.position, (forward + x * right + y * up).normalize())
}

/// The centres of the cells of an n x n grid over pixel (px, py), row by row, as image
/// points for `camera_ray`: the camera's samples are uniform over a pixel, so its value
/// converges to the mean over such points.
pub fn pixel_grid(px: u32, py: u32, n: u32) -> impl Iterator<Item = (f64, f64)> {
    (0..n * n)
        .map(move |k| (px as f64 + ((k % n) as f64 + 0.5) / n as f64, py as f64 + ((k / n) as f64 + 0.5) / n as f64))
}
