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

/// The furnace with a stack of `plates` thin boxes (closed solids, fronts outward, of the
/// walls' material and emission) across the room: a line through the stack crosses two
/// surfaces a plate and two walls, more than a line's bucket (`LINE_BUCKET`) holds. Its
/// radiance is still emission / (1 - albedo) everywhere.
fn stacked_furnace(albedo: f32, emission: f32, plates: usize) -> (firstshot::scene::Scene, Patches) {
    let (scene, mut patches) = furnace(albedo, emission);
    let template = patches.patches[0];
    for k in 0..plates {
        let y = -0.6 + 1.2 * k as f64 / plates as f64;
        let inward = room(DVec3::new(-0.7, y, -0.7), DVec3::new(0.9, y + 0.03, 0.8));
        for t in inward.into_iter().flat_map(|t| split(t, 2)) {
            let p = patch([t[0], t[2], t[1]]);
            patches.patches.push(firstshot::scene::Patch {
                vertices: p.vertices,
                normal: p.normal,
                area: p.area,
                ..template
            });
        }
    }
    (scene, patches)
}

fn options(scene: &firstshot::scene::Scene, iterations: u32, seed: u64) -> RenderOptions {
    let mut o = RenderOptions::from_scene(scene);
    o.iterations = iterations;
    o.seed = seed;
    o.bundle_resolution = Some(64);
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

#[test]
fn test05_bright_furnace_converges_with_bounded_variance() {
    // Albedo 0.9: a step's one direction multiplies each patch's incoming radiance by
    // 2 |cos| (mean 1, mean square 4/3), so without a remedy the state's variance grows
    // without bound (0.9^2 * 4/3 > 1) and the image mean of a few hundred steps sat 5-18%
    // low, varying wildly with the seed (8.2 and 9.1 for the exact 10 after 300 and 1000
    // steps). With the control variate of bundle_finalize every seed lands within 1.5%.
    let Some(ctx) = gpu() else { return };
    let (scene, patches) = furnace(0.9, 1.0);
    for seed in [1, 2, 3] {
        let mut o = options(&scene, 400, seed);
        o.burn_in = Some(100);
        let mean = render(&ctx, &scene, &patches, &o).unwrap().image.mean();
        eprintln!("bright furnace, seed {seed}: mean {mean:?} (exact 10)");
        for c in 0..3 {
            assert!((mean[c] - 10.0).abs() < 0.15, "seed {seed}: mean {mean:?}");
        }
    }
}

#[test]
fn test02_received_radiance_matches_the_form_factor() {
    let Some(ctx) = gpu() else { return };
    // An emitting square (radiance 1, black) and, facing it, one receiving triangle of
    // albedo 1: every pixel showing the triangle converges to F(triangle -> square). (The
    // receiver's mean form factor, 0.8784, is 0.7 % below the centre's 0.8845: a stratified
    // run's noise, 0.0012, is small enough to tell them apart.)
    let FormFactorScene { scene, patches, form_factor } = form_factor_scene(&[]);
    // Noise measured, not assumed: independent runs with different seeds, their standard
    // error of the mean.
    let runs: Vec<f64> = (0..8)
        .map(|seed| {
            let mut o = options(&scene, 250, 100 + seed);
            o.bundle_resolution = Some(48);
            // The centre pixels see the receiver (the camera looks at it from 0.2 away).
            centre_mean(&render(&ctx, &scene, &patches, &o).unwrap().image)
        })
        .collect();
    let mean = runs.iter().sum::<f64>() / runs.len() as f64;
    let var = runs.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (runs.len() - 1) as f64;
    let standard_error = (var / runs.len() as f64).sqrt();
    eprintln!("form factor {form_factor:.5}, measured {mean:.5} +- {standard_error:.5} (runs {runs:?})");
    assert!(standard_error < 0.05 * form_factor, "too noisy to judge: {standard_error}");
    // Four standard errors, plus the 1/N bias of starting from J = 0 (none here: the
    // receiver's first estimate is already unbiased, the emitter does not depend on J).
    assert!((mean - form_factor).abs() < 4.0 * standard_error, "measured {mean} against {form_factor}");
}

#[test]
fn test03_same_seed_same_bits_and_seeds_agree_within_noise() {
    let Some(ctx) = gpu() else { return };
    let (scene, patches) = furnace(0.6, 1.0);
    let run = |seed| render(&ctx, &scene, &patches, &options(&scene, 40, seed)).unwrap().image;
    let (a, b, c) = (run(7), run(7), run(8));
    let bits = |i: &firstshot::image::Image| i.pixels.iter().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<u32>>();
    assert_eq!(bits(&a), bits(&b), "the same seed must give the same image, bit for bit");
    assert_ne!(bits(&a), bits(&c), "another seed must give another image");
    // Every seed estimates L = 2.5 everywhere. An image's mean strays from seed to seed more
    // than its pixels stray from that mean (every pixel shares each step's direction: over
    // seeds 1-12 the means spread by 0.021, an image's pixels by 0.012), so the seeds are
    // held to the exact value through their own spread: the mean of eight seeds within four
    // of its standard errors.
    let means: Vec<f64> = (7..15).map(|seed| if seed == 7 { a.mean()[0] } else { run(seed).mean()[0] }).collect();
    let (mean, spread) = common::mean_and_spread(&means);
    let standard_error = spread / (means.len() as f64).sqrt();
    assert!(standard_error < 0.02, "too noisy to judge: {means:?}");
    assert!((mean - 2.5).abs() < 4.0 * standard_error, "seeds' mean {mean:.4} against 2.5: {means:?}");
}

#[test]
fn test04_fragment_overflow_is_detected_and_redone_exactly() {
    // Lines through the stack hold more surfaces than their buckets: the spill list
    // overflows at 16 and must grow.
    let Some(ctx) = gpu() else { return };
    let (scene, patches) = stacked_furnace(0.5, 1.0, 6);
    let run = |capacity: Option<u64>| {
        let mut o = options(&scene, 20, 3);
        o.bundle_capacity = capacity;
        // A coarse start (18 steps at 64, the last 2 steps of four bundles at 128): its own
        // list overflows and grows too.
        o.burn_in = Some(20);
        o.bundle_resolution = Some(128);
        render(&ctx, &scene, &patches, &o).unwrap()
    };
    let (normal, tight) = (run(None), run(Some(16)));
    assert!(tight.stats.bundle_capacity > 16, "the list must have grown");
    assert_eq!(tight.stats.coarse_burn_in_steps, 18);
    let bits = |i: &firstshot::image::Image| i.pixels.iter().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<u32>>();
    assert_eq!(bits(&normal.image), bits(&tight.image), "redone steps must give exactly the image of a run with room");
}

/// Keeps the iteration state of a run's end (its final checkpoint).
#[derive(Default)]
struct FinalState(Option<Vec<u8>>);

impl firstshot::render::Hooks for FinalState {
    fn wants_final_checkpoint(&self) -> bool {
        true
    }
    fn checkpoint(
        &mut self,
        checkpoint: firstshot::checkpoint::Checkpoint,
        _images: &[firstshot::image::Image],
    ) -> firstshot::Result<()> {
        self.0 = Some(checkpoint.state);
        Ok(())
    }
}

/// The octahedral map back to a unit vector (two snorm16 in 32 bits), written apart from the
/// WGSL's `octahedral_unpack`.
fn unpack_octahedral(bits: u32) -> DVec3 {
    let snorm = |h: u32| ((h as u16 as i16) as f64 / 32767.0).max(-1.0);
    let (x, y) = (snorm(bits & 0xffff), snorm(bits >> 16));
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 { ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum()) } else { (x, y) };
    DVec3::new(x, y, z).normalize()
}

