//! Ray-bundle stochastic iteration (docs/ALGORITHM.md 2): the buffers of one step and the order of
//! its stages. Each step k draws its direction, grid rotation and sub-pixel offset from
//! `StepRng(seed, k)`, so the state between steps is only J_j, win_j and the image sum.

use crate::gpu::profile::Stage;
use crate::gpu::scene_buffers::{IMAGE_SENDERS, OUTGOING, Paged, SceneBuffers, TRANSFER_SUMS};
use crate::gpu::{Context, buffers};
use crate::layout::{BURN_IN_STEP, GpuBundle, IMAGE_STEP, IMAGE_STEP_OWN_DIRECTIONS, LINE_BUCKET};
use crate::rng::StepRng;
use crate::scene::Patches;
use crate::stages::bundle_finalize::BundleFinalize;
use crate::stages::bundle_reflect::{BundleReflect, ReflectOutputs};
use crate::stages::bundle_transfer::BundleTransfer;
use crate::stages::bundle_visibility::BundleVisibility;
use crate::{Error, Result};
use glam::DVec3;

/// What every step's bundle uniform shares: the scene's bounding sphere, its size in
/// patches and the environment radiance.
#[derive(Debug, Clone, Copy)]
pub struct BundleScene {
    pub centre: DVec3,
    pub radius: f64,
    pub patch_count: u32,
    pub environment: [f32; 3],
}

/// Bundles a step draws where it draws several (`--bundles-per-step`, `auto_bundles_per_step`), each with its own direction,
/// together as many lines as one bundle at twice their resolution (`bundle_resolution_for`
/// halves the automatic choice), and each the gather of one pixel in four: one pixel of
/// every 2 x 2 block gathers through bundle q (which one, shuffled per block and step:
/// `class_pixel` in wgsl/image_estimate.wgsl). One direction a step for
/// every pixel made the image's error low-frequency: about 92 % of a 200-step image's
/// variance was which directions the run drew, shared by all pixels, so that averaging 2 x 2
/// pixels barely reduced it (docs/PERFORMANCE.md, "Where the image's error lies"). With
/// four bundles a step, neighbouring pixels gather along independent directions and their
/// errors average out; the state gets four directions a step (four bounces).
pub const BUNDLES_PER_STEP: u32 = 4;

/// The bundle counts a step may have: one, or four interleaved over 2 x 2 pixels.
pub const BUNDLES_PER_STEP_CHOICES: [u32; 2] = [1, BUNDLES_PER_STEP];

/// Which of a step's bundles: `index` of `per_step` (1 or 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepBundle {
    pub index: u32,
    pub per_step: u32,
}

/// The pixel stride of the gather's classes for `per_step` bundles a step: 1 or 2.
pub fn pixel_stride(per_step: u32) -> u32 {
    if per_step >= 4 { 2 } else { 1 }
}

/// Bundles of burn-in an image needs before its directions can be its own stratified set:
/// the images's steps then keep every Lbar_j as the burn-in left it (bundle_finalize), which
/// takes about this many bundles to settle (its weight, MEAN_RADIANCE_WEIGHT there, is 1/8).
/// With less (`--burn-in 0`), the image takes the run's blocks of directions and Lbar_j runs
/// on, as it did before images had sets of their own.
pub const SETTLED_MEAN_BUNDLES: u32 = 8;

/// The image a step belongs to: it started at step `start` and averages `steps` steps where
/// that is known (a run's `--iterations`, a walkthrough frame's steps) and the burn-in
/// settled Lbar_j (`SETTLED_MEAN_BUNDLES`), `None` where not (the viewer, which refines until
/// the camera moves).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImagePlan {
    pub start: u64,
    pub steps: Option<u64>,
}

/// A bundle's grid: `resolution` lines along an edge of the square around the scene's
/// bounding sphere, all of them (one level) or, where a fine window is set, only inside it,
/// with one wide line for each `wide` x `wide` block of them outside (docs/ALGORITHM.md
/// 6, "Two levels of lines").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub resolution: u32,
    pub window: Option<FineWindow>,
}

/// The patches that need the fine lines (the glossy ones, `BundleNeeds`), as a sphere that
/// holds them: each bundle keeps its fine lines only around the sphere's projection, a
/// square of about its diameter whatever the direction, and takes wide lines, `wide`
/// fine lines wide, everywhere else. A wide line is one sample of the transfer over its
/// whole square (its radiance counts `wide`^2 times a fine line's), which is what the
/// large diffuse patches outside need; the Sierpinski room's walls took three quarters of
/// a step's lines at the fractal's resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FineWindow {
    pub centre: DVec3,
    pub radius: f64,
    /// Fine lines along a wide line's edge: 2 or 4.
    pub wide: u32,
}

impl FineWindow {
    /// Fine lines from the sphere's projected centre to the window's edge, for lines `pixel`
    /// apart: the radius and one line of margin (a fragment's centre lies inside its
    /// triangle's projection, which lies inside the sphere's).
    pub fn extent(&self, pixel: f64) -> f64 {
        self.radius / pixel + 1.0
    }
}

/// Half the side of the square a grid at `resolution` spans around a sphere of `radius`:
/// `wide` lines of margin on each side, so that a grid shifted by up to half a wide line
/// still covers the sphere.
pub fn grid_half_extent(radius: f64, resolution: u32, wide: u32) -> f64 {
    let r = resolution as f64;
    radius * r / (r - 2.0 * wide as f64)
}

impl Grid {
    pub fn one_level(resolution: u32) -> Self {
        Grid { resolution, window: None }
    }

    /// Fine lines along a wide line's edge (1 with one level).
    pub fn wide(&self) -> u32 {
        self.window.map_or(1, |w| w.wide)
    }

