//! How fast the scene's light dies out, bounce by bounce: what the burn-in's length is
//! chosen from (docs/ALGORITHM.md 6, "Burn-in").
//!
//! J starts at 0, and after k bundles its mean carries the first k bounces of the light. The
//! share still missing falls as lambda^k, where lambda is the spectral radius of the scene's
//! transport operator: the factor by which light that has bounced many times loses energy at
//! each further bounce. lambda is at most the largest albedo of the scene's materials, which
//! is the bound the burn-in took before. But in a room of grey walls with a little of a
//! bright material, lambda is close to the walls' albedo. The Sierpinski scene's fractal
//! reflects 0.89 of red light and the walls about 0.6; lambda measures about 0.64. The bound
//! asked for 41 bounces, the measured rate asks for 11.
//!
//! lambda is measured here on the CPU, once a run, by a random walk over the patches
//! (`measured_decay_with` has the estimator): particles start at points uniform over the
//! reflecting surfaces' area; at each generation every particle sends its light into a
//! cosine-distributed direction, a ray cast (a BVH over the patches, `obvhs`) finds where it
//! lands, and the share kept there is the directional albedo of the material at the incidence
//! the light arrives with (nothing where it leaves the scene or meets a back face or a
//! light, both black). A generation's rate is the population's mean share kept; the
//! population is then resampled from where the light landed. Once the dominant mode has
//! taken over, that rate is lambda. The burn-in is then the bounces for the state's mean
//! plus 8 bundles for the control variates' running mean (`render::default_burn_in`).
//!
//! The walk is deterministic: its random numbers are seeded by the particle and the
//! generation alone, so every run of a scene, every shard and every resumed run gets the same
//! burn-in.

use crate::scene::{MaterialKind, Patches, Scene, brdf};
use glam::{DVec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    bvh2::builder::build_bvh2_from_tris,
    ray::{Ray, RayHit},
    triangle::Triangle,
};
use rand_core::RngCore;
use rand_pcg::Pcg32;
use rayon::prelude::*;

/// Particles of the walk's population.
pub const WALK_PARTICLES: u32 = 512;
/// Generations (bounces) the population is followed; the first `WALK_SETTLE` let the
/// dominant mode take over and are not averaged.
pub const WALK_GENERATIONS: u32 = 24;
pub const WALK_SETTLE: u32 = 8;
/// Past this many patches the walk is not run, and the burn-in keeps the largest albedo's
/// bound: its BVH (about 100 bytes a patch) would cost more time than a shorter burn-in
/// saves.
pub const WALK_MAX_PATCHES: usize = 4_000_000;

/// What the walk measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Decay {
    /// lambda: the share of its light the scene keeps from one bounce to the next, once
    /// many bounces have passed (at least the largest channel's).
    pub rate: f64,
    /// The rate's standard error, from the spread of the means of four runs of generations.
    pub standard_error: f64,
    /// The walk's population and the generations it was followed.
    pub particles: u32,
    pub generations: u32,
    /// What the walk took, its BVH included (wall time, milliseconds).
    pub ms: f64,
}

impl Decay {
    /// The rate the burn-in is sized by: two standard errors above the measured one, so
    /// that an unlucky walk does not cut the burn-in short.
    pub fn upper(&self) -> f64 {
        self.rate + 2.0 * self.standard_error
    }
}

/// The measured decay of the scene's light per bounce. `None` where no surface reflects, or
/// the scene has too many patches for the walk (`WALK_MAX_PATCHES`).
pub fn measured_decay(scene: &Scene, patches: &Patches) -> Option<Decay> {
    measured_decay_with(scene, patches, WALK_PARTICLES, WALK_GENERATIONS)
}

