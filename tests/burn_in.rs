//! The burn-in's random walk (src/burn_in.rs) against rooms whose decay per bounce is known.

mod common;

use common::*;
use firstshot::burn_in::{Decay, measured_decay, measured_decay_with};
use firstshot::scene::{Material, MaterialKind, Patches, Scene};
use glam::DVec3;

fn diffuse(name: &str, albedo: f32) -> Material {
    Material { name: name.into(), kind: MaterialKind::Diffuse { albedo: [albedo; 3] } }
}

/// A closed unit cube seen from inside, each face cut into 2 k^2 patches: material 0 on the
/// floor (y = 0), material 1 on the other five faces.
fn cube(floor: f32, rest: f32, k: u32) -> (Scene, Patches) {
    let mut scene = bare_scene();
    scene.materials = vec![diffuse("floor", floor), diffuse("rest", rest)];
    let tris: Vec<_> = room(DVec3::ZERO, DVec3::ONE).into_iter().flat_map(|t| split(t, k)).collect();
    let mut patches = patches_of(&tris, vec![]);
    for p in &mut patches.patches {
        p.material = Some(if p.normal.y > 0.5 { 0 } else { 1 });
    }
    (scene, patches)
}

fn precise(scene: &Scene, patches: &Patches) -> Decay {
    measured_decay_with(scene, patches, 8192, 48).expect("a walk")
}

#[test]
fn test01_a_closed_room_of_one_albedo_decays_by_its_albedo() {
    // No light leaves a closed room, so every path is reflected at every bounce: its energy
    // falls by exactly the albedo each time. A crack between patches, a self-hit or a back
    // face taken for a front would lose paths and lower the rate.
    let (scene, patches) = cube(0.7, 0.7, 4);
    let decay = measured_decay(&scene, &patches).expect("a walk");
    eprintln!("{decay:?}");
    let albedo = f64::from(0.7f32);
    assert!((decay.rate - albedo).abs() < 1e-12 && decay.standard_error < 1e-12, "{decay:?}");
    // The burn-in then asks for log 0.01 / log 0.7 = 12.9 bounces, as the albedo's bound does,
    // and 8 bundles more for the control variates' mean (`SETTLED_MEAN_BUNDLES`).
    assert_eq!(firstshot::render::default_burn_in(&scene, &patches).0, 13 + firstshot::iteration::SETTLED_MEAN_BUNDLES);
}

/// A closed sphere of radius 1 seen from inside: an icosahedron whose faces are cut `level`
/// times into four, its vertices pushed onto the sphere, fronts facing the centre.
fn sphere(level: u32) -> Vec<[DVec3; 3]> {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let v: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let faces = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut tris: Vec<[DVec3; 3]> = faces.iter().map(|f| [v[f[0]], v[f[1]], v[f[2]]]).collect();
    for _ in 0..level {
        tris = tris
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = ((a + b).normalize(), (b + c).normalize(), (c + a).normalize());
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
    }
    // Fronts towards the centre.
    tris.into_iter()
        .map(|t| {
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            if n.dot(t[0]) < 0.0 { t } else { [t[0], t[2], t[1]] }
        })
        .collect()
}

#[test]
fn test02_a_sphere_decays_by_its_area_weighted_albedo() {
    // Inside a sphere, the light a point sends out spreads over the sphere in proportion to
    // area, wherever the point is (the form factor to a piece of the sphere is its area over
    // 4 pi R^2). So after one bounce the light's distribution no longer depends on where it
    // was, and every later bounce keeps sum_j a_j A_j / A of it: the decay is the
    // area-weighted albedo, exactly for a sphere and to the faceting for this polyhedron.
    // A cap above y = 0.5 (a quarter of the area) reflects 0.95, the rest 0.3: the rate is
    // about 0.46, far from the largest albedo that bounded the burn-in before.
    let mut scene = bare_scene();
    scene.materials = vec![diffuse("cap", 0.95), diffuse("rest", 0.3)];
    let mut patches = patches_of(&sphere(3), vec![]);
    for p in &mut patches.patches {
        let centre = (p.vertices[0] + p.vertices[1] + p.vertices[2]) / 3.0;
        p.material = Some(if centre.y > 0.5 { 0 } else { 1 });
    }
    let area: f64 = patches.patches.iter().map(|p| p.area).sum();
    let albedo = |p: &firstshot::scene::Patch| [0.95f32, 0.3][p.material.unwrap() as usize] as f64;
    let exact: f64 = patches.patches.iter().map(|p| albedo(p) * p.area).sum::<f64>() / area;
    let decay = precise(&scene, &patches);
    eprintln!("{} patches: {decay:?} against {exact:.5}", patches.patches.len());
    // The faceting moves the rate by less than 0.001 from 320 to 5120 patches.
    let tolerance = 3.0 * decay.standard_error + 0.001;
    assert!((decay.rate - exact).abs() < tolerance, "{decay:?} against {exact} (tolerance {tolerance})");
    assert!((0.44..0.48).contains(&exact), "{exact}");
}

