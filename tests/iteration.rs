//! The stochastic iteration against closed-form answers.

mod common;

use common::*;
use firstshot::render::{RenderOptions, render};
use firstshot::scene::{Material, MaterialKind, Patches};
use glam::DVec3;

/// A closed room of diffuse walls with albedo `albedo` and emission `emission`, seen from
/// inside. Its radiance is emission / (1 - albedo) everywhere.
fn furnace(albedo: f32, emission: f32) -> (firstshot::scene::Scene, Patches) {
    let mut scene = bare_scene();
    scene.camera.position = DVec3::new(0.2, 0.1, -0.6);
    scene.camera.look_at = DVec3::new(0.0, 0.0, 1.0);
    scene.camera.fov_y = 90.0;
    scene.materials = vec![Material { name: "wall".into(), kind: MaterialKind::Diffuse { albedo: [albedo; 3] } }];
    let tris: Vec<_> =
        room(DVec3::new(-1.0, -0.8, -1.2), DVec3::new(1.3, 0.9, 1.1)).into_iter().flat_map(|t| split(t, 3)).collect();
    let mut patches = patches_of(&tris, vec![]);
    for p in &mut patches.patches {
        p.material = Some(0);
        p.emission = [emission; 3];
    }
    (scene, patches)
}

fn options(scene: &firstshot::scene::Scene, iterations: u32, seed: u64) -> RenderOptions {
    let mut o = RenderOptions::from_scene(scene);
    o.iterations = iterations;
    o.seed = seed;
    o.bundle_resolution = 64;
    o.first_shot = false;
    o
}

#[test]
fn test01_furnace_converges_to_emission_over_one_minus_albedo() {
    let Some(ctx) = gpu() else { return };
    let (scene, patches) = furnace(0.5, 1.0);
    let image = render(&ctx, &scene, &patches, &options(&scene, 400, 1)).unwrap().image;
    let mean = image.mean();
    let worst = image.pixels.iter().map(|p| (p[0] as f64 - 2.0).abs()).fold(0.0, f64::max);
    eprintln!("furnace: mean {mean:?}, worst pixel deviation {worst}");
    for c in 0..3 {
        assert!((mean[c] - 2.0).abs() < 0.02, "mean {mean:?}");
    }
}
