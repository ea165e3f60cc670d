//! Meshing: splitting each face into patches of roughly one target size.
//!
//! Quads become `nu x nv` grids whose cells are as square as the quad allows; triangles become
//! `k^2` triangles similar to the original, so no patch is thinner than the face it came from.

use crate::geometry::{Polygon, triangle_area};
use crate::scene::{Rgb, Scene};
use glam::{DAffine3, DVec3};
use rayon::prelude::*;

/// How finely to mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PatchTarget {
    /// About this many patches over the whole scene (at least one per face).
    Count(usize),
    /// Patches with edges of about this length, in scene units.
    EdgeLength(f64),
}

/// One patch: the unit of the radiosity solution, and what the server streams 4 bytes for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch {
    /// The patch's shape.
    pub polygon: Polygon,
    /// Indices into [`Mesh::positions`] of its corners, in the polygon's order (the fourth is
    /// unused for a triangle).
    pub corners: [u32; 4],
    /// Index of the scene face it came from.
    pub face: u32,
    /// Index of the scene object it belongs to.
    pub object: u32,
    /// Area in scene units squared.
    pub area: f64,
    /// Area-weighted centroid.
    pub centroid: DVec3,
    /// Unit normal of the front side.
    pub normal: DVec3,
    /// Bounding-sphere radius around the centroid.
    pub radius: f64,
    /// Diffuse reflectance.
    pub reflectance: Rgb,
    /// Emitted radiosity, W/m^2.
    pub emission: Rgb,
}

/// How far toward the centre of a patch that uses it a corner's light is read, as a fraction
/// of the distance: its shadow rays start there, and the reach tests burial there. Visibility
/// at a corner is so the mean over a small neighbourhood, not a point sample: a corner a
/// hair's breadth inside a contact line that falls between lattice points would otherwise
/// read fully dark while the probes just outside are lit (measured on the Cornell box: 0.25
/// lowers the smooth RMS at every knob; 1e-3 raises it at knob 0.05; 0.5 blurs penumbrae on
/// the shadow slab).
pub(crate) const CORNER_READING_INSET: f64 = 0.25;

/// The point [`CORNER_READING_INSET`] of the way from `corner` toward `inside`.
pub(crate) fn corner_reading_point(corner: DVec3, inside: DVec3) -> DVec3 {
    corner + (inside - corner) * CORNER_READING_INSET
}

impl Patch {
    /// Number of corners, three or four.
    pub fn corner_count(&self) -> usize {
        self.polygon.corners().len()
    }
}

/// The patches of a scene and the vertices they share (within a face).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Corner positions, shared by neighbouring patches of the same face.
    pub positions: Vec<DVec3>,
    /// The patches, face by face.
    pub patches: Vec<Patch>,
}

impl Mesh {
    /// Splits every face of `scene` into patches of about the target size.
    pub fn build(scene: &Scene, target: PatchTarget) -> Mesh {
        let edge = Self::edge_length(scene, target);
        let mut mesh = Mesh::default();
        for (face_index, face) in scene.faces.iter().enumerate() {
            let first_patch = mesh.patches.len();
            if face.polygon.is_quad() {
                mesh.split_quad(&face.polygon, edge);
            } else {
                mesh.split_triangle(&face.polygon, edge);
            }
            for patch in &mut mesh.patches[first_patch..] {
                patch.face = face_index as u32;
                patch.object = face.object;
                patch.reflectance = face.reflectance;
                patch.emission = face.emission;
            }
        }
        mesh
    }

    /// Patches [`Mesh::build`] would make for `target`, counted without building them: what
    /// a caller checks against memory before building.
    pub fn planned_count(scene: &Scene, target: PatchTarget) -> usize {
        Self::count_at(scene, Self::edge_length(scene, target))
    }

    fn edge_length(scene: &Scene, target: PatchTarget) -> f64 {
        match target {
            PatchTarget::Count(n) => Self::edge_length_for_count(scene, n),
            PatchTarget::EdgeLength(length) => length,
        }
    }

    /// Patches that [`Mesh::build`] makes for `scene` at this edge length, without building them.
    fn count_at(scene: &Scene, edge: f64) -> usize {
        scene
            .faces
            .iter()
            .map(|face| {
                let c = face.polygon.corners();
                if face.polygon.is_quad() {
                    let nu =
                        Self::cells_along(0.5 * (c[0].distance(c[1]) + c[3].distance(c[2])), edge);
                    let nv =
                        Self::cells_along(0.5 * (c[0].distance(c[3]) + c[1].distance(c[2])), edge);
                    nu as usize * nv as usize
                } else {
                    (Self::cells_along((2.0 * face.polygon.area()).sqrt(), edge) as usize).pow(2)
                }
            })
            .sum()
    }

