//! Shafts between pairs of elements (Haines, Wallace 1994, "Shaft Culling for Efficient
//! Ray-Cast Radiosity"): the faces that can block a pair, found by walking the cluster tree, so
//! that most links need no shadow rays at all.

use super::tree::{Bounds, Tree, union};
use crate::geometry::{Polygon, bounds};
use crate::mesh::Patch;
use glam::DVec3;

/// Nodes a walk of the cluster tree holds at once: a depth-first walk of a binary tree holds
/// at most one node a level plus one, and the cluster tree halves its faces at each level
/// ([`Tree::over`]), so over at most 2^32 faces (`u32` indices) it is at most 33 deep.
const WALK_DEPTH: usize = 64;

/// Faces in a shaft tested as a single blocker before rays decide.
pub(super) const MAX_BLOCKER_CANDIDATES: usize = 4;

/// The convex hull of two boxes as their union box cut by up to 12 planes through matching
/// edges (Haines, Wallace 1994): a point is outside when `normal . p > offset` for a plane,
/// each offset already widened by the margin.
struct Shaft {
    union: Bounds,
    planes: [(DVec3, f64); 12],
    /// Planes in use.
    count: usize,
    /// Margin that keeps the test conservative against round-off.
    margin: f64,
}

impl Shaft {
    fn new(a: Bounds, b: Bounds) -> Shaft {
        let union = union(a, b);
        // Which box alone sets the union's face on `axis` (`high`: its max side): Some(true) a,
        // Some(false) b, None both.
        let side = |bounds: Bounds, axis: usize, high: bool| {
            if high { bounds.1[axis] } else { bounds.0[axis] }
        };
        let owner = |axis: usize, high: bool| {
            let (va, vb) = (side(a, axis, high), side(b, axis, high));
            if va == vb {
                None
            } else {
                Some((va > vb) == high)
            }
        };
        let mut shaft = Shaft {
            union,
            planes: [(DVec3::ZERO, 0.0); 12],
            count: 0,
            margin: 1e-9 * (union.1 - union.0).length(),
        };
        for i in 0..3 {
            for j in i + 1..3 {
                for high_i in [false, true] {
                    for high_j in [false, true] {
                        let (Some(oi), Some(oj)) = (owner(i, high_i), owner(j, high_j)) else {
                            continue;
                        };
                        if oi == oj {
                            continue;
                        }
                        // The plane through the (i, j) edge of a and the same edge of b, facing
                        // the union's corner they cut off.
                        let (pa, pb) = (
                            (side(a, i, high_i), side(a, j, high_j)),
                            (side(b, i, high_i), side(b, j, high_j)),
                        );
                        let mut normal = DVec3::ZERO;
                        normal[i] = pb.1 - pa.1;
                        normal[j] = pa.0 - pb.0;
                        let towards_corner = normal[i] * if high_i { 1.0 } else { -1.0 }
                            + normal[j] * if high_j { 1.0 } else { -1.0 };
                        if towards_corner < 0.0 {
                            normal = -normal;
                        }
                        let offset = normal[i] * pa.0 + normal[j] * pa.1;
                        shaft.planes[shaft.count] =
                            (normal, offset + shaft.margin * normal.length());
                        shaft.count += 1;
                    }
                }
            }
        }
        shaft
    }

    /// False only when `bounds` lies wholly outside the shaft.
    fn may_meet_box(&self, (lo, hi): Bounds) -> bool {
        let m = self.margin;
        if lo.cmpgt(self.union.1 + m).any() || hi.cmplt(self.union.0 - m).any() {
            return false;
        }
        self.planes[..self.count].iter().all(|(normal, offset)| {
            let nearest = DVec3::select(normal.cmpgt(DVec3::ZERO), lo, hi);
            normal.dot(nearest) <= *offset
        })
    }

    /// False only when every point lies outside one and the same bounding plane of the shaft.
    fn may_meet_points(&self, points: &[DVec3]) -> bool {
        let m = self.margin;
        for axis in 0..3 {
            if points.iter().all(|p| p[axis] > self.union.1[axis] + m)
                || points.iter().all(|p| p[axis] < self.union.0[axis] - m)
            {
                return false;
            }
        }
        self.planes[..self.count]
            .iter()
            .all(|(normal, offset)| points.iter().any(|p| normal.dot(*p) <= *offset))
    }
}

