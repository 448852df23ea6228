//! Contact cuts: surface triangles are cut along the lines where other surfaces meet them,
//! before they are tessellated into patches.
//!
//! Why: a patch carries one incoming radiance J, the mean over its area. A floor patch that
//! reaches under a box standing on the floor has part of its area enclosed, where it sees
//! only the box's black back faces; its J, and the light it reflects onward, are then too
//! low by the enclosed share, however many steps are taken. Cut along the box's footprint,
//! the enclosed parts become patches of their own (dark, and never seen), and the patches
//! outside carry the radiance of the floor that is really there. The bias this removes is a
//! property of the patches, not of the noise: in a closed furnace room with a box on the
//! floor it was 1.5 % of the exact radiance.
//!
//! A cut is the full line, in the triangle's plane, through the segment where another
//! triangle touches or crosses it (an edge lying in the plane, or the crossing segment of a
//! triangle that passes through it). Cutting a convex polygon by a line leaves convex
//! polygons, which are fanned into triangles with the source's winding; the tessellator
//! then splits those as it splits any triangle. Coplanar triangles, contacts at a point and
//! lines along the triangle's own edges cut nothing, so meshes whose triangles only share
//! edges are left whole.

use super::{Light, Scene};
use glam::{DVec2, DVec3};
use rustc_hash::FxHashMap as HashMap;

/// Distances below this share of the scene's size count as contact (and as zero length).
const CONTACT_TOLERANCE: f64 = 1e-7;

/// Parallel surfaces closer than this share of the scene's size count as lying on each
/// other: an area light hung a hair below the ceiling encloses the ceiling above it just as
/// a box on the floor does.
const PARALLEL_GAP: f64 = 1e-3;

/// ... and closer than this share of the smaller triangle's longest edge: a hair against
/// the triangles themselves too, not only against the scene. Parallel triangles about their
/// own size apart enclose nothing: the faces of a Sierpinski fractal's neighbouring
/// tetrahedra lie 0.82 of an edge apart at every level, and at level 8 in the Sierpinski
/// room (edges 0.008, 0.006 apart, under a thousandth of the room's size) they were cut, each
/// of the fractal's 262 144 triangles into 7.5 patches on average (1.97 million), whose
/// glossy patches then asked the bundles for 12 times the lines. A quarter keeps nearly all
/// of the parallel contacts of the model in scenes/engine_room.toml: of the 16 188 pairs it
/// cut that lie more than a twentieth of an edge apart (median 0.09: slots and layers of the
/// engine's parts), 392 now stay whole.
const PARALLEL_GAP_OF_EDGE: f64 = 0.25;

/// Normals whose dot product reaches this count as parallel (within 0.08 degrees).
pub(super) const PARALLEL_COS: f64 = 1.0 - 1e-6;

/// The most cut lines one triangle takes; beyond it the remaining contacts are left uncut
/// (a bias of the kind described above, no error): keeps a triangle under a dense mesh from
/// splitting into an unbounded number of pieces.
pub const MAX_CUTS_PER_TRIANGLE: usize = 64;

/// Source triangles that other surfaces cut, by (surface, triangle) index: the triangles
/// that replace each one (counter-clockwise about the same normal, areas adding up to the
/// source's), grouped by the convex polygon of the cuts they were fanned from. Triangles not
/// in the map are not cut. No cut line runs through a polygon (every cut crosses the whole
/// triangle), so the image's gather treats a polygon's patches as one surface
/// (`scene::Piece`); only past `MAX_CUTS_PER_TRIANGLE` may a contact left uncut lie inside
/// one, as it then lies inside its patches too.
pub type Pieces = HashMap<(usize, usize), Vec<Vec<[DVec3; 3]>>>;

/// One triangle with its bounding box: a surface's (surface, triangle), or an area light's
/// (`None`: it cuts, but is not cut).
struct Entry {
    id: Option<(usize, usize)>,
    vertices: [DVec3; 3],
    /// Edge i (vertex i to i + 1) is inside its shape: shared with a triangle of the same
    /// shape in the same plane (a quad's diagonal), so lying on t it is no boundary of
    /// anything and cuts nothing.
    inner_edge: [bool; 3],
    lo: DVec3,
    hi: DVec3,
    /// The unit normal and the longest edge: what `could_meet` asks of a parallel pair.
    normal: DVec3,
    longest: f64,
}

/// What the contacts do to the surface triangles.
#[derive(Debug, Default)]
pub struct Contacts {
    /// The triangles that contact lines cut.
    pub pieces: Pieces,
    /// For each surface triangle along one of whose edges a contact runs (a wall standing on
    /// that edge, a light or another shape's triangle lying against it), which edges: edge i
    /// from vertex i to vertex i + 1. Such an edge cuts nothing, but two triangles that share
    /// it are not one surface for the gather (`tessellate`'s pieces), as a polygon of the
    /// cuts is.
    pub touched_edges: HashMap<(usize, usize), [bool; 3]>,
}

