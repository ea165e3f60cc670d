//! Lines in a face's plane, and the grid that finds the edges near a face: what contact lines
//! ([`super::contact`]) and sections ([`super::section`]) are both found and cut with.

use crate::geometry::{Polygon, bounds};
use crate::scene::Face;
use glam::DVec3;
use std::collections::HashMap;

/// Distances below this fraction of a face's radius count as zero: an edge this close to a
/// plane lies in it, and a cut leaving a piece thinner than this is not made.
pub(super) const RELATIVE_TOLERANCE: f64 = 1e-6;

/// Most grid cells along the scene's longest side, per square root of its face count: bounds
/// the grid whatever the face sizes, and grows with the faces as a surface does (a model's
/// faces spread over its extent's area). Measured loading (docs/BENCHMARKS.md): at a fixed
/// 1,024 a side the 1M-triangle village's cells held hundreds of edges each and it loaded in
/// 25-27 s; with 2,048 / 4,096 a side 16 / 15 s, while the 126k-face monastery loaded in 1.8 s
/// at 1,024 and 2.1 / 2.9 s at 2,048 / 4,096 (its large faces' boxes cover more empty cells).
const CELLS_PER_ROOT_FACE: f64 = 3.0;

/// A face's plane as the cuts read it: its corners, normal, and the distance below which an
/// offset from it counts as zero ([`RELATIVE_TOLERANCE`] of its radius).
pub(super) struct FacePlane<'a> {
    pub(super) corners: &'a [DVec3],
    pub(super) normal: DVec3,
    pub(super) tolerance: f64,
}

impl<'a> FacePlane<'a> {
    pub(super) fn of(polygon: &'a Polygon) -> Self {
        FacePlane {
            corners: polygon.corners(),
            normal: polygon.normal(),
            tolerance: RELATIVE_TOLERANCE * polygon.radius(),
        }
    }

    /// Signed distance of `p` from the plane, positive in front.
    pub(super) fn height(&self, p: DVec3) -> f64 {
        (p - self.corners[0]).dot(self.normal)
    }
}

/// Every face's edges, by the grid cells their bounding boxes cover.
pub(super) struct EdgeGrid {
    /// The median face's area: the grid's cell is its side.
    pub(super) median_area: f64,
    origin: DVec3,
    cell: f64,
    cells: HashMap<[i64; 3], Vec<(u32, u8)>>,
}

impl EdgeGrid {
    pub(super) fn new(faces: &[Face]) -> EdgeGrid {
        let (lo, hi) = bounds(
            faces
                .iter()
                .flat_map(|f| f.polygon.corners().iter().copied()),
        );
        let side = (hi - lo).max_element().max(f64::MIN_POSITIVE);
        // The median face's size, not the mean's: a ground of hundreds of square metres under
        // a model of centimetre triangles made the mean's cells hold thousands of edges each,
        // and finding the contacts took 7 of the 7.8 s a 13,776-triangle teddy bear took to load
        // (0.7 s now).
        let mut areas: Vec<f64> = faces.iter().map(|f| f.polygon.area()).collect();
        let middle = areas.len() / 2;
        let median_area = match areas.is_empty() {
            true => 0.0,
            false => *areas.select_nth_unstable_by(middle, f64::total_cmp).1,
        };
        let most_cells_per_side = CELLS_PER_ROOT_FACE * (faces.len() as f64).sqrt().max(1.0);
        let mut grid = EdgeGrid {
            median_area,
            origin: lo,
            cell: median_area.sqrt().max(side / most_cells_per_side),
            cells: HashMap::new(),
        };
        for (f, face) in faces.iter().enumerate() {
            let corners = face.polygon.corners();
            for k in 0..corners.len() {
                let (p, q) = (corners[k], corners[(k + 1) % corners.len()]);
                // Along the edge a cell at a time: a long slanted edge's box would span a
                // cube of cells.
                let steps = (p.distance(q) / grid.cell)
                    .ceil()
                    .clamp(1.0, 4.0 * most_cells_per_side);
                let mut keys: Vec<[i64; 3]> = (0..steps as usize)
                    .flat_map(|i| {
                        let (a, b) = (
                            p.lerp(q, i as f64 / steps),
                            p.lerp(q, (i + 1) as f64 / steps),
                        );
                        grid.keys(a.min(b), a.max(b))
                    })
                    .collect();
                keys.sort_unstable();
                keys.dedup();
                for key in keys {
                    grid.cells.entry(key).or_default().push((f as u32, k as u8));
                }
            }
        }
        grid
    }

