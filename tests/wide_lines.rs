//! Bundles of two levels of lines (docs/ALGORITHM.md 6, "Two levels of lines"): fine lines in
//! a window around the glossy patches, wide lines elsewhere. The window against the
//! projection of every glossy vertex, and the transfer and the gather through wide lines
//! against a closed furnace and a form factor.

mod common;

use common::*;
use firstshot::iteration::{BundleScene, Grid, StepBundle, bundle_of_step, fine_window, is_glossy};
use firstshot::render::{RenderOptions, render};
use firstshot::scene::{self, Material, MaterialKind};
use glam::DVec3;

#[test]
fn test01_the_fine_window_holds_every_glossy_patch_in_every_bundle() {
    // The Sierpinski scene at its bundle resolution: 704 fine lines, wide lines of 2 and 4.
    // Every vertex of a glossy patch must project inside its bundle's window with at least
    // half a line to spare (a fragment of the patch there would otherwise be drawn by
    // neither level, or by a wide line the gather does not take for it), the window must be
    // whole wide lines inside the grid, and its lines must fit the buffers.
    let scene = scene::load(&common::scenes::shipped("sierpinski")).unwrap();
    let options = RenderOptions::from_scene(&scene);
    let patches = scene::tessellate(&scene, options.patch_size).unwrap();
    let (centre, radius) = firstshot::gpu::scene_buffers::bounding_sphere(&patches);
    let bundle_scene = BundleScene { centre, radius, patch_count: patches.patches.len() as u32, environment: [0.0; 3] };
    let glossy: Vec<DVec3> =
        patches.patches.iter().filter(|p| is_glossy(p, &scene.materials)).flat_map(|p| p.vertices).collect();
    assert!(glossy.len() > 40_000, "the fractal's triangles are glossy: {}", glossy.len());
    let views = options.views(&scene);
    let needs = firstshot::iteration::BundleNeeds::of(&patches, &scene.materials, radius, &views);
    eprintln!("{needs:?}");
    let resolution = 704;
    for wide in [2, 4] {
        let window = fine_window(&patches, &scene.materials, radius, resolution, wide).expect("a window");
        let grid = Grid { resolution, window: Some(window) };
        let capacity = grid.line_capacity(radius);
        let largest_window = grid.largest_window(radius);
        assert!(2 * capacity <= resolution * resolution, "wide {wide}: {capacity} lines");
        let (mut least_margin, mut largest) = (f64::INFINITY, 0u32);
        for step in 0..400u64 {
            let which = StepBundle { index: 0, per_step: 1 };
            let (b, _) = bundle_of_step(7, step, which, None, &bundle_scene, &grid, 1 << 20);
            let [x0, y0, w, h] = b.fine_rect;
            assert_eq!((b.wide, b.wide_lines), (wide, (resolution / wide).pow(2)));
            assert!(x0 % wide == 0 && y0 % wide == 0 && w % wide == 0 && h % wide == 0, "{:?}", b.fine_rect);
            assert!(x0 + w <= resolution && y0 + h <= resolution && w <= largest_window && h <= largest_window);
            assert_eq!(b.line_count, b.wide_lines + w * h);
            assert!(b.line_count <= capacity && b.line_capacity == capacity);
            largest = largest.max(w.max(h));
            let r = resolution as f64;
            let axis = |a: [f32; 4]| (DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64), a[3] as f64);
            let ((u, su), (v, sv)) = (axis(b.axis_u), axis(b.axis_v));
            for &p in &glossy {
                let rel = p - centre;
                let x = 0.5 * (rel.dot(u) + su + 1.0) * r;
                let y = 0.5 * (1.0 - (rel.dot(v) + sv)) * r;
                let margin = [x - x0 as f64, (x0 + w) as f64 - x, y - y0 as f64, (y0 + h) as f64 - y];
                least_margin = margin.into_iter().fold(least_margin, f64::min);
            }
        }
        eprintln!(
            "wide {wide}: {capacity} lines held, largest window {largest} of {largest_window}, least margin {least_margin:.2} lines"
        );
        assert!(least_margin >= 0.5, "wide {wide}: a glossy vertex {least_margin:.2} lines inside the window's edge");
    }
    // One level where there is nothing glossy, or where the window would save too little.
    assert_eq!(fine_window(&patches, &[], radius, resolution, 2), None, "no glossy material");
    assert_eq!(fine_window(&patches, &scene.materials, radius, resolution, 1), None);
}

