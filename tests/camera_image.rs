//! The camera item buffer and the emission image against an oracle that shares no code with
//! them: the exact area of each pixel covered by the projected triangle (polygon clipping).

mod common;

use firstshot::render::{RenderOptions, render};
use firstshot::scene::{Camera, Patch, Patches, Scene, Settings};
use glam::{DVec2, DVec3};

fn scene(camera: Camera, environment: [f32; 3]) -> Scene {
    Scene {
        source: "test".into(),
        camera,
        cameras: vec![firstshot::scene::NamedCamera { name: "camera".into(), camera }],
        environment,
        settings: Settings::default(),
        materials: vec![],
        surfaces: vec![],
        lights: vec![],
        notes: vec![],
        file_origin: glam::DVec3::ZERO,
    }
}

fn patch(v: [DVec3; 3], emission: [f32; 3], twin: bool) -> Patch {
    Patch { emission, twin, ..common::patch(v) }
}

fn camera(position: DVec3, width: u32, height: u32) -> Camera {
    Camera { position, look_at: DVec3::ZERO, up: DVec3::Y, fov_y: 40.0, width, height }
}

/// Screen position in pixels (x right, y down) of a scene point, from the camera contract.
fn project(cam: &Camera, p: DVec3) -> DVec2 {
    let forward = (cam.look_at - cam.position).normalize();
    let right = forward.cross(cam.up).normalize();
    let up = right.cross(forward);
    let rel = p - cam.position;
    let z = rel.dot(forward);
    let tan_y = (cam.fov_y.to_radians() / 2.0).tan();
    let tan_x = tan_y * cam.width as f64 / cam.height as f64;
    let ndc = DVec2::new(rel.dot(right) / z / tan_x, rel.dot(up) / z / tan_y);
    DVec2::new((ndc.x + 1.0) / 2.0 * cam.width as f64, (1.0 - ndc.y) / 2.0 * cam.height as f64)
}

/// Area of a convex polygon clipped to the unit pixel square at (x, y) (Sutherland-Hodgman).
fn covered(poly: &[DVec2], x: f64, y: f64) -> f64 {
    let mut pts = poly.to_vec();
    let planes: [(DVec2, f64); 4] = [(DVec2::X, x), (-DVec2::X, -(x + 1.0)), (DVec2::Y, y), (-DVec2::Y, -(y + 1.0))];
    for (n, d) in planes {
        let inside = |p: DVec2| p.dot(n) >= d;
        let mut out = Vec::new();
        for i in 0..pts.len() {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                let t = (d - a.dot(n)) / (b - a).dot(n);
                out.push(a + (b - a) * t);
            }
        }
        pts = out;
        if pts.is_empty() {
            return 0.0;
        }
    }
    let mut area = 0.0;
    for i in 0..pts.len() {
        area += pts[i].perp_dot(pts[(i + 1) % pts.len()]);
    }
    area.abs() / 2.0
}

#[test]
fn emitting_triangle_covers_exactly_its_projection() {
    let Some(ctx) = common::gpu() else { return };
    let cam = camera(DVec3::new(0.3, 0.2, -5.0), 64, 48);
    // Counter-clockwise seen from the camera (front normal toward -z).
    let v = [DVec3::new(1.2, -0.9, 0.0), DVec3::new(-1.1, -0.4, 0.0), DVec3::new(0.2, 1.0, 0.5)];
    let tri = patch(v, [1.0, 2.0, 3.0], false);
    assert!(tri.normal.dot(cam.position - v[0]) > 0.0, "test triangle must face the camera");
    let env = [0.25, 0.5, 0.125];
    let sc = scene(cam, env);
    let patches = Patches { patches: vec![tri], ..Default::default() };
    let mut options = RenderOptions::from_scene(&sc);
    options.iterations = 0;
    let image = render(&ctx, &sc, &patches, &options).unwrap().image;
    let poly: Vec<DVec2> = v.iter().map(|&p| project(&cam, p)).collect();
    let (mut sum_expected, mut sum_image) = (0.0, 0.0);
    for y in 0..cam.height {
        for x in 0..cam.width {
            let c = covered(&poly, x as f64, y as f64);
            let got = image.at(x, y);
            for ch in 0..3 {
                let expected = c * tri.emission[ch] as f64 + (1.0 - c) * env[ch] as f64;
                let contrast = (tri.emission[ch] - env[ch]) as f64;
                if c == 0.0 || c == 1.0 {
                    // Every sample of the pixel lies on the same side of every edge.
                    let far_from_edge = (0..3).all(|k| {
                        let (a, b) = (poly[k], poly[(k + 1) % 3]);
                        let centre = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                        ((b - a).perp_dot(centre - a) / (b - a).length()).abs() > 0.75
                    });
                    if far_from_edge {
                        assert_eq!(got[ch] as f64, expected, "pixel ({x}, {y}) channel {ch}");
                    }
                }
                // 64 stratified samples: an edge through a pixel misclassifies at most one
                // row of 8 strata, 1/8 of the pixel.
                assert!(
                    (got[ch] as f64 - expected).abs() <= contrast / 8.0 + 1e-5,
                    "pixel ({x}, {y}) channel {ch}: {} against coverage {c}",
                    got[ch]
                );
                sum_expected += expected;
                sum_image += got[ch] as f64;
            }
        }
    }
    let rel = (sum_image - sum_expected).abs() / sum_expected;
    assert!(rel < 2e-3, "image total off by {rel}");
}

#[test]
fn back_faces_are_black_and_twins_show_the_front_one() {
    let Some(ctx) = common::gpu() else { return };
    let v = [DVec3::new(2.0, -2.0, 0.0), DVec3::new(-2.0, -2.0, 0.0), DVec3::new(0.0, 2.0, 0.0)];
    let front = patch(v, [1.0, 1.0, 1.0], true);
    let back = patch([v[0], v[2], v[1]], [5.0, 5.0, 5.0], true);
    let lone_back = patch([v[0], v[2], v[1]], [5.0, 5.0, 5.0], false);
    let env = [0.5; 3];
    let centre_of = |pos: DVec3, ps: Vec<Patch>| {
        let sc = scene(camera(pos, 16, 16), env);
        let patches = Patches { patches: ps, ..Default::default() };
        let mut options = RenderOptions::from_scene(&sc);
        options.iterations = 0;
        render(&ctx, &sc, &patches, &options).unwrap().image.at(8, 8)
    };
    // The front of `front` faces -z.
    assert_eq!(centre_of(DVec3::new(0.0, 0.0, -5.0), vec![front, back]), [1.0; 3]);
    assert_eq!(centre_of(DVec3::new(0.0, 0.0, -5.0), vec![back, front]), [1.0; 3]);
    assert_eq!(centre_of(DVec3::new(0.0, 0.0, 5.0), vec![front, back]), [5.0; 3]);
    // A one-sided patch seen from behind occludes and is black.
    assert_eq!(centre_of(DVec3::new(0.0, 0.0, -5.0), vec![lone_back]), [0.0; 3]);
}