    /// The largest side of a bundle's fine window in fine lines, in a scene's bounding
    /// sphere of `radius`; the resolution with one level. A window spans
    /// floor((a + e) / k) - floor((a - e) / k) + 1 <= floor(2 e / k) + 2 wide lines.
    pub fn largest_window(&self, radius: f64) -> u32 {
        match self.window {
            None => self.resolution,
            Some(w) => {
                let k = w.wide;
                let pixel = 2.0 * grid_half_extent(radius, self.resolution, k) / self.resolution as f64;
                let side = ((2.0 * w.extent(pixel) / k as f64).floor() as u32 + 2) * k;
                side.min(self.resolution)
            }
        }
    }

    /// The lines a bundle of this grid can have, which the line buffers hold.
    pub fn line_capacity(&self, radius: f64) -> u32 {
        let r = self.resolution;
        match self.window {
            None => r * r,
            Some(w) => {
                let side = self.largest_window(radius);
                (r / w.wide) * (r / w.wide) + side * side
            }
        }
    }
}

/// The widths a wide line may have, in fine lines (`--wide-lines`; 1: one level).
pub const WIDE_LINES_CHOICES: [u32; 3] = [1, 2, 4];

/// The wide lines' width where it is not asked for (`--wide-lines auto`): the widest of 4
/// and 2 fine lines that keeps a wide line at most twice as wide as the image's need asks of
/// a bundle's line (`BundleNeeds::image`, halved for four bundles a step, as the automatic
/// resolution is) and crossing the median reflecting patch that is not glossy at least once
/// a step (`BundleNeeds::diffuse`), where glossy patches ask for lines (`BundleNeeds::patches`);
/// else 1 (one level). `fine_window` then keeps one level where the window would not save
/// half the lines.
///
/// The image's need is where the gather's blur at contacts stays small (docs/ALGORITHM.md 6,
/// "Bundle resolution"), and twice it is a judgement: on the Sierpinski scene at 256 x 256
/// wide lines of 1.1 and 2.2 times its width left the error after 60 and 300 steps as it
/// was, and at 512 x 512 (four bundles of 416) wide lines of 1.1 times it after 40 steps,
/// but the Cornell boxes' uniform grids at twice their rule's width had 20-30 % more error
/// after 1000 steps, at their contacts (docs/PERFORMANCE.md, "Two levels of lines").
/// The diffuse patches' need keeps their J from spiking: the sun room at 64 x 48 (bundle 128,
/// a tiny image need) with wide lines of 4, 32 across the scene, had image means 2.1-2.5
/// times Mitsuba's on two seeds of eight, from the few patches such a line crossed.
pub fn auto_wide_lines(needs: &BundleNeeds, resolution: u32, per_step: u32) -> u32 {
    if needs.patches <= 0.0 {
        return 1;
    }
    let image = needs.image / pixel_stride(per_step) as f64;
    [4, 2]
        .into_iter()
        .find(|&k| {
            let wide = (resolution / k) as f64;
            resolution.is_multiple_of(k) && 2.0 * wide >= image && wide >= needs.diffuse
        })
        .unwrap_or(1)
}

/// The fine window of a grid at `resolution` with wide lines `wide` fine lines wide,
/// around the glossy patches (the ones whose size set the resolution, `BundleNeeds`), for a
/// scene in a sphere of `radius`; `None` where there is none or it would not save half the
/// lines.
pub fn fine_window(
    patches: &Patches,
    materials: &[crate::scene::Material],
    radius: f64,
    resolution: u32,
    wide: u32,
) -> Option<FineWindow> {
    if wide < 2 || !resolution.is_multiple_of(wide) || resolution / wide < MIN_BUNDLE_RESOLUTION {
        return None;
    }
    let (mut low, mut high) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let glossy = patches.patches.iter().filter(|p| is_glossy(p, materials));
    for p in glossy.clone() {
        for v in p.vertices {
            low = low.min(v);
            high = high.max(v);
        }
    }
    if low.x > high.x {
        return None;
    }
    let centre = 0.5 * (low + high);
    let sphere = glossy.flat_map(|p| p.vertices).map(|v| v.distance(centre)).fold(0.0f64, f64::max);
    let window = FineWindow { centre, radius: sphere, wide };
    let grid = Grid { resolution, window: Some(window) };
    let lines = resolution as u64 * resolution as u64;
    (2 * grid.line_capacity(radius) as u64 <= lines).then_some(window)
}

