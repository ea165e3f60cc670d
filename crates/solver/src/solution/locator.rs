//! Which patch of a mesh holds a point of a scene face, and where in it: what a ray that meets
//! the face sees of a solution (its corners' values interpolated as viewers show them).

use crate::geometry::fan_weights;
use crate::mesh::{Mesh, Patch};
use glam::{DVec2, DVec3};
use std::ops::Range;

/// Faces with at most this many patches are searched patch by patch; larger ones through a
/// grid in their plane.
const SCANNED_PATCHES: usize = 8;

/// A point's place in the mesh: its patch, the fan triangle `(c0, ck, ck+1)` of it that holds
/// the point (`fan` is `k`), and the interpolation weights of that triangle's corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Place {
    pub(super) patch: usize,
    pub(super) fan: usize,
    pub(super) weights: [f64; 3],
}

/// The corners of `patch`'s fan triangle `(c0, ck, ck+1)`, `k` = `fan`.
pub(super) fn fan_corners(patch: &Patch, fan: usize) -> [u32; 3] {
    [patch.corners[0], patch.corners[fan], patch.corners[fan + 1]]
}

/// A uniform grid over one face's patches in the face's plane: each cell lists the patches
/// whose bounding box overlaps it.
struct FaceGrid {
    origin: DVec3,
    axes: [DVec3; 2],
    cell: f64,
    size: [usize; 2],
    /// `cells[i]` for cell `i = x + size[0] * y`: indices into the mesh's patches.
    cells: Vec<Vec<u32>>,
}

impl FaceGrid {
    /// About one cell per patch over the patches' bounding rectangle in the face's plane.
    fn new(mesh: &Mesh, patches: Range<usize>) -> FaceGrid {
        let normal = mesh.patches[patches.start].normal;
        let (u, v) = normal.any_orthonormal_pair();
        let origin = mesh.patches[patches.start].centroid;
        let plane = |p: DVec3| DVec2::new((p - origin).dot(u), (p - origin).dot(v));
        let corner_boxes: Vec<(DVec2, DVec2)> = patches
            .clone()
            .map(|i| {
                let patch = &mesh.patches[i];
                let points = patch.corners[..patch.corner_count()]
                    .iter()
                    .map(|&c| plane(mesh.positions[c as usize]));
                points.fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p), hi.max(p))
                })
            })
            .collect();
        let (lo, hi) = corner_boxes
            .iter()
            .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b.0), hi.max(b.1))
            });
        let extent = (hi - lo).max(DVec2::splat(f64::MIN_POSITIVE));
        let cell = (extent.x * extent.y / patches.len() as f64)
            .sqrt()
            .max(extent.max_element() / 1024.0);
        let size = [
            ((extent.x / cell).ceil() as usize).clamp(1, 1024),
            ((extent.y / cell).ceil() as usize).clamp(1, 1024),
        ];
        let mut grid = FaceGrid {
            origin: origin + u * lo.x + v * lo.y,
            axes: [u, v],
            cell,
            size,
            cells: vec![Vec::new(); size[0] * size[1]],
        };
        for (i, (box_lo, box_hi)) in patches.zip(corner_boxes) {
            let ([x0, y0], [x1, y1]) = (grid.cell_of(box_lo - lo), grid.cell_of(box_hi - lo));
            for y in y0..=y1 {
                for x in x0..=x1 {
                    grid.cells[x + size[0] * y].push(i as u32);
                }
            }
        }
        grid
    }

    /// The cell holding in-plane offset `p` from the grid's origin, clamped to the grid.
    fn cell_of(&self, p: DVec2) -> [usize; 2] {
        let index = |t: f64, n: usize| ((t / self.cell).floor().max(0.0) as usize).min(n - 1);
        [index(p.x, self.size[0]), index(p.y, self.size[1])]
    }

    /// The patches that may hold `x`.
    fn candidates(&self, x: DVec3) -> &[u32] {
        let d = x - self.origin;
        let [cx, cy] = self.cell_of(DVec2::new(d.dot(self.axes[0]), d.dot(self.axes[1])));
        &self.cells[cx + self.size[0] * cy]
    }
}

/// How each face's patches are searched.
enum FaceIndex {
    Scan(Range<usize>),
    Grid(FaceGrid),
}

/// Point location on a mesh built face by face.
pub(super) struct PatchLocator {
    faces: Vec<FaceIndex>,
}

impl PatchLocator {
    /// Indexes `mesh`, whose patches come face by face, for `face_count` scene faces.
    pub(super) fn new(mesh: &Mesh, face_count: usize) -> PatchLocator {
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
        let faces = ranges
            .into_iter()
            .map(|range| match range.len() > SCANNED_PATCHES {
                true => FaceIndex::Grid(FaceGrid::new(mesh, range)),
                false => FaceIndex::Scan(range),
            })
            .collect();
        PatchLocator { faces }
    }

    /// Where `x`, a point of scene face `face`, lies in `mesh`: the fan triangle of the patch
    /// that holds it best (the largest smallest barycentric weight). `None` for a face with no
    /// patch.
    pub(super) fn place(&self, mesh: &Mesh, face: u32, x: DVec3) -> Option<Place> {
        let mut best: Option<(f64, Place)> = None;
        let mut consider = |i: usize| {
            let patch = &mesh.patches[i];
            let ids = &patch.corners[..patch.corner_count()];
            let mut positions = [DVec3::ZERO; 4];
            for (p, &c) in positions.iter_mut().zip(ids) {
                *p = mesh.positions[c as usize];
            }
            let (k, weights, inside) = fan_weights(&positions[..ids.len()], x);
            if best.is_none_or(|(b, _)| inside > b) {
                let place = Place {
                    patch: i,
                    fan: k,
                    weights,
                };
                best = Some((inside, place));
            }
        };
        match self.faces.get(face as usize)? {
            FaceIndex::Scan(range) => range.clone().for_each(&mut consider),
            FaceIndex::Grid(grid) => grid
                .candidates(x)
                .iter()
                .for_each(|&i| consider(i as usize)),
        }
        best.map(|(_, place)| place)
    }
}

#[cfg(test)]
mod tests {
    use super::{PatchLocator, SCANNED_PATCHES, fan_corners};
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
        assert!(count(0) > SCANNED_PATCHES && count(1) <= SCANNED_PATCHES);
        let locator = PatchLocator::new(&mesh, scene.faces.len());
        for (face, origin, u, v) in [
            (0, dvec3(-1.0, 0.5, 2.0), u, v),
            (1, DVec3::ZERO, small_u, small_v),
        ] {
            for k in 0..500 {
                let (s, t) = stratified_uv(k, 7);
                let x = origin + u * s + v * t;
                let place = locator.place(&mesh, face, x).expect("the face has patches");
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