/// A material of albedo 0.5 that counts as glossy (a specular part of 1e-5, so that its
/// patches get the fine window) but reflects, to 1e-5, as the diffuse walls do.
const NEARLY_DIFFUSE: &str = r#"
[materials.fractal]
type = "phong"
diffuse = [0.5, 0.5, 0.5]
specular = [0.00001, 0.00001, 0.00001]
shininess = 1.0
"#;

#[test]
fn test02_a_furnace_through_both_levels_is_exact() {
    // The closed furnace of tests/per_pixel.rs test13 (every surface emits 1 and reflects
    // half: radiance 2 everywhere) around a Sierpinski tetrahedron of glossy triangles, at
    // 128 fine lines and wide lines of 2 and 4: the walls exchange their light through both
    // levels, the fractal through fine lines alone, and every pixel still sees 2. A wide line
    // weighed other than wide^2 fine lines, or a part of the grid that no level draws,
    // would move the mean.
    let text = common::scenes::closed_furnace(0.5, 128, false)
        + NEARLY_DIFFUSE
        + r#"
[[shapes]]
type = "sierpinski"
center = [0.0, -0.3, 0.3]
size = 1.0
level = 3
material = "fractal"
emission = [1.0, 1.0, 1.0]
"#;
    let (_scratch, scene) = common::scenes::load_text("wide_lines", "furnace", &text);
    let Some(ctx) = gpu() else { return };
    for wide in [2, 4] {
        let mut options = RenderOptions::from_scene(&scene);
        (options.width, options.height, options.iterations, options.seed) = (48, 48, 300, 1);
        options.first_shot = false;
        options.bundles_per_step = Some(1);
        options.wide_lines = Some(wide);
        let patches = scene::tessellate(&scene, options.patch_size).unwrap();
        let result = render(&ctx, &scene, &patches, &options).unwrap();
        assert_eq!(result.stats.wide_lines, wide, "the run had two levels");
        assert!(result.stats.bundle_lines < 128 * 128 / 2, "{} lines", result.stats.bundle_lines);
        let image = result.image;
        let mean = image.mean()[0];
        let darkest = image.pixels.iter().map(|p| p[0] as f64).fold(f64::INFINITY, f64::min);
        let brightest = image.pixels.iter().map(|p| p[0] as f64).fold(0.0, f64::max);
        eprintln!("wide {wide}: mean {mean:.4}, pixels {darkest:.3} to {brightest:.3} (exact 2)");
        assert!((mean - 2.0).abs() < 0.008, "wide {wide}: mean {mean:.4}, exact 2");
        assert!(darkest > 1.8 && brightest < 2.2, "wide {wide}: pixels {darkest:.3} to {brightest:.3}, exact 2");
    }
}

#[test]
fn test03_the_gather_through_wide_lines_matches_the_form_factor() {
    // tests/iteration.rs test02 (an emitting square, radiance 1, and facing it a white
    // receiving triangle whose centre pixels converge to the form factor to the square) with
    // a small glossy triangle far to the side, so that the bundles have a fine window there
    // and the receiver gathers through wide lines (of 2 fine lines) in most of them.
    let Some(ctx) = gpu() else { return };
    let glossy = Material {
        name: "glossy".into(),
        kind: MaterialKind::Phong { diffuse: [0.0; 3], specular: [0.0001; 3], shininess: 10.0 },
    };
    let far = [DVec3::new(2.4, 0.0, 0.3), DVec3::new(2.5, 0.1, 0.3), DVec3::new(2.5, 0.0, 0.2)];
    let FormFactorScene { scene, patches, form_factor } = form_factor_scene(&[(far, glossy)]);
    let runs: Vec<f64> = (0..8)
        .map(|seed| {
            let mut o = RenderOptions::from_scene(&scene);
            (o.iterations, o.seed, o.first_shot) = (250, 100 + seed, false);
            (o.bundle_resolution, o.bundles_per_step, o.wide_lines) = (Some(64), Some(1), Some(2));
            let result = render(&ctx, &scene, &patches, &o).unwrap();
            assert_eq!(result.stats.wide_lines, 2, "the run had two levels");
            centre_mean(&result.image)
        })
        .collect();
    let (mean, spread) = mean_and_spread(&runs);
    let standard_error = spread / (runs.len() as f64).sqrt();
    eprintln!("form factor {form_factor:.5}, measured {mean:.5} +- {standard_error:.5} (runs {runs:?})");
    assert!(standard_error < 0.05 * form_factor, "too noisy to judge: {standard_error}");
    assert!((mean - form_factor).abs() < 4.0 * standard_error, "measured {mean} against {form_factor}");
}