/// The bundle of step `step` (the one place a `GpuBundle` is made): direction uniform on
/// the sphere, grid rotated uniformly about it and shifted by a uniform sub-pixel offset;
/// the grid covers the bounding sphere. The directions are stratified: over the image's own
/// steps where its length is known (`rng::image_direction`), else over blocks of the run's
/// steps (`rng::stratified_direction`). `image`: the step is past the burn-in, so its J
/// joins the state's running sum. Returns the step's generator, advanced past the bundle's
/// numbers, for the rest of the step's random choices.
pub fn bundle_of_step(
    seed: u64,
    step: u64,
    bundle: StepBundle,
    image: Option<ImagePlan>,
    scene: &BundleScene,
    grid: &Grid,
    capacity: u32,
) -> (GpuBundle, StepRng) {
    let resolution = grid.resolution;
    let k = grid.wide();
    // The bundles of all steps form one sequence: bundle q of step k is its element
    // k per_step + q (with one bundle a step, element k).
    let index = step * bundle.per_step as u64 + bundle.index as u64;
    let mut rng = StepRng::new(seed, index);
    let (d, image_step) = match image {
        Some(ImagePlan { start, steps: Some(steps) }) if step >= start => {
            let set = crate::rng::ImageDirections { start, steps };
            let d = crate::rng::image_direction(seed, set, bundle.index, bundle.per_step, step - start);
            (d, IMAGE_STEP_OWN_DIRECTIONS)
        }
        Some(_) => (crate::rng::stratified_direction(seed, index), IMAGE_STEP),
        None => (crate::rng::stratified_direction(seed, index), BURN_IN_STEP),
    };
    let angle = 2.0 * std::f64::consts::PI * rng.uniform();
    let t1 = d.any_orthonormal_vector();
    let t2 = d.cross(t1);
    let u = angle.cos() * t1 + angle.sin() * t2;
    let v = d.cross(u);
    // A wide line of margin on each side, so the shifted grid still covers the sphere;
    // the shift uniform over a wide line, so that a wide line's point is uniform over
    // its square as a fine line's is over its own.
    let r = resolution as f64;
    let half = grid_half_extent(scene.radius, resolution, k);
    let pixel = 2.0 * half / r;
    let kf = k as f64;
    let shift = [(rng.uniform() - 0.5) * 2.0 * kf / r, (rng.uniform() - 0.5) * 2.0 * kf / r];
    // The fine window: the lines around the projection of the fine patches' sphere, in
    // whole wide lines (`FineWindow`).
    let (fine_rect, wide_lines) = match grid.window {
        None => ([0, 0, resolution, resolution], 0),
        Some(w) => {
            let c = w.centre - scene.centre;
            let at = [0.5 * (c.dot(u) / half + shift[0] + 1.0) * r, 0.5 * (1.0 - (c.dot(v) / half + shift[1])) * r];
            let extent = w.extent(pixel);
            let [x0, x1, y0, y1] = [at[0] - extent, at[0] + extent, at[1] - extent, at[1] + extent]
                .map(|e| ((e / kf).floor().clamp(0.0, r / kf) as u32) * k);
            let (x1, y1) = ((x1 + k).min(resolution), (y1 + k).min(resolution));
            ([x0, y0, x1 - x0, y1 - y0], (resolution / k) * (resolution / k))
        }
    };
    let line_count = wide_lines + fine_rect[2] * fine_rect[3];
    debug_assert!(line_count <= grid.line_capacity(scene.radius));
    let f = |v: DVec3, w: f64| [v.x as f32, v.y as f32, v.z as f32, w as f32];
    let e = scene.environment;
    let bundle = GpuBundle {
        direction: f(d, pixel * pixel),
        axis_u: f(u / half, shift[0]),
        axis_v: f(v / half, shift[1]),
        centre: f(scene.centre, 1.0 / scene.radius),
        environment: [e[0], e[1], e[2], 0.0],
        resolution,
        patch_count: scene.patch_count,
        capacity,
        // J is zero before the first step has written it.
        use_state: (step > 0) as u32,
        image_step,
        pixel_class: bundle.index,
        pixel_stride: pixel_stride(bundle.per_step),
        // The image's, not the bundle's: a step's four bundles must split each block among
        // them, and each pixel gathers through the same bundle of every step of the image, so
        // that its directions are one bundle's stratified set (`rng::image_direction`).
        pixel_shuffle: image
            .map_or(0, |p| (crate::rng::splitmix64(seed ^ p.start.wrapping_mul(0x9e37_79b9_7f4a_7c15)) >> 32) as u32),
        fine_rect,
        wide: k,
        line_capacity: grid.line_capacity(scene.radius),
        wide_lines,
        line_count,
    };
    (bundle, rng)
}

/// The smallest bundle resolution: a projection keeps a pixel of margin on each side of the
/// scene's bounding sphere (the r - 2 of `fragment_bound`).
pub const MIN_BUNDLE_RESOLUTION: u32 = 4;

/// The bundle resolutions the automatic choice (`auto_bundle_resolution`) takes by itself;
/// `--bundle-resolution` may ask for others.
pub const AUTO_BUNDLE_MIN: u32 = 64;
pub const AUTO_BUNDLE_MAX: u32 = 1024;
/// How many pixel footprints wide a line may be at the median distance a view sees
/// (`auto_bundle_resolution`).
pub const AUTO_BUNDLE_LINE_PIXELS: f64 = 1.5;

/// The bundle resolution when neither the scene nor the command line sets one: the finer of
/// what the patches and what the images need, rounded up to a multiple of 64 within
/// [`AUTO_BUNDLE_MIN`, `AUTO_BUNDLE_MAX`]. `radius` is the bounding sphere's (the grid
/// covers its diameter, so a line is 2 radius / r wide).
///
/// - The patches: a patch of area A is crossed by A |cos| / dP lines of a step, A / (2 dP) on
///   average over directions. Its J_j is the mean of those lines' radiance weighted by the
///   area they stand for, so a patch crossed by fewer than one line has a J_j that is zero
///   on most steps and a multiple of its true value on the others: the spikes the image's
///   gather then reflects from a glossy patch, which sends the image its last few steps' J.
///   A diffuse patch sends the image the mean of its K_j over the image steps
///   (`bundle_reflect`'s image_senders), where one step's spike is one sample among many.
///   The rule gives the glossy patch of median area (`is_glossy`) one line per step on
///   average, r >= 2 radius sqrt(2 / A_median), where glossy patches fill at least
///   `GLOSSY_SHARE` of what the views see; otherwise (walls of fine mesh triangles, a
///   diffuse fractal, a small glossy object) the image alone decides, and with it four
///   bundles a step where the patches are few (docs/PERFORMANCE.md, "Diffuse patches need
///   no line a step").
/// - The images: the gather reads the line through a pixel's surface point, so the
///   sender it finds is the surface x's own ray hits only where that surface has a fragment
///   on the line; elsewhere (near edges and small patches) the indirect light is blurred
///   over about a line's width. The rule makes a line at most `AUTO_BUNDLE_LINE_PIXELS`
///   pixel footprints wide at the median distance of the surfaces a view sees (each patch
///   in the view's frustum weighted by the solid angle it fills, occlusion ignored), for
///   the view that needs it finest.
///
/// The cost of a step grows with r^2 (the fragments), so neither is asked more of. The two
/// constants (one line per median patch, 1.5 pixels) are where the error per second of the
/// bundled scenes peaked at 256 x 256 and 512 x 512 (docs/PERFORMANCE.md, "Bundle
/// resolution").
pub fn auto_bundle_resolution(
    patches: &Patches,
    materials: &[crate::scene::Material],
    radius: f64,
    views: &[crate::scene::NamedCamera],
) -> u32 {
    BundleNeeds::of(patches, materials, radius, views).resolution()
}

