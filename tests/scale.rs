//! Scenes beyond one storage binding: the per-patch arrays split over pages, a buffer each
//! (`gpu::scene_buffers::PerPatch`), read through the generated `<name>_at` accessors. A
//! render whose arrays are cut into many small pages (`RenderOptions::page_bytes`, which
//! emulates a device with small bindings) must be the render of one page, bit for bit.

mod common;

use firstshot::checkpoint::Checkpoint;
use firstshot::gpu::scene_buffers::{
    FIRST_SHOT_PAIRS, IMAGE_SENDERS, OUTGOING, PAGED_ARRAYS, PATCH_STATE, PATCH_TABLE, TRANSFER_SUMS,
};
use firstshot::image::Image;
use firstshot::render::{Hooks, RenderOptions, Rendered, render_with};
use firstshot::scene;

/// Keeps the state of the end of the run.
#[derive(Default)]
struct FinalState(Option<Vec<u8>>);

impl Hooks for FinalState {
    fn wants_final_checkpoint(&self) -> bool {
        true
    }
    fn checkpoint(&mut self, checkpoint: Checkpoint, _images: &[Image]) -> firstshot::Result<()> {
        self.0 = Some(checkpoint.state);
        Ok(())
    }
}

fn run(
    ctx: &firstshot::gpu::Context,
    scene: &scene::Scene,
    patches: &scene::Patches,
    options: &RenderOptions,
) -> (Rendered, Vec<u8>) {
    let mut hooks = FinalState::default();
    let rendered = render_with(ctx, scene, patches, options, None, &mut hooks).expect("renders");
    (rendered, hooks.0.expect("a final checkpoint"))
}

#[test]
fn test01_paged_per_patch_arrays_give_the_same_bits() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load(&common::scenes::shipped("cornell_box")).unwrap();
    let mut options = RenderOptions::from_scene(&scene);
    (options.width, options.height) = (40, 30);
    (options.patch_size, options.hemicube_resolution, options.shadow_resolution) = (60.0, Some(64), Some(64));
    (options.bundle_resolution, options.iterations, options.burn_in) = (Some(64), 12, Some(2));
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    let n = patches.patches.len() as u64;
    assert!(n > 100, "{n} patches");
    // Pages of 13.4 bytes a patch and a little: the patch table (96 bytes a patch) and the
    // state (144) take 8 and 11 pages, the image's senders 3, the vec4 arrays and the
    // transfer sums 2, so that every paged array has a page past the first and the 8-page
    // ones most of theirs.
    let page = 67 * n / 5 + 96;
    let pages = |a: firstshot::gpu::scene_buffers::PerPatch| n.div_ceil(a.patches_per_page(page));
    assert_eq!(pages(PATCH_TABLE), 8);
    assert_eq!(pages(PATCH_STATE), 11);
    assert_eq!(pages(OUTGOING), 2);
    assert_eq!(pages(IMAGE_SENDERS), 3);
    assert_eq!(pages(TRANSFER_SUMS), 2);
    assert!(PAGED_ARRAYS.iter().all(|&a| pages(a) >= 2 && pages(a) <= a.pages as u64));
    // The first shot's pairs (4 to 5 a patch) take 5 or 6 of their 8 pages.
    let pair_pages = |pairs: u64| pairs.div_ceil(FIRST_SHOT_PAIRS.patches_per_page(page));

    let (whole, whole_state) = run(&ctx, &scene, &patches, &options);
    let paged_options = RenderOptions { page_bytes: Some(page), ..options.clone() };
    let (paged, paged_state) = run(&ctx, &scene, &patches, &paged_options);
    assert_eq!(whole.stats.first_shot_pairs, paged.stats.first_shot_pairs);
    let pairs = whole.stats.first_shot_pairs as u64;
    assert!((2..=FIRST_SHOT_PAIRS.pages as u64).contains(&pair_pages(pairs)), "{pairs} pairs");
    assert_eq!(whole_state.len() as u64, n * PATCH_STATE.bytes);
    assert!(whole_state.iter().any(|&b| b != 0), "the state moved");
    assert!(whole_state == paged_state, "the paged state differs");
    let bits = |s: &[[f32; 4]]| s.iter().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
    assert!(bits(&whole.image_sum) == bits(&paged.image_sum), "the paged image sum differs");
    assert!(whole.image_sum.iter().all(|p| p[3] > 0.0), "every pixel has estimates");
    assert_eq!(whole.image.pixels, paged.image.pixels);

    // One page less than the 8 of the patch table is refused before any GPU work, with the
    // figures.
    let small = RenderOptions { page_bytes: Some(96 * n.div_ceil(8) - 96), ..options.clone() };
    match render_with(&ctx, &scene, &patches, &small, None, &mut FinalState::default()) {
        Err(e @ firstshot::Error::Limits(_)) => {
            let message = e.to_string();
            for part in [&format!("{n} patches"), "the patch table", "8 pages", "--patch-size"] {
                assert!(message.contains(part), "{message:?} lacks {part:?}");
            }
        }
        Err(e) => panic!("expected a limits refusal, got {e}"),
        Ok(_) => panic!("expected a limits refusal, it rendered"),
    }
}

#[test]
fn test02_a_paged_first_shot_pair_list_gives_the_same_bits() {
    // The first shot's pair list (16 bytes a pair, bounded by the windows' pixels, not by
    // the patches) is paged too: pages of 12 bytes a pair put it in 2, the per-patch arrays
    // in 1 or 2.
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load(&common::scenes::shipped("cornell_box")).unwrap();
    let mut options = RenderOptions::from_scene(&scene);
    (options.width, options.height) = (24, 24);
    (options.patch_size, options.hemicube_resolution, options.shadow_resolution) = (60.0, Some(64), Some(64));
    (options.bundle_resolution, options.iterations, options.burn_in) = (Some(64), 4, Some(1));
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    let (whole, whole_state) = run(&ctx, &scene, &patches, &options);
    let pairs = whole.stats.first_shot_pairs as u64;
    assert!(pairs > patches.patches.len() as u64, "{pairs} pairs");
    let page = 12 * pairs;
    assert_eq!(pairs.div_ceil(FIRST_SHOT_PAIRS.patches_per_page(page)), 2);
    let (paged, paged_state) = run(&ctx, &scene, &patches, &RenderOptions { page_bytes: Some(page), ..options });
    assert_eq!(paged.stats.first_shot_pairs as u64, pairs);
    assert!(whole_state == paged_state, "the paged state differs");
    let bits = |s: &[[f32; 4]]| s.iter().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
    assert!(bits(&whole.image_sum) == bits(&paged.image_sum), "the paged image sum differs");
}
