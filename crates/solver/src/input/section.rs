//! Sections: where one face runs across another (a rail through a baluster, a wall through a
//! ceiling, a beam through a wall), light falls on one side of the line they cross along and
//! not on the other, inside the solid. A large face is cut along the whole line of such a
//! section where the section runs along most of that line's chord through the face, so a cut
//! makes two pieces; a section closing on itself inside the face (a column's footprint through
//! a floor) is left to the hierarchy's reach, which splits the leaves straddling it. The same
//! discontinuity meshing as contact lines ([`super::contact`]; Heckbert 1992), for faces
//! that pass through one another, as real models' faces do.
//!
//! Measured on the monastery (docs/BENCHMARKS.md, 2026-12-06 evening): smooth RMS 5.10 / 5.25
//! / 5.45% -> 4.06 / 4.34 / 4.30% (seeds 0-2), a quarter more time, 1.6 -> 1.9 GB.

use super::lines::{FacePlane, Line, chord, crosses_interior};
use crate::scene::Face;
use glam::DVec3;

/// Least area a face must have, in median face areas, to be cut along its sections: below it
/// the pieces cost more leaves, gather points and memory than their light is worth (on the
/// monastery, cutting every face made 285k faces of 126k, 56-63 s and 2.3 GB for 4.2-4.4%;
/// faces of at least 4 median areas, 217k faces, 51-55 s and 1.9 GB for 4.2-4.4%; of at
/// least 16, 164k faces, 43-46 s, 4.5-6.0%).
pub(super) const MIN_AREA_IN_MEDIANS: f64 = 4.0;

/// Least share of its line's chord through a face that a section must run along for the face
/// to be cut by that whole line: half, so a wall ending inside a ceiling cuts it, a short
/// footprint inside a long face does not (spanning all of it: 6.15% on the monastery, seed 0,
/// against 4.39% at half).
const SPANNING_SHARE: f64 = 0.5;

/// The faces with an edge among `near` (the edges near face `index`, whose plane is `plane`)
/// that passes through the face's interior, where the face or the other is `large` (only
/// those are cut by sections). Two convex faces that cross meet so, one way or the other.
pub(super) fn pierced_by(
    faces: &[Face],
    (index, plane): (usize, &FacePlane),
    near: &[(u32, u8)],
    large: &[bool],
) -> Vec<u32> {
    let (normal, corners, tolerance) = (plane.normal, plane.corners, plane.tolerance);
    let mut by: Vec<u32> = (near.iter())
        .filter(|&&(other, k)| {
            if other as usize == index || !(large[index] || large[other as usize]) {
                return false;
            }
            let c = faces[other as usize].polygon.corners();
            let (p, q) = (c[k as usize], c[(k as usize + 1) % c.len()]);
            let (a, b) = (plane.height(p), plane.height(q));
            let through = (a > tolerance && b < -tolerance) || (a < -tolerance && b > tolerance);
            through && strictly_inside(corners, normal, p + (q - p) * (a / (a - b)), tolerance)
        })
        .map(|&(other, _)| other)
        .collect();
    by.dedup();
    by
}

/// Per face, whether it is large enough to be cut along its sections: at least `min_area`.
pub(super) fn large_faces(faces: &[Face], min_area: f64) -> Vec<bool> {
    faces.iter().map(|f| f.polygon.area() >= min_area).collect()
}

/// Per `large` face (empty for the others), the faces crossing it, from each face's
/// [`pierced_by`] list: a pair counts whichever of the two faces an edge of the other pierces.
pub(super) fn crossing_partners(pierced: Vec<Vec<u32>>, large: &[bool]) -> Vec<Vec<u32>> {
    let mut partners = vec![Vec::new(); pierced.len()];
    for (index, by) in pierced.into_iter().enumerate() {
        for other in by {
            if large[index] {
                partners[index].push(other);
            }
            if large[other as usize] {
                partners[other as usize].push(index as u32);
            }
        }
    }
    for list in &mut partners {
        list.sort_unstable();
        list.dedup();
    }
    partners
}

/// Whether `x` (in the plane of the convex polygon `corners`) lies inside it by more than
/// `tolerance`.
fn strictly_inside(corners: &[DVec3], normal: DVec3, x: DVec3, tolerance: f64) -> bool {
    (0..corners.len()).all(|k| {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        let inward = normal.cross(b - a);
        (x - a).dot(inward) > tolerance * inward.length()
    })
}

