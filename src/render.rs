//! The order of the pipeline: tessellated scene on the GPU -> first shot -> iteration loop
//! -> image. `main.rs` and the tests call `render`.

use crate::checkpoint::Checkpoint;
use crate::direct_light::DirectLights;
use crate::first_shot::{self, FirstShotStats, LightWindow};
use crate::gpu::profile::{Stage, StageTime, StageTimer};
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{AdapterSummary, Context};
use crate::image::Image;
use crate::iteration::{BundleScene, Iteration};
use crate::layout::*;
use crate::memory::initial_fragment_capacity;
use crate::rng::StepRng;
use crate::scene::{Camera, Light, NamedCamera, Patches, Scene};
use crate::stages::camera_item_buffer::{CameraItemBuffer, gpu_camera};
use crate::stages::image_estimate::{ImageEstimate, ImagePipelines};
use crate::{Error, Result};
use serde::Serialize;
use std::borrow::Borrow;
use std::time::Instant;

/// Passes of an image without iteration (`--direct-passes`): each a camera sample per
/// pixel (stratified) and a point on every area light (stratified over its triangles), so
/// that edges are anti-aliased like the references and penumbrae converge.
pub const DEFAULT_DIRECT_PASSES: u32 = 64;

/// The iteration's image estimates the direct light on each of its first
/// min(`direct_passes`, FRONT_DIRECT_PASSES) steps, then on one in `window_steps`, where a
/// light samples a new point on every pass (an area light, a first-shot emitting shape).
/// More in front buys a short run little: the gathered indirect light, estimated on every
/// step, is then the larger error, and each direct estimate of an area light renders its
/// window again (the costliest image stage: 32 ms on the Sierpinski scene on lavapipe).
/// Measured (docs/PERFORMANCE.md, "Direct-light passes in front"): 16 in front instead of 64
/// raised the error by 0-4 % and took 14-18 % less time, 8 about as good as 16.
pub const FRONT_DIRECT_PASSES: u32 = 16;

/// The same where every light keeps its window for the whole run (point, spot and
/// directional lights, or none): then a pass differs from the next only in its camera
/// sample, so D's error is the aliasing of the edges that cross a pixel, which the passes
/// on one step in `window_steps` go on averaging, while the gather's error, estimated
/// every step, is far the larger. On cornell_point 2, 4, 8 and 16 passes in front gave the
/// same image errors within 1 % at 20, 50 and 200 steps, and 4 instead of 16 took 5-18 %
/// less time (docs/PERFORMANCE.md, "Direct-light passes in front").
pub const FRONT_DIRECT_PASSES_KEPT_WINDOWS: u32 = 4;

/// Which image steps estimate the direct light: the first `front`, then one in `every`
/// (`DirectSchedule::of`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DirectSchedule {
    pub front: u32,
    pub every: u32,
}

impl DirectSchedule {
    /// The schedule of a render of `scene` (as `patches` tessellate it) with `options`:
    /// min(`direct_passes`, FRONT_DIRECT_PASSES) in front where a light samples new points
    /// on each pass, min(`direct_passes`, FRONT_DIRECT_PASSES_KEPT_WINDOWS) where none does,
    /// then one in `window_steps`.
    pub fn of(scene: &Scene, patches: &Patches, options: &RenderOptions) -> DirectSchedule {
        let sampled = options.first_shot
            && (scene.lights.iter().any(|l| matches!(l, Light::Area { .. })) || !patches.emitters.is_empty());
        let front = if sampled { FRONT_DIRECT_PASSES } else { FRONT_DIRECT_PASSES_KEPT_WINDOWS };
        DirectSchedule { front: options.direct_passes.min(front), every: options.window_steps.max(1) }
    }

    /// Whether image step `i` (0 for the first step past the burn-in) estimates the direct
    /// light (it converges in far fewer samples than the gathered indirect light, which
    /// every step estimates).
    pub fn due(&self, i: u32) -> bool {
        due(i, self.front, self.every)
    }

    /// How many of the first `n` image steps estimate the direct light (`due`).
    pub fn estimates(&self, n: u32) -> u32 {
        estimates(n, self.front, self.every)
    }
}

/// Image steps per direct-light estimate by default, after the first `direct_passes`: the
/// windows and the direct light cost about as much as a bundle step on a CPU adapter, and a
/// 1000-step run still estimates the direct light 181 times (64 + 117), which leaves its
/// image error where it is with one in four (Cornell box 2.06% against 2.10%).
pub const DEFAULT_WINDOW_STEPS: u32 = 8;

/// The burn-in leaves out of the image the steps before the state J carries all but this
/// share of the light of further bounces.
pub const BURN_IN_TOLERANCE: f64 = 0.01;
/// At most this many burn-in steps, whatever the albedo.
pub const MAX_BURN_IN: u32 = 100;

/// What a render is asked to do; `from_scene` takes the scene's `[settings]`, flags then
/// override fields.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub patch_size: f64,
    pub iterations: u32,
    pub seed: u64,
    /// Pixels along a full cube-face edge of the first shot's item buffers; `None`: chosen
    /// from the patches the light samples see (`first_shot::auto_resolution`).
    pub hemicube_resolution: Option<u32>,
    pub light_window: LightWindow,
    /// Pixels along each edge of a bundle's parallel projection; `None`: chosen from the
    /// patches and the views (`iteration::auto_bundle_resolution`).
    pub bundle_resolution: Option<u32>,
    /// Whether lights are first shot (else area lights are emitters in the iteration).
    pub first_shot: bool,
    /// Stop the iteration (or the passes of a direct-light image) after this much wall time
    /// since the render began, if given. A limit that ends the run before any step reached
    /// the image (shorter than the first shot or the burn-in) gives a direct-light image.
    pub time_limit: Option<std::time::Duration>,
    /// Rows per band of the image sum; `None`: as many as one storage binding holds
    /// (`image_estimate::band_rows`). Set only by tests, to check that bands change nothing.
    pub image_band_rows: Option<u32>,
    /// Largest page, in bytes, of the per-patch arrays split over several buffers
    /// (`scene_buffers::PerPatch`); `None`: one storage binding of the device. Set only by
    /// tests, to emulate a smaller device and check that pages change nothing.
    pub page_bytes: Option<u64>,
    /// Refuse a run predicted to need more host memory than this many bytes (`memory`);
    /// `None`: what the host has available (`MemAvailable`).
    pub memory_limit: Option<u64>,
    /// Initial room of a bundle step for the fragments past its lines' buckets;
    /// `None`: `memory::initial_fragment_capacity`. Tests set it small to exercise the
    /// overflow-and-redo path.
    pub bundle_capacity: Option<u64>,
    /// Pixels along a full face edge of the lights' windows for the per-pixel direct light
    /// (less if the shadow memory budget needs it); `None`: chosen from the patches the
    /// lights see (`direct_light::auto_resolution`).
    pub shadow_resolution: Option<u32>,
    /// Passes of an image without iteration.
    pub direct_passes: u32,
    /// Steps that advance the state before any is averaged into the image; `None`: from
    /// the light's measured decay per bounce (`default_burn_in`).
    pub burn_in: Option<u32>,
    /// Steps of the iteration per estimate of the direct light (Le + D, with new points on
    /// the area lights and their window item buffers, the costliest image stages); the
    /// indirect light G is estimated every step.
    pub window_steps: u32,
    /// The cameras whose images one run makes from the same iteration (`--all-cameras`), each
    /// at its own `width` x `height`; empty: `scene.camera` at `width` x `height` above.
    pub cameras: Vec<NamedCamera>,
    /// Bundles a step draws, 1 or 4 (`iteration::BUNDLES_PER_STEP`): with 4, each pixel of a
    /// 2 x 2 block gathers through its own; `None`: chosen from the patches and the views
    /// (`iteration::auto_bundles_per_step`).
    pub bundles_per_step: Option<u32>,
    /// Fine lines along the edge of a bundle's wide line outside the fine window around the
    /// glossy patches: 1 (one level), 2 or 4 (`iteration::WIDE_LINES_CHOICES`); `None`:
    /// chosen from the patches and the views (`iteration::auto_wide_lines`).
    pub wide_lines: Option<u32>,
    /// The gather takes every sender's first reflection of the lights at the patch level
    /// (the paper's Lfs_j at the patch's centre) instead of per point
    /// (`first_bounce_per_point`, docs/ALGORITHM.md 6).
    pub patch_first_bounce: bool,
    /// Whether the gather finishes every pixel in one pass or lists some for passes of their
    /// own (`image_estimate::fused_gather`: by the adapter unless asked; the same image).
    pub gather: crate::stages::image_estimate::GatherChoice,
    /// Texels per pixel side of the views' camera item buffers, 1 or `CAMERA_SUPERSAMPLE`;
    /// `None`: by each view's size (`camera_item_buffer::camera_supersample`). Set only by
    /// tests, to check that the supersampled buffer changes nothing but the rasters' count.
    pub camera_supersample: Option<u32>,
    /// Whether the item buffers draw only the chunks of triangles that can reach their view
    /// (`gpu::frustum`; the default). Set only by tests, to check that it changes no texel.
    pub cull_raster: bool,
    /// How the area lights' per-pixel visibility is found (`--light-visibility`).
    pub light_visibility: crate::direct_light::LightVisibility,
    /// Whether the shadow rays are left out where a patch sees a whole area light past every
    /// occluder (`direct_light::ShaftJob`): the same image, fewer rays. `None`: where the
    /// search pays (`direct_light::SHAFT_PIXELS_PER_PATCH`); set only by tests, which hold
    /// the image with it against the image without.
    pub light_shafts: Option<bool>,
}

/// Lines a step across the median glossy patch below which a bundle resolution gets a note
/// (`RenderOptions::coarse_bundle_note`): a quarter, lines twice as wide as one line a step
/// asks or wider. At one line a step and above, the glossy history's
/// eleven bundles smooth the spikes (`iteration::auto_bundle_resolution`).
pub const COARSE_BUNDLE_LINES: f64 = 0.25;

impl RenderOptions {
    pub fn from_scene(scene: &Scene) -> Self {
        RenderOptions {
            width: scene.camera.width,
            height: scene.camera.height,
            patch_size: scene.settings.patch_size,
            iterations: scene.settings.iterations,
            seed: scene.settings.seed,
            hemicube_resolution: scene.settings.hemicube_resolution,
            light_window: LightWindow::Hemicube,
            bundle_resolution: scene.settings.bundle_resolution,
            first_shot: true,
            time_limit: None,
            bundle_capacity: None,
            image_band_rows: None,
            page_bytes: None,
            memory_limit: None,
            shadow_resolution: None,
            direct_passes: DEFAULT_DIRECT_PASSES,
            burn_in: None,
            window_steps: DEFAULT_WINDOW_STEPS,
            cameras: Vec::new(),
            bundles_per_step: scene.settings.bundles_per_step,
            wide_lines: None,
            patch_first_bounce: false,
            gather: Default::default(),
            camera_supersample: None,
            cull_raster: true,
            light_visibility: Default::default(),
            light_shafts: None,
        }
    }

    /// Texels per pixel side of the camera item buffer of a view of `camera`'s size: the one
    /// asked for, else the automatic choice (`camera_item_buffer::camera_supersample`).
    pub fn camera_supersample_for(&self, camera: &Camera) -> u32 {
        self.camera_supersample
            .unwrap_or_else(|| crate::stages::camera_item_buffer::camera_supersample(camera.width, camera.height))
    }