/// A glossy history entry's J (`pack_history_radiance` in wgsl/common/layout.wgsl), written
/// apart from the WGSL's `unpack_history_radiance`: each channel a signed byte times the
/// unit 2^(e - 7) of the shared exponent e in the top byte (biased by 128). Returns the
/// channels and the unit.
fn unpack_history_radiance(bits: u32) -> ([f64; 3], f64) {
    let unit = 2f64.powi((bits >> 24) as i32 - 128 - 7);
    (std::array::from_fn(|c| ((bits >> (8 * c)) as u8 as i8) as f64 * unit), unit)
}

#[test]
fn test06_the_state_keeps_the_last_steps_j_for_the_glossy_reflection() {
    use firstshot::layout::{GLOSSY_HISTORY, GpuPatchState};
    let Some(ctx) = gpu() else { return };
    // Every other patch glossy: only a glossy patch's reflection reads its history
    // (bundle_reflect), so only its history moves; a diffuse patch's stays zero.
    let (mut scene, mut patches) = furnace(0.6, 1.0);
    let phong = MaterialKind::Phong { diffuse: [0.3; 3], specular: [0.1; 3], shininess: 3.0 };
    scene.materials.push(Material { name: "gloss".into(), kind: phong });
    for p in patches.patches.iter_mut().step_by(2) {
        p.material = Some(1);
    }
    let glossy = |j: usize| j.is_multiple_of(2);
    // The state after n steps (no burn-in: every step is an image step); step k's numbers
    // depend on (seed, k) alone, so the runs of 1, 2, ... steps pass through the same states.
    let state_after = |n: u32| {
        let mut o = options(&scene, n, 5);
        o.burn_in = Some(0);
        // One bundle a step, so that a step moves the history by one (four bundles move it by
        // four, each shifting in its own J as here).
        o.bundles_per_step = Some(1);
        let mut hooks = FinalState::default();
        firstshot::render::render_with(&ctx, &scene, &patches, &o, None, &mut hooks).unwrap();
        bytemuck::pod_collect_to_vec::<u8, GpuPatchState>(&hooks.0.unwrap())
    };
    let runs = GLOSSY_HISTORY as u32 + 1;
    let states: Vec<Vec<GpuPatchState>> = (1..=runs).map(state_after).collect();
    for (n, state) in (1..=runs).zip(&states) {
        let written = (n - 1).min(GLOSSY_HISTORY as u32) as f32;
        let bad: Vec<f32> = state.iter().map(|s| s.incoming[3]).filter(|&w| w != written).take(5).collect();
        assert!(bad.is_empty(), "after {n} steps {written} earlier J are kept, not {bad:?}");
    }
    let last = &states[GLOSSY_HISTORY];
    let mut moved = 0;
    for (j, s) in last.iter().enumerate() {
        if !glossy(j) {
            assert!(s.earlier.iter().all(|e| *e == [0, 0]), "diffuse patch {j} keeps a history: {:?}", s.earlier);
            continue;
        }
        for (i, e) in s.earlier.iter().enumerate() {
            // Newest first: entry i holds the J of the state i + 1 steps back.
            let before = &states[GLOSSY_HISTORY - 1 - i][j];
            // J to within half a unit of its shared exponent, which its largest channel sets.
            let (got, unit) = unpack_history_radiance(e[0]);
            let largest = before.incoming[..3].iter().fold(0.0f64, |m, &v| m.max((v as f64).abs()));
            if largest == 0.0 {
                assert_eq!(e[0], 0, "patch {j} entry {i}: J = 0");
            } else {
                let units = largest / unit;
                assert!((63.5..127.5).contains(&units), "patch {j} entry {i}: {largest} is {units} units");
            }
            for (c, (&back, &sent)) in got.iter().zip(&before.incoming[..3]).enumerate() {
                let err = (back - sent as f64).abs();
                assert!(err <= 0.5 * unit * (1.0 + 1e-6), "patch {j} entry {i}: J {c} {sent} comes back {back}");
            }
            // The state keeps win_j packed as the history does: the entry takes its bits.
            assert_eq!(e[1], before.direction, "patch {j} entry {i}: the direction's bits");
            moved += (before.incoming[0] != 0.0) as usize;
        }
    }
    assert!(moved > last.len() / 2, "the furnace's glossy patches receive light ({moved})");
    // Each state's win_j is -s_j d of its step's one bundle: the same direction up to its
    // sign on every patch, to the packing's 1e-4 rad.
    for (n, state) in (1..=runs).zip(&states) {
        let d = unpack_octahedral(state[0].direction);
        assert!((d.length() - 1.0).abs() < 1e-6, "after {n} steps: win_0 {d}");
        let worst = state.iter().map(|s| 1.0 - unpack_octahedral(s.direction).dot(d).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-7, "after {n} steps the patches' win_j are not one bundle's direction ({worst})");
    }
    // The reflection reads every entry: its unrolled sum has one term per entry.
    let reflect = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/wgsl/bundle_reflect.wgsl")).unwrap();
    assert_eq!(
        reflect.matches("earlier_glossy(m, n, state_at(j).earlier[").count(),
        GLOSSY_HISTORY,
        "bundle_reflect.wgsl"
    );
}