/// The share of what the views see (solid angle) from which glossy patches ask the patches'
/// rule for lines (`BundleNeeds::of`): where they fill less, their spikes reach little of the
/// image, and the rest of it is better served by the image's grid (four bundles where the
/// patches are few). A judgement, not a fit: the shipped scenes' glossy shares are 0 and
/// 0.13-0.30, and none of their choices turns on it.
pub const GLOSSY_SHARE: f64 = 0.1;

/// Whether patch `p` reflects glossily (a max-Phong material with some specular part): only
/// such patches ask the patches' rule for lines (`BundleNeeds::of`).
pub fn is_glossy(p: &crate::scene::Patch, materials: &[crate::scene::Material]) -> bool {
    use crate::scene::MaterialKind;
    p.material
        .and_then(|m| materials.get(m as usize))
        .is_some_and(|m| matches!(m.kind, MaterialKind::Phong { specular, .. } if specular.iter().any(|&s| s > 0.0)))
}

/// The two needs of `auto_bundle_resolution`, before rounding: the resolution that gives the
/// median patch one line a step, and the one that makes a line at most
/// `AUTO_BUNDLE_LINE_PIXELS` pixel footprints wide (0 where a rule has nothing to go by).
/// Also what `auto_bundles_per_step` weighs: the scene's patches and the largest view's
/// pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BundleNeeds {
    pub patches: f64,
    pub image: f64,
    /// The patches' rule for the glossy patches whatever their share of the views: `patches`
    /// where they fill at least `GLOSSY_SHARE` of them, else what the rule would ask (0
    /// without glossy patches; `RenderOptions::coarse_bundle_note`).
    pub glossy: f64,
    /// What the patches' rule would give the reflecting patches that are not glossy: the
    /// resolution that crosses their median one with one line a step (`auto_wide_lines`).
    pub diffuse: f64,
    pub patch_count: usize,
    pub view_pixels: u64,
}

/// The bundles a step takes unless told (`--bundles-per-step auto`): four where the image
/// sets the resolution (its need at least the patches'), so that the four bundles at half
/// of it cross the median glossy patch with at least the lines a step that one bundle at
/// the patches' need would; one where the patches set it. There, four bundles at half the
/// resolution cross a patch with fewer lines a step (their J spikier, though the glossy
/// history spreads each spike over eleven bundles), while the per-patch stages (reflect,
/// finalize, each triangle's rasterisation) run four times: on the Sierpinski scene at
/// 256 x 256 (patches 704, image less) four bundles of 352 had 0.83 of the squared error at
/// 50 steps for 1.2 times the time (0.79 with the history of eleven bundles), so one bundle
/// reached each error first; at its 512 x 512 (image 832) four of 416 had 0.58 of the
/// squared noise for 1.2 times the time; the Cornell
/// box (image 256, patches 70 at 256 x 256) reached a third of the squared error in 1.5
/// times the time (docs/PERFORMANCE.md, "Four bundles a step", "A longer glossy history").
/// (Until the glossy history spanned seven bundles, the image's need had to be twice the
/// patches': the history then held one step of four bundles, and four bundles of 352 on
/// Sierpinski had higher error than one of 704.)
///
/// And one where the scene has at least as many patches as the largest view has pixels:
/// four bundles repeat the per-patch work (the same lines in all, four times the patches
/// rasterised, reflected and finalised) to lower the variance of the per-pixel gather, so
/// they pay only while that work is small against the pixels'. The engine room's 295 463
/// patches at 480 x 360 took 6 times as long a step with four bundles, for 1.2 times less
/// noise at 20 steps; the Cornell box with walls of 20 972 fine mesh patches and the
/// Sierpinski scene with a diffuse fractal (22 420) at 256 x 256 halved their squared error
/// in the same time (docs/PERFORMANCE.md, "Diffuse patches need no line a step").
pub fn auto_bundles_per_step(needs: &BundleNeeds) -> u32 {
    let few_patches = (needs.patch_count as u64) < needs.view_pixels;
    if needs.image >= needs.patches && few_patches { BUNDLES_PER_STEP } else { 1 }
}

impl BundleNeeds {
    /// `auto_bundle_resolution`'s choice for one bundle a step.
    pub fn resolution(&self) -> u32 {
        let wanted = self.patches.max(self.image);
        let r = (wanted.min(AUTO_BUNDLE_MAX as f64).ceil() as u32).div_ceil(64) * 64;
        r.clamp(AUTO_BUNDLE_MIN, AUTO_BUNDLE_MAX)
    }