    /// The first shot's hemicube resolution for `patches`: the one asked for, else the
    /// automatic choice (`first_shot::auto_resolution`).
    pub fn hemicube_resolution_for(&self, patches: &Patches) -> u32 {
        self.hemicube_resolution.unwrap_or_else(|| crate::first_shot::auto_resolution(patches))
    }

    /// The bundle resolution of a render of `patches`: the one asked for, else the automatic
    /// choice for them and the views (`iteration::auto_bundle_resolution`), which is for one
    /// bundle a step: four bundles a step take half of it each, as many lines a step in all
    /// (each patch crossed as often), each line as wide against the pixels that gather
    /// through it (every other pixel in x and y).
    pub fn bundle_resolution_for(&self, scene: &Scene, patches: &Patches) -> u32 {
        self.bundles_for(scene, patches).0
    }

    /// The bundles a step of a render of `patches` draws: the number asked for, else the
    /// automatic choice for them and the views (`iteration::auto_bundles_per_step`).
    pub fn bundles_per_step_for(&self, scene: &Scene, patches: &Patches) -> u32 {
        self.bundles_for(scene, patches).1
    }

    /// (`bundle_resolution_for`, `bundles_per_step_for`), from one pass over the patches
    /// (their bounding sphere and needs) where either is automatic.
    pub fn bundles_for(&self, scene: &Scene, patches: &Patches) -> (u32, u32) {
        self.bundles_with(|| self.bundle_needs(scene, patches))
    }

    /// What the bundles of a render of `patches` need (`iteration::BundleNeeds`): a pass over
    /// the patches, their bounding sphere and the views.
    pub fn bundle_needs(&self, scene: &Scene, patches: &Patches) -> crate::iteration::BundleNeeds {
        let radius = crate::gpu::scene_buffers::bounding_sphere(patches).1;
        crate::iteration::BundleNeeds::of(patches, &scene.materials, radius, &self.views(scene))
    }

    /// `bundles_for`, with the needs from `needs`, asked for only where either is automatic
    /// (`Renderer::new` shares one pass over the patches with `coarse_bundle_note_with`).
    pub fn bundles_with<N: Borrow<crate::iteration::BundleNeeds>>(&self, needs: impl FnOnce() -> N) -> (u32, u32) {
        if let (Some(resolution), Some(per_step)) = (self.bundle_resolution, self.bundles_per_step) {
            return (resolution, per_step);
        }
        let needs = needs();
        let needs = needs.borrow();
        let per_step = self.bundles_per_step.unwrap_or_else(|| crate::iteration::auto_bundles_per_step(needs));
        let resolution =
            self.bundle_resolution.unwrap_or_else(|| needs.resolution() / crate::iteration::pixel_stride(per_step));
        (resolution, per_step)
    }

    /// A note where the bundles cross the median glossy patch with fewer than
    /// `COARSE_BUNDLE_LINES` lines a step: at a resolution that was asked for
    /// (`--bundle-resolution`, or the scene's `bundle_resolution`); at the automatic one where
    /// it stops at `iteration::AUTO_BUNDLE_MAX` (glossy meshes of very small triangles); or
    /// where the glossy patches fill under `iteration::GLOSSY_SHARE` of the views, so that
    /// the image alone sets the resolution (a small glossy object of fine triangles). Such a
    /// patch's J_j is then zero on most steps and many times its mean on the others, and the
    /// image reflects the glossy part of the last few steps' J_j (docs/ALGORITHM.md 6, "What
    /// the image takes from the senders"): the image stays unbiased, but its error comes in
    /// spikes and can rise for hundreds of steps before it falls (the Sierpinski scene at
    /// 128 x 128 with 128: 9 % after 64 steps, 26 % after 256; 2.5 % after 256 at the
    /// automatic 704). `None` without glossy patches or an iteration.
    pub fn coarse_bundle_note(&self, scene: &Scene, patches: &Patches) -> Option<String> {
        self.coarse_bundle_note_with(|| self.bundle_needs(scene, patches))
    }

    /// `coarse_bundle_note`, with the needs from `needs`, asked for only where the render
    /// iterates.
    pub fn coarse_bundle_note_with<N: Borrow<crate::iteration::BundleNeeds>>(
        &self,
        needs: impl FnOnce() -> N,
    ) -> Option<String> {
        if self.iterations == 0 {
            return None;
        }
        let needs = needs();
        let needs = needs.borrow();
        if needs.glossy <= 0.0 {
            return None;
        }
        let (resolution, per_step) = self.bundles_with(|| needs);
        let automatic = needs.resolution() / crate::iteration::pixel_stride(per_step);
        let lines = f64::from(per_step) * (f64::from(resolution) / needs.glossy).powi(2);
        if lines >= COARSE_BUNDLE_LINES {
            return None;
        }
        let bundles = format!("{per_step} bundle{} a step", if per_step == 1 { "" } else { "s" });
        let one_line = needs.glossy / f64::from(per_step).sqrt();
        let spikes = "its glossy reflections reach the image as rare spikes, and the image's error can grow for \
                      hundreds of steps before it falls";
        let costs =
            "A larger --bundle-resolution costs time as its square; glossy meshes of larger triangles cost none";
        Some(match (self.bundle_resolution, needs.patches > 0.0) {
            (Some(asked), true) => format!(
                "the bundle resolution {asked} (--bundle-resolution or the scene's bundle_resolution) crosses the \
                 median glossy patch with {lines:.2} lines a step ({bundles}; the automatic resolution, \
                 {automatic}, gives it about one): {spikes}. Leave the resolution automatic, or raise it toward that"
            ),
            (None, true) => format!(
                "the median glossy patch is crossed by {lines:.2} lines a step ({bundles}) even at the automatic \
                 bundle resolution, {automatic}, which stops at {} (one line a step would take about \
                 {one_line:.0}): {spikes}. {costs}",
                crate::iteration::AUTO_BUNDLE_MAX,
            ),
            (Some(asked), false) => format!(
                "the bundle resolution {asked} (--bundle-resolution or the scene's bundle_resolution) crosses the \
                 median glossy patch with {lines:.2} lines a step ({bundles}; about {one_line:.0} would give \
                 one): {spikes}. {costs}"
            ),
            (None, false) => format!(
                "the glossy patches fill under {:.0} % of the view, so the bundle resolution, {resolution}, follows \
                 the image and crosses their median patch with {lines:.2} lines a step ({bundles}; about \
                 {one_line:.0} would give one): their glossy reflections reach the image as rare bright pixels. \
                 {costs}",
                100.0 * crate::iteration::GLOSSY_SHARE,
            ),
        })
    }

    /// The grid of a render's bundles at `resolution` (`bundles_for`) with `per_step` of them
    /// a step, for patches in a bounding sphere of `radius` (`scene_buffers::bounding_sphere`):
    /// a fine window around the glossy patches and wide lines outside it where `wide_lines`
    /// (or the automatic choice) asks for them and they save lines (`iteration::fine_window`),
    /// else one level.
    pub fn grid_for(
        &self,
        scene: &Scene,
        patches: &Patches,
        radius: f64,
        resolution: u32,
        per_step: u32,
    ) -> crate::iteration::Grid {
        let wide = self.wide_lines.unwrap_or_else(|| {
            let needs = crate::iteration::BundleNeeds::of(patches, &scene.materials, radius, &self.views(scene));
            crate::iteration::auto_wide_lines(&needs, resolution, per_step)
        });
        let window = crate::iteration::fine_window(patches, &scene.materials, radius, resolution, wide);
        crate::iteration::Grid { resolution, window }
    }

    /// The views of the render, in order: `cameras`, or the scene's camera at `width` x
    /// `height` (named "camera").
    pub fn views(&self, scene: &Scene) -> Vec<NamedCamera> {
        if !self.cameras.is_empty() {
            return self.cameras.clone();
        }
        let camera = Camera { width: self.width, height: self.height, ..scene.camera };
        vec![NamedCamera { name: "camera".into(), camera }]
    }

    /// The pixels of all the render's views together.
    pub fn view_pixels(&self, scene: &Scene) -> u64 {
        self.views(scene).iter().map(|v| u64::from(v.camera.width) * u64::from(v.camera.height)).sum()
    }
}

/// A note for each view with a surface nearer its camera than the views' near distance
/// (`camera_item_buffer::NEAR_OF_RADIUS` of the scene's radius), which the camera's item buffer
/// cuts off: the image would lack what lies there without a word. (Only where the scene is
/// large against the camera's distance to it, 2^20 times: single-precision positions cannot
/// place such a surface apart from the eye either.)
pub fn camera_notes(scene: &Scene, patches: &Patches, options: &RenderOptions) -> Vec<String> {
    let radius = crate::gpu::scene_buffers::bounding_sphere(patches).1;
    let near = radius * crate::stages::camera_item_buffer::NEAR_OF_RADIUS;
    let mut notes = Vec::new();
    for view in options.views(scene) {
        let Some(d) = crate::scene::tessellate::nearest_patch_distance(patches, view.camera.position) else {
            continue;
        };
        if d < near {
            notes.push(format!(
                "camera \"{}\": a surface lies {d:.3e} from it, nearer than the {near:.3e} (2^-20 of the scene's \
                 radius {radius:.3e}) within which the GPU's single-precision positions cannot tell a surface from \
                 the eye, so the image leaves out what lies that near: move the camera away from the surface, or \
                 make the scene smaller around it",
                view.name
            ));
        }
    }
    notes
}

/// Whether the image's gather evaluates a near sender's first reflection of the first-shot
/// lights at the point it meets it, instead of taking the sender's patch-level Lfs
/// (docs/ALGORITHM.md 6, "Near senders' first bounce per point"): with first shot, unless an
/// emitting shape is among the lights. Such a shape can meet the surfaces it lights, and a
/// point next to it would see its D without bound (at x the gather shares that light by
/// multiple importance sampling; at the sender's point nothing would), so those scenes keep
/// the patch level.
pub fn first_bounce_per_point(options: &RenderOptions, patches: &Patches) -> bool {
    options.first_shot && patches.emitters.is_empty() && !options.patch_first_bounce
}

