//! Which runs of the rasterised triangles can reach a view: the host skips, per draw, the
//! chunks of consecutive triangles whose bounding box lies wholly outside the view's clip
//! volume (`view_clip` in `wgsl/common/layout.wgsl`).
//!
//! Why: a draw fetches, shades and clips every vertex it is given, also those of triangles
//! that fall outside the view, and a hemicube's side faces, a point light's cube faces and a
//! camera inside a large scene each see a small part of it. On lavapipe the engine room's first
//! shot (255 k rasterised triangles, 51 faces) took 12 % less time with the culling, and
//! the rest of a one-step run (burn-in, lights' windows, camera) 10 % less (docs/PERFORMANCE.md,
//! "Item buffers draw what their view can see"). The test is on the host, a few planes a
//! chunk, so that a draw needs no extra pass.
//! Tessellation emits each shape's triangles together, so a chunk of consecutive triangles is
//! a compact piece of one surface, and its box is a tight bound. A chunk is skipped only if
//! one clip plane has every corner of its box outside, by a margin above the shader's f32
//! rounding; such triangles produce no fragment, so the item buffers are the same to the bit,
//! and the draws keep their order.

use crate::layout::{GpuCamera, RasterVertex, VIEW_ORTHOGRAPHIC};
use std::ops::Range;

/// Triangles per chunk: small enough that a chunk is a compact piece of a surface, large
/// enough that the per-view test (a few planes a chunk) costs nothing next to the draw.
pub const CHUNK_TRIANGLES: u32 = 64;

/// Bounding boxes of consecutive runs of `CHUNK_TRIANGLES` triangles.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChunkBoxes {
    /// min and max corner of each chunk, in scene units.
    pub boxes: Vec<([f64; 3], [f64; 3])>,
    pub triangles: u32,
}

impl ChunkBoxes {
    /// The chunks of a triangle list (three vertices a triangle).
    pub fn of(vertices: &[RasterVertex]) -> ChunkBoxes {
        let per_chunk = 3 * CHUNK_TRIANGLES as usize;
        let boxes = vertices
            .chunks(per_chunk)
            .map(|chunk| {
                chunk.iter().fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), v| {
                    let p = v.position.map(f64::from);
                    (std::array::from_fn(|i| lo[i].min(p[i])), std::array::from_fn(|i| hi[i].max(p[i])))
                })
            })
            .collect();
        ChunkBoxes { boxes, triangles: (vertices.len() / 3) as u32 }
    }

    /// The triangle ranges to draw for `view`, in order, adjacent visible chunks merged: every
    /// triangle that can put a fragment inside the view's top `rows` rows (its `size.y` for
    /// all of it; fewer for a hemicube's half face).
    pub fn visible(&self, view: &GpuCamera, rows: u32) -> Vec<Range<u32>> {
        let planes = clip_planes(view, rows);
        let mut runs: Vec<Range<u32>> = Vec::new();
        for (c, (lo, hi)) in self.boxes.iter().enumerate() {
            if planes.iter().any(|plane| plane.excludes(lo, hi)) {
                continue;
            }
            let first = c as u32 * CHUNK_TRIANGLES;
            let end = (first + CHUNK_TRIANGLES).min(self.triangles);
            match runs.last_mut() {
                Some(run) if run.end == first => run.end = end,
                _ => runs.push(first..end),
            }
        }
        runs
    }
}

/// An affine function of the position, `normal . p + offset`, non-negative inside the view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub offset: f64,
}

impl Plane {
    fn at(&self, p: [f64; 3]) -> f64 {
        self.normal[0] * p[0] + self.normal[1] * p[1] + self.normal[2] * p[2] + self.offset
    }

    /// Whether the box `lo..hi` lies wholly outside, beyond a margin that covers the f32
    /// arithmetic of the vertex shader (relative 1e-4 of the terms' size).
    fn excludes(&self, lo: &[f64; 3], hi: &[f64; 3]) -> bool {
        // The corner that maximises the function, and the size of its terms.
        let corner: [f64; 3] = std::array::from_fn(|i| if self.normal[i] >= 0.0 { hi[i] } else { lo[i] });
        let scale = (0..3).map(|i| (self.normal[i] * corner[i]).abs()).sum::<f64>() + self.offset.abs();
        self.at(corner) < -1e-4 * scale.max(f64::MIN_POSITIVE)
    }
}

