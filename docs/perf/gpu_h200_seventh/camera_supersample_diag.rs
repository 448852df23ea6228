// Temporary diagnostic (not committed): per_pixel test20 on an NVIDIA GPU.
mod common;
use firstshot::image::Image;
use firstshot::render::{RenderOptions, render};
use firstshot::scene;
use firstshot::stages::image_estimate::GatherChoice;

fn count(a: &Image, b: &Image) -> (usize, f64, f32) {
    let differ = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .filter(|(p, q)| (0..3).any(|c| (p[c] - q[c]).abs() > 1e-5 * q[c].abs().max(1e-2)))
        .count();
    let (mut d2, mut b2, mut mx) = (0f64, 0f64, 0f32);
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for c in 0..3 {
            d2 += ((p[c] - q[c]) as f64).powi(2);
            b2 += (q[c] as f64).powi(2);
            mx = mx.max((p[c] - q[c]).abs() / q[c].abs().max(1e-2));
        }
    }
    (differ, (d2 / b2).sqrt(), mx)
}

#[test]
fn diag() {
    let Some(ctx) = common::gpu() else { return };
    let out = std::path::PathBuf::from(std::env::var("FIRSTSHOT_DIAG_OUT").unwrap_or("/tmp/diag".into()));
    std::fs::create_dir_all(&out).unwrap();
    let scenes = [
        ("sp", common::scenes::shipped("sierpinski"), false),
        ("cb", std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("benches/scenes/cornell_box_4cameras.toml"), true),
    ];
    for (name, path, all_cameras) in scenes {
        let scene = scene::load(&path).unwrap();
        let mut options = RenderOptions::from_scene(&scene);
        (options.width, options.height, options.iterations, options.burn_in) = (48, 48, 24, Some(2));
        options.wide_lines = Some(1);
        if all_cameras {
            options.cameras = scene
                .cameras
                .iter()
                .map(|c| scene::NamedCamera { camera: scene::Camera { width: 48, height: 48, ..c.camera }, ..c.clone() })
                .collect();
        }
        let patches = scene::tessellate(&scene, options.patch_size).unwrap();
        let mut runs = Vec::new();
        for gather in [GatherChoice::Fused, GatherChoice::Split] {
            for s in [1, 4] {
                for rep in 0..2 {
                    let o = RenderOptions { camera_supersample: Some(s), gather, ..options.clone() };
                    let r = render(&ctx, &scene, &patches, &o).unwrap();
                    let views: Vec<Image> = std::iter::once(r.image).chain(r.other_views.into_iter().map(|v| v.image)).collect();
                    for (v, im) in views.iter().enumerate() {
                        im.write_exr(&out.join(format!("{name}_{gather:?}_s{s}_r{rep}_v{v}.exr")), &[]).unwrap();
                    }
                    runs.push((format!("{gather:?} s{s} r{rep}"), views));
                }
            }
        }
        for i in 0..runs.len() {
            for j in i + 1..runs.len() {
                let line: Vec<String> = runs[i].1.iter().zip(&runs[j].1).map(|(a, b)| {
                    let (d, r, m) = count(a, b);
                    format!("{d} ({r:.1e}, max {m:.1e})")
                }).collect();
                eprintln!("{name}: {} vs {}: {}", runs[i].0, runs[j].0, line.join(" | "));
            }
        }
    }
}