/// Every surface triangle that another surface touches or crosses, cut along those lines,
/// and the triangles' edges that contacts run along.
pub fn contacts(scene: &Scene) -> Contacts {
    let mut entries: Vec<Entry> = Vec::new();
    for (s, surface) in scene.surfaces.iter().enumerate() {
        let triangles: Vec<[DVec3; 3]> = surface.triangles.iter().map(|t| t.vertices).collect();
        add_entries(&mut entries, &triangles, |t| Some((s, t)));
    }
    // Area lights are geometry too: they cut the surfaces they lie on (and are not cut,
    // their grid is the first shot's).
    for light in &scene.lights {
        if let Light::Area { vertices, .. } = *light {
            add_entries(&mut entries, &super::shapes::quad(vertices), |_| None);
        }
    }
    if entries.len() < 2 {
        return Contacts::default();
    }
    let lo = entries.iter().fold(DVec3::splat(f64::INFINITY), |a, e| a.min(e.lo));
    let hi = entries.iter().fold(DVec3::splat(f64::NEG_INFINITY), |a, e| a.max(e.hi));
    let size = (hi - lo).length().max(f64::MIN_POSITIVE);
    let tolerance = CONTACT_TOLERANCE * size;
    let gap = PARALLEL_GAP * size;

    // The pairs in a fixed order: the grid's hash order varies from run to run, and the
    // order of the cuts decides how each piece is fanned into triangles.
    let mut pairs = close_pairs(&entries, gap, |a, b| could_meet(a, b, tolerance, gap));
    pairs.sort_unstable();
    // Each triangle's close neighbours in that order, then its lines from them, triangle by
    // triangle on all cores (the same lines in the same order as one pass over the pairs).
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); entries.len()];
    for (i, j) in pairs {
        neighbours[i].push(j);
        neighbours[j].push(i);
    }
    use rayon::prelude::*;
    let (lines, touched): (Vec<Vec<Line>>, Vec<[bool; 3]>) = entries
        .par_iter()
        .zip(&neighbours)
        .map(|(e, close)| {
            let (mut lines, mut touched) = (Vec::new(), [false; 3]);
            if e.id.is_some() {
                for &b in close {
                    cut_lines(&e.vertices, &entries[b], tolerance, gap, &mut lines, &mut touched);
                }
            }
            (lines, touched)
        })
        .unzip();

    let mut out = Contacts::default();
    for ((e, cuts), touched) in entries.iter().zip(&lines).zip(touched) {
        let Some(id) = e.id else {
            continue;
        };
        if touched.contains(&true) {
            out.touched_edges.insert(id, touched);
        }
        if cuts.is_empty() {
            continue;
        }
        let split = split_triangle(&e.vertices, cuts, tolerance);
        if split.iter().map(Vec::len).sum::<usize>() > 1 {
            out.pieces.insert(id, split);
        }
    }
    out
}

/// Which edges of triangle `t` (edge i from vertex i to vertex i + 1, `corners` in t's
/// frame) the contact segment a-b runs along for more than the tolerance.
fn touched_edges(corners: &[DVec2; 3], a: DVec2, b: DVec2, tolerance: f64) -> [bool; 3] {
    std::array::from_fn(|i| {
        let (p, q) = (corners[i], corners[(i + 1) % 3]);
        let length = p.distance(q);
        let along = (q - p) / length;
        let off = |x: DVec2| along.perp_dot(x - p).abs();
        if off(a) > tolerance || off(b) > tolerance {
            return false;
        }
        // The overlap of a-b with the edge, measured along it.
        let (sa, sb) = ((a - p).dot(along), (b - p).dot(along));
        sa.max(sb).min(length) - sa.min(sb).max(0.0) > tolerance
    })
}

/// Whether `cut_lines` can find anything between a and b, from their boxes alone: they touch
/// or cross only where their boxes overlap within the tolerance, and one lies on the other
/// only where they are parallel and their boxes overlap within the gap (and within
/// `PARALLEL_GAP_OF_EDGE` of the smaller one's longest edge). In a dense mesh most pairs
/// within the gap are neither: the engine room's 110 340 triangles made 5.0 million pairs.
fn could_meet(a: &Entry, b: &Entry, tolerance: f64, gap: f64) -> bool {
    boxes_within(a, b, tolerance)
        || (a.normal.dot(b.normal).abs() >= PARALLEL_COS
            && boxes_within(a, b, gap.min(PARALLEL_GAP_OF_EDGE * a.longest.min(b.longest))))
}

/// Whether the boxes of a and b overlap when each grows by `d`.
fn boxes_within(a: &Entry, b: &Entry, d: f64) -> bool {
    (a.lo - d).cmple(b.hi).all() && (b.lo - d).cmple(a.hi).all()
}