#[test]
fn test07_the_automatic_bundle_resolution_follows_the_patches_and_the_image() {
    // CPU only. The two rules of `auto_bundle_resolution`, each checked alone against its
    // own closed form, then together, then at both clamps.
    use firstshot::iteration::{AUTO_BUNDLE_LINE_PIXELS, AUTO_BUNDLE_MAX, AUTO_BUNDLE_MIN, auto_bundle_resolution};
    use firstshot::scene::{Camera, Material, MaterialKind, NamedCamera};
    let up64 = |x: f64| ((x.ceil() as u32).div_ceil(64) * 64).clamp(AUTO_BUNDLE_MIN, AUTO_BUNDLE_MAX);
    // A 10 x 10 grid of right triangles of legs s (area s^2 / 2) in the plane z = 0, facing +z.
    let grid = |s: f64| -> Vec<[DVec3; 3]> {
        (0..100)
            .map(|i| {
                let c = DVec3::new((i % 10) as f64 * s, (i / 10) as f64 * s, 0.0);
                [c, c + DVec3::new(s, 0.0, 0.0), c + DVec3::new(0.0, s, 0.0)]
            })
            .collect()
    };
    let radius = 10.0;
    // Glossy patches (material 0; only they ask the patch rule for lines), and diffuse ones.
    let materials = [
        Material {
            name: "glossy".into(),
            kind: MaterialKind::Phong { diffuse: [0.2; 3], specular: [0.3; 3], shininess: 10.0 },
        },
        Material { name: "matte".into(), kind: MaterialKind::Diffuse { albedo: [0.5; 3] } },
    ];
    let with_material = |mut patches: firstshot::scene::Patches, m: u32| {
        patches.patches.iter_mut().for_each(|p| p.material = Some(m));
        patches
    };
    let auto_bundle_resolution = |patches: &firstshot::scene::Patches, radius: f64, views: &[NamedCamera]| {
        auto_bundle_resolution(patches, &materials, radius, views)
    };
    // Patches: one line per step on average for the median patch, r = 2 radius sqrt(2 / A).
    let s = 0.05;
    let patches = with_material(common::patches_of(&grid(s), vec![]), 0);
    let area = s * s / 2.0;
    let by_patches = up64(2.0 * radius * (2.0 / area).sqrt());
    assert_eq!(auto_bundle_resolution(&patches, radius, &[]), by_patches);
    // The same patches diffuse, or without a material (an area light's), ask for none.
    assert_eq!(auto_bundle_resolution(&with_material(patches.clone(), 1), radius, &[]), AUTO_BUNDLE_MIN);
    assert_eq!(auto_bundle_resolution(&common::patches_of(&grid(s), vec![]), radius, &[]), AUTO_BUNDLE_MIN);
    // Glossy patches among larger diffuse ones: theirs is the median, however many the
    // diffuse ones are, while they are at least GLOSSY_SHARE of them (no view here: by count).
    let mut mixed = with_material(common::patches_of(&[grid(s), grid(1.0)].concat(), vec![]), 1);
    mixed.patches.iter_mut().take(100).for_each(|p| p.material = Some(0));
    assert_eq!(auto_bundle_resolution(&mixed, radius, &[]), by_patches, "100 of 200 glossy");
    let few = (firstshot::iteration::GLOSSY_SHARE * 200.0) as usize - 1;
    mixed.patches.iter_mut().skip(few).take(100 - few).for_each(|p| p.material = Some(1));
    assert_eq!(auto_bundle_resolution(&mixed, radius, &[]), AUTO_BUNDLE_MIN, "{few} of 200 glossy");
    assert!(by_patches > AUTO_BUNDLE_MIN && by_patches < AUTO_BUNDLE_MAX, "{by_patches}");
    // ... and the result, fed back: A / (2 dP) >= 1 with dP the square of 2 radius / r.
    let line = 2.0 * radius / by_patches as f64;
    assert!(area / (2.0 * line * line) >= 1.0);

    // The image: large patches (the patch rule asks for the minimum) seen by a camera on the
    // grid's axis at distance 8 from its plane, looking at its centre.
    let big = with_material(common::patches_of(&grid(1.0), vec![]), 0);
    assert_eq!(auto_bundle_resolution(&big, radius, &[]), AUTO_BUNDLE_MIN);
    let centre = DVec3::new(5.0, 5.0, 0.0);
    let camera = |height: u32| NamedCamera {
        name: "camera".into(),
        camera: Camera {
            position: centre + DVec3::new(0.0, 0.0, 8.0),
            look_at: centre,
            up: DVec3::Y,
            fov_y: 40.0,
            width: height,
            height,
        },
    };
    // The patch centres the camera sees (within 8 tan 20 = 2.9 of the axis) lie at distances
    // from 8 to 9; the median, weighted by solid angle, lies between. A line of
    // AUTO_BUNDLE_LINE_PIXELS pixels there.
    let wanted = |distance: f64, height: u32| {
        let footprint = AUTO_BUNDLE_LINE_PIXELS * distance * 2.0 * (20.0f64).to_radians().tan() / height as f64;
        2.0 * radius / footprint
    };
    for height in [200, 400] {
        let r = auto_bundle_resolution(&big, radius, &[camera(height)]);
        assert!(
            r >= up64(wanted(9.0, height)) && r <= up64(wanted(8.0, height)),
            "{height} pixels: {r} outside [{}, {}]",
            up64(wanted(9.0, height)),
            up64(wanted(8.0, height))
        );
    }
    // The finest view decides; the patch rule and the image rule, the larger.
    let both = auto_bundle_resolution(&big, radius, &[camera(200), camera(400)]);
    assert_eq!(both, auto_bundle_resolution(&big, radius, &[camera(400)]));
    let small = auto_bundle_resolution(&patches, radius, &[camera(200)]);
    assert_eq!(small, by_patches.max(auto_bundle_resolution(&big, radius, &[camera(200)])));
    // A camera looking away sees no patch: only the patch rule counts.
    let mut away = camera(400);
    away.camera.look_at = away.camera.position + DVec3::new(0.0, 0.0, 1.0);
    assert_eq!(auto_bundle_resolution(&big, radius, &[away]), AUTO_BUNDLE_MIN);
    // Patches far too small for any grid: the largest the rule takes by itself.
    let tiny = with_material(common::patches_of(&grid(1e-4), vec![]), 0);
    assert_eq!(auto_bundle_resolution(&tiny, radius, &[]), AUTO_BUNDLE_MAX);
}