/// The largest hemispherical albedo (directional albedo averaged over cosine-weighted
/// incidence) of the scene's materials: a bound of how much of its light the scene keeps
/// from one bounce to the next.
pub fn largest_albedo(scene: &Scene) -> f64 {
    const POINTS: usize = 32;
    scene
        .materials
        .iter()
        .map(|m| {
            // Midpoint rule of 2 int a(mu) mu dmu over [0, 1].
            let mean: [f64; 3] = (0..POINTS).fold([0.0; 3], |acc, i| {
                let mu = (i as f64 + 0.5) / POINTS as f64;
                let a = crate::scene::brdf::directional_albedo(&m.kind, mu);
                std::array::from_fn(|c| acc[c] + a[c] * 2.0 * mu / POINTS as f64)
            });
            mean.into_iter().fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// Bounces until the state's missing share of further bounces, which falls as `rate`^k, is
/// below BURN_IN_TOLERANCE: k = log(BURN_IN_TOLERANCE) / log(rate), at most MAX_BURN_IN.
pub fn bounces_for_decay(rate: f64) -> u32 {
    if rate <= 0.0 {
        return 0;
    }
    if rate >= 1.0 {
        return MAX_BURN_IN;
    }
    ((BURN_IN_TOLERANCE.ln() / rate.ln()).ceil() as u32).min(MAX_BURN_IN)
}

/// The burn-in in bundles, and the walk's measurement it was sized by (`None` where the walk
/// was not run; docs/ALGORITHM.md 6, "Burn-in"). Two things must settle before the image's
/// first step:
/// - the state's mean, which needs `bounces_for_decay` of the light's measured decay per
///   bounce (`burn_in::measured_decay`, two standard errors up; never more than the largest
///   albedo, which is the rate where the walk is not run);
/// - then Lbar_j, the control variates' running mean of the state, whose memory is
///   `iteration::SETTLED_MEAN_BUNDLES` bundles: made of unconverged states it is a poorer
///   variate (Sierpinski at 11 bundles: 6-11 % more image error than at 19).
pub fn default_burn_in(scene: &Scene, patches: &Patches) -> (u32, Option<crate::burn_in::Decay>) {
    let bound = largest_albedo(scene);
    let decay = crate::burn_in::measured_decay(scene, patches);
    (burn_in_bundles(decay.map_or(bound, |d| d.upper().min(bound))), decay)
}

/// The burn-in in bundles for a decay `rate` per bounce: `bounces_for_decay`, then
/// `iteration::SETTLED_MEAN_BUNDLES` for Lbar_j (none where no bounce is needed), at most
/// MAX_BURN_IN.
fn burn_in_bundles(rate: f64) -> u32 {
    match bounces_for_decay(rate) {
        0 => 0,
        b => (b + crate::iteration::SETTLED_MEAN_BUNDLES).min(MAX_BURN_IN),
    }
}

/// Run statistics (`--stats`, docs/CLI.md).
#[derive(Debug, Clone, Serialize)]
pub struct RenderStats {
    pub adapter: AdapterSummary,
    pub scene: String,
    pub patches: usize,
    /// Triangles the render passes draw for them (lattices, docs/ALGORITHM.md 4).
    pub raster_triangles: u32,
    pub light_samples: usize,
    pub image: [u32; 2],
    pub patch_size: f64,
    pub camera_samples: u32,
    pub first_shot: bool,
    pub hemicube_resolution: u32,
    pub light_window: LightWindow,
    /// Stored (patch, light sample) pairs of the first shot.
    pub first_shot_pairs: u32,
    pub first_shot_faces: usize,
    pub first_shot_ms: f64,
    /// Face side of the lights' windows for the per-pixel direct light, and the texels of
    /// their atlases.
    pub shadow_resolution: u32,
    pub shadow_atlas_texels: u64,
    /// How the area lights' and emitting shapes' visibility was found: "rays" or "windows"
    /// (`--light-visibility`; windows where the scene's BVH does not fit the device).
    pub light_visibility: &'static str,
    /// With shadow rays: how many patches see some area light past every occluder, whose
    /// pixels cast no ray to it (`direct_light::ShaftJob`), and the host milliseconds the
    /// search took beside the first shot; null where it was not run.
    pub unshadowed_patches: Option<u64>,
    pub unshadowed_ms: Option<f64>,
    /// The memory predicted before any GPU work, and the peak resident set reached
    /// (`memory::MemoryPlan`).
    pub memory: crate::memory::MemoryPlan,
    pub bundle_resolution: u32,
    /// Bundles each step drew (`--bundles-per-step`), each at `bundle_resolution`.
    pub bundles_per_step: u32,
    /// Fine lines along a wide line's edge outside the fine window (`--wide-lines`; 1: one
    /// level), and the lines the buffers held for each bundle (`iteration::Grid`).
    pub wide_lines: u32,
    pub bundle_lines: u32,
    /// How the image's gather finished its pixels: "fused" (one pass) or "split"
    /// (`--gather`, `image_estimate::fused_gather`).
    pub gather: &'static str,
    /// Fragment capacity of a bundle step (grown if a step ever needed more).
    pub bundle_capacity: u32,
    /// Median wall time of a step, measured over batches of steps.
    pub iteration_ms_median: f64,
    pub iteration_ms: f64,
    /// Steps averaged into the image.
    pub iterations: u32,
    /// Steps before them that only advanced the state.
    pub burn_in_steps: u32,
    /// The light's measured decay per bounce (its rate, standard error, particles,
    /// generations and milliseconds) that the default burn-in was sized by; `null` with `--burn-in` or where the walk did not run
    /// (docs/ALGORITHM.md 6, "Burn-in").
    pub burn_in_decay: Option<crate::burn_in::Decay>,
    /// The first of those, run at the coarser bundle resolution
    /// (`iteration::coarse_burn_in`; 0 and `None` when there was none).
    pub coarse_burn_in_steps: u32,
    pub coarse_bundle_resolution: Option<u32>,
    pub seed: u64,
    /// `LP_NUM_THREADS` as the run had it: the worker threads of Mesa's CPU adapters (the
    /// command line sets four a core where it is unset, `gpu::context::set_cpu_adapter_threads`;
    /// `None` where a library caller left it unset, Mesa's one a core).
    pub lp_num_threads: Option<String>,
    pub tessellation_ms: f64,
    pub upload_ms: f64,
    pub image_ms: f64,
    pub total_ms: f64,
    /// The scene's notes (`Scene::notes`): what it holds that is not rendered, and glossy
    /// lobes sharper than the method samples well; the tessellation's (`Patches::notes`:
    /// emitting triangles past the first shot's sample cap); and a bundle resolution too
    /// coarse for the glossy patches (`RenderOptions::coarse_bundle_note`). `note: ...` on
    /// stderr too.
    pub notes: Vec<String>,
}

/// The rendered image and how it was made.
pub struct Rendered {
    /// The image of the first view (`RenderOptions::views`).
    pub image: Image,
    /// The raw image sum the image is the mean of (rgb sum, w the number of estimates per
    /// pixel), row by row: what a shard's part file keeps (`merge`).
    pub image_sum: Vec<[f32; 4]>,
    /// The images of the views after the first, in order (`--all-cameras`).
    pub other_views: Vec<RenderedView>,
    pub stats: RenderStats,
    /// The run was stopped by `Hooks::stop_requested` before its step count.
    pub interrupted: bool,
}

/// The image of one more view of a render.
pub struct RenderedView {
    /// The camera's name (`NamedCamera::name`).
    pub name: String,
    pub image: Image,
    pub image_sum: Vec<[f32; 4]>,
}

/// What a caller watches and steers during a render; every method has a do-nothing
/// default, so `NoHooks` is a full implementation.
pub trait Hooks {
    /// A phase ended after `ms` milliseconds ("first shot", "iteration", ...).
    fn phase(&mut self, _name: &str, _ms: f64) {}
    /// `done` steps so far of `total` (u32::MAX when only a time limit bounds the run).
    fn progress(&mut self, _done: u32, _total: u32) {}
    /// Asked after every step (and every pass of a direct-light image): stop after it (a
    /// stop signal). The run then ends as if its step count had been reached, with
    /// `Rendered::interrupted` set.
    fn stop_requested(&self) -> bool {
        false
    }
    /// Asked after every batch of steps: hand a checkpoint to `checkpoint` now?
    fn checkpoint_due(&mut self) -> bool {
        false
    }
    /// Whether `checkpoint` also gets the state at the end of the run.
    fn wants_final_checkpoint(&self) -> bool {
        false
    }
    /// The iteration state and the image of every view so far (in `RenderOptions::views`
    /// order).
    fn checkpoint(&mut self, _checkpoint: Checkpoint, _images: &[Image]) -> Result<()> {
        Ok(())
    }
}

/// What a walkthrough (`render_path`) does with each frame.
pub trait FrameHooks: Hooks {
    /// Frame `index` is done after `step` steps: its image, and the iteration state
    /// (`GpuPatchState` bytes) from which the next frame goes on.
    fn frame(&mut self, index: u32, image: &Image, step: u32, state: Vec<u8>) -> Result<()>;
}

/// Hooks that watch nothing and never stop.
pub struct NoHooks;
impl Hooks for NoHooks {}

/// Steps of the iteration before the first one averaged into the image: `--burn-in`, or
/// the scene's default (`default_burn_in`); none without an iteration. With the default, also
/// the walk's measurement.
/// `bundles_per_step`: `RenderOptions::bundles_per_step_for`.
pub fn burn_in_steps(
    scene: &Scene,
    patches: &Patches,
    options: &RenderOptions,
    bundles_per_step: u32,
) -> (u32, Option<crate::burn_in::Decay>) {
    match (options.iterations, options.burn_in) {
        (0, _) => (0, None),
        (_, Some(steps)) => (steps, None),
        // The default is in bounces; each of a step's bundles is one.
        _ => {
            let (bounces, decay) = default_burn_in(scene, patches);
            (bounces.div_ceil(bundles_per_step.max(1)), decay)
        }
    }
}

/// The longest burn-in `burn_in_steps` can choose, without the walk: the largest albedo's
/// bound. Memory plans take it, so that they never plan less than the run needs.
pub fn longest_burn_in_steps(scene: &Scene, options: &RenderOptions, bundles_per_step: u32) -> u32 {
    match (options.iterations, options.burn_in) {
        (0, _) => 0,
        (_, Some(steps)) => steps,
        _ => burn_in_bundles(largest_albedo(scene)).div_ceil(bundles_per_step.max(1)),
    }
}

fn due(i: u32, first: u32, every: u32) -> bool {
    i < first || i.is_multiple_of(every)
}

fn estimates(n: u32, first: u32, every: u32) -> u32 {
    if n <= first { n } else { first + n.div_ceil(every) - first.div_ceil(every) }
}

/// Identifies a scene and every option that changes the image (not the step count or the
/// time limit, which a resumed run may change), so a checkpoint is only resumed by the run
/// it belongs to.
pub fn fingerprint(scene: &Scene, options: &RenderOptions) -> u64 {
    let mut scene = scene.clone();
    scene.source = Default::default();
    let mut options = options.clone();
    options.iterations = 0;
    options.time_limit = None;
    options.bundle_capacity = None;
    options.image_band_rows = None;
    options.page_bytes = None;
    options.memory_limit = None;
    options.cull_raster = true;
    // Leaving out the rays that find nothing changes no pixel either (tests/per_pixel.rs
    // test25): a run may be resumed with the other setting.
    options.light_shafts = None;
    crate::checkpoint::fnv1a(format!("{scene:?}\n{options:?}").as_bytes())
}

/// Checks, before any GPU work, that `options` can be honoured for `scene`: `main.rs` calls
/// it before opening an adapter, so that such a refusal is a usage error (exit 2) even on a
/// machine without one.
pub fn check_options(scene: &Scene, options: &RenderOptions) -> Result<()> {
    use crate::scene::Light;
    // Lights without an area to emit from inside the iteration.
    let without_area = scene.lights.iter().find_map(|l| match l {
        Light::Point { .. } => Some("point"),
        Light::Spot { .. } => Some("spot"),
        Light::Directional { .. } => Some("directional"),
        Light::Area { .. } => None,
    });
    if let (false, Some(kind)) = (options.first_shot, without_area) {
        return Err(Error::Usage(format!(
            "--no-first-shot: the scene has {kind} lights, which only the first shot can handle (a {kind} light has no area to emit from inside the iteration); drop --no-first-shot or replace them by small area lights"
        )));
    }
    Ok(())
}

/// Checks, before any GPU work, that the scene and image fit the device's limits.
pub fn check_limits(limits: &wgpu::Limits, patches: &Patches, options: &RenderOptions) -> Result<()> {
    let binding = limits.max_storage_buffer_binding_size;
    let buffer = limits.max_buffer_size;
    let fit = |what: &str, bytes: u64, hint: &str| -> Result<()> {
        if bytes > binding.min(buffer) {
            Err(Error::Limits(format!(
                "{what} needs {bytes} bytes in one buffer, the device allows {} (max_storage_buffer_binding_size {binding}, max_buffer_size {buffer}); {hint}",
                binding.min(buffer)
            )))
        } else {
            Ok(())
        }
    };
    let n = patches.patches.len() as u64;
    if n > MAX_PATCHES as u64 {
        return Err(Error::Limits(format!("{n} patches exceed the limit of {MAX_PATCHES}; use a larger --patch-size")));
    }
    // Every kernel's storage bindings: the pages of the paged arrays count where the scene
    // needs more than one (an adapter with few storage buffers a stage, such as wgpu's GL
    // backend with 16, runs scenes whose per-patch arrays fit one binding each).
    let per_stage = limits.max_storage_buffers_per_shader_stage;
    let page = crate::gpu::scene_buffers::page_bytes(limits, options.page_bytes);
    let paging = crate::gpu::scene_buffers::paging_of(n, page);
    let count = |s: &&crate::gpu::bindings::KernelSpec| crate::gpu::bindings::storage_buffers(s, paging);
    if let Some(spec) = crate::stages::SPECS.iter().find(|s| count(s) > per_stage) {
        let fix = match paging {
            crate::gpu::kernel::Paging::Paged => {
                "use a larger --patch-size, so that each per-patch array fits one binding and its pages need not be bound, or an adapter that allows more"
            }
            crate::gpu::kernel::Paging::Whole => "use an adapter that allows more",
        };
        return Err(Error::Limits(format!(
            "the kernel {} binds {} storage buffers (the pages of its per-patch arrays included), the device allows {per_stage} per shader stage (max_storage_buffers_per_shader_stage); {fix}",
            spec.stem,
            count(spec)
        )));
    }
    let fewer = "use a larger --patch-size (or a coarser tessellation) or a GPU with more memory";
    // The per-patch arrays of more than 8 bytes a patch are split over pages, a buffer each
    // (`scene_buffers::PerPatch`): at most `pages` of them.
    for array in crate::gpu::scene_buffers::PAGED_ARRAYS {
        let capacity = array.capacity(page);
        if n > capacity {
            return Err(Error::Limits(format!(
                "{n} patches: {} ({} bytes a patch) holds at most {capacity} patches on this device, in {} pages of {} patches (a page at most {page} bytes: max_storage_buffer_binding_size {binding}, max_buffer_size {buffer}); {fewer}",
                array.what,
                array.bytes,
                array.pages,
                array.patches_per_page(page)
            )));
        }
    }
    // The rest are one buffer each: the first shot's sums (8 bytes a patch) and row counts
    // one binding, the triangles a vertex buffer (never bound as storage).
    fit("the first shot's per-patch sums", n * 8, fewer)?;
    let triangles =
        crate::gpu::scene_buffers::raster_triangle_count(patches) * 3 * std::mem::size_of::<RasterVertex>() as u64;
    if triangles > buffer {
        return Err(Error::Limits(format!(
            "the rasterised triangles need {triangles} bytes in one vertex buffer, the device allows {buffer} (max_buffer_size); {fewer}"
        )));
    }
    let max_dim = limits.max_texture_dimension_2d;
    let sizes = match options.cameras.is_empty() {
        true => vec![(options.width, options.height)],
        false => options.cameras.iter().map(|c| (c.camera.width, c.camera.height)).collect(),
    };
    for (width, height) in sizes {
        if width > max_dim || height > max_dim {
            return Err(Error::Limits(format!(
                "the image {width}x{height} exceeds the device's largest texture side {max_dim}; use a smaller --width/--height"
            )));
        }
        // The image sum is cut into bands of rows, each within one binding
        // (`image_estimate::band_rows`): only one row must fit.
        let row = width as u64 * crate::stages::image_estimate::IMAGE_SUM_BYTES_PER_PIXEL;
        fit("a row of the image", row, "use a smaller --width")?;
    }
    // The stages check these too, but only once the first shot (or the first shot and the
    // bundle buffers) exist: here they are refused before any GPU work, and the bundle's
    // line table, which no stage checked, cannot reach wgpu as a validation panic.
    // The automatic choice stays within first_shot::AUTO_RESOLUTION_MAX, which every
    // device's textures allow.
    if let (true, Some(r)) = (options.first_shot, options.hemicube_resolution)
        && r > max_dim
    {
        return Err(Error::Limits(format!(
            "--hemicube-resolution {r} exceeds the device's largest texture side {max_dim}; use a smaller --hemicube-resolution"
        )));
    }
    if options.iterations > 0 {
        // The automatic choice (`None`) stays within AUTO_BUNDLE_MAX, which every device's
        // textures allow (wgpu's smallest limit is 2048).
        let r = options.bundle_resolution.unwrap_or(crate::iteration::AUTO_BUNDLE_MAX);
        if !(crate::iteration::MIN_BUNDLE_RESOLUTION..=max_dim).contains(&r) {
            return Err(Error::Limits(format!(
                "--bundle-resolution {r}: expected {} to {max_dim} (the device's largest texture side)",
                crate::iteration::MIN_BUNDLE_RESOLUTION
            )));
        }
        // The largest resolution whose line table fits, for the hint (the table grows as r^2).
        let per_line = crate::iteration::line_table_bytes(1);
        let largest = ((binding.min(buffer) / per_line) as f64).sqrt() as u64;
        fit(
            "the ray-bundle line table",
            crate::iteration::line_table_bytes(r),
            &format!("use --bundle-resolution {largest} or less"),
        )?;
    }
    Ok(())
}

/// The memory of a render of `patches` with `options` on `ctx` (`memory::predict`), against
/// `options.memory_limit` or what the host has available.
pub fn predict_memory(
    ctx: &Context,
    scene: &Scene,
    patches: &Patches,
    options: &RenderOptions,
) -> crate::memory::MemoryPlan {
    let cpu = ctx.summary.is_cpu();
    let available = options.memory_limit.or_else(crate::memory::host_available);
    crate::memory::predict(scene, patches, options, &ctx.limits(), cpu, available)
}

fn milliseconds(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Renders `scene` (already tessellated into `patches`) on `ctx`.
pub fn render(ctx: &Context, scene: &Scene, patches: &Patches, options: &RenderOptions) -> Result<Rendered> {
    render_with(ctx, scene, patches, options, None, &mut NoHooks)
}

/// As `render`, continuing from `resume` if given, watched and steered by `hooks`.
pub fn render_with(
    ctx: &Context,
    scene: &Scene,
    patches: &Patches,
    options: &RenderOptions,
    resume: Option<&Checkpoint>,
    hooks: &mut dyn Hooks,
) -> Result<Rendered> {
    Renderer::new(ctx, scene, patches, options, hooks)?.run(resume, hooks)
}

/// A walkthrough to render: its frames' cameras, the steps each averages, and where it
/// starts.
#[derive(Debug, Clone, Copy)]
pub struct Walkthrough<'a> {
    pub frames: &'a [Camera],
    pub steps_per_frame: u32,
    /// `None`: from nothing.
    pub start: Option<PathStart<'a>>,
}

/// Where a walkthrough starts: from the state after some frames (a checkpoint of
/// `FrameHooks::frame`).
#[derive(Debug, Clone, Copy)]
pub struct PathStart<'a> {
    /// The iteration state after `step` steps.
    pub state: &'a [u8],
    pub step: u32,
}

/// What a walkthrough did.
#[derive(Debug, Clone)]
pub struct PathRendered {
    /// The frames rendered (and handed to `FrameHooks::frame`) by this run.
    pub frames: std::ops::Range<u32>,
    /// A stop (`Hooks::stop_requested`) ended the run inside frame `frames.end`, which was
    /// dropped.
    pub interrupted: bool,
    pub burn_in_steps: u32,
    /// Median wall time of a step.
    pub iteration_ms_median: f64,
    pub first_shot_ms: f64,
    pub total_ms: f64,
}

/// Renders a walkthrough: one image per camera of `walk.frames` (each at `options.width` x
/// `options.height`), from one iteration whose state carries on from frame to frame (it is
/// view-independent). The burn-in runs once, before the first frame; then each frame
/// averages its own `walk.steps_per_frame` steps (step k of the run is still step k of the
/// random streams, so a run resumed from a frame's state gives the same frames bit for bit).
/// The image is restarted at each frame, whose direct-light passes count from its start as
/// a run's do from the burn-in (`DirectSchedule::due`). `options.iterations` and `time_limit`
/// are not read.
pub fn render_path(
    ctx: &Context,
    scene: &Scene,
    patches: &Patches,
    options: &RenderOptions,
    walk: &Walkthrough<'_>,
    hooks: &mut dyn FrameHooks,
) -> Result<PathRendered> {
    let Walkthrough { frames, steps_per_frame, start } = *walk;
    if frames.is_empty() || steps_per_frame == 0 {
        return Err(Error::Usage("a camera path needs at least one frame of at least one step".into()));
    }
    let options = RenderOptions {
        iterations: (frames.len() as u32).saturating_mul(steps_per_frame).max(1),
        time_limit: None,
        cameras: Vec::new(),
        ..options.clone()
    };
    let mut renderer = Renderer::new(ctx, scene, patches, &options, hooks)?;
    let burn_in = renderer.burn_in;
    let mut step = 0;
    if let Some(s) = start {
        if s.state.len() as u64 != renderer.buffers.state.size() {
            return Err(Error::Usage("the checkpoint's state does not fit this scene; run without --resume".into()));
        }
        renderer.buffers.state.write(&ctx.queue, s.state);
        step = s.step;
    }
    let mut step_ms = Vec::new();
    if step < burn_in {
        renderer.image_start = burn_in;
        let done = renderer.advance(step, burn_in, hooks)?;
        step = burn_in;
        step_ms.push(done.step_ms_median);
    }
    let first = (step - burn_in) / steps_per_frame;
    let mut done = PathRendered {
        frames: first..first,
        interrupted: false,
        burn_in_steps: burn_in,
        iteration_ms_median: 0.0,
        first_shot_ms: renderer.first_shot.as_ref().map_or(0.0, |f| f.ms),
        total_ms: 0.0,
    };
    for f in first..frames.len() as u32 {
        let camera = Camera { width: options.width, height: options.height, ..frames[f as usize] };
        renderer.restart_image(camera, step, Some(steps_per_frame));
        let end = step + steps_per_frame;
        let stats = renderer.advance(step, end, hooks)?;
        step_ms.push(stats.step_ms_median);
        if stats.steps < end {
            done.interrupted = true;
            break;
        }
        step = end;
        let image = renderer.read_image()?;
        hooks.frame(f, &image, step, renderer.read_state()?)?;
        done.frames.end = f + 1;
        if hooks.stop_requested() && done.frames.end < frames.len() as u32 {
            done.interrupted = true;
            break;
        }
    }
    ctx.check()?;
    step_ms.sort_by(f64::total_cmp);
    done.iteration_ms_median = step_ms.get(step_ms.len() / 2).copied().unwrap_or(0.0);
    done.total_ms = milliseconds(renderer.start);
    Ok(done)
}

/// What belongs to one view of a render: its camera, its camera item buffer and its image
/// estimate (the running image sum). Everything else a step computes (the iteration state,
/// the step's bundle and what each patch sends the image, the lights' windows of a pass) is
/// view-independent and shared by every view, so a view costs its image stages only.
pub struct ViewImage {
    pub name: String,
    /// The camera, at the image's size (`Camera::width`, `Camera::height`).
    pub camera: Camera,
    item_buffer: CameraItemBuffer,
    estimate: ImageEstimate,
    /// The offset inside the strata of the sample its supersampled item buffer holds (the
    /// bits of `PixelSample::offset`), or `None` where it holds none that can be trusted (a
    /// new camera, a restored or redone batch).
    rastered: Option<[u64; 2]>,
    /// Whether this step renders the view's camera item buffer (`write_camera`).
    raster_due: bool,
    /// The view its item buffer is rendered from (the raster camera's uniform), whose
    /// frustum leaves out the triangles that cannot reach it (`gpu::frustum`).
    raster_view: GpuCamera,
}

/// One render, set up: the scene on the GPU, its first-shot table, the iteration state and
/// its views (each a camera item buffer and an image sum), owned together. `step_stages` is
/// the one description of a step, which `run` (the CLI and the tests), the benchmark
/// harness and its stage profiler all use.
pub struct Renderer<'a> {
    ctx: &'a Context,
    scene: &'a Scene,
    /// As given (`bundle_resolution` may be `None`: automatic).
    options: RenderOptions,
    /// The first shot's hemicube resolution in use (`RenderOptions::hemicube_resolution_for`).
    hemicube_resolution: u32,
    /// The bundle resolution in use (`RenderOptions::bundle_resolution_for`).
    bundle_resolution: u32,
    /// The bundles a step draws (`RenderOptions::bundles_per_step_for`).
    per_step: u32,
    buffers: SceneBuffers,
    direct: DirectLights,
    /// One per camera (`RenderOptions::views`), never empty.
    views: Vec<ViewImage>,
    /// The bundle stages; `None` for a first-shot-only image (`iterations == 0`).
    iteration: Option<Iteration>,
    /// The coarse burn-in (`iteration::coarse_burn_in`): the iteration at the smaller
    /// resolution, sharing the per-patch arrays, and the steps it runs (0..steps); dropped
    /// once they are done.
    coarse: Option<(Iteration, u32)>,
    /// Steps before the first one averaged into the image.
    burn_in: u32,
    /// The light's decay per bounce that sized the default burn-in (`default_burn_in`).
    burn_in_decay: Option<crate::burn_in::Decay>,
    /// The step whose estimate is the image's first: the burn-in, or a frame's first step
    /// (`render_path`), which counts its direct-light passes from there.
    image_start: u32,
    /// The steps the image averages where known (`options.iterations`, a frame's steps;
    /// `None` after the viewer's camera moves): its bundle directions are then stratified
    /// over them (`iteration::ImagePlan`).
    image_steps: Option<u32>,
    /// Which image steps estimate the direct light.
    direct_schedule: DirectSchedule,
    /// Whether this pass estimates the direct light (`image_stages`).
    direct_due: bool,
    /// Whether this pass renders the area lights' windows at new points.
    windows_due: bool,
    /// Whether the gathers evaluate near senders' first bounce per point
    /// (`first_bounce_per_point`): they read the area lights' windows on every image step.
    first_bounce_per_point: bool,
    first_shot: Option<FirstShotStats>,
    /// Near distance of the camera's reversed-z projection.
    near: f64,
    patch_count: usize,
    light_samples: usize,
    memory: crate::memory::MemoryPlan,
    upload_ms: f64,
    start: Instant,
    /// The scene's notes, the tessellation's and the bundle resolution's
    /// (`RenderOptions::coarse_bundle_note`), for the stats.
    notes: Vec<String>,
}

impl<'a> Renderer<'a> {
    /// Checks `options` against the scene and the device (before any GPU work), uploads the
    /// scene and runs the first shot.
    pub fn new(
        ctx: &'a Context,
        scene: &'a Scene,
        patches: &Patches,
        options: &RenderOptions,
        hooks: &mut dyn Hooks,
    ) -> Result<Self> {
        let start = Instant::now();
        // The automatic bundle and hemicube resolutions, chosen once: the checks and the
        // memory plan see the numbers. The Renderer keeps the options as given, whose fingerprint a
        // checkpoint or shard carries (the choice follows from them and the scene).
        let given = options;
        // One pass over the patches (`RenderOptions::bundle_needs`) for the automatic bundles
        // and the note on them, where either asks for it.
        let needs = std::cell::OnceCell::new();
        let needs = || needs.get_or_init(|| options.bundle_needs(scene, patches));
        let (bundle_resolution, per_step) = options.bundles_with(needs);
        let hemicube_resolution = options.hemicube_resolution_for(patches);
        let resolved = RenderOptions {
            hemicube_resolution: Some(hemicube_resolution),
            bundle_resolution: Some(bundle_resolution),
            bundles_per_step: Some(per_step),
            ..options.clone()
        };
        let options = &resolved;
        check_options(scene, options)?;
        check_limits(&ctx.limits(), patches, options)?;
        let memory = predict_memory(ctx, scene, patches, options);
        memory.check()?;
        let device = &ctx.device;
        let upload = Instant::now();
        let page = crate::gpu::scene_buffers::page_bytes(&ctx.limits(), options.page_bytes);
        let mut buffers = SceneBuffers::with_pages(device, scene, patches, options.first_shot, page);
        buffers.raster.cull = options.cull_raster;
        let upload_ms = milliseconds(upload);
        let mut direct = DirectLights::new(ctx, scene, patches, &buffers, options);
        let shaft_job = direct.take_shaft_job();
        // Only where the image gathers (an iteration) and there are lights to evaluate.
        let per_point = options.iterations > 0 && first_bounce_per_point(options, patches) && direct.count() > 0;
        // Three pieces of host work run on threads of their own while the device does the
        // first shot: the walk over the patches that sizes the burn-in (src/burn_in.rs, tens
        // of ms), the image estimate's pipelines, which a CPU adapter compiles on the threads
        // that ask for them (about 80 ms on two cores for the Sierpinski scene, when the
        // device sat idle), and the search for the patches that see an area light past every
        // occluder (`direct_light::ShaftJob`: their pixels cast no shadow ray).
        let (paging, scene_constants, lights) = (buffers.paging(), buffers.constants(), direct.specialization());
        let bvh = direct.bvh_specialization();
        let passes = crate::stages::image_estimate::fused_gather(&ctx.summary, options.gather);
        let (burn_in_walk, image_pipelines, shaft_bits, first_shot) = std::thread::scope(|s| {
            let walk = s.spawn(|| burn_in_steps(scene, patches, options, per_step));
            let pipelines = s.spawn(|| {
                ImagePipelines::build(&ctx.device, paging, &scene_constants, &lights, &bvh, per_point, passes)
            });
            let shafts = shaft_job.map(|job| {
                s.spawn(move || {
                    let started = Instant::now();
                    (job.run(patches), milliseconds(started))
                })
            });
            let first_shot = Self::first_shot_of(ctx, &mut buffers, patches, options, hemicube_resolution, hooks);
            (crate::joined(walk), crate::joined(pipelines), shafts.map(crate::joined), first_shot)
        });
        if let Some((bits, ms)) = shaft_bits {
            direct.set_unshadowed(&ctx.queue, &bits, ms);
        }
        let first_shot = first_shot?;
        let iteration = if options.iterations == 0 {
            None
        } else {
            let capacity =
                initial_fragment_capacity(options, &ctx.limits(), patches, buffers.radius, bundle_resolution);
            let grid = options.grid_for(scene, patches, buffers.radius, bundle_resolution, per_step);
            if grid.window.is_some() {
                let materials = &scene.materials;
                buffers
                    .raster
                    .set_fine_patches(|p| crate::iteration::is_glossy(&patches.patches[p as usize], materials));
            }
            Some(Iteration::new(ctx, &buffers, grid, capacity, per_point)?)
        };
        let (burn_in, burn_in_decay) = burn_in_walk;
        let coarse = match (&iteration, crate::iteration::coarse_burn_in(bundle_resolution, burn_in, per_step)) {
            (Some(full), Some((resolution, steps))) => {
                let capacity = initial_fragment_capacity(options, &ctx.limits(), patches, buffers.radius, resolution);
                Some((full.resized(ctx, &buffers, crate::iteration::Grid::one_level(resolution), capacity)?, steps))
            }
            _ => None,
        };
        let gathers = iteration.is_some();
        // Only a first-shot emitting shape's light is shared between D and G; without one the
        // gather skips the test (two loads of the sender's patch a pixel).
        let mis = gathers && options.first_shot && !patches.emitters.is_empty();
        // The views share the image's kernels and pipelines (`image_pipelines`): only their
        // buffers, textures and bind groups are their own.
        let gather = iteration.as_ref().map(|i| &i.gather);
        let stride = crate::iteration::pixel_stride(per_step);
        let mut views: Vec<ViewImage> = Vec::new();
        for NamedCamera { name, camera } in options.views(scene) {
            let like = views.first();
            let supersample = options.camera_supersample_for(&camera);
            let item_buffer =
                CameraItemBuffer::new(device, camera.width, camera.height, supersample, like.map(|v| &v.item_buffer));
            let band_rows = options
                .image_band_rows
                .unwrap_or_else(|| crate::stages::image_estimate::band_rows(&device.limits(), camera.width));
            let estimate = ImageEstimate::new(
                device,
                &buffers,
                &item_buffer,
                &direct,
                gather,
                band_rows,
                stride,
                &image_pipelines,
            );
            estimate.set_params(&ctx.queue, scene.environment, buffers.patch_count, direct.count(), mis, gathers);
            views.push(ViewImage {
                name,
                camera,
                item_buffer,
                estimate,
                rastered: None,
                raster_due: true,
                raster_view: bytemuck::Zeroable::zeroed(),
            });
        }
        Ok(Renderer {
            ctx,
            scene,
            options: given.clone(),
            hemicube_resolution,
            bundle_resolution,
            per_step,
            near: buffers.radius * crate::stages::camera_item_buffer::NEAR_OF_RADIUS,
            buffers,
            direct,
            views,
            iteration,
            coarse,
            burn_in,
            burn_in_decay,
            image_start: burn_in,
            image_steps: Some(options.iterations),
            direct_schedule: DirectSchedule::of(scene, patches, given),
            direct_due: true,
            windows_due: true,
            first_bounce_per_point: per_point,
            first_shot,
            patch_count: patches.patches.len(),
            light_samples: patches.samples.len(),
            memory,
            upload_ms,
            start,
            notes: scene
                .notes
                .iter()
                .chain(&patches.notes)
                .cloned()
                .chain(given.coarse_bundle_note_with(needs))
                .chain(camera_notes(scene, patches, given))
                .collect(),
        })
    }

    /// The first shot of `new` (none without first-shot lights or with `--no-first-shot`).
    fn first_shot_of(
        ctx: &Context,
        buffers: &mut SceneBuffers,
        patches: &Patches,
        options: &RenderOptions,
        hemicube_resolution: u32,
        hooks: &mut dyn Hooks,
    ) -> Result<Option<FirstShotStats>> {
        if !options.first_shot || patches.samples.is_empty() {
            return Ok(None);
        }
        let stats = first_shot::run(ctx, buffers, patches, hemicube_resolution, options.light_window)?;
        hooks.phase("first shot", stats.ms);
        Ok(Some(stats))
    }

    pub fn first_shot(&self) -> Option<&FirstShotStats> {
        self.first_shot.as_ref()
    }

    pub fn patch_count(&self) -> u32 {
        self.buffers.patch_count
    }

    fn iteration(&self) -> &Iteration {
        self.iteration.as_ref().expect("a Renderer built with iterations > 0")
    }

    /// The iteration that runs step `k`: the coarse one for the first steps of the burn-in.
    fn iteration_at(&self, k: u32) -> &Iteration {
        match &self.coarse {
            Some((coarse, steps)) if k < *steps => coarse,
            _ => self.iteration(),
        }
    }

    /// Fragment capacity of a bundle step and the bundle resolution.
    pub fn bundle_size(&self) -> (u32, u32) {
        let it = self.iteration();
        (it.capacity, it.grid.resolution)
    }

    fn bundle_scene(&self) -> BundleScene {
        BundleScene {
            centre: self.buffers.centre,
            radius: self.buffers.radius,
            patch_count: self.buffers.patch_count,
            environment: self.scene.environment,
        }
    }

    /// Steps before the first one averaged into the image.
    pub fn burn_in(&self) -> u32 {
        self.burn_in
    }

    /// Writes the uniforms of step `k`: its bundle, then, once past the burn-in, its camera
    /// sample (a uniform point of every pixel) and, on the steps that estimate the direct
    /// light (`DirectSchedule::due`), new points on the area lights, all from the step's own
    /// generator.
    pub fn write_step(&mut self, k: u32) {
        let queue = &self.ctx.queue;
        let image_step = k >= self.image_start;
        let per_step = self.per_step;
        let settled = self.burn_in.saturating_mul(per_step) >= crate::iteration::SETTLED_MEAN_BUNDLES;
        let image = image_step.then_some(crate::iteration::ImagePlan {
            start: self.image_start as u64,
            steps: self.image_steps.filter(|_| settled).map(u64::from),
        });
        let mut rng = self.iteration_at(k).write_bundles(
            queue,
            self.options.seed,
            k as u64,
            per_step,
            image,
            &self.bundle_scene(),
        );
        if image_step {
            let i = k - self.image_start;
            // Two draws the step's generator once gave the camera sample: kept, so that what
            // it draws next (the points on the lights) stays as it was.
            let _ = [rng.uniform(), rng.uniform()];
            let sample = crate::rng::stratified_pixel_sample(self.options.seed, i as u64);
            self.write_camera(sample.position());
            self.direct_due = self.direct_schedule.due(i);
            // The area lights' windows of the step's pass: new points on a step that estimates
            // the direct light; on the others, the last such step's, which the near senders'
            // first bounce reads (rendered again where a resumed run or a redone batch has
            // others in place, so that the image does not depend on either).
            self.windows_due = false;
            if self.direct_due || self.first_bounce_per_point {
                let pass = self.direct_schedule.estimates(i + 1) as u64 - 1;
                self.windows_due = self.direct.prepare_pass(queue, pass);
            }
        }
    }

    /// Every view's camera uniform, with the sample at `position` inside each pixel (x right,
    /// y down, in [0, 1)): the views share the step's sample, so each view's image is that of
    /// a run with its camera alone. And whether each view's item buffer is rendered this step
    /// (`ViewImage::raster_due`): at every sample where it holds one texel a pixel; where it
    /// holds S x S (`camera_supersample`), only where the sample's offset inside its S x S
    /// texels differs from the raster's, so that one raster serves the steps of a block of
    /// camera samples (`rng::stratified_pixel_sample`), and a direct-light image's passes, each
    /// at its own offset, render one each.
    fn write_camera(&mut self, position: [f64; 2]) {
        let queue = &self.ctx.queue;
        for view in &mut self.views {
            let c = view.camera;
            let s = view.item_buffer.supersample;
            let mut cam = gpu_camera(&c, c.width, c.height, self.near, [position[0] as f32, position[1] as f32]);
            if s == 1 {
                view.raster_due = true;
                view.raster_view = cam;
            } else {
                // The texel of the pixel's S x S that holds the sample, and the sample's offset
                // from that texel's corner, in texels (exact: S is a power of two).
                let scaled = position.map(|p| p * s as f64);
                let cell = scaled.map(|v| (v.floor() as u32).min(s - 1));
                let offset = [scaled[0] - cell[0] as f64, scaled[1] - cell[1] as f64];
                cam.size[3] = s | cell[0] << 8 | cell[1] << 16;
                let key = offset.map(f64::to_bits);
                view.raster_due = view.rastered != Some(key);
                if view.raster_due {
                    let raster = gpu_camera(&c, c.width * s, c.height * s, self.near, offset.map(|v| v as f32));
                    let buffer = view.item_buffer.raster_camera.as_ref().expect("a supersampled view's raster camera");
                    queue.write_buffer(buffer, 0, bytemuck::bytes_of(&raster));
                    view.rastered = Some(key);
                    view.raster_view = raster;
                }
            }
            queue.write_buffer(&view.item_buffer.camera, 0, bytemuck::bytes_of(&cam));
        }
    }

    /// Forgets what every view's item buffer holds, so that the next step renders it: after a
    /// new camera, a restored checkpoint or a redone batch.
    fn forget_rasters(&mut self) {
        for view in &mut self.views {
            view.rastered = None;
        }
    }

    /// The views, in order.
    pub fn views(&self) -> &[ViewImage] {
        &self.views
    }

    /// Points the first view at `camera` (of the view's size) and starts its image average
    /// afresh with step `step` (or, within the burn-in, with the burn-in's end): a frame of
    /// a walkthrough, or a camera move in the viewer. The iteration state carries on, since
    /// it does not depend on the view; so the new image sharpens within a few steps. `steps`:
    /// how many steps the new image will average, where known (its directions are then
    /// stratified over them, `iteration::ImagePlan`).
    pub fn restart_image(&mut self, camera: Camera, step: u32, steps: Option<u32>) {
        let view = &mut self.views[0];
        view.camera = Camera { width: view.camera.width, height: view.camera.height, ..camera };
        self.forget_rasters();
        self.clear_images();
        self.image_start = step.max(self.burn_in);
        self.image_steps = steps;
    }

    /// How many steps the image will average, where known (its directions are then
    /// stratified over them, `iteration::ImagePlan`); only before its first step, since its
    /// steps so far took their directions from the plan they had.
    pub fn set_image_steps(&mut self, steps: Option<u32>) {
        self.image_steps = steps;
    }

    /// The step whose estimate is the first of the image (`restart_image`).
    pub fn image_start(&self) -> u32 {
        self.image_start
    }

    /// Runs steps `step..end` in batches, as `run` does (fewer if the hooks stop them);
    /// returns the step reached. The viewer calls it with a few steps per frame.
    pub fn advance_to(&mut self, step: u32, end: u32, hooks: &mut dyn Hooks) -> Result<u32> {
        Ok(self.advance(step, end, hooks)?.steps)
    }

    /// Zeroes every view's image sum (a frame of a walkthrough starts its own average).
    fn clear_images(&self) {
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        for view in &self.views {
            view.estimate.clear(&mut encoder);
        }
        self.ctx.queue.submit([encoder.finish()]);
    }

    /// The stages of step `k`, in order (its uniforms written by `write_step`): for each of
    /// its bundles the bundle stages of the iteration, then, past the burn-in, the image
    /// stages: after the first bundle the camera item buffer and the direct light (when
    /// due) and each bundle's gather after its own stages (the pixels of its class).
    pub fn step_stages(&self, k: u32) -> Vec<Stage<'_>> {
        let iteration = self.iteration_at(k);
        let mut stages = Vec::new();
        for index in 0..self.per_step {
            stages.extend(iteration.stages(&self.buffers, index));
            if k >= self.image_start {
                match index {
                    0 => stages.extend(self.image_stages(self.direct_due, true)),
                    _ => stages.extend(self.gather_stages()),
                }
            }
        }
        stages
    }

    /// Every view's gather through the bundle last run (the pixels of its class).
    fn gather_stages(&self) -> Vec<Stage<'_>> {
        self.views.iter().flat_map(|view| gather_pass_stages(&view.estimate)).collect()
    }

    /// The stages that add one estimate of every pixel of every view to its image sum: per
    /// view the camera item buffer, then, if `direct`, the estimate of Le + D, then, if
    /// `gather`, the estimate of G through this step's bundle. The area lights' windows at
    /// this pass's points, which every view's Le + D reads (and its gathers, for the near
    /// senders' first bounce), are rendered once when due, after the first view's item
    /// buffer.
    fn image_stages(&self, direct: bool, gather: bool) -> Vec<Stage<'_>> {
        let (buffers, lights) = (&self.buffers, &self.direct);
        let windows_due = self.windows_due;
        let mut stages: Vec<Stage<'_>> = Vec::new();
        for (v, view) in self.views.iter().enumerate() {
            let (camera, estimate, raster_view) = (&view.item_buffer, &view.estimate, &view.raster_view);
            if view.raster_due {
                stages.push((
                    "camera",
                    Box::new(move |e: &mut wgpu::CommandEncoder| camera.record(e, &buffers.raster, raster_view)),
                ));
            }
            if (direct || windows_due) && v == 0 {
                stages.push((
                    "light_windows",
                    Box::new(move |e: &mut wgpu::CommandEncoder| {
                        if windows_due {
                            lights.record_pass(e, buffers)
                        }
                    }),
                ));
            }
            if direct {
                stages.push(("direct", Box::new(move |e: &mut wgpu::CommandEncoder| estimate.record_direct(e))));
            }
            if gather {
                stages.extend(gather_pass_stages(estimate));
            }
        }
        stages
    }

    /// Writes step `k`'s uniforms and submits the whole step in one command buffer.
    pub fn submit_step(&mut self, k: u32) {
        self.write_step(k);
        self.submit(&self.step_stages(k), "firstshot.render.step");
    }

    fn submit(&self, stages: &[Stage<'_>], label: &str) {
        let mut encoder =
            self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        for (_, record) in stages {
            record(&mut encoder);
        }
        self.ctx.queue.submit([encoder.finish()]);
    }

    /// Step `k` stage by stage, each submitted and timed on its own (`gpu::profile`); it
    /// leaves the same state as `submit_step`.
    ///
    /// Every view's camera item buffer is rendered in it, also where a supersampled one would
    /// have served this step from an earlier raster, so that the profile shows its cost.
    pub fn profile_step(&mut self, k: u32, timer: &StageTimer, before: Vec<Stage<'_>>) -> Result<Vec<StageTime>> {
        self.forget_rasters();
        self.write_step(k);
        let mut stages = before;
        stages.extend(self.step_stages(k));
        timer.run(self.ctx, &stages)
    }

    /// Fragments (surfaces on lines) of the last step: its last bundle's, times the bundles a
    /// step (the bundles differ only in direction, so they hold about as many each).
    pub fn fragments(&self) -> Result<u64> {
        Ok(self.iteration().fragments(self.ctx)? * self.per_step as u64)
    }

    /// The last step's fragments past their lines' buckets (spill nodes; `LINE_BUCKET`).
    pub fn spilled(&self) -> Result<u32> {
        Ok(self.iteration().tally(self.ctx)?[TALLY_SPILLED as usize])
    }

    /// Whether a step since the last `clear_overflow` ran out of fragment room.
    pub fn overflowed(&self) -> Result<bool> {
        Ok(self.iteration().overflowed(self.ctx)? || self.coarse_overflowed()?)
    }

    fn coarse_overflowed(&self) -> Result<bool> {
        self.coarse.as_ref().map_or(Ok(false), |(coarse, _)| coarse.overflowed(self.ctx))
    }

    pub fn clear_overflow(&self) {
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        self.iteration().clear_overflow(&mut encoder);
        if let Some((coarse, _)) = &self.coarse {
            coarse.clear_overflow(&mut encoder);
        }
        self.ctx.queue.submit([encoder.finish()]);
    }

    /// After an overflow: each iteration whose fragment list ran out of room gets one of
    /// twice the size (sharing the per-patch arrays, so the state is untouched).
    fn regrow(&mut self) -> Result<()> {
        let (ctx, device) = (self.ctx, &self.ctx.device);
        if let Some((coarse, steps)) = &self.coarse
            && coarse.overflowed(ctx)?
        {
            let capacity = (coarse.capacity as u64).saturating_mul(2);
            self.coarse = Some((coarse.resized(ctx, &self.buffers, coarse.grid, capacity)?, *steps));
        }
        let full = self.iteration();
        if full.overflowed(ctx)? {
            let capacity = (full.capacity as u64).saturating_mul(2);
            let iteration = full.resized(ctx, &self.buffers, full.grid, capacity)?;
            for view in &mut self.views {
                view.estimate.rebind_gather(device, &iteration.gather);
            }
            self.iteration = Some(iteration);
        }
        Ok(())
    }

    /// The iteration state (J_j, win_j of every patch) as bytes.
    pub fn read_state(&self) -> Result<Vec<u8>> {
        let mut out = Vec::with_capacity(self.buffers.state.size() as usize);
        for b in &self.buffers.state.pages {
            crate::gpu::buffers::read_back_into(&self.ctx.device, &self.ctx.queue, b, 0, b.size(), &mut out)?;
        }
        Ok(out)
    }

    /// The image of the first view so far: the mean of the estimates.
    pub fn read_image(&self) -> Result<Image> {
        self.read_view_image(0)
    }

    /// The image of view `v` so far.
    pub fn read_view_image(&self, v: usize) -> Result<Image> {
        let view = &self.views[v];
        let pixels = view.estimate.read_mean(&self.ctx.device, &self.ctx.queue)?;
        Ok(Image::new(view.camera.width, view.camera.height, pixels))
    }

    /// The images of every view so far.
    fn read_images(&self) -> Result<Vec<Image>> {
        (0..self.views.len()).map(|v| self.read_view_image(v)).collect()
    }

    /// Runs the render to its end (or until the hooks stop it) and reads the image back.
    pub fn run(mut self, resume: Option<&Checkpoint>, hooks: &mut dyn Hooks) -> Result<Rendered> {
        let image_start = Instant::now();
        let mut iteration_stats = IterationStats::default();
        let mut direct = DirectImage::default();
        if self.options.iterations == 0 {
            direct = self.direct_image(hooks)?;
        } else {
            iteration_stats = self.iterate(resume, hooks)?;
            hooks.phase("iteration", iteration_stats.ms);
            if iteration_stats.steps <= self.burn_in {
                // The time limit ended the run before any step reached the image (it was
                // shorter than the first shot, or than the burn-in): the image is the
                // direct light instead, without the state of the unfinished burn-in.
                direct = self.direct_image(hooks)?;
            }
        }
        let camera_samples = match direct.passes {
            0 => iteration_stats.steps.saturating_sub(self.burn_in),
            passes => passes,
        };
        let mut images = Vec::with_capacity(self.views.len());
        for view in &self.views {
            let image_sum = view.estimate.read_sum(&self.ctx.device, &self.ctx.queue)?;
            let pixels = crate::stages::image_estimate::image_of_sums(&image_sum)?;
            let image = Image::new(view.camera.width, view.camera.height, pixels);
            images.push(RenderedView { name: view.name.clone(), image, image_sum });
        }
        let first = images.remove(0);
        let image_ms = milliseconds(image_start);
        self.ctx.check()?;
        let (o, fs) = (&self.options, self.first_shot.as_ref());
        // The coarse burn-in planned, as `new` planned it (its iteration is gone by now).
        let coarse_plan = match self.iteration {
            Some(_) => crate::iteration::coarse_burn_in(self.bundle_resolution, self.burn_in, self.per_step),
            None => None,
        };
        Ok(Rendered {
            interrupted: iteration_stats.interrupted || direct.interrupted,
            image: first.image,
            image_sum: first.image_sum,
            other_views: images,
            stats: RenderStats {
                adapter: self.ctx.summary.clone(),
                scene: self.scene.source.display().to_string(),
                patches: self.patch_count,
                raster_triangles: self.buffers.raster.triangles,
                light_samples: self.light_samples,
                image: [o.width, o.height],
                patch_size: o.patch_size,
                camera_samples,
                first_shot: fs.is_some(),
                hemicube_resolution: self.hemicube_resolution,
                light_window: o.light_window,
                first_shot_pairs: fs.map_or(0, |f| f.pairs),
                first_shot_faces: fs.map_or(0, |f| f.faces),
                first_shot_ms: fs.map_or(0.0, |f| f.ms),
                shadow_resolution: self.direct.resolution,
                shadow_atlas_texels: self.direct.atlas_texels(),
                light_visibility: self.direct.visibility.name(),
                unshadowed_patches: self.direct.shaft_stats.map(|(patches, _)| patches),
                unshadowed_ms: self.direct.shaft_stats.map(|(_, ms)| ms),
                memory: crate::memory::MemoryPlan { peak_rss_bytes: crate::memory::peak_rss(), ..self.memory.clone() },
                bundle_resolution: self.bundle_resolution,
                bundles_per_step: self.per_step,
                wide_lines: self.iteration.as_ref().map_or(1, |i| i.grid.wide()),
                bundle_lines: self.iteration.as_ref().map_or(0, |i| i.grid.line_capacity(self.buffers.radius)),
                gather: self.views[0].estimate.passes().name(),
                bundle_capacity: iteration_stats.capacity,
                iteration_ms_median: iteration_stats.step_ms_median,
                iteration_ms: iteration_stats.ms,
                iterations: iteration_stats.steps.saturating_sub(self.burn_in),
                burn_in_steps: iteration_stats.steps.min(self.burn_in),
                burn_in_decay: self.burn_in_decay,
                coarse_burn_in_steps: coarse_plan.map_or(0, |(_, steps)| iteration_stats.steps.min(steps)),
                coarse_bundle_resolution: coarse_plan.map(|(resolution, _)| resolution),
                seed: o.seed,
                lp_num_threads: std::env::var("LP_NUM_THREADS").ok(),
                tessellation_ms: 0.0,
                upload_ms: self.upload_ms,
                image_ms,
                total_ms: milliseconds(self.start),
                notes: self.notes.clone(),
            },
        })
    }

    /// An image without iteration: emission and direct light, averaged over
    /// `direct_passes` passes, each with its own camera sample per pixel (stratified over a
    /// grid of the largest square number of passes) and its own points on the area lights.
    /// A stop (`Hooks::stop_requested`) or the time limit ends it after any pass but the first.
    fn direct_image(&mut self, hooks: &mut dyn Hooks) -> Result<DirectImage> {
        let passes = self.options.direct_passes.max(1);
        let per_axis = (passes as f64).sqrt().floor().max(1.0) as u32;
        let queue = &self.ctx.queue;
        // Pass k takes light triangle k mod T; the camera cells go in a shuffled order, so
        // that a pixel's sub-position is not tied to a part of the light.
        let cells = per_axis * per_axis;
        let mut order: Vec<u32> = (0..cells).collect();
        let mut shuffle = StepRng::new(self.options.seed, u64::MAX - passes as u64);
        for i in (1..order.len()).rev() {
            let pick = ((shuffle.uniform() * (i + 1) as f64) as usize).min(i);
            order.swap(i, pick);
        }
        // No gather adds its share of the emitting shapes' light, nor the emission the pixels
        // see: D's half takes all of it.
        for view in &self.views {
            view.estimate.set_params(
                queue,
                self.scene.environment,
                self.buffers.patch_count,
                self.direct.count(),
                false,
                false,
            );
        }
        let mut done = DirectImage::default();
        for k in 0..passes {
            // Generators of their own, apart from the steps' (seed, k) streams.
            let mut rng = StepRng::new(self.options.seed, u64::MAX - k as u64);
            let cell = order[(k % cells) as usize];
            let jitter = [
                ((cell % per_axis) as f64 + rng.uniform()) / per_axis as f64,
                ((cell / per_axis) as f64 + rng.uniform()) / per_axis as f64,
            ];
            self.write_camera(jitter);
            self.windows_due = self.direct.prepare_pass(queue, k as u64);
            self.submit(&self.image_stages(true, false), "firstshot.render.direct_image");
            done.passes = k + 1;
            if done.passes % STEPS_PER_BATCH == 0 {
                // Waiting now and then keeps the GPU's queue short, so that a stop or the
                // time limit takes effect within a few passes, not after all that were queued.
                self.ctx.wait()?;
            }
            if done.passes < passes && hooks.stop_requested() {
                done.interrupted = true;
                break;
            }
            if self.options.time_limit.is_some_and(|limit| self.start.elapsed() >= limit) {
                break;
            }
        }
        Ok(done)
    }

    /// The state after `step` steps, with the image sums of every view one after another.
    fn checkpoint(&self, step: u32) -> Result<(Checkpoint, Vec<Image>)> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let mut image_sum = Vec::new();
        for view in &self.views {
            for sum in view.estimate.sum_buffers() {
                crate::gpu::buffers::read_back_into(device, queue, sum, 0, sum.size(), &mut image_sum)?;
            }
        }
        let checkpoint = Checkpoint {
            fingerprint: fingerprint(self.scene, &self.options),
            step,
            state: self.read_state()?,
            image_sum,
        };
        Ok((checkpoint, self.read_images()?))
    }

    /// Puts a checkpoint's state and image sums on the GPU; returns its step. Its
    /// fingerprint was checked where it was read (`main.rs`); the sizes guard the copies.
    fn restore(&self, c: &Checkpoint) -> Result<u32> {
        let sums: u64 = self.views.iter().flat_map(|v| v.estimate.sum_buffers()).map(|b| b.size()).sum();
        if c.state.len() as u64 != self.buffers.state.size() || c.image_sum.len() as u64 != sums {
            return Err(Error::Usage("the checkpoint's state does not fit this scene; run without --resume".into()));
        }
        self.buffers.state.write(&self.ctx.queue, &c.state);
        let mut at = 0;
        for sum in self.views.iter().flat_map(|v| v.estimate.sum_buffers()) {
            let size = sum.size() as usize;
            self.ctx.queue.write_buffer(sum, 0, &c.image_sum[at..at + size]);
            at += size;
        }
        Ok(c.step)
    }

    /// The stochastic iteration: `options.iterations` steps (or fewer if `time_limit` or the
    /// hooks end it), each adding one image estimate. Steps run in batches; the state and
    /// image sum are kept at each batch's start, so a batch in which a line ran out of
    /// fragment room is redone, exactly, with a larger list.
    fn iterate(&mut self, resume: Option<&Checkpoint>, hooks: &mut dyn Hooks) -> Result<IterationStats> {
        let step = match resume {
            Some(c) => self.restore(c)?,
            None => 0,
        };
        let total = self.options.iterations.saturating_add(self.burn_in);
        self.advance(step, total, hooks)
    }

    /// Steps `step..total` (fewer if `time_limit` or the hooks end them), those from
    /// `image_start` on each adding one image estimate, in batches (`iterate`).
    fn advance(&mut self, mut step: u32, total: u32, hooks: &mut dyn Hooks) -> Result<IterationStats> {
        let (ctx, options) = (self.ctx, self.options.clone());
        let device = &ctx.device;
        let started = Instant::now();
        let backup = |b: &wgpu::Buffer, label: &str| {
            let copy = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: b.size(),
                usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            (b.clone(), copy)
        };
        let mut kept: Vec<_> =
            self.buffers.state.pages.iter().map(|b| backup(b, "firstshot.render.state_backup")).collect();
        kept.extend(
            self.views
                .iter()
                .flat_map(|v| v.estimate.sum_buffers())
                .map(|b| backup(b, "firstshot.render.image_backup")),
        );
        let copy_all = |to_backup: bool| {
            let mut encoder = device.create_command_encoder(&Default::default());
            for (live, copy) in &kept {
                let (from, to) = if to_backup { (live, copy) } else { (copy, live) };
                encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
            }
            ctx.queue.submit([encoder.finish()]);
        };
        let mut batch_ms = Vec::new();
        let mut interrupted = false;
        while step < total && !interrupted {
            // Past the time limit (even within the burn-in: `run` then makes a direct image).
            if options.time_limit.is_some_and(|limit| self.start.elapsed() >= limit) {
                break;
            }
            let batch_start = Instant::now();
            copy_all(true);
            self.clear_overflow();
            let mut batch = 0;
            while batch < STEPS_PER_BATCH && step + batch < total {
                self.submit_step(step + batch);
                batch += 1;
                // A stop waits for the burn-in and one image step, so that there is an image
                // to write (and a checkpoint to resume from).
                if hooks.stop_requested() && step + batch > self.image_start {
                    interrupted = true;
                    break;
                }
            }
            let overflowed = self.overflowed()?;
            ctx.check()?;
            if overflowed {
                // A line held more surfaces than the list had room for: restore the batch's
                // start and redo it with twice the room.
                copy_all(false);
                self.forget_rasters();
                self.regrow()?;
                interrupted = false;
                continue;
            }
            batch_ms.push(batch_start.elapsed().as_secs_f64() * 1e3 / batch as f64);
            step += batch;
            if self.coarse.as_ref().is_some_and(|(_, steps)| step >= *steps) {
                // Its steps are done: give its lines and fragments back.
                self.coarse = None;
            }
            hooks.progress(step, total);
            if step > self.image_start && hooks.checkpoint_due() {
                let (checkpoint, images) = self.checkpoint(step)?;
                hooks.checkpoint(checkpoint, &images)?;
            }
        }
        ctx.wait()?;
        if hooks.wants_final_checkpoint() && step > self.image_start {
            let (checkpoint, images) = self.checkpoint(step)?;
            hooks.checkpoint(checkpoint, &images)?;
        }
        batch_ms.sort_by(f64::total_cmp);
        Ok(IterationStats {
            steps: step,
            capacity: self.bundle_size().0,
            step_ms_median: batch_ms.get(batch_ms.len() / 2).copied().unwrap_or(0.0),
            ms: started.elapsed().as_secs_f64() * 1e3,
            interrupted,
        })
    }
}