#[test]
fn test03_light_that_leaves_the_scene_does_not_come_back() {
    // A floor alone under an empty sky: what it reflects never returns, so no bounce after
    // the first carries any light, and the default burn-in is none.
    let mut scene = bare_scene();
    scene.materials = vec![diffuse("floor", 0.8)];
    let floor = room(DVec3::ZERO, DVec3::ONE).into_iter().take(2).flat_map(|t| split(t, 3)).collect::<Vec<_>>();
    let mut patches = patches_of(&floor, vec![]);
    patches.patches.iter_mut().for_each(|p| p.material = Some(0));
    let decay = measured_decay(&scene, &patches).expect("a walk");
    assert_eq!(decay.rate, 0.0, "{decay:?}");
    assert_eq!(firstshot::render::default_burn_in(&scene, &patches).0, 0);
    // The cube with its ceiling taken away keeps less than its albedo: light leaves through
    // the opening at every bounce.
    let (scene, mut patches) = cube(0.7, 0.7, 4);
    patches.patches.retain(|p| p.normal.y > -0.5);
    let open = precise(&scene, &patches);
    eprintln!("open box: {open:?}");
    assert!(open.rate < 0.7 * 0.85 && open.rate > 0.7 * 0.4, "{open:?}");
}

#[test]
fn test04_both_sides_of_a_two_sided_plate_reflect() {
    // A two-sided plate inside the closed room is two patches back to back at the same place
    // (`Patch::twin`): the ray that meets the plate meets both, and the walk must take the
    // one whose front it sees. The room still loses nothing: the rate is the albedo.
    let (scene, mut patches) = cube(0.7, 0.7, 3);
    let plate = [DVec3::new(0.2, 0.5, 0.2), DVec3::new(0.8, 0.5, 0.2), DVec3::new(0.5, 0.5, 0.8)];
    for t in split(plate, 3) {
        for v in [t, [t[0], t[2], t[1]]] {
            let mut p = patch(v);
            (p.material, p.twin) = (Some(1), true);
            patches.patches.push(p);
        }
    }
    let decay = measured_decay(&scene, &patches).expect("a walk");
    assert!((decay.rate - f64::from(0.7f32)).abs() < 1e-12, "{decay:?}");
}

#[test]
fn test05_the_walk_sizes_the_default_burn_in_and_the_bound_caps_it() {
    // The Sierpinski scene's fractal reflects up to 0.89 of red light, its walls about 0.6:
    // the bound asks for 41 bounces, the light's measured decay (about 0.64) for 11. `--burn-in`
    // still decides where given, and the memory plan keeps the bound.
    let scene = firstshot::scene::load(&common::scenes::shipped("sierpinski")).unwrap();
    let options = firstshot::render::RenderOptions::from_scene(&scene);
    let patches = firstshot::scene::tessellate(&scene, options.patch_size).unwrap();
    let (bundles, decay) = firstshot::render::default_burn_in(&scene, &patches);
    let decay = decay.expect("a walk");
    let bound = firstshot::render::largest_albedo(&scene);
    eprintln!("{bundles} bundles from {decay:?}; the bound {bound:.4}");
    assert_eq!(firstshot::render::bounces_for_decay(bound), 41);
    assert!(decay.upper() < bound && decay.rate > 0.55 && decay.rate < 0.7, "{decay:?}");
    let settle = firstshot::iteration::SETTLED_MEAN_BUNDLES;
    assert_eq!(bundles, firstshot::render::bounces_for_decay(decay.upper()) + settle);
    // Deterministic: the same scene walks the same paths.
    let (again, walked) = firstshot::render::default_burn_in(&scene, &patches);
    let walked = walked.expect("a walk");
    assert_eq!((again, walked.rate, walked.standard_error), (bundles, decay.rate, decay.standard_error));
    let given = firstshot::render::RenderOptions { burn_in: Some(5), ..options.clone() };
    assert_eq!(firstshot::render::burn_in_steps(&scene, &patches, &given, 1), (5, None));
    assert_eq!(firstshot::render::burn_in_steps(&scene, &patches, &options, 4).0, bundles.div_ceil(4));
    assert_eq!(firstshot::render::longest_burn_in_steps(&scene, &options, 4), (41 + settle).div_ceil(4));
}

#[test]
fn test06_a_closed_room_far_from_the_origin_decays_as_at_it() {
    // test01's room of albedo 0.7 moved 1e5 from the origin, where single precision (the
    // walk's BVH) holds a coordinate to 2^-7, about 1 % of the room. Cast in world
    // coordinates, rays started 1e-5 of the radius off their surface fell back onto it and
    // left through it: the rate came out low. The walk casts relative to the scene's centre.
    let mut scene = bare_scene();
    scene.materials = vec![diffuse("all", 0.7)];
    let corner = DVec3::new(1.0e5, 0.0, -1.0e5);
    let tris: Vec<_> = room(corner, corner + DVec3::ONE).into_iter().flat_map(|t| split(t, 4)).collect();
    let mut patches = patches_of(&tris, vec![]);
    for p in &mut patches.patches {
        p.material = Some(0);
    }
    let decay = measured_decay(&scene, &patches).expect("a walk");
    eprintln!("{decay:?}");
    assert!((decay.rate - f64::from(0.7f32)).abs() < 1e-12 && decay.standard_error < 1e-12, "{decay:?}");
}