/// The sections of face `index` by the faces crossing it (`partners`) that run along at
/// least [`SPANNING_SHARE`] of their line's chord through it, as lines to cut it by.
pub(super) fn spanning_sections(faces: &[Face], index: usize, partners: &[u32]) -> Vec<Line> {
    let plane = FacePlane::of(&faces[index].polygon);
    let (normal, corners, tolerance) = (plane.normal, plane.corners, plane.tolerance);
    let height = |p: DVec3| plane.height(p);
    let mut lines = Vec::new();
    for &other in partners {
        let crossing = &faces[other as usize].polygon;
        if crossing.normal().dot(normal).abs() > 1.0 - 1e-9 {
            continue;
        }
        // Where the convex crossing face's edges pass through the face's plane: its section.
        let c = crossing.corners();
        let ends: Vec<DVec3> = (0..c.len())
            .filter_map(|k| {
                let (p, q) = (c[k], c[(k + 1) % c.len()]);
                let (a, b) = (height(p), height(q));
                ((a > 0.0) != (b > 0.0)).then(|| p + (q - p) * (a / (a - b)))
            })
            .collect();
        let (Some(&p), Some(&q)) = (ends.first(), ends.last()) else {
            continue;
        };
        let Some((chord_enter, chord_leave)) = chord(corners, normal, p, q) else {
            continue;
        };
        let along = (chord_leave.min(1.0) - chord_enter.max(0.0)).max(0.0);
        // `crosses_interior` also asks the part inside to be longer than the tolerance.
        if along >= SPANNING_SHARE * (chord_leave - chord_enter)
            && crosses_interior(corners, normal, p, q, tolerance)
        {
            lines.push(Line {
                point: p,
                direction: q - p,
            });
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::super::contact::split_faces_at_contacts;
    use super::super::lines::FacePlane;
    use super::{large_faces, pierced_by};
    use crate::hierarchy::fixtures::{GREY, add_parallelogram};
    use crate::scene::{Face, Scene};
    use glam::{DVec3, dvec3};

    /// A 10 x 10 floor facing up, centred on the origin.
    fn add_floor(scene: &mut Scene) {
        let (x, z) = (DVec3::X, DVec3::Z);
        let corner = dvec3(-5.0, 0.0, -5.0);
        add_parallelogram(scene, "floor", (corner, z * 10.0, x * 10.0), GREY);
    }

    /// `count` 0.1 x 0.1 tiles facing up, `per_row` along x, `spacing` apart from `first`.
    fn add_tiles(scene: &mut Scene, first: DVec3, (count, per_row): (usize, usize), spacing: f64) {
        let (x, z) = (DVec3::X, DVec3::Z);
        for i in 0..count {
            let o = first + (x * (i % per_row) as f64 + z * (i / per_row) as f64) * spacing;
            add_parallelogram(scene, "tile", (o, z * 0.1, x * 0.1), GREY);
        }
    }

    /// The areas of the pieces of object `object`, smallest first.
    fn areas(faces: &[Face], object: u32) -> Vec<f64> {
        let mut areas: Vec<f64> = (faces.iter())
            .filter(|f| f.object == object)
            .map(|f| f.polygon.area())
            .collect();
        areas.sort_by(f64::total_cmp);
        areas
    }

    #[test]
    fn a_wall_and_a_shelf_through_it_are_cut_along_the_line_they_cross_on() {
        // A 4 x 4 wall (object 0) in the plane z = 0 and a 6 x 2 shelf (object 1) at y = 1
        // running through it, from x = -1 to 5 and z = -1 to 1: each runs across the other.
        // Three 0.1 x 0.1 tiles far away make the median face small.
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        let mut scene = Scene::default();
        add_parallelogram(&mut scene, "wall", (DVec3::ZERO, x * 4.0, y * 4.0), GREY);
        add_parallelogram(
            &mut scene,
            "shelf",
            (dvec3(-1.0, 1.0, -1.0), z * 2.0, x * 6.0),
            GREY,
        );
        add_tiles(&mut scene, dvec3(50.0, 0.0, 50.0), (3, 3), 1.0);
        let (faces, cut) = split_faces_at_contacts(scene.faces.clone());
        assert_eq!(cut, 2, "the wall and the shelf");
        assert_eq!(areas(&faces, 0), [4.0, 12.0], "below and above the shelf");
        assert_eq!(
            areas(&faces, 1),
            [6.0, 6.0],
            "in front of and behind the wall"
        );
        for piece in faces.iter().filter(|f| f.object == 0) {
            let c = piece.polygon.corners();
            assert!(
                c.iter().all(|p| p.y <= 1.0) || c.iter().all(|p| p.y >= 1.0),
                "{c:?}"
            );
        }
    }

    #[test]
    fn a_post_through_a_floor_is_left_to_the_reach_and_small_faces_stay_whole() {
        // A post 0.2 m across from y = -1 to 1 through a 10 x 10 floor: its sides' sections
        // close a footprint inside the floor, each along 2% of its line's chord; the floor
        // runs across each side, whose area (0.4 m^2, the median) is too small to cut.
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        let mut scene = Scene::default();
        add_floor(&mut scene);
        let (corner, side) = (dvec3(-0.1, -1.0, -0.1), 0.2);
        for (o, u) in [
            (corner, x * side),
            (corner + x * side, z * side),
            (corner + (x + z) * side, -x * side),
            (corner + z * side, -z * side),
        ] {
            add_parallelogram(&mut scene, "post", (o, u, y * 2.0), GREY);
        }
        let (faces, cut) = split_faces_at_contacts(scene.faces.clone());
        assert_eq!((faces.len(), cut), (5, 0));
    }

    #[test]
    fn a_pierced_list_holds_what_it_found_not_the_edges_it_looked_at() {
        // A 10 x 10 floor under 1,000 tiles lying 1 cm above it: 4,000 edges near the floor,
        // none through it. Collected in place from the near edges, every face's list kept
        // their buffer (4.5 GB over the village's million faces).
        let mut scene = Scene::default();
        add_floor(&mut scene);
        add_tiles(&mut scene, dvec3(-5.0, 0.01, -5.0), (1000, 40), 0.25);
        let near: Vec<(u32, u8)> = (1..=1000)
            .flat_map(|f| (0..4).map(move |k| (f, k)))
            .collect();
        let large = large_faces(&scene.faces, 1.0);
        let plane = FacePlane::of(&scene.faces[0].polygon);
        let by = pierced_by(&scene.faces, (0, &plane), &near, &large);
        assert_eq!((by.len(), by.capacity()), (0, 0));
    }
}
