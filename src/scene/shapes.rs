//! Shapes -> triangles: quad, triangle, box, sierpinski, OBJ mesh, and their transforms.
//!
//! Every triangle produced here runs counter-clockwise seen from its front, so that its
//! normal (v1 - v0) x (v2 - v0) points out of closed shapes. `load` attaches materials and
//! runs `check_polygon` on what comes out, after the transform, on the geometry the renderer
//! will actually see.

use glam::{DQuat, DVec3};
use std::f64::consts::TAU;
use std::fmt;

/// Largest distance of a vertex of a shape quad or an OBJ face from the polygon's plane, as
/// a fraction of the polygon's size (see `check_polygon`). Loose, because such a polygon is
/// rendered as its fan of triangles anyway: it only catches a mistyped coordinate. The
/// Cornell box's measured left wall is 4e-3 off and must load.
pub const POLYGON_PLANARITY: f64 = 1e-2;

/// The same for area lights, whose light samples assume one plane (docs/SCENE_FORMAT.md: "planar
/// within 1e-4 of its size").
pub const LIGHT_PLANARITY: f64 = 1e-4;

/// A triangle whose area is at most this fraction of its polygon's squared size has "zero
/// area": far above f64 rounding of the cross product (about 1e-16), far below any triangle a
/// person means to draw.
pub const ZERO_AREA: f64 = 1e-12;

/// The deepest Sierpinski level: level l has 4^l tetrahedra, 4^(l+1) triangles.
pub const MAX_SIERPINSKI_LEVEL: u32 = 8;

/// Largest coordinate magnitude: geometry is uploaded as f32.
pub const MAX_COORDINATE: f64 = f32::MAX as f64;

/// `transform = { scale, rotate, translate }`: scale, then rotate, then translate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Every component > 0, so a transform never mirrors and winding is kept.
    pub scale: DVec3,
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    pub const IDENTITY: Transform =
        Transform { scale: DVec3::ONE, rotation: DQuat::IDENTITY, translation: DVec3::ZERO };

    /// `rotate = [axis_x, axis_y, axis_z, degrees]`: right-handed (counter-clockwise seen from
    /// the tip of the axis) about the axis through the origin. `None` for a zero axis.
    pub fn rotation(axis: DVec3, degrees: f64) -> Option<DQuat> {
        let axis = axis.try_normalize()?;
        Some(DQuat::from_axis_angle(axis, degrees.to_radians()))
    }

    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation * (self.scale * p) + self.translation
    }

    pub fn apply_triangle(&self, t: [DVec3; 3]) -> [DVec3; 3] {
        t.map(|p| self.apply(p))
    }
}

/// A quad split into (v0, v1, v2) and (v0, v2, v3).
pub fn quad(v: [DVec3; 4]) -> [[DVec3; 3]; 2] {
    [[v[0], v[1], v[2]], [v[0], v[2], v[3]]]
}

/// A polygon split into the fan (v0, v_i, v_i+1); right for the convex polygons that
/// `check_polygon` lets through.
pub fn fan(polygon: &[DVec3]) -> impl Iterator<Item = [DVec3; 3]> + '_ {
    polygon.windows(2).skip(1).map(move |w| [polygon[0], w[0], w[1]])
}

/// The closed axis-aligned box [min, max]: 12 triangles facing outward.
pub fn box_triangles(min: DVec3, max: DVec3) -> Vec<[DVec3; 3]> {
    let corner = |a: usize, at_max: bool, u: f64, v: f64| {
        // (a, a+1, a+2) is a cyclic permutation of (x, y, z), so e_u x e_v = e_a.
        let mut p = DVec3::ZERO;
        p[a] = if at_max { max[a] } else { min[a] };
        p[(a + 1) % 3] = if u > 0.5 { max[(a + 1) % 3] } else { min[(a + 1) % 3] };
        p[(a + 2) % 3] = if v > 0.5 { max[(a + 2) % 3] } else { min[(a + 2) % 3] };
        p
    };
    let mut out = Vec::with_capacity(12);
    for a in 0..3 {
        // Counter-clockwise in (u, v) faces +a: right for the max side, reversed for the min.
        let ccw = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
        let top = ccw.map(|(u, v)| corner(a, true, u, v));
        let mut bottom = ccw.map(|(u, v)| corner(a, false, u, v));
        bottom.reverse();
        out.extend(quad(top));
        out.extend(quad(bottom));
    }
    out
}