    /// The edge length whose mesh comes closest to `count` patches. Rounding per face (and the
    /// one-patch minimum) makes the count a step function of the edge, so bisect on it.
    fn edge_length_for_count(scene: &Scene, count: usize) -> f64 {
        let total_area: f64 = scene.faces.iter().map(|f| f.polygon.area()).sum();
        let guess = (total_area / count.max(1) as f64).sqrt();
        // At the scene's diagonal every face is one cell, however thin (a sliver of small
        // area and huge length needs an edge far above the area's guess).
        let diagonal = scene.bounds().map_or(0.0, |(lo, hi)| lo.distance(hi));
        let (mut fine, mut coarse) = (guess / 8.0, (guess * 8.0).max(diagonal));
        for _ in 0..40 {
            let middle = (fine * coarse).sqrt();
            if Self::count_at(scene, middle) > count {
                fine = middle
            } else {
                coarse = middle
            }
        }
        let miss = |edge| Self::count_at(scene, edge).abs_diff(count);
        if miss(fine) < miss(coarse) {
            fine
        } else {
            coarse
        }
    }

    /// Per corner, the area-weighted mean of `values` (one per patch) over the patches that
    /// share it: how a patch solution becomes corner values where nothing better is at hand
    /// (progressive estimates, the emission-only state).
    pub fn corner_means(&self, values: &[Rgb]) -> Vec<Rgb> {
        let mut sums = vec![(Rgb::ZERO, 0.0); self.positions.len()];
        for (patch, value) in self.patches.iter().zip(values) {
            for &c in &patch.corners[..patch.corner_count()] {
                sums[c as usize].0 += *value * patch.area;
                sums[c as usize].1 += patch.area;
            }
        }
        sums.into_iter()
            .map(|(sum, area)| if area > 0.0 { sum / area } else { Rgb::ZERO })
            .collect()
    }

    /// Per patch, the mean over it of `values` (one per corner) interpolated linearly over its
    /// fan triangles, as viewers show them.
    pub fn patch_means(&self, values: &[Rgb]) -> Vec<Rgb> {
        (self.patches.par_iter())
            .map(|patch| self.interpolated_mean(&patch.corners[..patch.corner_count()], values))
            .collect()
    }

    /// The mean over a patch (corners `ids`) of `values` (one per corner) interpolated linearly
    /// over its fan triangles, as viewers show them.
    pub(crate) fn interpolated_mean(&self, ids: &[u32], values: &[Rgb]) -> Rgb {
        (ids.iter().zip(self.interpolation_weights(ids)))
            .map(|(&c, weight)| values[c as usize] * weight)
            .sum()
    }

    /// Per corner of a patch (corners `ids`), its weight in the mean of values interpolated
    /// linearly over the patch's fan triangles: a third of the area share of each fan triangle
    /// it is a corner of (all zero for a patch of no area).
    pub(crate) fn interpolation_weights(&self, ids: &[u32]) -> [f64; 4] {
        let at = |k: usize| self.positions[ids[k] as usize];
        let mut weights = [0.0; 4];
        let mut total = 0.0;
        for k in 1..ids.len() - 1 {
            let area = triangle_area(at(0), at(k), at(k + 1));
            for corner in [0, k, k + 1] {
                weights[corner] += area / 3.0;
            }
            total += area;
        }
        if total > 0.0 {
            weights.iter_mut().for_each(|w| *w /= total);
        }
        weights
    }

    /// Moves every patch of `object` (and the corners they use) rigidly by `motion`.
    pub fn move_object(&mut self, object: u32, motion: &DAffine3) {
        let mut moved = vec![false; self.positions.len()];
        for patch in self.patches.iter_mut().filter(|p| p.object == object) {
            patch.polygon = patch.polygon.moved(motion);
            patch.centroid = motion.transform_point3(patch.centroid);
            patch.normal = motion.transform_vector3(patch.normal);
            for &c in &patch.corners[..patch.polygon.corners().len()] {
                if !std::mem::replace(&mut moved[c as usize], true) {
                    self.positions[c as usize] =
                        motion.transform_point3(self.positions[c as usize]);
                }
            }
        }
    }

    fn push_patch(&mut self, polygon: Polygon, corners: [u32; 4]) {
        self.patches.push(Patch {
            polygon,
            corners,
            face: 0,
            object: 0,
            area: polygon.area(),
            centroid: polygon.centroid(),
            normal: polygon.normal(),
            radius: polygon.radius(),
            reflectance: Rgb::ZERO,
            emission: Rgb::ZERO,
        });
    }

    /// Number of cells along an edge of this length (at least one).
    fn cells_along(length: f64, edge: f64) -> u32 {
        // Cap so that a tiny `edge` cannot ask for more cells than memory holds.
        (length / edge).round().clamp(1.0, 65_535.0) as u32
    }

    fn split_quad(&mut self, quad: &Polygon, edge: f64) {
        let c = quad.corners();
        let nu = Self::cells_along(0.5 * (c[0].distance(c[1]) + c[3].distance(c[2])), edge);
        let nv = Self::cells_along(0.5 * (c[0].distance(c[3]) + c[1].distance(c[2])), edge);
        let base = self.positions.len() as u32;
        for b in 0..=nv {
            for a in 0..=nu {
                self.positions
                    .push(quad.point_at(a as f64 / nu as f64, b as f64 / nv as f64));
            }
        }
        let index = |a: u32, b: u32| base + b * (nu + 1) + a;
        for b in 0..nv {
            for a in 0..nu {
                let ids = [
                    index(a, b),
                    index(a + 1, b),
                    index(a + 1, b + 1),
                    index(a, b + 1),
                ];
                let p = ids.map(|i| self.positions[i as usize]);
                self.push_patch(Polygon::quad(p[0], p[1], p[2], p[3]), ids);
            }
        }
    }

