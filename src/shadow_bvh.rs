//! The scene's triangles in a bounding volume hierarchy, for the per-pixel direct light's shadow
//! rays (docs/ALGORITHM.md 6, "Visibility").
//!
//! Every pass of the image's direct light takes a new point y on each area light (and on each
//! first-shot emitting shape), and every pixel's point x asks whether the segment from y to x
//! is free. The paper's way, and firstshot's before, is an item buffer around y (a window)
//! rendered again at every pass, read at the texels around x's direction: exact only where an
//! occluder covers one of those texel centres, and on a CPU adapter a raster of the whole
//! scene per pass (the Sierpinski scene: 50 ms of a 140 ms step that estimates the direct
//! light). A shadow ray through this hierarchy is exact everywhere and costs nothing to set
//! up per pass: the hierarchy is built once, on the host, over the rasterised triangles
//! (`scene_buffers::raster_triangles`, a lattice drawn as its source triangle), and
//! `wgsl/image_estimate.wgsl` (`occluded`) walks it.
//!
//! The build is obvhs's (the burn-in's random walk casts its rays with it too); this module
//! flattens its tree into two tables the kernel reads (`GpuBvhNode`, depth-first with escapes
//! and half-float boxes; `GpuBvhTriangle`, the triangles in leaf order).

use crate::gpu::scene_buffers::RasterTriangles;
use crate::layout::{BVH_TRIANGLE_BACK, GpuBvhNode, GpuBvhTriangle, LATTICE_CORNER_SHIFT, VERTEX_TWIN_BIT};
use glam::{DVec3, Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::triangle::Triangle;

/// The segment from y to x leaves out this share of its length at each end: its ends lie on
/// the light and on x's own surface (the windows' test, `SEGMENT_EPSILON` in the kernel).
pub const SEGMENT_EPSILON: f32 = 1e-4;

#[derive(Debug, Clone, PartialEq)]
pub struct ShadowBvh {
    pub nodes: Vec<GpuBvhNode>,
    pub triangles: Vec<GpuBvhTriangle>,
    /// Nodes on the longest path from the root to a leaf.
    pub depth: u32,
    /// The frame the nodes' boxes are kept in: (p - centre) * scale, centre the triangles'
    /// bounding box's centre and scale the inverse of its half diagonal, so that every
    /// corner lies within [-1, 1], where half floats resolve 2^-11.
    pub frame: (Vec3, f32),
}

impl ShadowBvh {
    /// The hierarchy over `raster`'s triangles (a patch's twin, drawn as a second triangle,
    /// is left out: it lies in the same plane). `None` for a scene without triangles.
    pub fn build(raster: &RasterTriangles) -> Option<ShadowBvh> {
        let corner = |v: &crate::layout::RasterVertex| Vec3A::from(Vec3::from(v.position));
        let lattice_corner = |word: u32| (word >> LATTICE_CORNER_SHIFT) & 3;
        // Each kept triangle's corners, and the patch a ray meeting it meets (`hit_patch` in
        // the kernel): the front's first patch, corner v0's lattice word, v1's and v2's
        // lattice corners, and whether a twin follows it (its back, patch + 1).
        let mut source: Vec<([Vec3A; 3], [u32; 3])> = Vec::with_capacity(raster.vertices.len() / 3);
        for (t, tri) in raster.vertices.chunks_exact(3).enumerate() {
            let corners = [corner(&tri[0]), corner(&tri[1]), corner(&tri[2])];
            // A twin (the back of a two-sided surface) follows its front with the same corners.
            if let Some(last) = source.last_mut().filter(|last| same_corners(&last.0, &corners)) {
                last.1[2] |= BVH_TRIANGLE_BACK;
                continue;
            }
            let words = &raster.lattice[3 * t..3 * t + 3];
            let hit =
                [tri[0].patch & !VERTEX_TWIN_BIT, words[0], lattice_corner(words[1]) | lattice_corner(words[2]) << 2];
            source.push((corners, hit));
        }
        if source.is_empty() {
            return None;
        }
        let triangles: Vec<Triangle> = source.iter().map(|&([v0, v1, v2], _)| Triangle { v0, v1, v2 }).collect();
        let bvh = build_bvh2_from_tris(&triangles, BvhBuildParams::fast_build(), &mut Default::default());
        // Leaves index the triangle table directly: the triangles go in the order of obvhs's
        // primitive indices.
        let ordered: Vec<GpuBvhTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| {
                let ([v0, v1, v2], [first_patch, lattice, corners]) = source[i as usize];
                let v3 = |v: Vec3A| [v.x, v.y, v.z];
                GpuBvhTriangle { v0: v3(v0), first_patch, e1: v3(v1 - v0), lattice, e2: v3(v2 - v0), corners }
            })
            .collect();
        let root = bvh.nodes[0].aabb;
        let centre = Vec3::from((root.min + root.max) * 0.5);
        let half_diagonal = Vec3::from(root.max - root.min).length() * 0.5;
        let frame = (centre, if half_diagonal > 0.0 { 1.0 / half_diagonal } else { 1.0 });
        let (nodes, depth) = threaded(&bvh.nodes, frame);
        Some(ShadowBvh { nodes, triangles: ordered, depth, frame })
    }

    /// Whether a triangle crosses the segment from y (on a light of normal `n_y`) to x (on a
    /// surface of normal `n_x`), its ends moved off their surfaces (`lifted`) and left out: the kernel's
    /// `occluded`, step for step, on the host (tests hold it against every triangle).
    pub fn occluded(&self, y: Vec3, n_y: Vec3, x: Vec3, n_x: Vec3) -> bool {
        let (y, x) = (lifted(y, n_y, x), lifted(x, n_x, y));
        let dir = x - y;
        let (centre, scale) = self.frame;
        let origin = (y - centre) * scale;
        let inv = safe_inverse(dir * scale);
        let mut node = 0usize;
        while node < self.nodes.len() {
            let n = &self.nodes[node];
            let (min, max) = unpack_bounds(n.bounds);
            let (t_near, t_far) = slab(min, max, origin, inv);
            let leaf = n.link & LEAF != 0;
            if t_near <= t_far {
                if !leaf {
                    node += 1;
                    continue;
                }
                let first = (n.link & !LEAF) >> LEAF_COUNT_BITS;
                if (first..=first + (n.link & LEAF_COUNT_MASK))
                    .any(|k| segment_hits(&self.triangles[k as usize], y, dir))
                {
                    return true;
                }
            }
            node = if leaf { node + 1 } else { n.link as usize };
        }
        false
    }
}