/// The Sierpinski tetrahedron of docs/SCENE_FORMAT.md: 4^level regular tetrahedra, 4 outward
/// triangles each. A level above `MAX_SIERPINSKI_LEVEL` (which the loader refuses) is
/// clamped to it rather than allocating 4^level tetrahedra.
pub fn sierpinski(center: DVec3, size: f64, level: u32) -> Vec<[DVec3; 3]> {
    let h = size * (2.0f64 / 3.0).sqrt();
    let r = size / 3.0f64.sqrt();
    let base = |k: f64| {
        let t = TAU * k / 3.0;
        center + DVec3::new(r * t.sin(), -h / 4.0, -r * t.cos())
    };
    let apex = center + DVec3::new(0.0, 0.75 * h, 0.0);
    let mut tetrahedra = vec![[apex, base(0.0), base(1.0), base(2.0)]];
    for _ in 0..level.min(MAX_SIERPINSKI_LEVEL) {
        tetrahedra = tetrahedra.iter().flat_map(|t| (0..4).map(move |c| t.map(|q| (t[c] + q) * 0.5))).collect();
    }
    // (b0, b1, b2) faces down, away from the apex (checked by the tests); the other three
    // faces follow from the tetrahedron's orientation.
    tetrahedra.iter().flat_map(|&[a, b0, b1, b2]| [[a, b1, b0], [a, b0, b2], [a, b2, b1], [b0, b1, b2]]).collect()
}

/// Twice the triangle's area.
fn double_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    (b - a).cross(c - a).length()
}

/// Why a polygon cannot be rendered as its fan of triangles.
#[derive(Debug, Clone, PartialEq)]
pub enum PolygonProblem {
    /// Fewer than 3 vertices.
    TooFew(usize),
    /// A coordinate is non-finite or beyond the f32 range (after a transform).
    OutOfRange { vertex: usize },
    /// The fan triangle of these vertices has zero area.
    ZeroArea { vertices: [usize; 3] },
    /// A vertex lies `distance` from the polygon's plane, more than `tolerance` x `size`.
    NotPlanar {
        vertex: usize,
        /// The vertices whose plane it is measured from.
        plane: [usize; 3],
        distance: f64,
        size: f64,
        tolerance: f64,
    },
    /// The boundary turns the wrong way at this vertex, or winds around more than once.
    NotConvex { vertex: usize },
}

impl fmt::Display for PolygonProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            PolygonProblem::TooFew(n) => write!(f, "a polygon needs at least 3 vertices, got {n}"),
            PolygonProblem::OutOfRange { vertex } => {
                write!(f, "vertex {vertex} is out of range (beyond {MAX_COORDINATE:e}, the f32 range the GPU works in)")
            }
            PolygonProblem::ZeroArea { vertices: [a, b, c] } => write!(
                f,
                "degenerate: the triangle of vertices {a}, {b}, {c} has zero area (they coincide or lie on one line)"
            ),
            PolygonProblem::NotPlanar { vertex, plane: [a, b, c], distance, size, tolerance } => write!(
                f,
                "not planar: vertex {vertex} lies {distance:.4e} from the plane of vertices {a}, {b}, {c}, more than {tolerance:e} of its size {size:.4e} (the diagonal of its bounding box)"
            ),
            PolygonProblem::NotConvex { vertex } => write!(
                f,
                "not convex at vertex {vertex}: list the vertices in order around a convex boundary, or split the polygon into triangles"
            ),
        }
    }
}

