//! Which patch of a mesh holds a point of a scene face, and where in it: what a ray that meets
//! the face sees of a solution (its corners' values interpolated as viewers show them), and
//! what a probe of [`crate::accuracy`] reads there.
//!
//! The bounce's rays ask this tens of millions of times on a large model, so each face keeps
//! its patches' fan triangles in its own plane, side by side in memory, each as the affine map
//! from a point's in-plane coordinates to its weights: a candidate costs six multiplications
//! and no read of the mesh.

use crate::mesh::{Mesh, Patch};
use glam::{DVec2, DVec3};
use std::ops::Range;

/// Faces with at most this many fan triangles are searched triangle by triangle; larger ones
/// through a grid in their plane.
const SCANNED_TRIANGLES: usize = 16;

/// A point's place in the mesh: its patch, the fan triangle `(c0, ck, ck+1)` of it that holds
/// the point (`fan` is `k`), and the interpolation weights of that triangle's corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Place {
    pub(crate) patch: usize,
    pub(crate) fan: usize,
    pub(crate) weights: [f64; 3],
}

/// The corners of `patch`'s fan triangle `(c0, ck, ck+1)`, `k` = `fan`.
pub(crate) fn fan_corners(patch: &Patch, fan: usize) -> [u32; 3] {
    [patch.corners[0], patch.corners[fan], patch.corners[fan + 1]]
}

/// One fan triangle of a patch in its face's plane: the weights of `ck` and `ck+1` at in-plane
/// point `p` are `to_weights * (p - c0)`.
struct FanTriangle {
    c0: DVec2,
    /// Rows of the inverse of the matrix whose columns are `ck - c0` and `ck+1 - c0` (zero for
    /// a triangle of no area: every point then has `c0`'s weight 1).
    to_weights: [DVec2; 2],
    patch: u32,
    fan: u32,
}

impl FanTriangle {
    fn new([a, b, c]: [DVec2; 3], patch: usize, fan: usize) -> FanTriangle {
        let (e1, e2) = (b - a, c - a);
        let det = e1.perp_dot(e2);
        let to_weights = if det == 0.0 {
            [DVec2::ZERO; 2]
        } else {
            [DVec2::new(e2.y, -e2.x) / det, DVec2::new(-e1.y, e1.x) / det]
        };
        FanTriangle {
            c0: a,
            to_weights,
            patch: patch as u32,
            fan: fan as u32,
        }
    }

    /// The barycentric weights of in-plane point `p`.
    fn weights(&self, p: DVec2) -> [f64; 3] {
        let d = p - self.c0;
        let (w1, w2) = (self.to_weights[0].dot(d), self.to_weights[1].dot(d));
        [1.0 - w1 - w2, w1, w2]
    }
}

