//! Stage-by-stage profiling of a bundle step (`gpu::profile`, `Iteration::profile_step`),
//! which the benchmark harness relies on: it must compute exactly what `record_step` does,
//! and opening a device with optional features must only ever enable what the adapter has.

mod common;

use common::*;
use firstshot::gpu::context::list_adapters;
use firstshot::gpu::profile::{StageTimer, TIMESTAMP_FEATURES};
use firstshot::gpu::{AdapterChoice, Context};
use firstshot::render::{NoHooks, RenderOptions, Renderer};
use firstshot::scene::{Material, MaterialKind, Patches};
use glam::DVec3;

const RESOLUTION: u32 = 64;
const PER_STEP: u32 = 4;
const BUNDLE_STAGES: [&str; 5] = ["clear", "reflect", "visibility", "transfer", "finalize"];

/// A closed diffuse room with glowing walls, seen from inside: every step has work in
/// every stage.
fn room_scene() -> (firstshot::scene::Scene, Patches) {
    let mut scene = bare_scene();
    scene.camera.position = DVec3::new(0.1, 0.0, -0.9);
    scene.materials = vec![Material { name: "wall".into(), kind: MaterialKind::Diffuse { albedo: [0.5; 3] } }];
    let tris: Vec<_> =
        room(DVec3::new(-1.0, -0.8, -1.2), DVec3::new(1.3, 0.9, 1.1)).into_iter().flat_map(|t| split(t, 3)).collect();
    let mut patches = patches_of(&tris, vec![]);
    for p in &mut patches.patches {
        p.material = Some(0);
        p.emission = [1.0; 3];
    }
    (scene, patches)
}

/// Three steps, recorded whole or profiled stage by stage: the state's and the image's
/// bits after them, the last step's fragments and the fragment bound.
fn three_steps(ctx: &Context, profiled: bool) -> (Vec<u8>, Vec<[f32; 3]>, u64, u64) {
    let (scene, patches) = room_scene();
    let options = RenderOptions {
        first_shot: false,
        iterations: 3,
        seed: 7,
        bundle_resolution: Some(RESOLUTION),
        // Every step reaches the image, so every stage runs.
        burn_in: Some(0),
        // Steps 0 and 2 estimate the direct light and gather, step 1 only gathers.
        direct_passes: 1,
        window_steps: 2,
        // Four bundles a step: each runs the bundle stages and its pixels' gather.
        bundles_per_step: Some(PER_STEP),
        ..RenderOptions::from_scene(&scene)
    };
    let mut renderer = Renderer::new(ctx, &scene, &patches, &options, &mut NoHooks).unwrap();
    let timer = StageTimer::new(ctx, 64);
    // The gather's passes, each its own stage: split on a CPU adapter (this scene has no first
    // shot, so no pass for near senders' first bounces), one fused pass elsewhere
    // (`image_estimate::fused_gather`).
    let gather: &[&str] = if ctx.summary.is_cpu() { &["gather", "gather_edges"] } else { &["gather"] };
    for k in 0..3 {
        if profiled {
            let times = renderer.profile_step(k, &timer, vec![]).unwrap();
            let names: Vec<&str> = times.iter().map(|t| t.name).collect();
            // The direct light on the first `direct_passes` steps and then every
            // `window_steps` steps (`render::DirectSchedule`), the gather every step.
            // Each of the step's bundles runs the bundle stages and then the gather of its
            // pixels; the camera and the direct light come once, after the first bundle.
            let mut expected = BUNDLE_STAGES.to_vec();
            expected.push("camera");
            if k % options.window_steps == 0 {
                expected.extend(["light_windows", "direct"]);
            }
            expected.extend(gather);
            for _ in 1..PER_STEP {
                expected.extend(BUNDLE_STAGES);
                expected.extend(gather);
            }
            assert_eq!(names, expected, "step {k}");
            assert!(times.iter().all(|t| t.wall_ms >= 0.0));
            assert_eq!(times.iter().all(|t| t.gpu_ms.is_some()), timer.has_timestamps());
        } else {
            renderer.submit_step(k);
        }
    }
    let radius = firstshot::gpu::scene_buffers::bounding_sphere(&patches).1;
    // `fragments` counts the step's bundles together.
    let bound = firstshot::iteration::fragment_bound(&patches, radius, RESOLUTION) * PER_STEP as u64;
    let image = renderer.read_image().unwrap().pixels;
    (renderer.read_state().unwrap(), image, renderer.fragments().unwrap(), bound)
}

#[test]
fn test01_profiled_steps_compute_exactly_what_recorded_steps_do() {
    let Some(ctx) = gpu() else { return };
    let (whole, image_whole, fragments_whole, bound) = three_steps(&ctx, false);
    let (profiled, image_profiled, fragments_profiled, _) = three_steps(&ctx, true);
    assert_eq!(whole, profiled, "stage by stage must leave the same state, bit for bit");
    let bits = |image: &[[f32; 3]]| image.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&image_whole), bits(&image_profiled), "and the same image, bit for bit");
    assert_eq!(fragments_whole, fragments_profiled);
    // A closed room: every line through it crosses at least two walls, so a step has
    // fragments, and never more than the geometric bound.
    assert!(fragments_whole > 0 && fragments_whole <= bound, "{fragments_whole} fragments, bound {bound}");
    assert!(whole.iter().any(|&b| b != 0), "the steps must have written the state");
}

#[test]
fn test02_optional_features_are_enabled_only_where_the_adapter_has_them() {
    let Some(plain) = gpu() else { return };
    assert!(plain.features().is_empty(), "the product path opens no optional feature");
    assert!(!StageTimer::new(&plain, 4).has_timestamps());
    let index = list_adapters().iter().position(|(a, _)| *a == plain.summary).expect("the test adapter is listed");
    let ctx = Context::new_with_features(&AdapterChoice::Index(index), TIMESTAMP_FEATURES).unwrap();
    assert_eq!(ctx.summary, plain.summary, "AdapterChoice::Index opens the adapter list_adapters shows there");
    assert_eq!(ctx.features(), TIMESTAMP_FEATURES & ctx.adapter.features());
    assert_eq!(StageTimer::new(&ctx, 4).has_timestamps(), ctx.features().contains(TIMESTAMP_FEATURES));
    eprintln!("{}: timestamps {}", ctx.summary, ctx.features().contains(TIMESTAMP_FEATURES));
}