/// Every pair i < j of entries whose boxes overlap (within the tolerance) and that `keep`
/// keeps, once each, in no particular order. A uniform grid with cells about twice the
/// median triangle's size keeps this near linear in the number of triangles; triangles that
/// span many cells (walls, floors) are instead tested against every other triangle, which
/// costs little as there are few. The cells and the large triangles are searched on all
/// cores.
fn close_pairs(entries: &[Entry], tolerance: f64, keep: impl Fn(&Entry, &Entry) -> bool + Sync) -> Vec<(usize, usize)> {
    use rayon::prelude::*;
    let overlap = |a: &Entry, b: &Entry| boxes_within(a, b, tolerance);
    let mut sizes: Vec<f64> = entries.iter().map(|e| (e.hi - e.lo).max_element()).collect();
    let middle = sizes.len() / 2;
    let median = *sizes.select_nth_unstable_by(middle, f64::total_cmp).1;
    let lo = entries.iter().fold(DVec3::splat(f64::INFINITY), |a, e| a.min(e.lo)) - tolerance;
    let cell = (2.0 * median).max(4.0 * tolerance);
    let index = |p: DVec3| ((p - lo) / cell).floor().as_i64vec3();
    // Cells a triangle may cover before it counts as large.
    const LARGE: i64 = 64;
    let mut grid: HashMap<glam::I64Vec3, Vec<usize>> = HashMap::default();
    let mut large = Vec::new();
    for (i, e) in entries.iter().enumerate() {
        let (a, b) = (index(e.lo - tolerance), index(e.hi + tolerance));
        let span = b - a + 1;
        if span.x.saturating_mul(span.y).saturating_mul(span.z) > LARGE {
            large.push(i);
            continue;
        }
        for x in a.x..=b.x {
            for y in a.y..=b.y {
                for z in a.z..=b.z {
                    grid.entry(glam::I64Vec3::new(x, y, z)).or_default().push(i);
                }
            }
        }
    }
    // A pair of small triangles meets in several cells; it is taken only in the cell that
    // holds the low corner of the two boxes' overlap.
    let cells: Vec<(&glam::I64Vec3, &Vec<usize>)> = grid.iter().collect();
    let mut pairs: Vec<(usize, usize)> = cells
        .par_iter()
        .flat_map_iter(|&(key, members)| {
            let mut found = Vec::new();
            for (n, &i) in members.iter().enumerate() {
                for &j in &members[n + 1..] {
                    let (a, b) = (&entries[i], &entries[j]);
                    if overlap(a, b) && index(a.lo.max(b.lo)) == *key && keep(a, b) {
                        found.push((i.min(j), i.max(j)));
                    }
                }
            }
            found
        })
        .collect();
    let mut is_large = vec![false; entries.len()];
    for &i in &large {
        is_large[i] = true;
    }
    let keep = &keep;
    // Large with large once (the lower index takes it), large with every small.
    pairs.par_extend(large.par_iter().flat_map_iter(|&i| {
        let is_large = &is_large;
        (0..entries.len())
            .filter(move |&j| j != i && !(is_large[j] && j < i))
            .filter(move |&j| overlap(&entries[i], &entries[j]) && keep(&entries[i], &entries[j]))
            .map(move |j| (i.min(j), i.max(j)))
    }));
    pairs
}

/// Appends one shape's triangles, marking the edges that two of its triangles in the same
/// plane share.
fn add_entries(entries: &mut Vec<Entry>, triangles: &[[DVec3; 3]], id: impl Fn(usize) -> Option<(usize, usize)>) {
    let key = |a: DVec3, b: DVec3| {
        let (a, b) = (a.to_array().map(f64::to_bits), b.to_array().map(f64::to_bits));
        if a <= b { (a, b) } else { (b, a) }
    };
    let normal = |t: &[DVec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]).normalize();
    let mut by_edge: HashMap<_, Vec<usize>> = HashMap::default();
    for (i, t) in triangles.iter().enumerate() {
        for e in 0..3 {
            by_edge.entry(key(t[e], t[(e + 1) % 3])).or_default().push(i);
        }
    }
    for (i, t) in triangles.iter().enumerate() {
        let inner_edge = std::array::from_fn(|e| {
            by_edge[&key(t[e], t[(e + 1) % 3])]
                .iter()
                .any(|&j| j != i && normal(t).dot(normal(&triangles[j])) >= PARALLEL_COS)
        });
        let v = *t;
        entries.push(Entry {
            id: id(i),
            vertices: v,
            inner_edge,
            lo: v[0].min(v[1]).min(v[2]),
            hi: v[0].max(v[1]).max(v[2]),
            normal: normal(t),
            longest: longest_edge(t),
        });
    }
}

/// A line in the plane of the triangle it cuts, in that triangle's 2-D frame.
#[derive(Debug, Clone, Copy)]
struct Line {
    point: DVec2,
    /// Unit direction.
    direction: DVec2,
}

/// The triangle's plane frame: origin v0, axes u = unit(v1 - v0) and w = n x u, so that 2-D
/// counter-clockwise is counter-clockwise about the front normal n.
struct Frame {
    origin: DVec3,
    u: DVec3,
    w: DVec3,
    normal: DVec3,
}

impl Frame {
    fn of(t: &[DVec3; 3]) -> Frame {
        let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        let u = (t[1] - t[0]).normalize();
        Frame { origin: t[0], u, w: normal.cross(u), normal }
    }
    fn to_2d(&self, p: DVec3) -> DVec2 {
        let r = p - self.origin;
        DVec2::new(r.dot(self.u), r.dot(self.w))
    }
    fn to_3d(&self, p: DVec2) -> DVec3 {
        self.origin + self.u * p.x + self.w * p.y
    }
}