/// A uniform grid over one face's fan triangles in its plane: each cell lists the triangles
/// whose bounding box overlaps it.
struct FaceGrid {
    lo: DVec2,
    cell: f64,
    size: [usize; 2],
    /// Cell `i = x + size[0] * y` lists `items[starts[i]..starts[i + 1]]`, indices into the
    /// locator's triangles.
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl FaceGrid {
    /// About one cell per triangle over the triangles' bounding rectangle: `boxes` are theirs,
    /// the first being the locator's triangle `first`.
    fn new(boxes: &[(DVec2, DVec2)], first: u32) -> FaceGrid {
        let (lo, hi) = boxes
            .iter()
            .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b.0), hi.max(b.1))
            });
        let extent = (hi - lo).max(DVec2::splat(f64::MIN_POSITIVE));
        let cell = (extent.x * extent.y / boxes.len() as f64)
            .sqrt()
            .max(extent.max_element() / 1024.0);
        let size = [
            ((extent.x / cell).ceil() as usize).clamp(1, 1024),
            ((extent.y / cell).ceil() as usize).clamp(1, 1024),
        ];
        let mut grid = FaceGrid {
            lo,
            cell,
            size,
            starts: Vec::new(),
            items: Vec::new(),
        };
        let cells_of = |b: &(DVec2, DVec2)| {
            let ([x0, y0], [x1, y1]) = (grid.cell_of(b.0), grid.cell_of(b.1));
            (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| x + size[0] * y))
        };
        // Counted, then filled: one allocation for the lists of every cell.
        let mut counts = vec![0u32; size[0] * size[1] + 1];
        for b in boxes {
            cells_of(b).for_each(|i| counts[i + 1] += 1);
        }
        for i in 1..counts.len() {
            counts[i] += counts[i - 1];
        }
        let mut next = counts.clone();
        let mut items = vec![0; counts[counts.len() - 1] as usize];
        for (t, b) in boxes.iter().enumerate() {
            for i in cells_of(b) {
                items[next[i] as usize] = first + t as u32;
                next[i] += 1;
            }
        }
        (grid.starts, grid.items) = (counts, items);
        grid
    }

    /// The cell holding in-plane point `p`, clamped to the grid.
    fn cell_of(&self, p: DVec2) -> [usize; 2] {
        let d = p - self.lo;
        let index = |t: f64, n: usize| ((t / self.cell).floor().max(0.0) as usize).min(n - 1);
        [index(d.x, self.size[0]), index(d.y, self.size[1])]
    }

    /// The triangles that may hold in-plane point `p`.
    fn candidates(&self, p: DVec2) -> &[u32] {
        let [x, y] = self.cell_of(p);
        let i = x + self.size[0] * y;
        &self.items[self.starts[i] as usize..self.starts[i + 1] as usize]
    }
}

/// One scene face's plane and how its triangles are searched (boxed, the grid of the few faces
/// that have one: a million faces of soup, a patch each, are a million of these).
struct FaceIndex {
    origin: DVec3,
    axes: [DVec3; 2],
    triangles: Range<u32>,
    grid: Option<Box<FaceGrid>>,
}

impl FaceIndex {
    /// `x`'s coordinates in the face's plane.
    fn in_plane(&self, x: DVec3) -> DVec2 {
        let d = x - self.origin;
        DVec2::new(d.dot(self.axes[0]), d.dot(self.axes[1]))
    }
}

/// Point location on a mesh built face by face.
pub(crate) struct PatchLocator {
    /// Per scene face; `None` for a face with no patch.
    faces: Vec<Option<FaceIndex>>,
    triangles: Vec<FanTriangle>,
}

impl PatchLocator {
    /// Indexes `mesh`, whose patches come face by face, for `face_count` scene faces.
    pub(crate) fn new(mesh: &Mesh, face_count: usize) -> PatchLocator {
        // `end == 0` marks a face not met yet: a real range ends at 1 or later.
        let mut ranges = vec![0..0; face_count];
        for (i, patch) in mesh.patches.iter().enumerate() {
            let range = &mut ranges[patch.face as usize];
            *range = if range.end == 0 {
                i..i + 1
            } else {
                range.start..i + 1
            };
        }
        let mut triangles = Vec::with_capacity(mesh.patches.len() * 2);
        let faces = ranges
            .into_iter()
            .map(|patches| {
                let first = patches.clone().next()?;
                let origin = mesh.patches[first].centroid;
                let (u, v) = mesh.patches[first].normal.any_orthonormal_pair();
                let start = triangles.len();
                let mut index = FaceIndex {
                    origin,
                    axes: [u, v],
                    triangles: 0..0,
                    grid: None,
                };
                let mut boxes = Vec::new();
                for i in patches {
                    let patch = &mesh.patches[i];
                    let ids = &patch.corners[..patch.corner_count()];
                    let at = |k: usize| index.in_plane(mesh.positions[ids[k] as usize]);
                    for fan in 1..ids.len() - 1 {
                        let corners = [at(0), at(fan), at(fan + 1)];
                        triangles.push(FanTriangle::new(corners, i, fan));
                        let (lo, hi) = (corners[0].min(corners[1]), corners[0].max(corners[1]));
                        boxes.push((lo.min(corners[2]), hi.max(corners[2])));
                    }
                }
                index.triangles = start as u32..triangles.len() as u32;
                if boxes.len() > SCANNED_TRIANGLES {
                    index.grid = Some(Box::new(FaceGrid::new(&boxes, start as u32)));
                }
                Some(index)
            })
            .collect();
        PatchLocator { faces, triangles }
    }