/// Checks that a polygon (vertices in order, counter-clockwise from its front) is finite,
/// that none of the triangles of its fan has zero area, that it is planar (no vertex lies
/// further than `planarity` x its size, the diagonal of its bounding box, from the plane of
/// its largest fan triangle) and convex. A triangle needs only the first two.
pub fn check_polygon(p: &[DVec3], planarity: f64) -> Result<(), PolygonProblem> {
    let n = p.len();
    if n < 3 {
        return Err(PolygonProblem::TooFew(n));
    }
    if let Some(vertex) = p.iter().position(|v| !v.is_finite() || v.abs().max_element() > MAX_COORDINATE) {
        return Err(PolygonProblem::OutOfRange { vertex });
    }
    let (lo, hi) = p.iter().fold((p[0], p[0]), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let size = (hi - lo).length();
    // Coordinates near f32::MAX overflow f64 squares; such a polygon is out of range.
    if !size.is_finite() || !(size * size).is_finite() {
        return Err(PolygonProblem::OutOfRange { vertex: 0 });
    }
    let min_double_area = 2.0 * ZERO_AREA * size * size;
    let mut largest = (0.0, 1);
    for i in 1..n - 1 {
        let area = double_area(p[0], p[i], p[i + 1]);
        if area.is_nan() || area <= min_double_area {
            return Err(PolygonProblem::ZeroArea { vertices: [0, i, i + 1] });
        }
        if area > largest.0 {
            largest = (area, i);
        }
    }
    if n == 3 {
        return Ok(());
    }

    // Newell's normal: the polygon's area vector, well defined even when slightly warped.
    let centroid = p.iter().sum::<DVec3>() / n as f64;
    let area_vector: DVec3 = (0..n).map(|i| (p[i] - centroid).cross(p[(i + 1) % n] - centroid)).sum();
    // Its fan triangles have area, so a polygon with no net area crosses itself (a bow tie).
    let Some(normal) = area_vector.try_normalize() else {
        return Err(PolygonProblem::NotConvex { vertex: 0 });
    };

    // The plane of the largest fan triangle: for a quad, the distance of the fourth vertex
    // from the plane of the other three, which is what "planar within" usually means.
    let i = largest.1;
    let plane = [0, i, i + 1];
    let plane_normal = (p[i] - p[0]).cross(p[i + 1] - p[0]) / largest.0;
    for (vertex, &v) in p.iter().enumerate() {
        let distance = (v - p[0]).dot(plane_normal).abs();
        if distance > planarity * size {
            return Err(PolygonProblem::NotPlanar { vertex, plane, distance, size, tolerance: planarity });
        }
    }

    // Convex: no corner turns clockwise (straight corners are allowed), and the turns add up
    // to one full turn, which rules out star polygons whose corners all turn the same way.
    let mut turning = 0.0;
    let in_plane = |e: DVec3| e - normal * e.dot(normal);
    for i in 0..n {
        let e1 = in_plane(p[i] - p[(i + n - 1) % n]);
        let e2 = in_plane(p[(i + 1) % n] - p[i]);
        let sine = e1.cross(e2).dot(normal);
        if sine < -min_double_area {
            return Err(PolygonProblem::NotConvex { vertex: i });
        }
        turning += sine.max(0.0).atan2(e1.dot(e2));
    }
    if (turning - TAU).abs() > 1e-6 {
        return Err(PolygonProblem::NotConvex { vertex: 0 });
    }
    Ok(())
}

/// A parsed Wavefront OBJ file: positions and polygonal faces; everything else is ignored.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Obj {
    pub positions: Vec<DVec3>,
    pub faces: Vec<ObjFace>,
    /// Every face's vertex indices (0-based, into `positions`), face after face.
    pub indices: Vec<usize>,
}

/// One `f` statement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjFace {
    /// 1-based line of the `f` statement, for messages.
    pub line: usize,
    /// What the closest `usemtl` above resolved to; `None` before the first `usemtl`.
    pub material: Option<u32>,
    /// `indices[first..first + count]` are its vertices.
    pub first: usize,
    pub count: usize,
}

impl Obj {
    pub fn face_indices(&self, face: &ObjFace) -> &[usize] {
        &self.indices[face.first..face.first + face.count]
    }
}

/// A problem at a line of an OBJ file.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjError {
    pub line: usize,
    pub message: String,
}