/// `measured_decay` with another population or number of generations (tests ask for more
/// precision than a run needs). `generations` must exceed `WALK_SETTLE` by at least 4.
///
/// The estimator is the power iteration of Monte Carlo criticality codes (the k-eigenvalue
/// of neutron transport): each generation, every particle sends its light one bounce on,
/// and the population's mean weight afterwards is that generation's rate. The population
/// is then drawn anew from where the light landed, in proportion to the light each particle
/// kept (systematic resampling), so that its spread follows the dominant mode and no path's
/// weight grows without bound, as a product of many albedos would.
pub fn measured_decay_with(scene: &Scene, patches: &Patches, particles: u32, generations: u32) -> Option<Decay> {
    assert!(generations >= WALK_SETTLE + 4, "too few generations to average");
    let start = std::time::Instant::now();
    let walk = Walk::new(scene, patches)?;
    let mut population: Vec<Particle> = (0..particles).map(|i| walk.start(i)).collect();
    let mut rates = Vec::new();
    for generation in 0..generations {
        let landed: Vec<Option<(Particle, f64)>> = population
            .par_iter()
            .enumerate()
            .map(|(i, p)| walk.bounce(p, &mut rng(generation + 1, i as u32)))
            .collect();
        // Summed in the particles' order, so that the result does not depend on the threads.
        let total: f64 = landed.iter().map(|l| l.as_ref().map_or(0.0, |(_, w)| *w)).sum();
        rates.push(total / f64::from(particles));
        if total <= 0.0 {
            // All the light has left the scene: no later bounce carries any.
            rates.resize(generations as usize, 0.0);
            break;
        }
        // Systematic resampling: `particles` equally spaced points through the cumulative
        // weights, from one random offset.
        let step = total / f64::from(particles);
        let mut next = step * uniform(&mut rng(generation + 1, particles));
        let mut cumulative = 0.0;
        let mut drawn = Vec::with_capacity(particles as usize);
        for (p, w) in landed.iter().flatten() {
            cumulative += w;
            while next < cumulative && drawn.len() < particles as usize {
                drawn.push(*p);
                next += step;
            }
        }
        // Rounding can leave the last draw or two short.
        while drawn.len() < particles as usize {
            drawn.push(*drawn.last().expect("a particle"));
        }
        population = drawn;
    }
    let averaged = &rates[WALK_SETTLE as usize..];
    let rate = averaged.iter().sum::<f64>() / averaged.len() as f64;
    // Consecutive generations are correlated (they share particles): the spread of the
    // means of four runs of them gives the error.
    let runs: Vec<f64> =
        averaged.chunks(averaged.len().div_ceil(4)).map(|c| c.iter().sum::<f64>() / c.len() as f64).collect();
    let n = runs.len() as f64;
    let variance = runs.iter().map(|r| (r - rate).powi(2)).sum::<f64>() / (n - 1.0);
    let ms = start.elapsed().as_secs_f64() * 1e3;
    Some(Decay { rate, standard_error: (variance / n).sqrt(), particles, generations, ms })
}

/// Where a particle's light is: the patch it reached and the point on it.
#[derive(Debug, Clone, Copy)]
struct Particle {
    patch: u32,
    point: DVec3,
}

/// The generator of particle `index` at generation `generation` (0: the start).
fn rng(generation: u32, index: u32) -> Pcg32 {
    let key = (u64::from(generation) << 32) | u64::from(index);
    Pcg32::new(crate::rng::splitmix64(key), 0x5851_f42d_4c95_7f2d)
}

fn uniform(rng: &mut Pcg32) -> f64 {
    (rng.next_u32() >> 8) as f64 * (1.0 / 16_777_216.0)
}

/// The scene's patches, ready for the walk.
struct Walk<'a> {
    scene: &'a Scene,
    patches: &'a Patches,
    triangles: Vec<Triangle>,
    /// Per material: its glossy lobe's albedo table (`brdf::glossy_albedo_table`), where it
    /// has a lobe. A lookup costs far less than the closed form at each of the walk's hits.
    lobe_tables: Vec<Option<Vec<f32>>>,
    bvh: obvhs::bvh2::Bvh2,
    /// Running sum of the reflecting patches' areas, for picking a start by area.
    area_cdf: Vec<(f64, u32)>,
    /// How far a ray starts off the surface it leaves, against self-hits.
    offset: f64,
    /// The scene's centre: the BVH and its rays are in single precision, relative to it
    /// (`local`), so that their rounding is a share of the scene's size wherever it lies. In
    /// world coordinates a Cornell box 1e5 mm from the origin lost its rays to self-hits past
    /// the offset (its measured decay per bounce 0.61 against 0.68, one burn-in step less).
    centre: DVec3,
}