/// Appends the lines along which `other` meets triangle `t`: where it touches or crosses
/// t's plane inside t, or, when it lies on t (parallel and closer than `gap`), its own edges
/// where they pass over t. The contact segments that run along t's own edges mark them in
/// `touched` (`Contacts::touched_edges`).
fn cut_lines(
    t: &[DVec3; 3],
    other_entry: &Entry,
    tolerance: f64,
    gap: f64,
    out: &mut Vec<Line>,
    touched: &mut [bool; 3],
) {
    let other = &other_entry.vertices;
    let frame = Frame::of(t);
    let own = t.map(|p| frame.to_2d(p));
    let mut touch = |a: DVec2, b: DVec2| {
        for (mark, hit) in touched.iter_mut().zip(touched_edges(&own, a, b, tolerance)) {
            *mark |= hit;
        }
    };
    let height = other.map(|p| (p - frame.origin).dot(frame.normal));
    let edge = longest_edge(t).min(other_entry.longest);
    let lying = height.iter().all(|h| h.abs() <= gap && h.abs() <= PARALLEL_GAP_OF_EDGE * edge);
    if frame.normal.dot(other_entry.normal).abs() >= PARALLEL_COS && lying {
        // Lying on t. Neighbours in one plane meet t only along its edges, which cut nothing.
        let corners = other.map(|p| frame.to_2d(p));
        for i in (0..3).filter(|&i| !other_entry.inner_edge[i]) {
            touch(corners[i], corners[(i + 1) % 3]);
            out.extend(clipped_line(t, &frame, corners[i], corners[(i + 1) % 3], tolerance));
        }
        return;
    }
    if let Some((a, b)) = contact_segment(t, other, tolerance) {
        touch(a, b);
        out.extend(clipped_line(t, &frame, a, b, tolerance));
    }
}

fn longest_edge(t: &[DVec3; 3]) -> f64 {
    t[0].distance(t[1]).max(t[1].distance(t[2])).max(t[2].distance(t[0]))
}

/// The line along which `other` touches or crosses triangle `t`, if that contact is a
/// segment of positive length that reaches into `t`.
#[cfg(test)]
fn cut_line(t: &[DVec3; 3], other: &[DVec3; 3], tolerance: f64) -> Option<Line> {
    let (a, b) = contact_segment(t, other, tolerance)?;
    clipped_line(t, &Frame::of(t), a, b, tolerance)
}

/// The segment (2-D, in t's frame) along which `other` touches or crosses t's plane, if it
/// has a positive length; `None` for a triangle in t's plane (`cut_lines` handles it).
fn contact_segment(t: &[DVec3; 3], other: &[DVec3; 3], tolerance: f64) -> Option<(DVec2, DVec2)> {
    let frame = Frame::of(t);
    let height = other.map(|p| (p - frame.origin).dot(frame.normal));
    if height.iter().all(|h| h.abs() <= tolerance) {
        return None; // coplanar: `cut_lines` handles it
    }
    // The points of `other` in the plane: its vertices on it, and where its edges cross it.
    let mut points: Vec<DVec3> = Vec::with_capacity(3);
    for i in 0..3 {
        let (a, b) = (i, (i + 1) % 3);
        if height[a].abs() <= tolerance {
            points.push(other[a]);
        } else if height[b].abs() > tolerance && (height[a] < 0.0) != (height[b] < 0.0) {
            let s = height[a] / (height[a] - height[b]);
            points.push(other[a] + (other[b] - other[a]) * s);
        }
    }
    let points: Vec<DVec2> = points.into_iter().map(|p| frame.to_2d(p)).collect();
    // The two points farthest apart span the contact segment.
    let mut segment = None;
    let mut longest = tolerance;
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            let d = points[i].distance(points[j]);
            if d > longest {
                longest = d;
                segment = Some((points[i], points[j]));
            }
        }
    }
    segment
}

/// The line through segment a-b (2-D, in t's frame) if the segment reaches into triangle t
/// by more than the tolerance (Cyrus-Beck clipping).
fn clipped_line(t: &[DVec3; 3], frame: &Frame, a: DVec2, b: DVec2, tolerance: f64) -> Option<Line> {
    let corners = t.map(|p| frame.to_2d(p));
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let d = b - a;
    if d.length() <= tolerance {
        return None;
    }
    for i in 0..3 {
        let (p, q) = (corners[i], corners[(i + 1) % 3]);
        let edge = q - p;
        // Inward normal of a counter-clockwise edge.
        let inward = DVec2::new(-edge.y, edge.x).normalize();
        let start = (a - p).dot(inward);
        let rate = d.dot(inward);
        if rate.abs() < f64::EPSILON * d.length() {
            if start < -tolerance {
                return None;
            }
        } else {
            let s = -start / rate;
            if rate > 0.0 {
                t0 = t0.max(s);
            } else {
                t1 = t1.min(s);
            }
        }
    }
    if (t1 - t0) * d.length() <= tolerance {
        return None;
    }
    Some(Line { point: a, direction: d / d.length() })
}

/// Triangle `t` cut by every line (those along its own edges cut nothing), as the convex
/// polygons the lines leave, each as the triangles fanned from it; the triangle itself when
/// nothing cuts it.
fn split_triangle(t: &[DVec3; 3], cuts: &[Line], tolerance: f64) -> Vec<Vec<[DVec3; 3]>> {
    let frame = Frame::of(t);
    let mut polygons: Vec<Vec<DVec2>> = vec![t.iter().map(|&p| frame.to_2d(p)).collect()];
    for line in cuts.iter().take(MAX_CUTS_PER_TRIANGLE) {
        let mut next = Vec::with_capacity(polygons.len() + 1);
        for polygon in polygons {
            let side: Vec<f64> = polygon.iter().map(|&p| line.direction.perp_dot(p - line.point)).collect();
            let above = side.iter().any(|&s| s > tolerance);
            let below = side.iter().any(|&s| s < -tolerance);
            if !(above && below) {
                next.push(polygon);
                continue;
            }
            let (mut left, mut right) = (Vec::new(), Vec::new());
            for i in 0..polygon.len() {
                let j = (i + 1) % polygon.len();
                let (p, q, sp, sq) = (polygon[i], polygon[j], side[i], side[j]);
                if sp >= -tolerance {
                    left.push(p);
                }
                if sp <= tolerance {
                    right.push(p);
                }
                if (sp > tolerance && sq < -tolerance) || (sp < -tolerance && sq > tolerance) {
                    let x = p + (q - p) * (sp / (sp - sq));
                    left.push(x);
                    right.push(x);
                }
            }
            next.push(left);
            next.push(right);
        }
        polygons = next;
    }
    if polygons.len() == 1 {
        return vec![vec![*t]];
    }
    let mut fans = Vec::new();
    for polygon in polygons {
        let polygon = without_collinear(polygon, tolerance);
        let mut fan = Vec::new();
        for i in 1..polygon.len().saturating_sub(1) {
            let corners = [polygon[0], polygon[i], polygon[i + 1]];
            if (corners[1] - corners[0]).perp_dot(corners[2] - corners[0]) > tolerance * tolerance {
                fan.push(corners.map(|p| frame.to_3d(p)));
            }
        }
        if !fan.is_empty() {
            fans.push(fan);
        }
    }
    fans
}