/// Parses the `v`, `f` and `usemtl` statements of an OBJ file; other statements (`vt`, `vn`,
/// `o`, `g`, `s`, `mtllib`, ...) are ignored. Face vertices may be written `v`, `v/vt`,
/// `v//vn` or `v/vt/vn`, with 1-based or negative (relative) indices. `material` resolves a
/// `usemtl` name, or says why it cannot.
pub fn parse_obj(text: &str, mut material: impl FnMut(&str) -> Result<u32, String>) -> Result<Obj, ObjError> {
    let mut obj = Obj::default();
    let mut current = None;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let err = |message: String| ObjError { line, message };
        let content = raw.split('#').next().unwrap_or("");
        let mut tokens = content.split_whitespace();
        match tokens.next() {
            Some("v") => {
                let mut xyz = [0.0; 3];
                for (k, slot) in xyz.iter_mut().enumerate() {
                    let Some(token) = tokens.next() else {
                        return Err(err(format!("expected 3 numbers after `v` (x y z), got {k}")));
                    };
                    *slot = obj_number(token).map_err(err)?;
                }
                obj.positions.push(DVec3::from_array(xyz));
            }
            Some("f") => {
                let first = obj.indices.len();
                for token in tokens {
                    let index = obj_index(token, obj.positions.len()).map_err(err)?;
                    obj.indices.push(index);
                }
                let count = obj.indices.len() - first;
                if count < 3 {
                    return Err(err(format!("a face needs at least 3 vertices, got {count}")));
                }
                obj.faces.push(ObjFace { line, material: current, first, count });
            }
            Some("usemtl") => {
                let name = content.trim_start().strip_prefix("usemtl").unwrap_or("").trim();
                if name.is_empty() {
                    return Err(err("expected a material name after `usemtl`".into()));
                }
                current = Some(material(name).map_err(err)?);
            }
            _ => {}
        }
    }
    // Positive indices may refer to vertices defined further down, so they are checked last.
    let defined = obj.positions.len();
    for face in &obj.faces {
        if let Some(&bad) = obj.face_indices(face).iter().find(|&&i| i >= defined) {
            return Err(ObjError {
                line: face.line,
                message: format!("vertex {} does not exist (the file defines {defined})", bad + 1),
            });
        }
    }
    Ok(obj)
}

/// The `mtllib` statements of an OBJ file: (line, file name) for each library it names, in
/// order. Read before the faces, so that `usemtl` can name the libraries' materials.
pub fn obj_material_libraries(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let content = raw.split('#').next().unwrap_or("");
        let mut tokens = content.split_whitespace();
        if tokens.next() == Some("mtllib") {
            out.extend(tokens.map(|name| (index + 1, name.to_string())));
        }
    }
    out
}

fn obj_number(token: &str) -> Result<f64, String> {
    let x: f64 = token.parse().map_err(|_| format!("expected a number, got `{token}`"))?;
    if !x.is_finite() || x.abs() > MAX_COORDINATE {
        return Err(format!("expected a finite number within ±{MAX_COORDINATE:e}, got `{token}`"));
    }
    Ok(x)
}