    /// Where `x`, a point of scene face `face`, lies in the mesh: the fan triangle that holds
    /// it best (the largest smallest barycentric weight). `None` for a face with no patch.
    pub(crate) fn place(&self, face: u32, x: DVec3) -> Option<Place> {
        let index = self.faces.get(face as usize)?.as_ref()?;
        let p = index.in_plane(x);
        let mut best: Option<(f64, u32, [f64; 3])> = None;
        let mut consider = |t: u32| {
            let weights = self.triangles[t as usize].weights(p);
            let inside = weights[0].min(weights[1]).min(weights[2]);
            if best.is_none_or(|(b, _, _)| inside > b) {
                best = Some((inside, t, weights));
            }
        };
        match &index.grid {
            Some(grid) => grid.candidates(p).iter().copied().for_each(&mut consider),
            None => index.triangles.clone().for_each(&mut consider),
        }
        best.map(|(_, t, weights)| {
            let triangle = &self.triangles[t as usize];
            Place {
                patch: triangle.patch as usize,
                fan: triangle.fan as usize,
                weights,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::{PatchLocator, SCANNED_TRIANGLES, fan_corners};
    use crate::hierarchy::fixtures::{GREY, add_parallelogram};
    use crate::mesh::{Mesh, PatchTarget};
    use crate::sampling::stratified_uv;
    use crate::scene::Scene;
    use glam::{DVec3, dvec3};

    #[test]
    fn a_point_of_a_face_is_placed_in_the_patch_that_holds_it_with_weights_that_rebuild_it() {
        // A tilted 3 x 2 wall meshed finely enough for the grid, and a small plate scanned.
        let mut scene = Scene::default();
        let (u, v) = (dvec3(3.0, 0.0, 1.0), dvec3(0.0, 2.0, 0.5));
        add_parallelogram(&mut scene, "wall", (dvec3(-1.0, 0.5, 2.0), u, v), GREY);
        let (small_u, small_v) = (DVec3::X * 0.2, DVec3::Z * 0.2);
        add_parallelogram(&mut scene, "plate", (DVec3::ZERO, small_u, small_v), GREY);
        let mesh = Mesh::build(&scene, PatchTarget::EdgeLength(0.25));
        let count = |face: u32| mesh.patches.iter().filter(|p| p.face == face).count();
        assert!(count(0) > SCANNED_TRIANGLES && count(1) * 2 <= SCANNED_TRIANGLES);
        let locator = PatchLocator::new(&mesh, scene.faces.len());
        for (face, origin, u, v) in [
            (0, dvec3(-1.0, 0.5, 2.0), u, v),
            (1, DVec3::ZERO, small_u, small_v),
        ] {
            for k in 0..500 {
                let (s, t) = stratified_uv(k, 7);
                let x = origin + u * s + v * t;
                let place = locator.place(face, x).expect("the face has patches");
                assert_eq!(mesh.patches[place.patch].face, face);
                let corners = fan_corners(&mesh.patches[place.patch], place.fan);
                let rebuilt: DVec3 = (corners.iter().zip(place.weights))
                    .map(|(&c, w)| mesh.positions[c as usize] * w)
                    .sum();
                assert!(rebuilt.distance(x) < 1e-9, "{x} placed at {rebuilt}");
                assert!(place.weights.iter().all(|&w| w >= -1e-9), "{place:?}");
                let ids = &mesh.patches[place.patch].corners;
                assert!(corners.iter().all(|c| ids.contains(c)));
            }
        }
    }
}