/// The tree in the form the shafts' test walks it on the host (`ShadowBvh::shafts`): each
/// node's box and each triangle's corners in scene coordinates, decoded once.
pub struct ShaftTree<'a> {
    bvh: &'a ShadowBvh,
    boxes: Vec<(DVec3, DVec3)>,
    corners: Vec<[DVec3; 3]>,
}

impl ShadowBvh {
    /// The tree ready for `ShaftTree::is_clear`.
    pub fn shafts(&self) -> ShaftTree<'_> {
        let (centre, scale) = self.frame;
        let (centre, inverse) = (centre.as_dvec3(), 1.0 / f64::from(scale));
        let world = |v: Vec3| centre + v.as_dvec3() * inverse;
        let boxes = self
            .nodes
            .iter()
            .map(|n| {
                let (min, max) = unpack_bounds(n.bounds);
                (world(min), world(max))
            })
            .collect();
        let corners = self
            .triangles
            .iter()
            .map(|t| {
                let a = Vec3::from_slice(&t.v0).as_dvec3();
                [a, a + Vec3::from_slice(&t.e1).as_dvec3(), a + Vec3::from_slice(&t.e2).as_dvec3()]
            })
            .collect();
        ShaftTree { bvh: self, boxes, corners }
    }
}

impl ShaftTree<'_> {
    /// Whether no triangle of the tree can cross a segment between two points of the convex
    /// region `shaft` (the light's and a patch's hull, `Shaft::hull`): so that every shadow
    /// ray between them would find nothing, and a pixel on the patch needs none for that
    /// light (`direct_light::ShaftJob`). A triangle is left out where one plane separates
    /// it from the shaft, touching allowed: one of the shaft's faces, or its own plane (which
    /// leaves out the patch's neighbours in its plane and the light's own triangles, which
    /// a segment meets only at its ends, where the kernel's test leaves them out too).
    /// Conservative: a triangle that no plane of those separates counts as crossing, though
    /// it may miss the shaft.
    pub fn is_clear(&self, shaft: &Shaft) -> bool {
        let nodes = &self.bvh.nodes;
        let mut node = 0usize;
        while node < nodes.len() {
            let link = nodes[node].link;
            let leaf = link & LEAF != 0;
            let (lo, hi) = self.boxes[node];
            if !shaft.misses_box(lo, hi) {
                if !leaf {
                    node += 1;
                    continue;
                }
                let first = ((link & !LEAF) >> LEAF_COUNT_BITS) as usize;
                let last = first + (link & LEAF_COUNT_MASK) as usize;
                if self.corners[first..=last].iter().any(|c| !shaft.misses_triangle(c)) {
                    return false;
                }
            }
            node = if leaf { node + 1 } else { link as usize };
        }
        true
    }
}

/// The most points a shaft is the hull of: a light's corners (`direct_light::light_corners`
/// keeps at most 12) and a patch's three.
pub const SHAFT_POINTS: usize = 15;
/// A hull of n points in general position has at most 2n - 4 faces.
const SHAFT_PLANES: usize = 2 * SHAFT_POINTS - 4;

/// A convex region between a light and a patch: the hull of their corners, as the planes
/// of its faces (outward unit normal n and offset d: n . p <= d inside) and its box. Fixed
/// arrays: one is made for every patch and light.
#[derive(Debug, Clone)]
pub struct Shaft {
    points: [DVec3; SHAFT_POINTS],
    point_count: usize,
    planes: [(DVec3, f64); SHAFT_PLANES],
    plane_count: usize,
    lo: DVec3,
    hi: DVec3,
    /// Distances within this of a plane count as on it: a few units in the last place of
    /// the f32 coordinates the triangles are kept in.
    tolerance: f64,
}