/// A view's gather through the bundle last run: a stage for each of its passes
/// (`ImageEstimate::gather_passes`), so that the profile times them apart.
fn gather_pass_stages(estimate: &ImageEstimate) -> Vec<Stage<'_>> {
    let passes = estimate.gather_passes().into_iter().enumerate();
    passes
        .map(|(pass, name)| -> Stage<'_> {
            (name, Box::new(move |e: &mut wgpu::CommandEncoder| estimate.record_gather_pass(e, pass)))
        })
        .collect()
}

/// The passes of a direct-light image that ran, and whether a stop ended them early.
#[derive(Debug, Default, Clone, Copy)]
struct DirectImage {
    passes: u32,
    interrupted: bool,
}

#[derive(Debug, Default, Clone, Copy)]
struct IterationStats {
    steps: u32,
    capacity: u32,
    step_ms_median: f64,
    ms: f64,
    interrupted: bool,
}

/// Steps per batch between checks of the fragment overflow flag (each check waits for the GPU).
const STEPS_PER_BATCH: u32 = 8;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bundle_resolution_too_coarse_for_the_glossy_patches_gets_a_note() {
        let note = |name: &str, bundle_resolution: Option<u32>, bundles_per_step: Option<u32>| {
            let scene = crate::scene::load::load(std::path::Path::new(&format!("scenes/{name}.toml"))).unwrap();
            let patches = crate::scene::tessellate::tessellate(&scene, scene.settings.patch_size).unwrap();
            let options = RenderOptions {
                bundle_resolution,
                bundles_per_step,
                iterations: 8,
                ..RenderOptions::from_scene(&scene)
            };
            options.coarse_bundle_note(&scene, &patches)
        };
        // The fractal's triangles (edge 2 / 64) in a room of radius 5.8 ask for about 640 for
        // one line a step: 128 crosses the median one with (128 / 640)^2 = 0.04 lines a step of
        // one bundle, 256 with 0.16, 352 with 0.3.
        let coarse = note("sierpinski", Some(128), Some(1)).expect("128 is far too coarse for the fractal");
        assert!(coarse.contains("bundle resolution 128") && coarse.contains("0.04 lines"), "{coarse}");
        assert!(coarse.contains("1 bundle a step; the automatic resolution, 832"), "{coarse}");
        assert!(note("sierpinski", Some(256), Some(1)).is_some());
        assert_eq!(note("sierpinski", Some(352), Some(1)), None);
        // A small glossy fractal (size 0.5: under a tenth of the view) leaves the resolution to
        // the image: 192 at 128 x 128, against about 2 600 for one line a step.
        // The Sierpinski scene with `edits` made to its file, and its patches.
        let edited = |edits: &[(&str, &str)]| {
            let text = edits
                .iter()
                .fold(std::fs::read_to_string("scenes/sierpinski.toml").unwrap(), |t, (from, to)| t.replace(from, to));
            let scene = crate::scene::load::load_str(&text, std::path::Path::new("edited.toml")).unwrap();
            let patches = crate::scene::tessellate::tessellate(&scene, scene.settings.patch_size).unwrap();
            (scene, patches)
        };
        let (scene, patches) =
            edited(&[("size = 2.0", "size = 0.5"), ("width = 512", "width = 128"), ("height = 512", "height = 128")]);
        let small = RenderOptions { iterations: 8, ..RenderOptions::from_scene(&scene) };
        let noted = small.coarse_bundle_note(&scene, &patches).expect("the image's resolution is far too coarse");
        assert!(noted.contains("under 10 % of the view") && noted.contains("resolution, 192"), "{noted}");
        // Asked for there, the note names the asked resolution and what one line would take.
        let asked = RenderOptions { bundle_resolution: Some(256), ..small };
        let noted = asked.coarse_bundle_note(&scene, &patches).expect("256 is far too coarse too");
        assert!(noted.contains("bundle resolution 256 (") && noted.contains("about 2581 would give one"), "{noted}");
        // Four bundles a step (the scene's 512 x 512 takes them when automatic) give four times
        // the lines, at half the automatic resolution.
        let four = note("sierpinski", Some(128), None).expect("0.16 lines a step");
        assert!(
            four.contains("0.16 lines") && four.contains("4 bundles a step; the automatic resolution, 416"),
            "{four}"
        );
        assert_eq!(note("sierpinski", Some(256), None), None);
        // Automatic: not where the automatic resolution gives one line a step.
        assert_eq!(note("sierpinski", None, None), None);
        // But where it stops at its cap: a fractal of level 7 and size 1 (edge 1 / 128, area
        // 2.6e-5), seen from close by, would need 2 r sqrt(2 / A) = 2 580, so 1 024 crosses
        // its median triangle with (1024 / 2580)^2 = 0.16 lines a step.
        let (scene, patches) = edited(&[
            ("level = 6", "level = 7"),
            ("size = 2.0", "size = 1.0"),
            ("position = [0.8, 1.45, 2.8]", "position = [0.4, 0.9, 1.4]"),
        ]);
        let options = RenderOptions { iterations: 8, bundles_per_step: Some(1), ..RenderOptions::from_scene(&scene) };
        let capped = options.coarse_bundle_note(&scene, &patches).expect("the cap binds");
        assert!(capped.contains("0.16 lines") && capped.contains("about 2581"), "{capped}");
        // No iteration, no note.
        assert_eq!(RenderOptions { iterations: 0, ..options }.coarse_bundle_note(&scene, &patches), None);
        // Diffuse scenes: never.
        assert_eq!(note("cornell_box", Some(16), None), None);
        // The glossy blocks of cornell_point are large: a coarse grid still crosses them.
        assert_eq!(note("cornell_point", Some(64), None), None);
    }

    #[test]
    fn direct_schedule_keeps_16_front_passes_only_where_a_light_samples_new_points() {
        // (scene, first shot, --direct-passes, --window-steps) -> its schedule.
        let schedule = |name: &str, first_shot: bool, direct_passes: u32, window_steps: u32| {
            let scene = crate::scene::load::load(std::path::Path::new(&format!("scenes/{name}.toml"))).unwrap();
            let patches = crate::scene::tessellate::tessellate(&scene, scene.settings.patch_size).unwrap();
            let options =
                RenderOptions { first_shot, direct_passes, window_steps, ..RenderOptions::from_scene(&scene) };
            DirectSchedule::of(&scene, &patches, &options)
        };
        let (passes, every) = (DEFAULT_DIRECT_PASSES, DEFAULT_WINDOW_STEPS);
        // An area light, emitting shapes: every pass a new point on them.
        assert_eq!(schedule("cornell_box", true, passes, every).front, FRONT_DIRECT_PASSES);
        assert_eq!(schedule("cornell_emissive", true, passes, every).front, FRONT_DIRECT_PASSES);
        // A point light; a spot and a sun: windows kept for the run.
        assert_eq!(schedule("cornell_point", true, passes, every).front, FRONT_DIRECT_PASSES_KEPT_WINDOWS);
        assert_eq!(schedule("sun_room", true, passes, every).front, FRONT_DIRECT_PASSES_KEPT_WINDOWS);
        // Without first shot there is no direct light to sample.
        assert_eq!(schedule("cornell_box", false, passes, every).front, FRONT_DIRECT_PASSES_KEPT_WINDOWS);
        // `--direct-passes` below either caps it; `--window-steps` sets the rest.
        assert_eq!(schedule("cornell_box", true, 2, 5), DirectSchedule { front: 2, every: 5 });
        assert_eq!(schedule("cornell_point", true, 2, 5), DirectSchedule { front: 2, every: 5 });
        let point = schedule("cornell_point", true, passes, every);
        assert_eq!((0..20).filter(|&i| point.due(i)).count() as u32, point.estimates(20));
        assert_eq!(point.estimates(20), 4 + 2);
    }

    #[test]
    fn direct_light_estimates_count_the_steps_that_are_due() {
        for (first, every) in [(0, 1), (0, 4), (1, 2), (64, 4), (5, 3), (7, 7), (3, 1000)] {
            let mut count = 0;
            for n in 0..300 {
                assert_eq!(estimates(n, first, every), count, "first {first}, every {every}, n {n}");
                count += due(n, first, every) as u32;
            }
        }
        // Every step at first, then one in four.
        assert_eq!(estimates(64, 64, 4), 64);
        assert_eq!(estimates(1000, 64, 4), 64 + 234);
    }
}