/// One face vertex `v[/vt][/vn]` -> 0-based position index. `defined` positions precede it.
fn obj_index(token: &str, defined: usize) -> Result<usize, String> {
    let v = token.split('/').next().unwrap_or("");
    let i: i64 =
        v.parse().map_err(|_| format!("expected a vertex index (v, v/vt, v//vn or v/vt/vn), got `{token}`"))?;
    match i {
        0 => Err("vertex index 0 (OBJ indices start at 1; negative ones count back)".into()),
        i if i > 0 => usize::try_from(i - 1).map_err(|_| format!("vertex index {i} is too large")),
        i => usize::try_from(i.unsigned_abs()).ok().and_then(|back| defined.checked_sub(back)).ok_or_else(|| {
            format!("relative vertex index {i} reaches before the first vertex ({defined} defined so far)")
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Rounding tolerance for sums over at most a few thousand f64 triangles of unit size.
    const EPS: f64 = 1e-9;

    fn cross(t: &[DVec3; 3]) -> DVec3 {
        (t[1] - t[0]).cross(t[2] - t[0])
    }

    fn area(ts: &[[DVec3; 3]]) -> f64 {
        ts.iter().map(|t| cross(t).length() / 2.0).sum()
    }

    /// Divergence theorem: the volume a closed, outward-facing surface encloses.
    fn volume(ts: &[[DVec3; 3]]) -> f64 {
        ts.iter().map(|t| ((t[0] + t[1] + t[2]) / 3.0).dot(cross(t)) / 6.0).sum()
    }

    #[test]
    fn quad_splits_along_v0_v2() {
        let v = [DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE];
        assert_eq!(quad(v), [[v[0], v[1], v[2]], [v[0], v[2], v[3]]]);
        let pentagon: Vec<DVec3> = (0..5).map(|i| DVec3::splat(i as f64)).collect();
        let f: Vec<_> = fan(&pentagon).collect();
        assert_eq!(f.len(), 3);
        assert_eq!(f[2], [pentagon[0], pentagon[3], pentagon[4]]);
    }

    #[test]
    fn box_is_closed_and_faces_outward() {
        let (min, max) = (DVec3::new(-1.0, 2.0, 0.5), DVec3::new(2.0, 3.0, 4.5));
        let d = max - min;
        let ts = box_triangles(min, max);
        assert_eq!(ts.len(), 12);
        assert!((area(&ts) - 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)).abs() < EPS);
        assert!((volume(&ts) - d.x * d.y * d.z).abs() < EPS);
        let middle = (min + max) / 2.0;
        for t in &ts {
            let n = cross(t).normalize();
            assert!((n.abs().max_element() - 1.0).abs() < EPS, "not axis-aligned: {n}");
            assert!(n.dot((t[0] + t[1] + t[2]) / 3.0 - middle) > 0.0, "inward: {t:?}");
            assert!(check_polygon(t, POLYGON_PLANARITY).is_ok());
        }
    }

    #[test]
    fn sierpinski_level_0_is_the_regular_tetrahedron_of_the_format() {
        let (center, a) = (DVec3::new(1.0, -2.0, 3.0), 2.0);
        let ts = sierpinski(center, a, 0);
        assert_eq!(ts.len(), 4);
        let h = a * (2.0f64 / 3.0).sqrt();
        let apex = center + DVec3::new(0.0, 0.75 * h, 0.0);
        assert!(ts.iter().flatten().any(|&p| p.distance(apex) < EPS));
        for t in &ts {
            for k in 0..3 {
                assert!((t[k].distance(t[(k + 1) % 3]) - a).abs() < EPS);
            }
        }
        let corners: DVec3 = ts[3].iter().sum::<DVec3>() + apex;
        assert!(corners.distance(4.0 * center) < EPS, "centroid is not center");
        // The base faces down.
        assert!(cross(&ts[3]).normalize().distance(DVec3::NEG_Y) < EPS);
    }

    #[test]
    fn sierpinski_levels_halve_the_volume_and_face_outward() {
        let (center, a) = (DVec3::new(0.5, 0.0, -1.0), 3.0f64);
        let v0 = a.powi(3) / (6.0 * 2.0f64.sqrt());
        for level in 0..=3 {
            let ts = sierpinski(center, a, level);
            assert_eq!(ts.len(), 4usize.pow(level + 1));
            let expected = v0 * 0.5f64.powi(level as i32);
            assert!((volume(&ts) - expected).abs() < EPS * v0, "level {level}");
            for tetrahedron in ts.chunks(4) {
                let inside = tetrahedron.iter().flatten().sum::<DVec3>() / 12.0;
                assert!((volume(tetrahedron) - v0 / 8.0f64.powi(level as i32)).abs() < EPS * v0);
                for t in tetrahedron {
                    let outward = (t[0] + t[1] + t[2]) / 3.0 - inside;
                    assert!(cross(t).dot(outward) > 0.0, "level {level}: inward {t:?}");
                }
            }
        }
    }

    #[test]
    fn sierpinski_clamps_the_level_instead_of_allocating() {
        assert_eq!(sierpinski(DVec3::ZERO, 1.0, 50).len(), 4usize.pow(9));
    }

    #[test]
    fn transform_scales_then_rotates_then_translates() {
        let t = Transform {
            scale: DVec3::new(2.0, 3.0, 1.0),
            rotation: Transform::rotation(DVec3::new(0.0, 0.0, 5.0), 90.0).unwrap(),
            translation: DVec3::new(1.0, 0.0, 0.0),
        };
        // x scaled to 2, turned right-handed about +z onto +y, then moved along x.
        assert!(t.apply(DVec3::X).distance(DVec3::new(1.0, 2.0, 0.0)) < EPS);
        assert!(t.apply(DVec3::Y).distance(DVec3::new(-2.0, 0.0, 0.0)) < EPS);
        assert!(Transform::rotation(DVec3::ZERO, 10.0).is_none());
        // A positive scale keeps winding: the transformed box still encloses +volume.
        let ts: Vec<_> = box_triangles(DVec3::ZERO, DVec3::ONE).into_iter().map(|tri| t.apply_triangle(tri)).collect();
        assert!((volume(&ts) - 6.0).abs() < EPS);
    }

    fn square() -> Vec<DVec3> {
        vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]
    }

    #[test]
    fn convex_planar_polygons_pass() {
        assert_eq!(check_polygon(&square(), LIGHT_PLANARITY), Ok(()));
        let pentagon: Vec<DVec3> = (0..5)
            .map(|k| {
                let t = TAU * k as f64 / 5.0;
                DVec3::new(t.cos(), t.sin(), 0.0)
            })
            .collect();
        assert_eq!(check_polygon(&pentagon, LIGHT_PLANARITY), Ok(()));
        // A straight corner (at v0) that no fan triangle spans is allowed.
        let straight = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::NEG_X];
        assert_eq!(check_polygon(&straight, LIGHT_PLANARITY), Ok(()));
    }

    #[test]
    fn cornell_left_wall_is_planar_enough_for_a_shape_not_for_a_light() {
        let wall = [
            DVec3::new(552.8, 0.0, 0.0),
            DVec3::new(549.6, 0.0, 559.2),
            DVec3::new(556.0, 548.8, 559.2),
            DVec3::new(556.0, 548.8, 0.0),
        ];
        assert_eq!(check_polygon(&wall, POLYGON_PLANARITY), Ok(()));
        assert!(matches!(check_polygon(&wall, LIGHT_PLANARITY), Err(PolygonProblem::NotPlanar { .. })));
    }

    #[test]
    fn bad_polygons_are_named() {
        let mut bow_tie = square();
        bow_tie.swap(2, 3);
        assert!(matches!(check_polygon(&bow_tie, POLYGON_PLANARITY), Err(PolygonProblem::NotConvex { .. })));
        let pentagram: Vec<DVec3> = (0..5)
            .map(|k| {
                let t = TAU * (2 * k) as f64 / 5.0;
                DVec3::new(t.cos(), t.sin(), 0.0)
            })
            .collect();
        assert!(matches!(check_polygon(&pentagram, POLYGON_PLANARITY), Err(PolygonProblem::NotConvex { .. })));
        let arrow = [DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), DVec3::new(1.0, 0.5, 0.0), DVec3::new(1.0, 2.0, 0.0)];
        assert!(matches!(check_polygon(&arrow, POLYGON_PLANARITY), Err(PolygonProblem::NotConvex { vertex: 2 })));
        let mut warped = square();
        warped[2].z = 0.5;
        assert!(matches!(check_polygon(&warped, POLYGON_PLANARITY), Err(PolygonProblem::NotPlanar { .. })));
        let mut repeated = square();
        repeated[3] = repeated[2];
        assert_eq!(check_polygon(&repeated, POLYGON_PLANARITY), Err(PolygonProblem::ZeroArea { vertices: [0, 2, 3] }));
        let line = [DVec3::ZERO, DVec3::X, DVec3::new(2.0, 0.0, 0.0)];
        assert!(matches!(check_polygon(&line, POLYGON_PLANARITY), Err(PolygonProblem::ZeroArea { .. })));
        assert_eq!(check_polygon(&square()[..2], POLYGON_PLANARITY), Err(PolygonProblem::TooFew(2)));
        let far = [DVec3::ZERO, DVec3::X, DVec3::new(0.0, 1e39, 0.0)];
        assert_eq!(check_polygon(&far, POLYGON_PLANARITY), Err(PolygonProblem::OutOfRange { vertex: 2 }));
    }

    fn materials(name: &str) -> Result<u32, String> {
        match name {
            "red" => Ok(0),
            "white" => Ok(1),
            _ => Err(format!("unknown material \"{name}\"")),
        }
    }

    #[test]
    fn obj_reads_polygons_relative_indices_and_usemtl() {
        let text = "\
# a quad, a pentagon and a triangle
mtllib scene.mtl
o thing
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 1
f 1/1/1 2/1/1 3/1/1 4/1/1
usemtl red
v 0 0 1
v 1 0 1
v 1.5 0.5 1
v 1 1 1
v 0 1 1
f -5 -4 -3 -2 -1   # the pentagon
s off
usemtl white
f 1//1 -1//1 5//1
";
        let obj = parse_obj(text, materials).unwrap();
        assert_eq!(obj.positions.len(), 9);
        assert_eq!(obj.faces.len(), 3);
        let lines: Vec<_> = obj.faces.iter().map(|f| f.line).collect();
        assert_eq!(lines, [10, 17, 20]);
        let mats: Vec<_> = obj.faces.iter().map(|f| f.material).collect();
        assert_eq!(mats, [None, Some(0), Some(1)]);
        assert_eq!(obj.face_indices(&obj.faces[1]), &[4, 5, 6, 7, 8]);
        assert_eq!(obj.face_indices(&obj.faces[2]), &[0, 8, 4]);
    }

    #[test]
    fn obj_allows_forward_references() {
        let obj = parse_obj("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", materials).unwrap();
        assert_eq!(obj.face_indices(&obj.faces[0]), &[0, 1, 2]);
    }

    #[test]
    fn obj_errors_name_their_line() {
        let cases = [
            ("v 0 0 0\nv 1 0\n", 2, "expected 3 numbers"),
            ("v 0 0 0\nv a 0 0\n", 2, "expected a number"),
            ("\n\nv nan 0 0\n", 3, "finite"),
            ("v 0 0 1e39\n", 1, "finite"),
            ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3, "at least 3 vertices"),
            ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\n", 4, "index 0"),
            ("v 0 0 0\nf 1 2 3\nv 1 0 0\n", 2, "vertex 3 does not exist"),
            ("v 0 0 0\nv 1 0 0\nf -1 -2 -3\n", 3, "before the first vertex"),
            ("v 0 0 0\nf 1 x 1\n", 2, "expected a vertex index"),
            ("f 1 2 99999999999999999999\n", 1, "expected a vertex index"),
            ("usemtl\n", 1, "material name"),
            ("# c\nusemtl gold\n", 2, "unknown material \"gold\""),
        ];
        for (text, line, message) in cases {
            let e = parse_obj(text, materials).unwrap_err();
            assert_eq!(e.line, line, "{text:?}: {e:?}");
            assert!(e.message.contains(message), "{text:?}: {e:?}");
        }
    }

    /// One OBJ line, valid or not.
    fn obj_line() -> impl Strategy<Value = String> {
        let number = prop_oneof![
            (-10.0f64..10.0).prop_map(|x| x.to_string()),
            Just("nan".to_string()),
            Just("-inf".to_string()),
            Just("1e400".to_string()),
            Just("x".to_string()),
        ];
        let index = prop_oneof![
            (-12i64..12).prop_map(|i| i.to_string()),
            (-12i64..12).prop_map(|i| format!("{i}/1/-1")),
            (-12i64..12).prop_map(|i| format!("{i}//2")),
            Just("9223372036854775807".to_string()),
            Just("-9223372036854775808".to_string()),
            Just("/".to_string()),
        ];
        prop_oneof![
            4 => prop::collection::vec(number, 0..5).prop_map(|n| format!("v {}", n.join(" "))),
            4 => prop::collection::vec(index, 0..7).prop_map(|i| format!("f {}", i.join(" "))),
            1 => prop_oneof![Just("red"), Just("white"), Just("gold"), Just("")]
                .prop_map(|m| format!("usemtl {m}")),
            1 => "[ -~]{0,20}",
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]

        #[test]
        fn obj_parsing_never_panics(lines in prop::collection::vec(obj_line(), 0..30)) {
            if let Ok(obj) = parse_obj(&lines.join("\n"), materials) {
                for face in &obj.faces {
                    let polygon: Vec<DVec3> =
                        obj.face_indices(face).iter().map(|&i| obj.positions[i]).collect();
                    if check_polygon(&polygon, POLYGON_PLANARITY).is_ok() {
                        prop_assert!(area(&fan(&polygon).collect::<Vec<_>>()) > 0.0);
                    }
                }
            }
        }

        #[test]
        fn polygon_check_never_panics(
            points in prop::collection::vec(prop::array::uniform3(
                prop_oneof![-1e3f64..1e3, Just(0.0), Just(f64::NAN), Just(1e38), Just(-3.4e38)]
            ), 0..8)
        ) {
            let polygon: Vec<DVec3> = points.into_iter().map(DVec3::from_array).collect();
            let _ = check_polygon(&polygon, LIGHT_PLANARITY);
        }
    }
}