impl Shaft {
    /// The convex hull of `points` (at most SHAFT_POINTS: so the faces are found by trying
    /// every plane through three of them). `tolerance`: see the field.
    pub fn hull(points: &[DVec3], tolerance: f64) -> Shaft {
        assert!(points.len() <= SHAFT_POINTS, "{} points for a shaft", points.len());
        let mut shaft = Shaft {
            points: [DVec3::ZERO; SHAFT_POINTS],
            point_count: points.len(),
            planes: [(DVec3::ZERO, 0.0); SHAFT_PLANES],
            plane_count: 0,
            lo: DVec3::splat(f64::INFINITY),
            hi: DVec3::splat(f64::NEG_INFINITY),
            tolerance,
        };
        shaft.points[..points.len()].copy_from_slice(points);
        for &p in points {
            shaft.lo = shaft.lo.min(p);
            shaft.hi = shaft.hi.max(p);
        }
        let extent = (shaft.hi - shaft.lo).max_element().max(tolerance);
        for i in 0..points.len() {
            for j in i + 1..points.len() {
                for k in j + 1..points.len() {
                    let normal = (points[j] - points[i]).cross(points[k] - points[i]);
                    let length = normal.length();
                    // A plane through three points nearly on a line is no face: its normal
                    // is rounding.
                    if length <= 1e-9 * extent * extent {
                        continue;
                    }
                    // A face has every point on one side (within `flat` of it); most planes
                    // through three points have some on each, found after a few.
                    let (d, flat) = (normal.dot(points[i]), 1e-9 * extent * length);
                    let (mut below, mut above) = (false, false);
                    for p in points {
                        let s = normal.dot(*p) - d;
                        below |= s < -flat;
                        above |= s > flat;
                        if below && above {
                            break;
                        }
                    }
                    let face = match (below, above) {
                        (true, true) => continue,
                        (_, false) => (normal / length, d / length),
                        (false, true) => (-normal / length, -d / length),
                    };
                    let same =
                        |(m, e): &(DVec3, f64)| m.dot(face.0) > 1.0 - 1e-12 && (e - face.1).abs() <= 1e-9 * extent;
                    // More faces than a hull can have only where points nearly coincide: the
                    // ones past the array are left out, which only makes the shaft larger.
                    if shaft.plane_count < SHAFT_PLANES && !shaft.planes[..shaft.plane_count].iter().any(same) {
                        shaft.planes[shaft.plane_count] = face;
                        shaft.plane_count += 1;
                    }
                }
            }
        }
        shaft
    }

    fn planes(&self) -> &[(DVec3, f64)] {
        &self.planes[..self.plane_count]
    }

    /// Whether the box [lo, hi] lies outside the shaft, touching allowed.
    fn misses_box(&self, lo: DVec3, hi: DVec3) -> bool {
        let t = self.tolerance;
        if (lo - self.hi).max_element() >= -t || (self.lo - hi).max_element() >= -t {
            return true;
        }
        self.planes().iter().any(|&(n, d)| {
            // The box's corner farthest into the shaft along -n.
            let nearest = DVec3::select(n.cmpge(DVec3::ZERO), lo, hi);
            n.dot(nearest) - d >= -t
        })
    }

    /// Whether the triangle lies outside the shaft, touching allowed: one of the shaft's
    /// planes has it on its outer side, or its own plane has the whole shaft on one side.
    fn misses_triangle(&self, corners: &[DVec3; 3]) -> bool {
        let t = self.tolerance;
        if self.planes().iter().any(|&(n, d)| corners.iter().all(|c| n.dot(*c) - d >= -t)) {
            return true;
        }
        let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
        let length = normal.length();
        if length == 0.0 {
            // A degenerate triangle crosses no segment in the kernel's test (its determinant
            // is zero).
            return true;
        }
        let n = normal / length;
        let d = n.dot(corners[0]);
        let (below, above) = self.points[..self.point_count].iter().fold((0.0f64, 0.0f64), |(b, a), p| {
            let s = n.dot(*p) - d;
            (b.min(s), a.max(s))
        });
        above <= t || below >= -t
    }
}

/// `GpuBvhNode::link` of a leaf: this bit, its first triangle << LEAF_COUNT_BITS and its count
/// - 1 (obvhs makes leaves of at most 8).
pub const LEAF: u32 = 1 << 31;
pub const LEAF_COUNT_BITS: u32 = 4;
pub const LEAF_COUNT_MASK: u32 = (1 << LEAF_COUNT_BITS) - 1;