#[test]
fn test08_the_coarse_burn_in_keeps_the_expected_state() {
    // The first burn-in steps run at half the bundle resolution (iteration::coarse_burn_in):
    // fewer lines, the same expectation. In a closed furnace every patch's expected outgoing
    // radiance after step k is the truncated series O(k) = Le (1 - a^(k+1)) / (1 - a)
    // whatever the grid, and what a patch receives in step k carries the projected-area
    // share |n . d| of mean 1/2: E[K_j] = O(k - 1) / 2. The state is read right after the
    // coarse steps, before any full-resolution step could hide an error of theirs.
    use firstshot::render::{NoHooks, Renderer};
    let Some(ctx) = gpu() else { return };
    // Albedo 0.7: the state's variance stays small (at 0.9 its distribution has a long tail,
    // and a mean over a few seeds sits low, at the full resolution as at the coarse one).
    // A coarse step that scaled J by 1 + e would move the fixed point by about 2.3 e.
    let (albedo, le) = (0.7f64, 1.0f64);
    let (scene, patches) = furnace(albedo as f32, le as f32);
    let o = |k: u32| le * (1.0 - albedo.powi(k as i32 + 1)) / (1.0 - albedo);
    let burn_in = 30;
    // Four bundles a step keep 8 bundles (2 steps) fine; the run below takes one a step, so
    // that a step is a bounce of the series.
    assert_eq!(firstshot::iteration::coarse_burn_in(128, burn_in, 4), Some((64, burn_in - 2)));
    let (coarse, steps) = firstshot::iteration::coarse_burn_in(128, burn_in, 1).expect("a coarse start at 128");
    assert_eq!((coarse, steps), (64, burn_in - firstshot::iteration::FINE_BURN_IN_BUNDLES));
    // Not below 64 lines (`COARSE_BURN_IN_MIN`).
    assert_eq!(firstshot::iteration::coarse_burn_in(64, burn_in, 1), None);
    let area: f64 = patches.patches.iter().map(|p| p.area).sum();
    let state_bytes = std::mem::size_of::<firstshot::layout::GpuPatchState>();
    let mut means = Vec::new();
    for seed in 1..=16 {
        let mut opts = options(&scene, 8, seed);
        opts.burn_in = Some(burn_in);
        (opts.bundles_per_step, opts.bundle_resolution) = (Some(1), Some(128));
        let mut renderer = Renderer::new(&ctx, &scene, &patches, &opts, &mut NoHooks).unwrap();
        assert_eq!(renderer.advance_to(0, steps, &mut NoHooks).unwrap(), steps);
        let state = renderer.read_state().unwrap();
        let k_mean: f64 = patches
            .patches
            .iter()
            .enumerate()
            .map(|(j, p)| {
                let s: &firstshot::layout::GpuPatchState =
                    bytemuck::from_bytes(&state[j * state_bytes..(j + 1) * state_bytes]);
                p.area * s.diffuse[0] as f64
            })
            .sum::<f64>()
            / area;
        means.push(k_mean);
    }
    let (mean, spread) = common::mean_and_spread(&means);
    let exact = o(steps - 1) / 2.0;
    eprintln!(
        "after {steps} coarse steps: mean K {mean:.4} (seeds {means:?}, spread {spread:.4}), exact {exact:.4}; converged {:.4}",
        o(1000) / 2.0
    );
    // Three standard errors of the seeds' mean, which must be tight enough to matter.
    let tolerance = 3.0 * spread / (means.len() as f64).sqrt();
    assert!(tolerance < 0.03 * exact, "too noisy to tell: tolerance {tolerance}");
    assert!((mean - exact).abs() < tolerance, "mean K {mean} against {exact} (tolerance {tolerance})");
    // The whole run reports its coarse start.
    let mut opts = options(&scene, 2, 1);
    opts.burn_in = Some(burn_in);
    (opts.bundles_per_step, opts.bundle_resolution) = (Some(1), Some(128));
    let done = render(&ctx, &scene, &patches, &opts).unwrap();
    assert_eq!((done.stats.coarse_bundle_resolution, done.stats.coarse_burn_in_steps), (Some(coarse), steps));
    assert_eq!(done.stats.burn_in_steps, burn_in);
}