    /// The needs of `patches` in a bounding sphere of `radius`, seen by `views`.
    pub fn of(
        patches: &Patches,
        materials: &[crate::scene::Material],
        radius: f64,
        views: &[crate::scene::NamedCamera],
    ) -> BundleNeeds {
        let sampled = patches.median_sample();
        // Only glossy patches ask for lines: the image reads a diffuse sender through the mean
        // of its K_j over the image steps, which carries none of one step's spike, and a
        // glossy one through its last few steps. Their median, so that how finely the
        // diffuse surfaces are cut does not decide (a Sierpinski room whose walls outnumber
        // the fractal's triangles got four bundles of 224 and 2 to 3 times the error).
        let mut glossy_areas: Vec<f64> = sampled.clone().filter(|p| is_glossy(p, materials)).map(|p| p.area).collect();
        let glossy_need =
            crate::scene::tessellate::median(&mut glossy_areas).map_or(0.0, |a| 2.0 * radius * (2.0 / a).sqrt());
        let mut diffuse_areas: Vec<f64> =
            sampled.clone().filter(|p| p.material.is_some() && !is_glossy(p, materials)).map(|p| p.area).collect();
        let diffuse =
            crate::scene::tessellate::median(&mut diffuse_areas).map_or(0.0, |a| 2.0 * radius * (2.0 / a).sqrt());
        // The glossy patches' share of what the views see (solid angle, occlusion ignored).
        let (mut seen_all, mut seen_glossy) = (0.0f64, 0.0f64);
        let mut wanted: f64 = 0.0;
        let view_pixels =
            views.iter().map(|v| u64::from(v.camera.width) * u64::from(v.camera.height)).max().unwrap_or(0);
        for view in views {
            let c = &view.camera;
            let forward = (c.look_at - c.position).normalize_or_zero();
            let right = forward.cross(c.up).normalize_or_zero();
            let up = right.cross(forward);
            let tan_y = (0.5 * c.fov_y.to_radians()).tan();
            let tan_x = tan_y * c.width as f64 / c.height.max(1) as f64;
            // (distance, solid angle) of each patch centre in the frustum.
            let mut seen: Vec<(f64, f64)> = sampled
                .clone()
                .filter_map(|p| {
                    let v = (p.vertices[0] + p.vertices[1] + p.vertices[2]) / 3.0 - c.position;
                    let z = v.dot(forward);
                    if z <= 0.0 || v.dot(right).abs() > tan_x * z || v.dot(up).abs() > tan_y * z {
                        return None;
                    }
                    let d2 = v.length_squared();
                    let solid_angle = p.area * p.normal.dot(v).abs() / (d2 * d2.sqrt());
                    seen_all += solid_angle;
                    if is_glossy(p, materials) {
                        seen_glossy += solid_angle;
                    }
                    (solid_angle > 0.0).then(|| (d2.sqrt(), solid_angle))
                })
                .collect();
            if seen.is_empty() || c.height == 0 {
                continue;
            }
            seen.sort_by(|a, b| a.0.total_cmp(&b.0));
            let half: f64 = 0.5 * seen.iter().map(|s| s.1).sum::<f64>();
            let mut acc = 0.0;
            let distance = seen.iter().find(|s| {
                acc += s.1;
                acc >= half
            });
            if let Some(&(distance, _)) = distance {
                let footprint = AUTO_BUNDLE_LINE_PIXELS * distance * 2.0 * tan_y / c.height as f64;
                wanted = wanted.max(2.0 * radius / footprint);
            }
        }
        // Without a view that sees a patch, the glossy patches' share of the patches.
        let share = if seen_all > 0.0 {
            seen_glossy / seen_all
        } else {
            glossy_areas.len() as f64 / sampled.clone().count().max(1) as f64
        };
        let by_patches = if share >= GLOSSY_SHARE { glossy_need } else { 0.0 };
        BundleNeeds {
            patches: by_patches,
            image: wanted,
            glossy: glossy_need,
            diffuse,
            patch_count: patches.patches.len(),
            view_pixels,
        }
    }
}

/// The last burn-in bundles (bounces) run at the full bundle resolution (`coarse_burn_in`).
pub const FINE_BURN_IN_BUNDLES: u32 = 8;
/// The coarse burn-in's bundle resolution is the full one divided by this.
pub const COARSE_BURN_IN_DIVISOR: u32 = 2;
/// Below this the coarse grid is too coarse for Lbar_j, or saves too little to be worth a
/// second set of line buffers. At 32 lines across the Cornell box (a 128 x 128 image's
/// automatic bundle of 64 halved), lines of 31 mm crossed the 380 mm^2 patches at its
/// creases a few times a bundle: their Lbar_j rose to 14-21 where the median is 0.04, the 8
/// fine bundles after kept a third of that, and the gather's control variate at those
/// patches gave pixels of +-15 after one image step and 46 negative pixels after 50 (down to
/// -0.99; docs/PERFORMANCE.md, "A coarse burn-in of 32 lines"). From 64 lines up it stays.
pub const COARSE_BURN_IN_MIN: u32 = 64;

/// The coarse start of the burn-in: `Some((resolution, steps))` when the first `steps` of a
/// burn-in of `burn_in` steps of `per_step` bundles run at the smaller bundle `resolution`, a quarter of the
/// lines and fragments. The burn-in only has to bring the state's mean near the fixed
/// point, and that mean does not depend on the resolution: each step is an unbiased
/// estimate of the transport of the state before it (random direction, rotation and
/// shift), so E[J_k] = T^k whatever the grid. What the coarse grid adds is variance
/// (fewer lines cross each patch); the last `FINE_BURN_IN_BUNDLES` bundles at the full grid
/// (in whole steps) let it decay (each bounce attenuates it by about the albedo squared)
/// before the first image step.
pub fn coarse_burn_in(resolution: u32, burn_in: u32, per_step: u32) -> Option<(u32, u32)> {
    let coarse = resolution / COARSE_BURN_IN_DIVISOR;
    let steps = burn_in.saturating_sub(FINE_BURN_IN_BUNDLES.div_ceil(per_step.max(1)));
    (coarse >= COARSE_BURN_IN_MIN && steps > 0).then_some((coarse, steps))
}