/// obvhs's tree (children side by side at `first_index`) in depth-first order, each node with
/// its escape: the node to go on with where the segment misses its box, or after its leaf's
/// triangles (the next subtree to the right; `nodes.len()` past the last). An inner node's
/// first child is the next node. So the kernel walks the tree without a stack: on lavapipe a
/// per-lane stack of 64 entries in private memory made Sierpinski's direct pass 62.4 ms
/// against 48.6 ms without one. Returns the nodes and the tree's depth.
fn threaded(tree: &[obvhs::bvh2::node::Bvh2Node], frame: (Vec3, f32)) -> (Vec<GpuBvhNode>, u32) {
    let mut out: Vec<GpuBvhNode> = Vec::with_capacity(tree.len());
    let mut depth = 0;
    // Preorder, (tree node, its depth), with an explicit stack: the right child pushed first.
    let mut pending = vec![(0usize, 1u32)];
    let mut order: Vec<(usize, u32)> = Vec::with_capacity(tree.len());
    while let Some((t, d)) = pending.pop() {
        depth = depth.max(d);
        order.push((t, d));
        let n = &tree[t];
        if n.prim_count == 0 {
            pending.push((n.first_index as usize + 1, d + 1));
            pending.push((n.first_index as usize, d + 1));
        }
    }
    // In preorder a node's escape is the first later node whose depth is at most its own.
    let mut escape = vec![order.len() as u32; order.len()];
    let mut waiting: Vec<usize> = Vec::new();
    for (i, &(_, d)) in order.iter().enumerate() {
        while let Some(&w) = waiting.last() {
            if order[w].1 >= d {
                escape[w] = i as u32;
                waiting.pop();
            } else {
                break;
            }
        }
        waiting.push(i);
    }
    for (i, &(t, _)) in order.iter().enumerate() {
        let n = &tree[t];
        let link = if n.prim_count == 0 {
            escape[i]
        } else {
            // A leaf's escape is the next node in depth-first order.
            debug_assert_eq!(escape[i], i as u32 + 1);
            assert!(n.prim_count <= LEAF_COUNT_MASK + 1 && n.first_index < (!LEAF) >> LEAF_COUNT_BITS);
            LEAF | n.first_index << LEAF_COUNT_BITS | (n.prim_count - 1)
        };
        let bounds = pack_bounds(Vec3::from(n.aabb.min), Vec3::from(n.aabb.max), frame);
        out.push(GpuBvhNode { bounds, link });
    }
    (out, depth)
}

/// A box in the frame as six half floats, each corner rounded outward (the box only grows).
/// The kernel decodes them by hand (`halves` in image_estimate.wgsl), exactly as `half` does.
fn pack_bounds(min: Vec3, max: Vec3, (centre, scale): (Vec3, f32)) -> [u32; 3] {
    let lo = ((min - centre) * scale).to_array().map(half_down);
    let hi = ((max - centre) * scale).to_array().map(half_up);
    let pair = |a: half::f16, b: half::f16| u32::from(a.to_bits()) | u32::from(b.to_bits()) << 16;
    [pair(lo[0], lo[1]), pair(lo[2], hi[0]), pair(hi[1], hi[2])]
}

/// The box of `pack_bounds`, as the kernel's `halves` reads it.
fn unpack_bounds(bounds: [u32; 3]) -> (Vec3, Vec3) {
    let h = |word: u32, high: bool| half::f16::from_bits((if high { word >> 16 } else { word }) as u16).to_f32();
    let [a, b, c] = bounds;
    (Vec3::new(h(a, false), h(a, true), h(b, false)), Vec3::new(h(b, true), h(c, false), h(c, true)))
}

/// The largest half float at most `v`.
fn half_down(v: f32) -> half::f16 {
    let h = half::f16::from_f32(v);
    if h.to_f32() <= v {
        return h;
    }
    // One step toward minus infinity: the magnitude shrinks for a positive value (zero
    // becomes the smallest negative one) and grows for a negative one.
    let bits = h.to_bits();
    half::f16::from_bits(match bits {
        0 => 0x8001,
        b if b & 0x8000 == 0 => b - 1,
        b => b + 1,
    })
}

/// The smallest half float at least `v`.
fn half_up(v: f32) -> half::f16 {
    -half_down(-v)
}

fn same_corners(a: &[Vec3A; 3], b: &[Vec3A; 3]) -> bool {
    a.iter().all(|p| b.contains(p))
}

/// 1 / d per axis, with a zero component taken as a tiny one (the slab test then sees an
/// infinite slope, as it should, instead of 0 x infinity).
fn safe_inverse(d: Vec3) -> Vec3 {
    let tiny = |v: f32| if v.abs() < 1e-30 { 1e-30 } else { v };
    Vec3::new(1.0 / tiny(d.x), 1.0 / tiny(d.y), 1.0 / tiny(d.z))
}

/// The segment's parameters where it enters and leaves the box, clipped to the segment.
fn slab(min: Vec3, max: Vec3, y: Vec3, inv: Vec3) -> (f32, f32) {
    let t0 = (min - y) * inv;
    let t1 = (max - y) * inv;
    // Only the kept part of the segment: a box that holds the segment's ends alone (the light's
    // own triangles, x's own surface) is not entered.
    let near = t0.min(t1).max_element().max(SEGMENT_EPSILON);
    let far = t0.max(t1).min_element().min(1.0 - SEGMENT_EPSILON);
    (near, far)
}

/// A coordinate of magnitude m is held in f32 to m x 2^-23; a point computed on a surface (x
/// from the camera ray and its patch's plane, y on its light) lies off that surface's plane
/// by a fraction of that (the kernel's `POSITION_ULPS`).
pub const POSITION_ULPS: f32 = 2.0 * f32::EPSILON;

/// The end p of a segment (on a surface of normal n) moved off its surface toward the other
/// end q by a few units in the last place of p's coordinates: the kernel's `lifted`, which
/// says why.
pub fn lifted(p: Vec3, n: Vec3, q: Vec3) -> Vec3 {
    p + if n.dot(q - p) >= 0.0 { n } else { -n } * (POSITION_ULPS * p.abs().max_element())
}