    fn split_triangle(&mut self, triangle: &Polygon, edge: f64) {
        let c = triangle.corners();
        // k^2 similar triangles of area A / k^2: pick k so that area is about edge^2 / 2.
        let k = Self::cells_along((2.0 * triangle.area()).sqrt(), edge);
        let base = self.positions.len() as u32;
        let at = |s: u32, t: u32| {
            c[0] + (c[1] - c[0]) * (s as f64 / k as f64) + (c[2] - c[0]) * (t as f64 / k as f64)
        };
        // Row t holds the k + 1 - t lattice points with s = 0..=k-t.
        let mut row_start = Vec::with_capacity(k as usize + 1);
        for t in 0..=k {
            row_start.push(self.positions.len() as u32 - base);
            for s in 0..=k - t {
                self.positions.push(at(s, t));
            }
        }
        let index = |s: u32, t: u32| base + row_start[t as usize] + s;
        for t in 0..k {
            for s in 0..k - t {
                let up = [index(s, t), index(s + 1, t), index(s, t + 1)];
                let p = up.map(|i| self.positions[i as usize]);
                self.push_patch(
                    Polygon::triangle(p[0], p[1], p[2]),
                    [up[0], up[1], up[2], up[2]],
                );
                if s + t + 1 < k {
                    let down = [index(s + 1, t), index(s + 1, t + 1), index(s, t + 1)];
                    let p = down.map(|i| self.positions[i as usize]);
                    self.push_patch(
                        Polygon::triangle(p[0], p[1], p[2]),
                        [down[0], down[1], down[2], down[2]],
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Material;
    use glam::dvec3;

    fn scene_with(corners: &[DVec3]) -> Scene {
        let mut scene = Scene::default();
        let object = scene.add_object("plate");
        scene.add_polygon(
            object,
            corners,
            Material {
                reflectance: Rgb::splat(0.5),
                emission: Rgb::ZERO,
            },
        );
        scene
    }

    #[test]
    fn patches_tile_each_face_exactly() {
        let quad = scene_with(&[
            DVec3::ZERO,
            dvec3(4.0, 0.0, 0.0),
            dvec3(4.0, 1.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
        ]);
        let triangle = scene_with(&[DVec3::ZERO, dvec3(3.0, 0.0, 0.0), dvec3(0.0, 2.0, 0.0)]);
        for scene in [quad, triangle] {
            let area = scene.faces[0].polygon.area();
            for target in [
                PatchTarget::Count(1),
                PatchTarget::Count(37),
                PatchTarget::EdgeLength(0.1),
            ] {
                let mesh = Mesh::build(&scene, target);
                let sum: f64 = mesh.patches.iter().map(|p| p.area).sum();
                assert!((sum - area).abs() < 1e-9 * area, "{target:?}");
                assert!(
                    mesh.patches
                        .iter()
                        .all(|p| p.normal.distance(scene.faces[0].polygon.normal()) < 1e-9)
                );
            }
        }
    }

    #[test]
    fn quad_cells_follow_the_aspect_ratio() {
        let long = scene_with(&[
            DVec3::ZERO,
            dvec3(8.0, 0.0, 0.0),
            dvec3(8.0, 2.0, 0.0),
            dvec3(0.0, 2.0, 0.0),
        ]);
        let mesh = Mesh::build(&long, PatchTarget::Count(16));
        assert_eq!(mesh.patches.len(), 16);
        for p in &mesh.patches {
            let c = p.polygon.corners();
            let aspect = c[0].distance(c[1]) / c[0].distance(c[3]);
            assert!(
                (aspect - 1.0).abs() < 1e-9,
                "cells should be square, got {aspect}"
            );
        }
    }

    #[test]
    fn triangle_split_shares_vertices_and_keeps_shape() {
        let triangle = scene_with(&[DVec3::ZERO, dvec3(1.0, 0.0, 0.0), dvec3(0.0, 1.0, 0.0)]);
        let mesh = Mesh::build(&triangle, PatchTarget::EdgeLength(0.25));
        // Area 0.5: k = round(sqrt(2 * 0.5) / 0.25) = 4.
        let k = 4;
        assert_eq!(mesh.patches.len(), k * k);
        assert_eq!(mesh.positions.len(), (k + 1) * (k + 2) / 2);
        for p in &mesh.patches {
            assert!((p.area - 0.5 / (k * k) as f64).abs() < 1e-12);
            for (corner, &id) in p.polygon.corners().iter().zip(&p.corners) {
                assert_eq!(*corner, mesh.positions[id as usize]);
            }
        }
    }
}