/// Whether face `blocker` lies strictly between the point sets `a` and `b` (convex polygons'
/// corners) and covers every segment from one to the other: all such segments cross its plane
/// inside the convex hull of the corner-to-corner crossings, so those crossings decide.
/// Whether the plane of `face` (normal `normal`) leaves every point of `a` and `b` on one side
/// (or on it): then no segment between them crosses the face, so it cannot block the pair. The
/// faces around a receiver in a tessellated wall are such faces: coplanar with it.
fn cannot_separate(face: &Polygon, normal: DVec3, a: &[DVec3], b: &[DVec3]) -> bool {
    let c = face.corners()[0];
    let tolerance = 1e-9 * face.radius();
    let height = |p: &DVec3| (*p - c).dot(normal);
    let mut heights = a.iter().chain(b).map(height);
    heights.clone().all(|h| h >= -tolerance) || heights.all(|h| h <= tolerance)
}

fn blocks_every_segment(blocker: &Polygon, normal: DVec3, a: &[DVec3], b: &[DVec3]) -> bool {
    let c = blocker.corners();
    let tolerance = 1e-9 * blocker.radius();
    let height = |p: &DVec3| (*p - c[0]).dot(normal);
    let (above_a, below_a) = (
        a.iter().all(|p| height(p) > tolerance),
        a.iter().all(|p| height(p) < -tolerance),
    );
    let (above_b, below_b) = (
        b.iter().all(|p| height(p) > tolerance),
        b.iter().all(|p| height(p) < -tolerance),
    );
    if !((above_a && below_b) || (below_a && above_b)) {
        return false;
    }
    a.iter().all(|p| {
        b.iter().all(|q| {
            let (hp, hq) = (height(p), height(q));
            let x = *p + (*q - *p) * (hp / (hp - hq));
            // Strictly inside every edge (CCW about `normal`), by a relative margin.
            (0..c.len()).all(|k| {
                let edge = c[(k + 1) % c.len()] - c[k];
                edge.cross(x - c[k]).dot(normal) > 1e-9 * edge.length_squared()
            })
        })
    })
}

/// How the shaft saw a pair of elements.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Visibility {
    /// Nothing can block: no rays.
    Clear,
    /// One face covers every segment between them: no rays.
    Hidden,
    /// Shadow rays decide.
    Partial,
    /// A cluster takes part: the factor is sampled with rays.
    Sampled,
}