/// The clip volume of `view_clip` as planes in the scene: the clip coordinates (cx, cy, cz, cw)
/// it gives are affine in the position, and the rasteriser keeps -cw <= cx, cy <= cw and
/// 0 <= cz <= cw; `rows` below `size.y` adds the scissor's bottom, with a row to spare.
pub fn clip_planes(view: &GpuCamera, rows: u32) -> Vec<Plane> {
    let f = |v: [f32; 4]| [v[0] as f64, v[1] as f64, v[2] as f64, v[3] as f64];
    let (eye, right, up, forward, jitter) = (f(view.eye), f(view.right), f(view.up), f(view.forward), f(view.jitter));
    let size = [view.size[0].max(1) as f64, view.size[1].max(1) as f64];
    let shift = [2.0 * (0.5 - jitter[0]) / size[0], -2.0 * (0.5 - jitter[1]) / size[1]];
    // Each coordinate as (gradient, value at the eye's origin): a . (p - eye) + b.
    let axis = |a: [f64; 4]| [a[0], a[1], a[2]];
    let lin = |g: [f64; 3], b: f64| (g, b);
    let (cx, cy, cz, cw) = if view.size[2] == VIEW_ORTHOGRAPHIC {
        let cx = lin(axis(right).map(|v| v / right[3]), shift[0]);
        let cy = lin(axis(up).map(|v| v / up[3]), shift[1]);
        let cz = lin(axis(forward).map(|v| -v / forward[3]), 1.0);
        (cx, cy, cz, lin([0.0; 3], 1.0))
    } else {
        let z = axis(forward);
        let cx: [f64; 3] = std::array::from_fn(|i| (right[i] - jitter[2] * z[i]) / right[3] + shift[0] * z[i]);
        let cy: [f64; 3] = std::array::from_fn(|i| (up[i] - jitter[3] * z[i]) / up[3] + shift[1] * z[i]);
        (lin(cx, 0.0), lin(cy, 0.0), lin([0.0; 3], forward[3]), lin(z, 0.0))
    };
    // a*u + b*v for coordinates u, v, then moved from `p - eye` to `p`.
    let combine = |a: f64, u: ([f64; 3], f64), b: f64, v: ([f64; 3], f64)| {
        let normal: [f64; 3] = std::array::from_fn(|i| a * u.0[i] + b * v.0[i]);
        let at_eye = a * u.1 + b * v.1;
        let offset = at_eye - (normal[0] * eye[0] + normal[1] * eye[1] + normal[2] * eye[2]);
        Plane { normal, offset }
    };
    let mut planes = vec![
        combine(1.0, cw, -1.0, cx),
        combine(1.0, cw, 1.0, cx),
        combine(1.0, cw, -1.0, cy),
        combine(1.0, cw, 1.0, cy),
        combine(1.0, cz, 0.0, cz),
        combine(1.0, cw, -1.0, cz),
    ];
    if rows < view.size[1] {
        // Rows [0, rows) from the top: y_ndc >= 1 - 2 (rows + 1) / height, one row to spare.
        let bottom = 1.0 - 2.0 * (rows as f64 + 1.0) / size[1];
        planes.push(combine(1.0, cy, -bottom, cw));
    }
    planes
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `view_clip` of wgsl/common/layout.wgsl, in f64, the oracle the planes are held to.
    fn view_clip(view: &GpuCamera, p: [f64; 3]) -> [f64; 4] {
        let f = |v: [f32; 4]| v.map(f64::from);
        let (eye, right, up, forward, jitter) =
            (f(view.eye), f(view.right), f(view.up), f(view.forward), f(view.jitter));
        let rel = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
        let dot = |a: [f64; 4]| rel[0] * a[0] + rel[1] * a[1] + rel[2] * a[2];
        let (x, y, z) = (dot(right), dot(up), dot(forward));
        let size = [view.size[0] as f64, view.size[1] as f64];
        let shift = [2.0 * (0.5 - jitter[0]) / size[0], -2.0 * (0.5 - jitter[1]) / size[1]];
        if view.size[2] == VIEW_ORTHOGRAPHIC {
            return [x / right[3] + shift[0], y / up[3] + shift[1], 1.0 - z / forward[3], 1.0];
        }
        let window = [x - jitter[2] * z, y - jitter[3] * z];
        [window[0] / right[3] + shift[0] * z, window[1] / up[3] + shift[1] * z, forward[3], z]
    }

    fn inside(c: [f64; 4], rows: u32, height: u32) -> bool {
        let [x, y, z, w] = c;
        let in_rows = y >= (1.0 - 2.0 * rows as f64 / height as f64) * w;
        -w <= x && x <= w && -w <= y && y <= w && 0.0 <= z && z <= w && in_rows
    }

    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn view(rng: &mut Lcg, orthographic: bool) -> GpuCamera {
        let v = |r: &mut Lcg| glam::DVec3::new(r.next() - 0.5, r.next() - 0.5, r.next() - 0.5);
        let forward = v(rng).normalize();
        let right = forward.cross(v(rng)).normalize();
        let up = right.cross(forward);
        let f4 = |a: glam::DVec3, w: f64| [a.x as f32, a.y as f32, a.z as f32, w as f32];
        let eye = v(rng) * 4.0;
        let size = 64 + (rng.next() * 200.0) as u32;
        GpuCamera {
            eye: f4(eye, 0.0),
            right: f4(right, if orthographic { 0.5 + rng.next() * 3.0 } else { 0.2 + rng.next() * 1.5 }),
            up: f4(up, if orthographic { 0.5 + rng.next() * 3.0 } else { 0.2 + rng.next() * 1.5 }),
            forward: f4(forward, if orthographic { 2.0 + rng.next() * 6.0 } else { 1e-3 + rng.next() * 0.5 }),
            jitter: [rng.next() as f32, rng.next() as f32, (rng.next() - 0.5) as f32, (rng.next() - 0.5) as f32],
            size: [size, size, if orthographic { VIEW_ORTHOGRAPHIC } else { 0 }, 0],
        }
    }

    #[test]
    fn a_skipped_box_has_no_point_inside_the_view_and_most_outside_boxes_are_skipped() {
        // Random views (perspective, off-centre and parallel, with half faces) and random
        // boxes; each skipped box is sampled densely (corners, edges, inside) through the
        // shader's formula: none of its points may be in the clip volume. And the test must
        // not pass by skipping nothing: boxes far outside are skipped.
        let mut rng = Lcg(7);
        let (mut skipped, mut outside) = (0, 0);
        for round in 0..400 {
            let orthographic = round % 3 == 0;
            let view = view(&mut rng, orthographic);
            let rows = if round % 2 == 0 { 1 + (rng.next() * view.size[1] as f64) as u32 } else { view.size[1] };
            let planes = clip_planes(&view, rows);
            for _ in 0..50 {
                let centre: [f64; 3] = std::array::from_fn(|_| (rng.next() - 0.5) * 12.0);
                let half: [f64; 3] = std::array::from_fn(|_| rng.next() * 1.5);
                let lo: [f64; 3] = std::array::from_fn(|i| centre[i] - half[i]);
                let hi: [f64; 3] = std::array::from_fn(|i| centre[i] + half[i]);
                let points: Vec<[f64; 3]> = (0..400)
                    .map(|k| {
                        std::array::from_fn(|i| {
                            // Corners first, then points inside.
                            let t = if k < 8 { ((k >> i) & 1) as f64 } else { rng.next() };
                            lo[i] + t * (hi[i] - lo[i])
                        })
                    })
                    .collect();
                let any_inside = points.iter().any(|&p| inside(view_clip(&view, p), rows, view.size[1]));
                let skip = planes.iter().any(|plane| plane.excludes(&lo, &hi));
                if skip {
                    skipped += 1;
                    assert!(
                        !any_inside,
                        "round {round}: a skipped box has a point in the view: {view:?} {lo:?} {hi:?}"
                    );
                }
                outside += !any_inside as u32;
            }
        }
        // Most boxes with no sampled point inside are skipped (the rest straddle a corner
        // of the frustum, where no single plane excludes them).
        assert!(skipped as f64 > 0.6 * outside as f64, "skipped {skipped} of {outside} boxes outside");
    }

    #[test]
    fn runs_merge_adjacent_chunks_and_end_at_the_last_triangle() {
        // Triangles along x, a chunk every 4 units; a parallel view looking down -z at
        // |x| <= 4.5 keeps the chunks whose boxes meet that strip, as one run.
        let n = CHUNK_TRIANGLES * 5 + 7;
        let vertices: Vec<RasterVertex> = (0..n * 3)
            .map(|v| {
                let chunk = (v / 3 / CHUNK_TRIANGLES) as f32;
                RasterVertex { position: [chunk * 4.0 - 8.0 + (v % 3) as f32 * 0.1, 0.0, 0.0], patch: 0 }
            })
            .collect();
        let boxes = ChunkBoxes::of(&vertices);
        assert_eq!(boxes.boxes.len(), 6);
        let view = GpuCamera {
            eye: [0.0, 0.0, 5.0, 0.0],
            right: [1.0, 0.0, 0.0, 4.5],
            up: [0.0, 1.0, 0.0, 4.5],
            forward: [0.0, 0.0, -1.0, 10.0],
            jitter: [0.5, 0.5, 0.0, 0.0],
            size: [64, 64, VIEW_ORTHOGRAPHIC, 0],
        };
        // Chunks at x = -8, -4, 0, 4, 8, 12: the middle three are inside |x| <= 4.5.
        assert_eq!(boxes.visible(&view, 64), vec![CHUNK_TRIANGLES..CHUNK_TRIANGLES * 4]);
        let wide = GpuCamera { right: [1.0, 0.0, 0.0, 100.0], ..view };
        assert_eq!(boxes.visible(&wide, 64), vec![0..n]);
    }
}