    /// How many cells the box from `lo` to `hi` covers.
    fn cell_count(&self, lo: DVec3, hi: DVec3) -> f64 {
        let at = |p: DVec3| ((p - self.origin) / self.cell).floor();
        let span = at(hi) - at(lo) + DVec3::ONE;
        span.x * span.y * span.z
    }

    /// The cell holding `p`.
    fn key(&self, p: DVec3) -> [i64; 3] {
        ((p - self.origin) / self.cell)
            .floor()
            .as_i64vec3()
            .to_array()
    }

    /// The cells a box from `lo` to `hi` covers.
    fn keys(&self, lo: DVec3, hi: DVec3) -> impl Iterator<Item = [i64; 3]> {
        let (a, b) = (self.key(lo), self.key(hi));
        (a[0]..=b[0]).flat_map(move |x| {
            (a[1]..=b[1]).flat_map(move |y| (a[2]..=b[2]).map(move |z| [x, y, z]))
        })
    }

    /// The edges near the face of `plane` (within its tolerance of its bounding box), each
    /// once.
    pub(super) fn edges_near_face(&self, plane: &FacePlane) -> Vec<(u32, u8)> {
        let (lo, hi) = bounds(plane.corners.iter().copied());
        let margin = DVec3::splat(plane.tolerance);
        self.edges_near(lo - margin, hi + margin)
    }

    /// The edges near the box from `lo` to `hi`, each once.
    fn edges_near(&self, lo: DVec3, hi: DVec3) -> Vec<(u32, u8)> {
        let mut edges: Vec<(u32, u8)> = if self.cell_count(lo, hi) > self.cells.len() as f64 {
            // A box wider than the occupied grid (a large slanted face): the occupied cells in it.
            let (a, b) = (self.key(lo), self.key(hi));
            self.cells
                .iter()
                .filter(|(key, _)| (0..3).all(|i| a[i] <= key[i] && key[i] <= b[i]))
                .flat_map(|(_, edges)| edges.iter().copied())
                .collect()
        } else {
            self.keys(lo, hi)
                .filter_map(|key| self.cells.get(&key))
                .flatten()
                .copied()
                .collect()
        };
        edges.sort_unstable();
        edges.dedup();
        edges
    }
}

/// A segment in a face's plane from `point` to `point + direction`; as a cut, its whole line.
#[derive(Clone, Copy, Debug)]
pub(super) struct Line {
    pub(super) point: DVec3,
    pub(super) direction: DVec3,
}

/// Whether the segment `p`..`q` (in the plane of the convex polygon `corners`, normal
/// `normal`) runs through the polygon's interior for longer than `tolerance`, and its line
/// leaves corners on both sides (a segment along an edge cuts nothing).
pub(super) fn crosses_interior(
    corners: &[DVec3],
    normal: DVec3,
    p: DVec3,
    q: DVec3,
    tolerance: f64,
) -> bool {
    let line = Line {
        point: p,
        direction: q - p,
    };
    let sides: Vec<f64> = corners.iter().map(|c| side(line, normal, *c)).collect();
    if !(sides.iter().any(|s| *s > tolerance) && sides.iter().any(|s| *s < -tolerance)) {
        return false;
    }
    chord(corners, normal, p, q).is_some_and(|(enter, leave)| {
        (leave.min(1.0) - enter.max(0.0)) * (q - p).length() > tolerance
    })
}

/// The parameters `t` between which `p + t (q - p)` lies in the convex polygon `corners`
/// (Cyrus-Beck against every edge's half-plane), `None` where the line misses it.
pub(super) fn chord(corners: &[DVec3], normal: DVec3, p: DVec3, q: DVec3) -> Option<(f64, f64)> {
    let (mut enter, mut leave) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..corners.len() {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        let inward = normal.cross(b - a);
        let (start, rate) = ((p - a).dot(inward), (q - p).dot(inward));
        if rate == 0.0 {
            if start < 0.0 {
                return None;
            }
        } else if rate > 0.0 {
            enter = enter.max(-start / rate);
        } else {
            leave = leave.min(-start / rate);
        }
    }
    (leave > enter).then_some((enter, leave))
}

/// Signed distance of `x` from `line`, in the plane of normal `normal` (positive on the left
/// of its direction seen from the front).
pub(super) fn side(line: Line, normal: DVec3, x: DVec3) -> f64 {
    line.direction.cross(x - line.point).dot(normal) / line.direction.length()
}