/// Bytes of the lines' buckets in a step's fragment list (`LINE_BUCKET` slots of 8 bytes a
/// line), which one binding must hold with room to spare for the long lines' slices.
pub fn line_table_bytes(resolution: u32) -> u64 {
    8 * LINE_BUCKET as u64 * resolution as u64 * resolution as u64
}

/// The largest capacity (fragments past the lines' buckets) a device holds at `resolution`:
/// the spill list (16 bytes a node) and the fragment list (the buckets, then as many
/// fragments of long lines) each in one binding.
pub fn max_capacity(limits: &wgpu::Limits, resolution: u32) -> u64 {
    let largest = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    (largest / 16).min((largest.saturating_sub(line_table_bytes(resolution))) / 8)
}

/// Fragments a step can produce at most: a triangle's projection holds at most
/// area / dP + perimeter / pixel + 1 pixel centres, and projection only shrinks both.
pub fn fragment_bound(patches: &Patches, radius: f64, resolution: u32) -> u64 {
    let r = resolution as f64;
    let pixel = 2.0 * radius * r / (r - 2.0) / r;
    patches
        .patches
        .iter()
        .map(|p| {
            let [a, b, c] = p.vertices;
            let perimeter = a.distance(b) + b.distance(c) + c.distance(a);
            (p.area / (pixel * pixel) + perimeter / pixel + 1.0).ceil() as u64
        })
        .sum()
}

/// What the image estimate reads of a step to gather per pixel: the bundle, its sorted
/// lines (offsets and fragments) and what each patch sends the image (`image_senders` of
/// `bundle_reflect`).
pub struct GatherBuffers {
    pub bundle: wgpu::Buffer,
    /// Surfaces per line, and (begin, end) of each longer line's slice of `fragments`
    /// (bundle_transfer); a line of at most `LINE_BUCKET` is its bucket.
    pub counts: wgpu::Buffer,
    pub slices: wgpu::Buffer,
    pub fragments: wgpu::Buffer,
    /// What each patch sends the image and its Lbar_j before this step (`GpuImageSender`),
    /// in pages (`scene_buffers::IMAGE_SENDERS`).
    pub image_senders: Vec<wgpu::Buffer>,
}

/// The buffers and stages of a step.
pub struct Iteration {
    bundle: wgpu::Buffer,
    /// The step's bundles (`write_bundles`), copied one by one into `bundle` in front of
    /// each bundle's stages, so that a whole step is one submission.
    step_bundles: wgpu::Buffer,
    counts: wgpu::Buffer,
    heads: wgpu::Buffer,
    tally: wgpu::Buffer,
    max_bits: wgpu::Buffer,
    overflow: wgpu::Buffer,
    reflect: BundleReflect,
    visibility: BundleVisibility,
    transfer: BundleTransfer,
    finalize: BundleFinalize,
    pub capacity: u32,
    /// The bundles' grid: its resolution and levels (`Grid`).
    pub grid: Grid,
    pub gather: GatherBuffers,
    /// Whether the reflection also writes Lfs_j for the image (`new`).
    image_first_bounce_per_point: bool,
    /// The fine windows of the step's bundles (`write_bundles`), the scissor of their fine
    /// lines' draw.
    fine_rects: std::sync::Mutex<[[u32; 4]; BUNDLES_PER_STEP as usize]>,
    arrays: StepArrays,
    _owned: [wgpu::Buffer; 3],
}

/// The per-patch arrays of a step: written and read within it, so an iteration at another
/// bundle resolution (the coarse burn-in, a regrown fragment list) shares them.
#[derive(Clone)]
struct StepArrays {
    /// O_j, what each patch sends into this step's bundle.
    outgoing: Paged,
    image_senders: Paged,
    /// The transfer's fixed-point sums.
    sums: Paged,
}

impl Iteration {
    /// `image_first_bounce_per_point`: the image's gather evaluates near senders' first
    /// reflection of the lights per point (`render::first_bounce_per_point`), so it reads
    /// each patch's Lfs_j as well (`ReflectOutputs::writes_first_bounce`).
    pub fn new(
        ctx: &Context,
        scene: &SceneBuffers,
        grid: Grid,
        capacity: u64,
        image_first_bounce_per_point: bool,
    ) -> Result<Self> {
        let device = &ctx.device;
        let n = scene.patch_count as u64;
        let none = wgpu::BufferUsages::empty();
        let (pages, zeroed) = (scene.page_bytes, Paged::zeroed);
        let arrays = StepArrays {
            outgoing: zeroed(device, "firstshot.iteration.outgoing", OUTGOING, n, pages, none),
            image_senders: zeroed(device, "firstshot.iteration.image_senders", IMAGE_SENDERS, n, pages, none),
            sums: zeroed(device, "firstshot.iteration.sums", TRANSFER_SUMS, n, pages, none),
        };
        Self::with_arrays(ctx, scene, arrays, grid, capacity, image_first_bounce_per_point, None)
    }

    /// An iteration over `grid` with room for `capacity` fragments that shares this
    /// one's per-patch arrays and its pipelines (only the line buffers and bind groups are
    /// new: building the pipelines again took about 45 ms on lavapipe): the coarse burn-in
    /// (`coarse_burn_in`), or this resolution with a larger fragment list after an overflow.
    pub fn resized(&self, ctx: &Context, scene: &SceneBuffers, grid: Grid, capacity: u64) -> Result<Self> {
        let per_point = self.image_first_bounce_per_point;
        Self::with_arrays(ctx, scene, self.arrays.clone(), grid, capacity, per_point, Some(self))
    }