#[test]
fn test09_lines_past_their_bucket_keep_every_surface_in_order() {
    // Six plates across the furnace: the lines through them hold 14 surfaces, 6 past their
    // bucket, chained in the spill list and gathered by the transfer into a slice of their
    // own. A lost or misplaced surface would pair a patch with a neighbour's back (black)
    // or with the environment (black too): the furnace's uniform radiance shows either.
    use firstshot::render::{NoHooks, Renderer};
    let Some(ctx) = gpu() else { return };
    let (scene, patches) = stacked_furnace(0.5, 1.0, 6);
    let o = options(&scene, 300, 2);
    // A burn-in of one step has no coarse start, so step 0 runs on the full grid, whose
    // spill list `spilled` reads.
    let first = RenderOptions { burn_in: Some(1), ..o.clone() };
    let mut renderer = Renderer::new(&ctx, &scene, &patches, &first, &mut NoHooks).unwrap();
    renderer.advance_to(0, 1, &mut NoHooks).unwrap();
    let spilled = renderer.spilled().unwrap();
    assert!(spilled > 100, "the stack must spill: {spilled} fragments past the buckets");
    let done = render(&ctx, &scene, &patches, &o).unwrap();
    let mean = done.image.mean();
    let worst = done.image.pixels.iter().map(|p| (p[0] as f64 - 2.0).abs()).fold(0.0, f64::max);
    eprintln!("stacked furnace: {spilled} spilled, mean {mean:?}, worst pixel deviation {worst}");
    for c in 0..3 {
        assert!((mean[c] - 2.0).abs() < 0.02, "mean {mean:?}");
    }
}