/// Moller-Trumbore, either side, for t strictly inside the segment's kept part.
fn segment_hits(t: &GpuBvhTriangle, y: Vec3, dir: Vec3) -> bool {
    let a = Vec3::from_slice(&t.v0);
    let e1 = Vec3::from_slice(&t.e1);
    let e2 = Vec3::from_slice(&t.e2);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-30 {
        return false;
    }
    let inv = 1.0 / det;
    let s = y - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let t = e2.dot(q) * inv;
    t > SEGMENT_EPSILON && t < 1.0 - SEGMENT_EPSILON
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::RasterVertex;

    fn raster(triangles: &[[Vec3; 3]]) -> RasterTriangles {
        let mut out = RasterTriangles::default();
        for (i, t) in triangles.iter().enumerate() {
            for v in t {
                out.vertices.push(RasterVertex { position: v.to_array(), patch: i as u32 });
                out.lattice.push(1);
            }
        }
        out
    }

    /// A deterministic cloud of small random triangles in the unit cube.
    fn cloud(count: usize, seed: u64) -> Vec<[Vec3; 3]> {
        let mut rng = crate::rng::StepRng::new(seed, 0);
        let mut f = || rng.uniform() as f32;
        (0..count)
            .map(|_| {
                let c = Vec3::new(f(), f(), f());
                let e = |f: &mut dyn FnMut() -> f32| Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5) * 0.15;
                [c, c + e(&mut f), c + e(&mut f)]
            })
            .collect()
    }

    #[test]
    fn test01_the_hierarchy_finds_what_every_triangle_finds() {
        // The oracle: the segment test against every triangle, no hierarchy.
        let triangles = cloud(3000, 7);
        let bvh = ShadowBvh::build(&raster(&triangles)).expect("a tree");
        assert_eq!(bvh.triangles.len(), triangles.len());
        let brute: Vec<GpuBvhTriangle> = triangles
            .iter()
            .map(|&[v0, v1, v2]| GpuBvhTriangle {
                v0: v0.to_array(),
                e1: (v1 - v0).to_array(),
                e2: (v2 - v0).to_array(),
                ..bytemuck::Zeroable::zeroed()
            })
            .collect();
        let mut rng = crate::rng::StepRng::new(11, 0);
        let mut point = || Vec3::new(rng.uniform() as f32, rng.uniform() as f32, rng.uniform() as f32) * 1.4 - 0.2;
        let (mut blocked, mut free) = (0, 0);
        for _ in 0..4000 {
            let (y, x) = (point(), point());
            let (n_y, n_x) = ((point() - 0.5).normalize(), (point() - 0.5).normalize());
            let (from, to) = (lifted(y, n_y, x), lifted(x, n_x, y));
            let expected = brute.iter().any(|t| segment_hits(t, from, to - from));
            assert_eq!(bvh.occluded(y, n_y, x, n_x), expected, "segment {y} -> {x}");
            if expected { blocked += 1 } else { free += 1 }
        }
        // Both answers occur often: the test says something either way.
        assert!(blocked > 500 && free > 500, "blocked {blocked}, free {free}");
        assert!(bvh.depth > 5, "depth {}", bvh.depth);
    }

    #[test]
    fn test02_the_ends_and_twins_are_left_out() {
        // A floor square of two triangles and its twins: a segment that ends on it is not
        // blocked by it, one that passes through it is; the twins are not stored twice.
        let a = Vec3::new(-1.0, 0.0, -1.0);
        let b = Vec3::new(1.0, 0.0, -1.0);
        let c = Vec3::new(1.0, 0.0, 1.0);
        let d = Vec3::new(-1.0, 0.0, 1.0);
        let mut r = raster(&[[a, d, c], [a, c, b]]);
        // Twins: the same corners, reversed, with the twin bit, each after its front.
        let mut with_twins = RasterTriangles::default();
        for (i, tri) in r.vertices.chunks_exact(3).enumerate() {
            with_twins.vertices.extend_from_slice(tri);
            let twin = [tri[0], tri[2], tri[1]]
                .map(|v| RasterVertex { patch: (2 * i as u32 + 1) | crate::layout::VERTEX_TWIN_BIT, ..v });
            with_twins.vertices.extend_from_slice(&twin);
        }
        with_twins.lattice = vec![1; with_twins.vertices.len()];
        r = with_twins;
        let bvh = ShadowBvh::build(&r).expect("a tree");
        assert_eq!(bvh.triangles.len(), 2);
        let light = Vec3::new(0.1, 3.0, 0.2);
        let (down, up) = (Vec3::NEG_Y, Vec3::Y);
        assert!(!bvh.occluded(light, down, Vec3::new(0.3, 0.0, -0.4), up), "a point on the floor sees the light");
        assert!(bvh.occluded(light, down, Vec3::new(0.3, -1.0, -0.4), up), "a point below the floor does not");
        assert!(!bvh.occluded(light, down, Vec3::new(3.0, -1.0, 0.0), up), "beside the floor it does");
    }

    #[test]
    fn test06_far_from_the_origin_an_end_is_not_shadowed_by_its_own_surface() {
        // A floor, a slanted panel above it and a wall meeting the floor at a crease, all moved
        // 1e5 from the origin, where f32 holds a coordinate to 2^-7. Points are found as the
        // kernel finds x: a camera ray met with a triangle's plane, in f32. Such a point lies
        // up to a tenth of 2^-7 off its plane, and the segment to a light above then crosses
        // its own triangle short of the kept part's end (before the ends were moved off their
        // surfaces, the panel's pixels lost 18 % of the light in tests/per_pixel.rs test22).
        let o = Vec3::new(1.0e5, 0.0, -3.0e4);
        let floor = [o + Vec3::new(-2.0, 0.0, -2.0), o + Vec3::new(-2.0, 0.0, 2.0), o + Vec3::new(2.0, 0.0, 2.0)];
        let panel = [o + Vec3::new(-0.4, 0.6, -0.3), o + Vec3::new(-0.1, 0.7, 0.5), o + Vec3::new(0.5, 0.55, 0.0)];
        let wall = [o + Vec3::new(-2.0, 0.0, 2.0), o + Vec3::new(2.0, 0.0, 2.0), o + Vec3::new(0.0, 2.0, 2.0)];
        let bvh = ShadowBvh::build(&raster(&[floor, panel, wall])).expect("a tree");
        let normal = |t: &[Vec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        let n_panel = normal(&panel);
        let n_panel = if n_panel.y > 0.0 { n_panel } else { -n_panel };
        let light = o + Vec3::new(0.05, 1.6, 0.02);
        let eye = o + Vec3::new(0.0, 2.2, -2.4);
        // Where the ray from the eye toward `target` meets the plane of `t`, in f32.
        let seen = |t: &[Vec3; 3], target: Vec3| {
            let n = normal(t);
            let dir = (target - eye).normalize();
            eye + dir * ((n.dot(t[0]) - n.dot(eye)) / n.dot(dir))
        };
        let mut rng = crate::rng::StepRng::new(3, 0);
        let own = GpuBvhTriangle {
            v0: panel[0].to_array(),
            e1: (panel[1] - panel[0]).to_array(),
            e2: (panel[2] - panel[0]).to_array(),
            ..bytemuck::Zeroable::zeroed()
        };
        let mut crossing_own = 0;
        for _ in 0..400 {
            let (a, b) = (rng.uniform() as f32, rng.uniform() as f32);
            let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
            let target = panel[0] + a * (panel[1] - panel[0]) + b * (panel[2] - panel[0]);
            let x = seen(&panel, target);
            crossing_own += segment_hits(&own, light, x - light) as u32;
            assert!(!bvh.occluded(light, Vec3::NEG_Y, x, n_panel), "the panel at {x} sees the light");
        }
        // The test says something: rounding put many of the points behind their own plane,
        // where the segment crosses the panel itself inside its kept part.
        assert!(crossing_own > 40, "{crossing_own} of 400 segments cross their own triangle");
        // The panel still shadows the floor beneath it, and the wall a point behind it; a
        // point on the floor beside the crease sees the light.
        let under = seen(&floor, o + Vec3::new(0.0, 0.0, 0.05));
        assert!(bvh.occluded(light, Vec3::NEG_Y, under, Vec3::Y), "the floor under the panel at {under}");
        let behind = o + Vec3::new(0.05, 0.3, 2.5);
        assert!(bvh.occluded(light, Vec3::NEG_Y, behind, Vec3::Z), "a point behind the wall");
        let crease = seen(&floor, o + Vec3::new(1.5, 0.0, 1.9));
        assert!(!bvh.occluded(light, Vec3::NEG_Y, crease, Vec3::Y), "the floor beside the crease at {crease}");
    }

    #[test]
    fn test04_half_float_boxes_only_grow() {
        let mut rng = crate::rng::StepRng::new(5, 0);
        for _ in 0..10_000 {
            let v = ((rng.uniform() - 0.5) * 2.5) as f32 * 10f32.powi((rng.uniform() * 6.0) as i32 - 5);
            let (down, up) = (half_down(v).to_f32(), half_up(v).to_f32());
            assert!(down <= v && v <= up, "{down} <= {v} <= {up}");
            assert!(up - down <= v.abs() * 2e-3 + 1e-7, "{down} .. {up} around {v}");
        }
        assert!(half_down(0.0).to_f32() <= 0.0 && half_up(0.0).to_f32() >= 0.0);
        let (min, max) = (Vec3::new(-1.0, 0.25, 3.0), Vec3::new(2.0, 0.5, 7.5));
        let (lo, hi) = unpack_bounds(pack_bounds(min, max, (Vec3::new(0.5, 0.0, 5.0), 0.2)));
        let frame = |p: Vec3| (p - Vec3::new(0.5, 0.0, 5.0)) * 0.2;
        assert!(lo.cmple(frame(min)).all() && hi.cmpge(frame(max)).all(), "{lo} {hi}");
    }

    /// image_estimate.wgsl's `halves`, step for step.
    fn kernel_half(bits: u32) -> f32 {
        let sign = (bits & 0x8000) << 16;
        let exponent = (bits >> 10) & 0x1f;
        let mantissa = bits & 0x3ff;
        if exponent == 0 {
            return f32::from_bits(sign | (mantissa as f32 * 5.960_464_5e-8).to_bits());
        }
        f32::from_bits(sign | (exponent + 112) << 23 | mantissa << 13)
    }

    #[test]
    fn test05_the_kernels_half_decoding_is_exact() {
        // Every finite half, normal and subnormal, both signs.
        for bits in 0u32..0x10000 {
            let h = half::f16::from_bits(bits as u16);
            if h.is_finite() {
                assert_eq!(kernel_half(bits).to_bits(), h.to_f32().to_bits(), "half bits {bits:#06x}");
            }
        }
    }

    #[test]
    fn test03_an_empty_scene_has_no_tree() {
        assert!(ShadowBvh::build(&RasterTriangles::default()).is_none());
    }

    #[test]
    fn test07_a_shafts_faces_are_its_hulls() {
        let d = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
        // A cube: 6 faces, each counted once though 4 of its corners span each.
        let cube: Vec<DVec3> = (0..8).map(|k| d((k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64)).collect();
        assert_eq!(Shaft::hull(&cube, 1e-9).planes().len(), 6);
        // A square light above a triangle: the two planes and 3 + 4 sides where the triangle
        // lies inside the square's outline (each side plane through a square edge and a
        // triangle corner, or a triangle edge and a square corner).
        let mut points = vec![d(-1.0, 2.0, -1.0), d(1.0, 2.0, -1.0), d(1.0, 2.0, 1.0), d(-1.0, 2.0, 1.0)];
        points.extend([d(-0.2, 0.0, -0.2), d(0.3, 0.0, -0.1), d(0.0, 0.0, 0.3)]);
        let shaft = Shaft::hull(&points, 1e-9);
        assert!(shaft.planes().len() >= 5, "{} faces", shaft.planes().len());
        // Every face has every point on its inner side or on it, and each of the points on
        // some face.
        for (n, d) in shaft.planes() {
            assert!((n.length() - 1.0).abs() < 1e-12);
            assert!(points.iter().all(|p| n.dot(*p) - d <= 1e-9), "plane {n} {d}");
        }
        for p in &points {
            assert!(shaft.planes().iter().any(|(n, d)| (n.dot(*p) - d).abs() <= 1e-9), "{p} on no face");
        }
        // The middle of the shaft is inside every face, a point beside it outside one.
        let inside = |q: DVec3| shaft.planes().iter().all(|(n, d)| n.dot(q) - d < 0.0);
        assert!(inside(d(0.0, 1.0, 0.0)));
        assert!(!inside(d(0.9, 0.2, 0.9)));
    }

    /// Random points of the triangle with corners `c`, and of the square light below.
    fn point_of(c: &[DVec3; 3], u: f64, v: f64) -> DVec3 {
        let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
        c[0] + u * (c[1] - c[0]) + v * (c[2] - c[0])
    }

    #[test]
    fn test08_a_clear_shaft_has_no_triangle_across_any_of_its_segments() {
        // The oracle: the segment test against every triangle, no hierarchy, at segments
        // between random points of the light and of the patch. A cloud of small triangles
        // in the unit cube, a square light above it and patches below: a patch the search
        // calls clear must have no blocked segment, and both answers must occur often (a
        // search that called every shaft blocked would pass the first part).
        let triangles = cloud(400, 5);
        let bvh = ShadowBvh::build(&raster(&triangles)).expect("a tree");
        let tree = bvh.shafts();
        let brute: Vec<[DVec3; 3]> = triangles.iter().map(|t| t.map(|v| v.as_dvec3())).collect();
        let light = [
            DVec3::new(0.3, 1.6, 0.3),
            DVec3::new(0.7, 1.6, 0.3),
            DVec3::new(0.7, 1.6, 0.7),
            DVec3::new(0.3, 1.6, 0.7),
        ];
        let mut rng = crate::rng::StepRng::new(17, 0);
        let (mut clear, mut blocked_found) = (0, 0);
        for _ in 0..300 {
            // Around the cloud, far enough out that some shafts pass beside it.
            let (x, z) = (rng.uniform() * 9.0 - 4.0, rng.uniform() * 9.0 - 4.0);
            let y = -0.3 + 0.2 * rng.uniform();
            let size = 0.02 + 0.1 * rng.uniform();
            let patch = [DVec3::new(x, y, z), DVec3::new(x + size, y, z), DVec3::new(x, y, z + size)];
            let mut points = light.to_vec();
            points.extend(patch);
            if !tree.is_clear(&Shaft::hull(&points, 1e-6)) {
                continue;
            }
            clear += 1;
            for _ in 0..200 {
                let on_light = point_of(&[light[0], light[1], light[2]], rng.uniform(), rng.uniform());
                let on_light = if rng.uniform() < 0.5 { on_light } else { light[0] + light[2] - on_light };
                let on_patch = point_of(&patch, rng.uniform(), rng.uniform());
                let dir = on_patch - on_light;
                let hit = brute.iter().any(|t| {
                    let gpu = GpuBvhTriangle {
                        v0: t[0].as_vec3().to_array(),
                        e1: (t[1] - t[0]).as_vec3().to_array(),
                        e2: (t[2] - t[0]).as_vec3().to_array(),
                        ..bytemuck::Zeroable::zeroed()
                    };
                    segment_hits(&gpu, on_light.as_vec3(), dir.as_vec3())
                });
                assert!(!hit, "a clear shaft's segment {on_light} -> {on_patch} is blocked");
            }
        }
        // Patches under the cloud: the search finds some blocked (every one, for those
        // whose centre's segment to the light's centre is blocked).
        for _ in 0..300 {
            let (x, z) = (rng.uniform(), rng.uniform());
            let patch = [DVec3::new(x, -0.2, z), DVec3::new(x + 0.05, -0.2, z), DVec3::new(x, -0.2, z + 0.05)];
            let centre = patch.iter().sum::<DVec3>() / 3.0;
            let blocked = bvh.occluded(DVec3::new(0.5, 1.6, 0.5).as_vec3(), Vec3::NEG_Y, centre.as_vec3(), Vec3::Y);
            let mut points = light.to_vec();
            points.extend(patch);
            let found = !tree.is_clear(&Shaft::hull(&points, 1e-6));
            assert!(found || !blocked, "the shaft to {centre} is called clear, its centre's ray is blocked");
            blocked_found += usize::from(found);
        }
        assert!(clear > 60 && blocked_found > 100, "clear {clear}, blocked {blocked_found}");
    }

    #[test]
    fn test09_neighbours_in_a_patchs_plane_and_walls_it_touches_leave_its_shaft_clear() {
        // A floor of two triangles, a wall standing on its edge and a light above: a floor
        // patch at the wall's foot sees the whole light (the wall touches its shaft along the
        // edge only, the floor's triangles lie in its plane); a box between the light and
        // the patch blocks it.
        let d = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let floor = [
            [d(-2.0, 0.0, -2.0), d(-2.0, 0.0, 2.0), d(2.0, 0.0, 2.0)],
            [d(-2.0, 0.0, -2.0), d(2.0, 0.0, 2.0), d(2.0, 0.0, -2.0)],
        ];
        let wall = [
            [d(-2.0, 0.0, -2.0), d(2.0, 0.0, -2.0), d(2.0, 3.0, -2.0)],
            [d(-2.0, 0.0, -2.0), d(2.0, 3.0, -2.0), d(-2.0, 3.0, -2.0)],
        ];
        let light = [
            DVec3::new(-0.5, 2.9, -0.5),
            DVec3::new(0.5, 2.9, -0.5),
            DVec3::new(0.5, 2.9, 0.5),
            DVec3::new(-0.5, 2.9, 0.5),
        ];
        let patch = [DVec3::new(0.0, 0.0, -2.0), DVec3::new(0.0, 0.0, -1.7), DVec3::new(0.3, 0.0, -2.0)];
        let shaft = |triangles: &[[Vec3; 3]]| {
            let bvh = ShadowBvh::build(&raster(triangles)).expect("a tree");
            let mut points = light.to_vec();
            points.extend(patch);
            bvh.shafts().is_clear(&Shaft::hull(&points, 1e-6))
        };
        let room: Vec<[Vec3; 3]> = floor.iter().chain(&wall).copied().collect();
        assert!(shaft(&room), "the floor and the wall block nothing");
        let mut with_box = room.clone();
        with_box.push([d(-0.2, 0.5, -2.0), d(0.6, 0.5, -2.0), d(0.1, 0.5, -1.2)]);
        assert!(!shaft(&with_box), "a triangle between the patch and the light blocks it");
    }

    #[test]
    fn test10_each_triangle_names_the_patches_a_ray_meets() {
        // The kernel's `hit_patch` reads a hit's patch off its triangle: the front's first
        // patch, corner v0's lattice word, v1's and v2's lattice corners, and whether a twin
        // (the back, first patch + 1) follows. A lattice of side 3 with twins, drawn as
        // raster_triangles draws it (the front, then the back with the winding reversed), and
        // a one-sided triangle of one patch.
        use crate::layout::{LATTICE_TWINS, RasterVertex};
        let mut r = RasterTriangles::default();
        let mut push = |t: [Vec3; 3], corners: [u32; 3], patch: u32, word: u32| {
            for (v, corner) in t.into_iter().zip(corners) {
                r.vertices.push(RasterVertex { position: v.to_array(), patch });
                r.lattice.push(word | corner << LATTICE_CORNER_SHIFT);
            }
        };
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        push([a, b, c], [0, 1, 2], 10, 3 | LATTICE_TWINS);
        push([a, c, b], [0, 2, 1], 11, 3 | LATTICE_TWINS);
        let far = Vec3::Z * 2.0;
        push([a + far, b + far, c + far], [0, 1, 2], 28 | VERTEX_TWIN_BIT, 1);
        let bvh = ShadowBvh::build(&r).expect("a tree");
        assert_eq!(bvh.triangles.len(), 2, "the back is no triangle of its own");
        for t in &bvh.triangles {
            if t.v0[2] == 0.0 {
                assert_eq!((t.first_patch, t.lattice), (10, 3 | LATTICE_TWINS));
                assert_eq!(t.corners, 1 | 2 << 2 | BVH_TRIANGLE_BACK);
            } else {
                assert_eq!((t.first_patch, t.lattice, t.corners), (28, 1, 1 | 2 << 2));
            }
        }
    }
}