    fn with_arrays(
        ctx: &Context,
        scene: &SceneBuffers,
        arrays: StepArrays,
        grid: Grid,
        capacity: u64,
        image_first_bounce_per_point: bool,
        like: Option<&Iteration>,
    ) -> Result<Self> {
        let resolution = grid.resolution;
        let device = &ctx.device;
        let limits = ctx.limits();
        // The resolution and the line table were checked by `render::check_limits`; the
        // capacity grows at run time (overflow and redo), so it is checked here.
        // At most resolution^2 (`FineWindow` is only chosen where it saves lines), which
        // `render::check_limits` checked.
        let lines = grid.line_capacity(scene.radius);
        let max = max_capacity(&limits, resolution);
        if capacity > max {
            return Err(Error::Limits(format!(
                "a bundle step may need {capacity} fragments past its lines' buckets, more than one buffer of this device holds ({max}); use a smaller --bundle-resolution or a larger --patch-size"
            )));
        }
        let none = wgpu::BufferUsages::empty();
        let bundle = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("firstshot.iteration.bundle"),
            size: std::mem::size_of::<GpuBundle>() as u64,
            // STORAGE: `bundle_reflect` and the image's gather read it as a storage buffer
            // (their SPECs say why); the other stages as a uniform.
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let step_bundles = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("firstshot.iteration.step_bundles"),
            size: BUNDLES_PER_STEP as u64 * std::mem::size_of::<GpuBundle>() as u64,
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let StepArrays { outgoing, image_senders, sums } = &arrays;
        let max_bits = buffers::storage_zeroed(device, "firstshot.iteration.max_bits", 16, none);
        // COPY_SRC: `fragments` sums the counts on the host.
        let counts = buffers::storage_zeroed(
            device,
            "firstshot.iteration.counts",
            4 * lines as u64,
            wgpu::BufferUsages::COPY_SRC,
        );
        let heads = buffers::storage_zeroed(device, "firstshot.iteration.heads", 4 * lines as u64, none);
        let slices = buffers::storage_zeroed(device, "firstshot.iteration.slices", 8 * lines as u64, none);
        let fragments = buffers::storage_zeroed(
            device,
            "firstshot.iteration.fragments",
            8 * (lines as u64 * LINE_BUCKET as u64 + capacity.max(1)),
            none,
        );
        let spill = buffers::storage_zeroed(device, "firstshot.iteration.spill", 16 * capacity.max(1), none);
        let long_lines = buffers::storage_zeroed(device, "firstshot.iteration.long_lines", 4 * capacity.max(1), none);
        let tally = buffers::storage_zeroed(device, "firstshot.iteration.tally", 16, wgpu::BufferUsages::COPY_SRC);
        let overflow = buffers::storage_zeroed(device, "firstshot.iteration.overflow", 4, wgpu::BufferUsages::COPY_SRC);
        Ok(Iteration {
            reflect: BundleReflect::new(
                device,
                scene,
                &bundle,
                &max_bits,
                ReflectOutputs { outgoing, image_senders, writes_first_bounce: image_first_bounce_per_point },
                like.map(|l| &l.reflect),
            ),
            visibility: BundleVisibility::new(
                device,
                [
                    (&bundle).into(),
                    (&counts).into(),
                    (&heads).into(),
                    (&fragments).into(),
                    (&spill).into(),
                    (&tally).into(),
                    (&overflow).into(),
                    (&long_lines).into(),
                    outgoing.resource(),
                ],
                grid,
                like.map(|l| &l.visibility),
            ),
            transfer: BundleTransfer::new(
                device,
                [
                    (&bundle).into(),
                    (&counts).into(),
                    (&heads).into(),
                    (&fragments).into(),
                    (&spill).into(),
                    (&tally).into(),
                    (&overflow).into(),
                    (&slices).into(),
                    (&long_lines).into(),
                    outgoing.resource(),
                    sums.resource(),
                    (&max_bits).into(),
                ],
                lines,
                like.map(|l| &l.transfer),
            ),
            finalize: BundleFinalize::new(
                device,
                [
                    (&bundle).into(),
                    scene.patches.resource(),
                    sums.resource(),
                    (&max_bits).into(),
                    outgoing.resource(),
                    scene.state.resource(),
                    (&scene.materials).into(),
                ],
                scene.patch_count,
                like.map(|l| &l.finalize),
            ),
            gather: GatherBuffers {
                bundle: bundle.clone(),
                counts: counts.clone(),
                slices,
                fragments: fragments.clone(),
                image_senders: image_senders.pages.clone(),
            },
            image_first_bounce_per_point,
            fine_rects: std::sync::Mutex::new([[0, 0, resolution, resolution]; BUNDLES_PER_STEP as usize]),
            bundle,
            step_bundles,
            counts,
            heads,
            tally,
            max_bits,
            overflow,
            capacity: capacity as u32,
            grid,
            arrays,
            _owned: [fragments, spill, long_lines],
        })
    }

    /// Writes the `per_step` bundles of step `step` and returns the generator of its first
    /// (see `bundle_of_step`), for the step's other random choices.
    pub fn write_bundles(
        &self,
        queue: &wgpu::Queue,
        seed: u64,
        step: u64,
        per_step: u32,
        image: Option<ImagePlan>,
        scene: &BundleScene,
    ) -> StepRng {
        let mut first = None;
        let mut bundles = Vec::with_capacity(per_step as usize);
        for index in 0..per_step {
            let which = StepBundle { index, per_step };
            let (bundle, rng) = bundle_of_step(seed, step, which, image, scene, &self.grid, self.capacity);
            self.fine_rects.lock().expect("not poisoned")[index as usize] = bundle.fine_rect;
            bundles.push(bundle);
            first.get_or_insert(rng);
        }
        queue.write_buffer(&self.step_bundles, 0, bytemuck::cast_slice(&bundles));
        first.expect("a step has at least one bundle")
    }