/// Clear, hidden or partial, from the faces of `tree` in the shaft between `p` and `q`.
pub(super) fn shaft_visibility(tree: &Tree, p: &Patch, q: &Patch) -> Visibility {
    let (cp, cq) = (p.polygon.corners(), q.polygon.corners());
    let shaft = Shaft::new(bounds(cp.iter().copied()), bounds(cq.iter().copied()));
    let mut candidates = 0;
    // On the stack, no allocation: this runs for every pair refinement decides.
    let mut stack = [0u32; WALK_DEPTH];
    let mut depth = 1;
    while depth > 0 {
        depth -= 1;
        let n = stack[depth];
        let node = &tree.nodes[n as usize];
        if !shaft.may_meet_box(node.bounds) {
            continue;
        }
        let Some(element) = &node.element else {
            for child in node.children() {
                stack[depth] = child;
                depth += 1;
            }
            continue;
        };
        // An input face (the search never goes below them).
        let face = element.patch.face;
        let polygon = &tree.faces[face as usize];
        if face == p.face
            || face == q.face
            || !shaft.may_meet_points(polygon.corners())
            || cannot_separate(polygon, element.patch.normal, cp, cq)
        {
            continue;
        }
        if blocks_every_segment(polygon, element.patch.normal, cp, cq) {
            return Visibility::Hidden;
        }
        // Rays decide from here; looking further for a single face that hides everything
        // costs a walk over every face in a shaft across a furnished room.
        candidates += 1;
        if candidates == MAX_BLOCKER_CANDIDATES {
            return Visibility::Partial;
        }
    }
    if candidates == 0 {
        return Visibility::Clear;
    }
    Visibility::Partial
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{splitmix64, unit_interval};
    use glam::dvec3;

    #[test]
    fn a_shaft_holds_every_segment_between_its_boxes_and_nothing_beside_them() {
        let a = (dvec3(0.0, 0.0, 0.0), dvec3(1.0, 1.0, 1.0));
        let b = (dvec3(4.0, 3.0, -1.0), dvec3(5.0, 5.0, 0.5));
        let shaft = Shaft::new(a, b);
        assert!(shaft.count > 0);
        let mut seed = 7u64;
        let mut unit = || {
            seed = splitmix64(seed);
            unit_interval(seed)
        };
        for _ in 0..1000 {
            let p = a.0 + (a.1 - a.0) * DVec3::new(unit(), unit(), unit());
            let q = b.0 + (b.1 - b.0) * DVec3::new(unit(), unit(), unit());
            let x = p.lerp(q, unit());
            assert!(
                shaft.may_meet_box((x, x)),
                "{x} lies on a segment between the boxes"
            );
        }
        // Inside the union box but off the hull: the corner regions the planes cut away.
        assert!(!shaft.may_meet_box((dvec3(0.0, 4.5, 0.0), dvec3(0.5, 5.0, 0.2))));
        assert!(!shaft.may_meet_box((dvec3(4.5, 0.0, 0.0), dvec3(5.0, 0.5, 0.2))));
        assert!(!shaft.may_meet_points(&[dvec3(6.0, 0.0, 0.0), dvec3(7.0, 1.0, 0.0)]));
    }

    #[test]
    fn one_face_hides_a_pair_only_when_it_covers_every_segment() {
        let square = |z: f64, half: f64| {
            [
                dvec3(-half, -half, z),
                dvec3(half, -half, z),
                dvec3(half, half, z),
                dvec3(-half, half, z),
            ]
        };
        let (below, above) = (square(0.0, 0.5), square(2.0, 0.5));
        let [a, b, c, d] = square(1.0, 2.0);
        let big = Polygon::quad(a, b, c, d);
        assert!(blocks_every_segment(&big, big.normal(), &below, &above));
        let [a, b, c, d] = square(1.0, 0.4);
        let small = Polygon::quad(a, b, c, d);
        assert!(
            !blocks_every_segment(&small, small.normal(), &below, &above),
            "segments pass around a smaller square"
        );
        let [a, b, c, d] = square(0.0, 2.0);
        let level = Polygon::quad(a, b, c, d);
        assert!(
            !blocks_every_segment(&level, level.normal(), &below, &above),
            "a face in the plane of one end separates nothing"
        );
    }

    #[test]
    fn only_a_face_whose_plane_separates_the_pair_can_block_it() {
        let square = |x: f64, z: f64, half: f64| {
            [
                dvec3(x - half, -half, z),
                dvec3(x + half, -half, z),
                dvec3(x + half, half, z),
                dvec3(x - half, half, z),
            ]
        };
        let (floor_piece, lamp) = (square(0.0, 0.0, 0.5), square(0.0, 3.0, 0.5));
        // The floor piece's neighbour in a tessellated floor, and a wall behind both ends.
        let [a, b, c, d] = square(1.0, 0.0, 0.5);
        let neighbour = Polygon::quad(a, b, c, d);
        assert!(cannot_separate(
            &neighbour,
            neighbour.normal(),
            &floor_piece,
            &lamp
        ));
        let wall = Polygon::quad(
            dvec3(5.0, -1.0, 0.0),
            dvec3(5.0, 1.0, 0.0),
            dvec3(5.0, 1.0, 3.0),
            dvec3(5.0, -1.0, 3.0),
        );
        assert!(cannot_separate(&wall, wall.normal(), &floor_piece, &lamp));
        // A shelf between them: its plane separates, so it stays a candidate.
        let [a, b, c, d] = square(2.0, 1.5, 1.0);
        let shelf = Polygon::quad(a, b, c, d);
        assert!(!cannot_separate(
            &shelf,
            shelf.normal(),
            &floor_piece,
            &lamp
        ));
    }
}