/// The polygon without vertices that lie on the line through their neighbours (a cut
/// ending at a vertex leaves one), which would otherwise fan into zero-area triangles.
fn without_collinear(mut polygon: Vec<DVec2>, tolerance: f64) -> Vec<DVec2> {
    let mut i = 0;
    while polygon.len() > 3 && i < polygon.len() {
        let n = polygon.len();
        let (p, q, r) = (polygon[(i + n - 1) % n], polygon[i], polygon[(i + 1) % n]);
        let chord = r - p;
        let off = if chord.length() > 0.0 { chord.perp_dot(q - p).abs() / chord.length() } else { 0.0 };
        if off <= tolerance {
            polygon.remove(i);
        } else {
            i += 1;
        }
    }
    polygon
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(t: &[DVec3; 3]) -> f64 {
        (t[1] - t[0]).cross(t[2] - t[0]).length() / 2.0
    }

    fn normal(t: &[DVec3; 3]) -> DVec3 {
        (t[1] - t[0]).cross(t[2] - t[0]).normalize()
    }

    /// The floor triangle of a unit square, facing +y.
    const FLOOR: [DVec3; 3] = [DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.0, 0.0, 4.0), DVec3::new(4.0, 0.0, 0.0)];

    #[test]
    fn a_wall_standing_on_a_triangle_cuts_it_along_its_foot() {
        // A vertical triangle whose bottom edge lies on the floor along x = 1, z in [0.5, 2].
        let wall = [DVec3::new(1.0, 0.0, 0.5), DVec3::new(1.0, 0.0, 2.0), DVec3::new(1.0, 1.0, 1.0)];
        let line = cut_line(&FLOOR, &wall, 1e-9).expect("the wall's foot cuts the floor");
        let frame = Frame::of(&FLOOR);
        // The line runs along x = 1 in scene space.
        for s in [-3.0, 0.0, 5.0] {
            let p = frame.to_3d(line.point + line.direction * s);
            assert!((p.x - 1.0).abs() < 1e-12 && p.y.abs() < 1e-12, "{p}");
        }
        let pieces = split_triangle(&FLOOR, &[line], 1e-9).concat();
        assert!(pieces.len() >= 2);
        let total: f64 = pieces.iter().map(area).sum();
        assert!((total - area(&FLOOR)).abs() < 1e-12, "{total}");
        for p in &pieces {
            assert!((normal(p) - normal(&FLOOR)).length() < 1e-12, "winding kept");
            // No piece straddles the line.
            let left = p.iter().any(|v| v.x < 1.0 - 1e-9);
            let right = p.iter().any(|v| v.x > 1.0 + 1e-9);
            assert!(!(left && right), "{p:?}");
        }
    }

    #[test]
    fn a_triangle_crossing_the_plane_cuts_along_the_crossing() {
        let blade = [DVec3::new(0.5, -1.0, 1.0), DVec3::new(2.5, 1.0, 1.0), DVec3::new(0.5, 1.0, 1.0)];
        let line = cut_line(&FLOOR, &blade, 1e-9).expect("crossing");
        let frame = Frame::of(&FLOOR);
        let p = frame.to_3d(line.point);
        assert!((p.z - 1.0).abs() < 1e-12, "the crossing runs along z = 1: {p}");
        assert!((frame.to_3d(line.point + line.direction).z - 1.0).abs() < 1e-12);
    }

    #[test]
    fn contacts_that_cut_nothing() {
        // Coplanar neighbour.
        let beside = [DVec3::new(4.0, 0.0, 0.0), DVec3::new(0.0, 0.0, 4.0), DVec3::new(4.0, 0.0, 4.0)];
        assert!(cut_line(&FLOOR, &beside, 1e-9).is_none());
        // Touching at one point only.
        let tip = [DVec3::new(1.0, 0.0, 1.0), DVec3::new(2.0, 1.0, 1.0), DVec3::new(1.0, 1.0, 2.0)];
        assert!(cut_line(&FLOOR, &tip, 1e-9).is_none());
        // Standing on the floor's plane, but outside the triangle.
        let away = [DVec3::new(5.0, 0.0, 5.0), DVec3::new(6.0, 0.0, 5.0), DVec3::new(5.0, 1.0, 5.0)];
        assert!(cut_line(&FLOOR, &away, 1e-9).is_none());
        // Above the floor, not touching.
        let above = [DVec3::new(1.0, 0.1, 0.5), DVec3::new(1.0, 0.1, 2.0), DVec3::new(1.0, 1.0, 1.0)];
        assert!(cut_line(&FLOOR, &above, 1e-9).is_none());
        // A wall along the floor's own edge (x = 0) yields a line, but it splits nothing.
        let edge_wall = [DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.0, 1.0, 0.0), DVec3::new(0.0, 0.0, 4.0)];
        let line = cut_line(&FLOOR, &edge_wall, 1e-9).expect("contact along the edge");
        assert_eq!(split_triangle(&FLOOR, &[line], 1e-9), vec![vec![FLOOR]]);
    }

    #[test]
    fn a_box_on_a_floor_leaves_its_footprint_as_pieces_of_their_own() {
        use crate::scene::shapes::box_triangles;
        let floor = [
            [DVec3::new(-2.0, 0.0, -2.0), DVec3::new(-2.0, 0.0, 2.0), DVec3::new(2.0, 0.0, 2.0)],
            [DVec3::new(-2.0, 0.0, -2.0), DVec3::new(2.0, 0.0, 2.0), DVec3::new(2.0, 0.0, -2.0)],
        ];
        let (x0, x1, z0, z1) = (-0.1, 0.5, -0.45, 0.25);
        let cube = box_triangles(DVec3::new(x0, 0.0, z0), DVec3::new(x1, 1.0, z1));
        let scene = crate::scene::tessellate::tests::scene_of(
            vec![
                crate::scene::tessellate::tests::surface(&floor, false),
                crate::scene::tessellate::tests::surface(&cube, false),
            ],
            vec![],
        );
        let pieces = contacts(&scene).pieces;
        assert!(pieces.keys().all(|&(s, _)| s == 0), "only the floor is cut: {:?}", pieces.keys());
        let mut inside = 0.0;
        for (t, tri) in floor.iter().enumerate() {
            let split = pieces.get(&(0, t)).expect("both floor triangles reach under the box").concat();
            let total: f64 = split.iter().map(area).sum();
            assert!((total - area(tri)).abs() < 1e-12);
            for p in &split {
                let c = (p[0] + p[1] + p[2]) / 3.0;
                let is_inside = c.x > x0 && c.x < x1 && c.z > z0 && c.z < z1;
                for v in p {
                    let v_inside = v.x > x0 + 1e-9 && v.x < x1 - 1e-9 && v.z > z0 + 1e-9 && v.z < z1 - 1e-9;
                    assert!(!v_inside || is_inside, "piece {p:?} straddles the footprint");
                    if is_inside {
                        assert!(v.x >= x0 - 1e-9 && v.x <= x1 + 1e-9 && v.z >= z0 - 1e-9 && v.z <= z1 + 1e-9);
                    }
                }
                if is_inside {
                    inside += area(p);
                }
            }
        }
        assert!((inside - 0.6 * 0.7).abs() < 1e-12, "the footprint's area: {inside}");
    }

    #[test]
    fn the_same_scene_is_cut_the_same_way_every_time() {
        // The contact search goes through hash maps, whose order varies between instances.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.toml");
        let (scene, _) = crate::scene::tessellate::tests::scene_from_file(&path);
        let first = contacts(&scene).pieces;
        assert!(!first.is_empty());
        for _ in 0..4 {
            assert_eq!(contacts(&scene).pieces, first);
        }
    }

    /// The Cornell box's blocks' footprints: the bottom edges of their side faces (y = 0), as
    /// 2-D convex polygons in x-z, from the scene itself (shapes 5-9 and 10-14 hold the top
    /// and the four sides of each block).
    fn cornell_footprints(scene: &Scene) -> [Vec<glam::DVec2>; 2] {
        let footprint = |shapes: std::ops::Range<usize>| -> Vec<glam::DVec2> {
            let mut corners: Vec<glam::DVec2> = Vec::new();
            for s in shapes {
                for t in &scene.surfaces[s].triangles {
                    for v in t.vertices {
                        let p = glam::DVec2::new(v.x, v.z);
                        if v.y == 0.0 && !corners.contains(&p) {
                            corners.push(p);
                        }
                    }
                }
            }
            assert_eq!(corners.len(), 4);
            let c = corners.iter().sum::<glam::DVec2>() / 4.0;
            corners.sort_by(|a, b| (a.y - c.y).atan2(a.x - c.x).total_cmp(&(b.y - c.y).atan2(b.x - c.x)));
            corners
        };
        [footprint(5..10), footprint(10..15)]
    }

    /// Whether p lies inside the convex polygon by more than `margin`.
    fn inside(poly: &[glam::DVec2], p: glam::DVec2, margin: f64) -> bool {
        (0..poly.len()).all(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            (b - a).perp_dot(p - a) / (b - a).length() > margin
        })
    }

    fn cornell_box() -> (Scene, crate::scene::Patches) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.toml");
        let (scene, patch_size) = crate::scene::tessellate::tests::scene_from_file(&path);
        let patches = crate::scene::tessellate(&scene, patch_size).unwrap();
        (scene, patches)
    }

    #[test]
    fn no_cornell_floor_patch_reaches_under_a_block() {
        let (scene, patches) = cornell_box();
        let mut under = 0;
        for block in cornell_footprints(&scene) {
            for patch in patches.patches.iter().filter(|p| p.kind == crate::scene::PatchKind::Surface { surface: 0 }) {
                let corners = patch.vertices.map(|v| glam::DVec2::new(v.x, v.z));
                let centre = corners.iter().sum::<glam::DVec2>() / 3.0;
                if inside(&block, centre, 0.0) {
                    under += 1;
                    // Wholly inside: every corner on the footprint or within it.
                    assert!(corners.iter().all(|&v| inside(&block, v, -1e-6)), "{patch:?}");
                } else {
                    assert!(corners.iter().all(|&v| !inside(&block, v, 1e-6)), "{patch:?}");
                }
            }
        }
        assert!(under > 0);
    }

    /// The gather takes a patch of x's piece on x's line for x's own (wgsl/image_estimate.wgsl,
    /// `own_received`): a piece must be one plane facing one way, and no contact may run
    /// through it, or a floor point beside a block would receive what the floor under the
    /// block receives (nothing).
    #[test]
    fn cornell_pieces_are_planar_and_end_at_the_blocks_feet() {
        let (scene, patches) = cornell_box();
        let footprints = cornell_footprints(&scene);
        let mut covered = vec![0u32; patches.patches.len()];
        let (mut floor_under, mut floor_outside) = (0, 0);
        for piece in &patches.pieces {
            assert!(piece.first < piece.end && piece.end as usize <= patches.patches.len(), "{piece:?}");
            assert_eq!(piece.sides, 1, "the Cornell box has no two-sided surface");
            let run = &patches.patches[piece.first as usize..piece.end as usize];
            let p0 = &run[0];
            for (i, p) in run.iter().enumerate() {
                covered[piece.first as usize + i] += 1;
                assert!(p.normal.dot(p0.normal) > 1.0 - 1e-12, "{piece:?}: {p:?} against {p0:?}");
                for v in p.vertices {
                    assert!((p0.normal.dot(v - p0.vertices[0])).abs() < 1e-9, "{piece:?}: {p:?} off {p0:?}'s plane");
                }
                assert_eq!(p.kind, p0.kind);
            }
            if p0.kind == (crate::scene::PatchKind::Surface { surface: 0 }) {
                let centre = |p: &crate::scene::Patch| {
                    let c = (p.vertices[0] + p.vertices[1] + p.vertices[2]) / 3.0;
                    glam::DVec2::new(c.x, c.z)
                };
                let under = |p: &crate::scene::Patch| footprints.iter().any(|f| inside(f, centre(p), 0.0));
                let n = run.iter().filter(|p| under(p)).count();
                assert!(n == 0 || n == run.len(), "{piece:?}: {n} of {} patches under a block", run.len());
                if n == 0 {
                    floor_outside += 1;
                } else {
                    floor_under += 1;
                }
            }
        }
        // Every surface patch in exactly one piece (the area light's patches in none).
        for (p, &n) in patches.patches.iter().zip(&covered) {
            let surface = matches!(p.kind, crate::scene::PatchKind::Surface { .. });
            assert_eq!(n, u32::from(surface), "{p:?}");
        }
        assert!(floor_under > 0 && floor_outside > 0);
        // A piece is a whole convex polygon of the cuts, not each triangle fanned from it.
        let cut = contacts(&scene).pieces;
        let fanned: usize =
            (0..scene.surfaces[0].triangles.len()).map(|t| cut.get(&(0, t)).map_or(1, |p| p.concat().len())).sum();
        assert!(
            floor_under + floor_outside < fanned,
            "{} floor pieces of {fanned} triangles",
            floor_under + floor_outside
        );
    }

    #[test]
    fn the_cornell_ceiling_is_cut_along_the_light_below_it() {
        // The light hangs 0.1 mm below the ceiling, parallel to it: the ceiling above it is
        // enclosed, and no ceiling patch may reach both over it and beyond it.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.toml");
        let (scene, patch_size) = crate::scene::tessellate::tests::scene_from_file(&path);
        let Light::Area { vertices, .. } = scene.lights[0] else { panic!("the Cornell light is an area light") };
        let (lo, hi) =
            (vertices.iter().fold(DVec3::MAX, |a, &v| a.min(v)), vertices.iter().fold(DVec3::MIN, |a, &v| a.max(v)));
        let patches = crate::scene::tessellate(&scene, patch_size).unwrap();
        let over = |v: DVec3, margin: f64| {
            v.x > lo.x + margin && v.x < hi.x - margin && v.z > lo.z + margin && v.z < hi.z - margin
        };
        let mut above = 0.0;
        for patch in patches.patches.iter().filter(|p| p.kind == crate::scene::PatchKind::Surface { surface: 1 }) {
            let centre = (patch.vertices[0] + patch.vertices[1] + patch.vertices[2]) / 3.0;
            if over(centre, 0.0) {
                above += patch.area;
                assert!(patch.vertices.iter().all(|&v| over(v, -1e-6)), "{patch:?}");
            } else {
                assert!(patch.vertices.iter().all(|&v| !over(v, 1e-6)), "{patch:?}");
            }
        }
        let light_area = (hi.x - lo.x) * (hi.z - lo.z);
        assert!((above - light_area).abs() < 1e-6 * light_area, "{above} against {light_area}");
    }

    #[test]
    fn small_parallel_triangles_their_own_size_apart_are_no_contact() {
        // A Sierpinski fractal of level 7 and size 1 in the 6 x 4 x 6 room: its triangles'
        // edges are 1 / 128, and neighbouring tetrahedra's parallel faces lie 0.82 of an
        // edge apart, under a thousandth of the scene's size but as far as the faces are
        // wide. Nothing is enclosed there, so no triangle may be cut: 4^8 patches.
        let text =
            std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sierpinski.toml"))
                .unwrap()
                .replace("level = 6", "level = 7")
                .replace("size = 2.0", "size = 1.0");
        let scene = crate::scene::load::load_str(&text, std::path::Path::new("level7.toml")).unwrap();
        assert!(contacts(&scene).pieces.keys().all(|&(surface, _)| scene.surfaces[surface].triangles.len() < 1000));
        let patches = crate::scene::tessellate(&scene, scene.settings.patch_size).unwrap();
        let fractal =
            scene.surfaces.iter().position(|s| s.triangles.len() == 1 << 16).expect("the fractal's 4^8 triangles");
        let pieces =
            patches.patches.iter().filter(|p| p.kind == crate::scene::PatchKind::Surface { surface: fractal as u32 });
        assert_eq!(pieces.count(), 1 << 16);
        // A hair is still a hair: a triangle of edge 1 a thousandth above the floor of a
        // scene of size 10 lies on it (the Cornell box's light below its ceiling, in small).
        let floor = [DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.0, 0.0, 10.0), DVec3::new(10.0, 0.0, 0.0)];
        let tile = [DVec3::new(1.0, 1e-3, 1.0), DVec3::new(1.0, 1e-3, 2.0), DVec3::new(2.0, 1e-3, 1.0)];
        let entry = |vertices: [DVec3; 3]| Entry {
            id: None,
            vertices,
            inner_edge: [false; 3],
            lo: vertices.iter().fold(DVec3::MAX, |a, &v| a.min(v)),
            hi: vertices.iter().fold(DVec3::MIN, |a, &v| a.max(v)),
            normal: normal(&vertices),
            longest: longest_edge(&vertices),
        };
        let mut lines = Vec::new();
        cut_lines(&floor, &entry(tile), 1e-9, 1e-2, &mut lines, &mut [false; 3]);
        assert_eq!(lines.len(), 3, "the tile's three edges cut the floor");
        // The same tile shrunk to edge 0.002 at the same height: half its size away, no
        // contact.
        let speck = tile.map(|v| DVec3::new(1.0 + (v.x - 1.0) * 2e-3, v.y, 1.0 + (v.z - 1.0) * 2e-3));
        lines.clear();
        cut_lines(&floor, &entry(speck), 1e-9, 1e-2, &mut lines, &mut [false; 3]);
        assert!(lines.is_empty(), "{lines:?}");
    }

    #[test]
    fn the_pair_search_misses_no_pair_that_cuts_or_touches() {
        // A soup of small triangles: random ones, pairs sharing an edge or a corner, walls
        // standing on others, parallel copies a little above (some within the gap and a
        // quarter of an edge, some not), and two large ones across it all. Every pair whose
        // `cut_lines` finds a line or a touched edge, either way, must be among
        // `close_pairs`' (which also leaves out the pairs `could_meet` rules out).
        use rand_core::RngCore;
        let mut rng = rand_pcg::Pcg32::new(7, 11);
        let mut uniform = move || f64::from(rng.next_u32()) / f64::from(u32::MAX);
        let mut point =
            |scale: f64, at: DVec3| at + DVec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5) * scale;
        let mut triangles: Vec<[DVec3; 3]> = Vec::new();
        for k in 0..120 {
            let c = point(4.0, DVec3::ZERO);
            let t = [point(0.4, c), point(0.4, c), point(0.4, c)];
            triangles.push(t);
            match k % 4 {
                0 => triangles.push([t[1], t[0], point(0.4, c)]),
                1 => triangles.push([t[2], point(0.4, c), point(0.4, c)]),
                2 => {
                    let n = normal(&t) * if k % 8 == 2 { 0.004 } else { 0.05 };
                    triangles.push(t.map(|v| v + n));
                }
                _ => triangles.push([(t[0] + t[1]) / 2.0, t[2], t[2] + normal(&t) * 0.3]),
            }
        }
        triangles.push([DVec3::new(-3.0, 0.0, -3.0), DVec3::new(-3.0, 0.0, 3.0), DVec3::new(3.0, 0.0, 3.0)]);
        triangles.push([DVec3::new(-3.0, -3.0, 0.1), DVec3::new(3.0, -3.0, 0.1), DVec3::new(0.0, 3.0, 0.1)]);
        let mut entries = Vec::new();
        for (i, t) in triangles.iter().enumerate() {
            add_entries(&mut entries, std::slice::from_ref(t), |_| Some((i, 0)));
        }
        let (tolerance, gap) = (1e-9, 0.01);
        let found: std::collections::HashSet<(usize, usize)> =
            close_pairs(&entries, gap, |a, b| could_meet(a, b, tolerance, gap)).into_iter().collect();
        let mut meeting = 0;
        for i in 0..entries.len() {
            for j in i + 1..entries.len() {
                let meets = [(i, j), (j, i)].iter().any(|&(a, b)| {
                    let (mut lines, mut touched) = (Vec::new(), [false; 3]);
                    cut_lines(&entries[a].vertices, &entries[b], tolerance, gap, &mut lines, &mut touched);
                    !lines.is_empty() || touched.contains(&true)
                });
                if meets {
                    meeting += 1;
                    assert!(found.contains(&(i, j)), "pair {i}, {j} meets but was not searched");
                }
            }
        }
        assert!(meeting > 80 && found.len() < 3 * meeting, "{meeting} pairs meet, {} searched", found.len());
    }
}