    /// The stages of bundle `index` of a step, in order (`write_bundles` must have written
    /// the step): its uniform, then J_j and win_j of every patch replaced by this bundle's.
    /// `render::Renderer` runs them, recorded into one encoder or, for the profiler, one by
    /// one.
    pub fn stages<'a>(&'a self, scene: &'a SceneBuffers, index: u32) -> Vec<Stage<'a>> {
        let size = std::mem::size_of::<GpuBundle>() as u64;
        vec![
            (
                "clear",
                Box::new(move |e: &mut wgpu::CommandEncoder| {
                    e.copy_buffer_to_buffer(&self.step_bundles, index as u64 * size, &self.bundle, 0, size);
                    e.clear_buffer(&self.max_bits, 0, None);
                    e.clear_buffer(&self.counts, 0, None);
                    e.clear_buffer(&self.heads, 0, None);
                    e.clear_buffer(&self.tally, 0, None);
                }),
            ),
            ("reflect", Box::new(move |e: &mut wgpu::CommandEncoder| self.reflect.record(e))),
            (
                "visibility",
                Box::new(move |e: &mut wgpu::CommandEncoder| {
                    let rect = self.fine_rects.lock().expect("not poisoned")[index as usize];
                    self.visibility.record(e, &scene.raster, rect)
                }),
            ),
            ("transfer", Box::new(move |e: &mut wgpu::CommandEncoder| self.transfer.record(e))),
            ("finalize", Box::new(move |e: &mut wgpu::CommandEncoder| self.finalize.record(e))),
        ]
    }

    /// Fragments (surfaces on lines) of the last step: the sum of its lines' counts.
    pub fn fragments(&self, ctx: &Context) -> Result<u64> {
        let counts = buffers::read_back::<u32>(&ctx.device, &ctx.queue, &self.counts, self.counts.size())?;
        Ok(counts.iter().map(|&c| c as u64).sum())
    }

    /// The last step's `tally`, indexed by `layout::TALLY_*`.
    pub fn tally(&self, ctx: &Context) -> Result<Vec<u32>> {
        buffers::read_back::<u32>(&ctx.device, &ctx.queue, &self.tally, self.tally.size())
    }

    /// Whether any step since the last `clear_overflow` ran out of fragment room.
    pub fn overflowed(&self, ctx: &Context) -> Result<bool> {
        Ok(buffers::read_back::<u32>(&ctx.device, &ctx.queue, &self.overflow, 4)?[0] != 0)
    }

    pub fn clear_overflow(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.overflow, 0, None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wide_lines_where_the_glossy_patches_set_the_grid() {
        let needs = |patches: f64, image: f64| BundleNeeds {
            patches,
            image,
            glossy: patches,
            diffuse: 80.0,
            patch_count: 22_420,
            view_pixels: 256 * 256,
        };
        // The Sierpinski scene at 256 x 256: 176 lines would be 2.2 times the image's width.
        assert_eq!(auto_wide_lines(&needs(645.0, 384.0), 704, 1), 2);
        assert_eq!(auto_wide_lines(&needs(645.0, 350.0), 704, 1), 4, "176 >= 350 / 2");
        // At 512 x 512: four bundles of 416, each serving a quarter of the pixels.
        assert_eq!(auto_wide_lines(&needs(645.0, 768.0), 416, 4), 2, "four bundles a step");
        assert_eq!(auto_wide_lines(&needs(300.0, 400.0), 384, 1), 1, "the image sets the grid: 192 < 400 / 2");
        assert_eq!(auto_wide_lines(&needs(0.0, 384.0), 704, 1), 1, "no glossy patch asks for lines");
        assert_eq!(auto_wide_lines(&needs(645.0, 0.0), 704, 1), 4, "no view");
        assert_eq!(auto_wide_lines(&needs(1024.0, 900.0), 1024, 1), 2);
        assert_eq!(auto_wide_lines(&needs(1200.0, 1100.0), 1024, 1), 1, "512 < 1100 / 2");
        let fine_walls = BundleNeeds { diffuse: 200.0, ..needs(645.0, 300.0) };
        assert_eq!(auto_wide_lines(&fine_walls, 704, 1), 2, "176 would cross the walls' median patch < once a step");
        let sun_room = BundleNeeds { diffuse: 300.0, ..needs(128.0, 40.0) };
        assert_eq!(auto_wide_lines(&sun_room, 128, 1), 1, "the sun room at 64 x 48");
    }

    #[test]
    fn four_bundles_where_the_image_sets_the_grid_and_the_patches_are_few() {
        let needs = |patches: f64, image: f64, patch_count: usize| BundleNeeds {
            patches,
            image,
            glossy: patches,
            diffuse: 0.0,
            patch_count,
            view_pixels: 256 * 256,
        };
        assert_eq!(auto_bundles_per_step(&needs(70.0, 256.0, 6065)), BUNDLES_PER_STEP, "the Cornell box");
        assert_eq!(auto_bundles_per_step(&needs(0.0, 256.0, 6065)), BUNDLES_PER_STEP, "all diffuse");
        assert_eq!(auto_bundles_per_step(&needs(704.0, 400.0, 22_420)), 1, "the patches set the grid");
        assert_eq!(auto_bundles_per_step(&needs(200.0, 199.0, 6065)), 1, "the image needs less");
        assert_eq!(auto_bundles_per_step(&needs(704.0, 832.0, 22_420)), BUNDLES_PER_STEP, "Sierpinski at 512 x 512");
        assert_eq!(auto_bundles_per_step(&needs(200.0, 200.0, 6065)), BUNDLES_PER_STEP, "as much");
        assert_eq!(auto_bundles_per_step(&needs(0.0, 640.0, 256 * 256)), 1, "as many patches as pixels");
        assert_eq!(auto_bundles_per_step(&needs(0.0, 640.0, 256 * 256 - 1)), BUNDLES_PER_STEP);
    }
}