#[test]
fn test10_patches_smaller_than_a_line_keep_their_mean_radiance_bounded() {
    // Lbar_j, the running mean of the radiance a patch receives (the control variates'
    // coefficient), of a patch far smaller than a line's pixel: one line crossing it weighs
    // dP / A_j times its share, here about 55 times, so one crossing used to throw Lbar_j to
    // 14 times the radiance (a quarter of that spike, with the weight 1/8), and the image's
    // first steps then had pixels of +-50 where the radiance was 0.2. Its weight now shrinks
    // by A_j / dP: a crossing moves Lbar_j by about a quarter of the radiance. In the
    // furnace (L = 2.5 everywhere) 64 such specks, each crossed by a line about once in 64
    // steps, must all keep Lbar_j below twice L after 120 steps, while the walls reach L.
    use firstshot::layout::GpuPatchState;
    let Some(ctx) = gpu() else { return };
    let (scene, mut patches) = furnace(0.6, 1.0);
    let walls = patches.patches.len();
    // The grid of 64 lines spans the bounding sphere (radius about 1.84): dP about
    // (3.8 / 64)^2 = 3.5e-3, against a speck's 6.3e-5.
    let side = 0.0112;
    for k in 0..64 {
        let c = DVec3::new(-0.6 + 0.17 * (k % 8) as f64, -0.5 + 0.14 * (k / 8) as f64, 0.1 * (k % 3) as f64);
        let speck = [c, c + DVec3::new(side, 0.0, 0.0), c + DVec3::new(0.0, side, 0.0)];
        patches.patches.push(firstshot::scene::Patch { material: Some(0), emission: [1.0; 3], ..patch(speck) });
    }
    let mut o = options(&scene, 120, 3);
    o.burn_in = Some(0);
    let mut hooks = FinalState::default();
    firstshot::render::render_with(&ctx, &scene, &patches, &o, None, &mut hooks).unwrap();
    let state = bytemuck::pod_collect_to_vec::<u8, GpuPatchState>(&hooks.0.unwrap());
    let exact = 2.5f32;
    let wall_mean = state[..walls].iter().map(|s| s.mean_radiance[0]).sum::<f32>() / walls as f32;
    assert!((wall_mean / exact - 1.0).abs() < 0.1, "the walls' Lbar {wall_mean} against {exact}");
    let specks: Vec<f32> = state[walls..].iter().map(|s| s.mean_radiance[0]).collect();
    let largest = specks.iter().cloned().fold(0.0f32, f32::max);
    assert!(largest < 2.0 * exact, "a speck's Lbar {largest} against {exact}: {specks:?}");
}