impl<'a> Walk<'a> {
    fn new(scene: &'a Scene, patches: &'a Patches) -> Option<Self> {
        if patches.patches.is_empty() || patches.patches.len() > WALK_MAX_PATCHES {
            return None;
        }
        let mut total = 0.0;
        let area_cdf: Vec<(f64, u32)> = patches
            .patches
            .iter()
            .enumerate()
            .filter(|(_, p)| p.material.is_some() && p.area > 0.0)
            .map(|(i, p)| {
                total += p.area;
                (total, i as u32)
            })
            .collect();
        if area_cdf.is_empty() {
            return None;
        }
        let (centre, radius) = crate::gpu::scene_buffers::bounding_sphere(patches);
        let local = |p: DVec3| single(p - centre);
        let triangles: Vec<Triangle> = patches
            .patches
            .iter()
            .map(|p| Triangle { v0: local(p.vertices[0]), v1: local(p.vertices[1]), v2: local(p.vertices[2]) })
            .collect();
        let bvh = build_bvh2_from_tris(&triangles, BvhBuildParams::fast_build(), &mut Default::default());
        let lobe_tables = scene
            .materials
            .iter()
            .map(|m| match m.kind {
                MaterialKind::Diffuse { .. } => None,
                MaterialKind::Phong { shininess, .. } => Some(brdf::glossy_albedo_table(f64::from(shininess))),
            })
            .collect();
        Some(Walk { scene, patches, triangles, lobe_tables, bvh, area_cdf, offset: 1e-5 * radius, centre })
    }

    /// Particle `index` of the first generation: a point uniform over the reflecting
    /// surfaces' area.
    fn start(&self, index: u32) -> Particle {
        let mut rng = rng(0, index);
        let total = self.area_cdf.last().map_or(0.0, |c| c.0);
        let pick = uniform(&mut rng) * total;
        let at = self.area_cdf.partition_point(|c| c.0 <= pick).min(self.area_cdf.len() - 1);
        let patch = self.area_cdf[at].1;
        let (mut s, mut t) = (uniform(&mut rng), uniform(&mut rng));
        if s + t > 1.0 {
            (s, t) = (1.0 - s, 1.0 - t);
        }
        let [a, b, c] = self.patches.patches[patch as usize].vertices;
        Particle { patch, point: a + s * (b - a) + t * (c - a) }
    }

    /// One bounce: the light at `from` leaves in a cosine-distributed direction. Where it
    /// lands on a reflecting front, the new place and the share of the light kept there
    /// (the directional albedo at that incidence, its largest channel); `None` where it
    /// leaves the scene or meets a back face or a light (both black).
    fn bounce(&self, from: &Particle, rng: &mut Pcg32) -> Option<(Particle, f64)> {
        let normal = self.patches.patches[from.patch as usize].normal;
        let direction = cosine_direction(normal, uniform(rng), uniform(rng));
        let (hit, distance) = self.cast(from.point + self.offset * normal, direction)?;
        let patch = &self.patches.patches[hit];
        let cos_in = -patch.normal.dot(direction);
        let material = patch.material.filter(|_| cos_in > 0.0)?;
        let kept = self.albedo(material as usize, cos_in).into_iter().fold(0.0, f64::max);
        Some((Particle { patch: hit as u32, point: from.point + distance * direction }, kept))
    }

    /// Material `material`'s directional albedo at incidence cos theta = `cos_in`.
    fn albedo(&self, material: usize, cos_in: f64) -> [f64; 3] {
        match (&self.scene.materials[material].kind, &self.lobe_tables[material]) {
            (MaterialKind::Phong { diffuse, specular, .. }, Some(table)) => {
                let lobe = brdf::glossy_albedo_lookup(table, cos_in);
                std::array::from_fn(|c| f64::from(diffuse[c]) + f64::from(specular[c]) * lobe)
            }
            (kind, _) => brdf::directional_albedo(kind, cos_in),
        }
    }

    /// The nearest patch along the ray and its distance. The back of a two-sided surface's
    /// patch is passed over: its twin's front lies at the same place.
    fn cast(&self, origin: DVec3, direction: DVec3) -> Option<(usize, f64)> {
        let ray = Ray::new_inf(single(origin - self.centre), single(direction));
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(ray, &mut hit, |ray, id| {
            let index = self.bvh.primitive_indices[id] as usize;
            let patch = &self.patches.patches[index];
            if patch.twin && patch.normal.dot(direction) > 0.0 {
                return f32::INFINITY;
            }
            self.triangles[index].intersect(ray)
        });
        found.then(|| (self.bvh.primitive_indices[hit.primitive_id as usize] as usize, f64::from(hit.t)))
    }
}

/// `p` in single precision, as the BVH and its rays take it.
fn single(p: DVec3) -> Vec3A {
    Vec3A::new(p.x as f32, p.y as f32, p.z as f32)
}

/// A direction about `normal` with density cos(theta) / pi.
fn cosine_direction(normal: DVec3, u: f64, v: f64) -> DVec3 {
    let r = u.sqrt();
    let phi = 2.0 * std::f64::consts::PI * v;
    let (x, y) = (r * phi.cos(), r * phi.sin());
    let z = (1.0 - u).max(0.0).sqrt();
    let (t, b) = normal.any_orthonormal_pair();
    x * t + y * b + z * normal
}