#[test]
fn test11_an_image_with_its_own_directions_keeps_the_burn_ins_mean_radiance() {
    // An image whose directions are its own stratified set (rng::image_direction) must not
    // move Lbar_j, the control variates' coefficient: a direction of the set depends on the
    // set's earlier ones, so a Lbar_j made from them would bias the variates (ALGORITHM.md
    // 2.4). So after a burn-in of 24 steps, the state's Lbar_j after 1 and after 6 image steps
    // is the burn-in's to the bit, while J has moved on. After a burn-in of 2 steps (fewer
    // than iteration::SETTLED_MEAN_BUNDLES bundles) the image takes the run's blocks of
    // directions and Lbar_j runs on.
    use firstshot::layout::GpuPatchState;
    let Some(ctx) = gpu() else { return };
    let (scene, patches) = furnace(0.6, 1.0);
    let state_after = |burn_in: u32, iterations: u32| {
        let mut o = options(&scene, iterations, 4);
        o.burn_in = Some(burn_in);
        o.bundles_per_step = Some(1);
        let mut hooks = FinalState::default();
        firstshot::render::render_with(&ctx, &scene, &patches, &o, None, &mut hooks).unwrap();
        bytemuck::pod_collect_to_vec::<u8, GpuPatchState>(&hooks.0.unwrap())
    };
    // Patches whose Lbar_j (or J) differs between the two states.
    let moved = |a: &[GpuPatchState], b: &[GpuPatchState], field: fn(&GpuPatchState) -> [f32; 4]| {
        a.iter().zip(b).filter(|(p, q)| field(p) != field(q)).count()
    };
    let (one, six) = (state_after(24, 1), state_after(24, 6));
    assert!(one.iter().all(|p| p.mean_radiance[0] > 0.5), "the burn-in leaves Lbar_j near L = 2.5");
    let n = one.len();
    let lbar_moved = moved(&one, &six, |p| p.mean_radiance);
    assert_eq!(lbar_moved, 0, "an image with its own directions moved Lbar_j of {lbar_moved} of {n} patches");
    assert!(moved(&one, &six, |p| p.incoming) > n / 2, "the image's steps move J");
    let (one, six) = (state_after(2, 1), state_after(2, 6));
    assert!(moved(&one, &six, |p| p.mean_radiance) > n / 2, "after a short burn-in Lbar_j runs on");
}
