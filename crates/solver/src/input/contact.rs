//! Contact lines: where one face stands on another (a box on a floor, a wall on the ground),
//! the face under it is cut along the line they share, so that no element, and no smoothly
//! shaded patch, straddles it. Light falls on one side of such a line and none on the other;
//! straddled, the lit side was interpolated toward the dark one, and within 4 mm of the
//! Cornell blocks lay 70% of the box's squared error (docs/BENCHMARKS.md). This is the first
//! step of discontinuity meshing (Heckbert 1992, "Discontinuity Meshing for Radiosity";
//! Lischinski, Tampieri, Greenberg 1992): the contact discontinuities, known from the geometry
//! alone, before any light.
//!
//! Around its contact segments a face is quartered until the segments are as long as the
//! quarters, and each quarter is cut by the whole lines of the segments crossing it, so every
//! piece stays convex and the cuts stay near the contacts. The pieces keep the face's
//! material, object and orientation and name it as their source ([`Face::source`]).

use super::lines::{EdgeGrid, FacePlane, Line, RELATIVE_TOLERANCE, crosses_interior, side};
use super::section;
use crate::geometry::{Polygon, convex_pieces};
use crate::scene::{Face, Scene};
use glam::DVec3;
use rayon::prelude::*;

/// Most pieces a face is cut into per contact segment on it. A segment quarters about two
/// cells a level and cuts the last ones: a few dozen pieces.
const MAX_PIECES_PER_SEGMENT: usize = 64;

/// Cuts every face of `scene` along the contact lines of the faces standing on it; each
/// face's [`Face::source`] becomes its index before the cut.
pub(crate) fn split_at_contacts(scene: &mut Scene) {
    for (index, face) in scene.faces.iter_mut().enumerate() {
        face.source = index as u32;
    }
    let triangles = scene.triangle_count();
    let (faces, cut) = split_faces_at_contacts(std::mem::take(&mut scene.faces));
    (scene.faces, scene.faces_cut_at_contacts) = (faces, cut);
    scene.triangles_before_cuts = triangles;
}

/// `faces` with every face cut along the contact segments of the faces that stand on it (and,
/// first, a large face along the sections that run across it: [`section`]), and how many faces
/// were cut. Pieces of one face follow one another, in the face's place. Faces
/// are cut in parallel (on the 125k-triangle monastery the cuts were most of its serial load).
pub(super) fn split_faces_at_contacts(faces: Vec<Face>) -> (Vec<Face>, usize) {
    let grid = EdgeGrid::new(&faces);
    let large = section::large_faces(&faces, section::MIN_AREA_IN_MEDIANS * grid.median_area);
    // One look at the edges near each face finds what stands on it and what crosses it.
    let (segments, pierced): (Vec<Vec<Line>>, Vec<Vec<u32>>) = (0..faces.len())
        .into_par_iter()
        .map(|index| {
            let plane = FacePlane::of(&faces[index].polygon);
            let near = grid.edges_near_face(&plane);
            (
                contact_segments(&faces, (index, &plane), &near),
                section::pierced_by(&faces, (index, &plane), &near, &large),
            )
        })
        .unzip();
    let partners = section::crossing_partners(pierced, &large);
    let cut_faces: Vec<(Vec<Polygon>, bool)> = (0..faces.len())
        .into_par_iter()
        .map(|index| {
            let face = &faces[index];
            let normal = face.polygon.normal();
            let segments = &segments[index];
            let sections = section::spanning_sections(&faces, index, &partners[index]);
            // The sections' whole lines first, then each convex piece around its contacts.
            let tolerance = RELATIVE_TOLERANCE * face.polygon.radius();
            let mut pieces: Vec<Vec<DVec3>> =
                cut_along(face.polygon.corners(), normal, &sections, tolerance)
                    .into_iter()
                    .flat_map(|piece| convex_pieces(&without_straight_corners(piece)))
                    .flat_map(|piece| cut_locally(piece.corners().to_vec(), normal, segments, 0))
                    .collect();
            // A bound whatever the input: past it the face stays whole, as before contact
            // lines.
            if pieces.len() > MAX_PIECES_PER_SEGMENT * (segments.len() + sections.len()) {
                pieces = vec![face.polygon.corners().to_vec()];
            }
            let cut = pieces.len() > 1;
            (with_area(pieces, face.polygon.area()), cut)
        })
        .collect();
    let cut = cut_faces.iter().filter(|(_, cut)| *cut).count();
    let mut split = Vec::with_capacity(faces.len());
    for (face, (pieces, _)) in faces.iter().zip(cut_faces) {
        split.extend(pieces.into_iter().map(|polygon| Face {
            polygon,
            ..face.clone()
        }));
    }
    (split, cut)
}

/// Segments crossing a cell that are cut by their whole lines without quartering it first:
/// whole lines leave no T-junction (quarters of different depths meet at T-junctions, where
/// f32 rays slip through a crack and visibility turned on rounding: the Cornell box scaled by
/// 1e-14 refined six leaves more), and a few lines across a face are cheap.
const FEW_SEGMENTS: usize = 16;

/// Deepest quartering of a face around its contact segments ([`cut_locally`]).
const MAX_CELL_DEPTH: u32 = 16;

/// The pieces of a face of area `area` as convex polygons, but those of no area next to it (a
/// fan triangle of corners a cut left in line): a leaf of no area has no mean, and one sent
/// the leaves' solve to NaN.
fn with_area(pieces: Vec<Vec<DVec3>>, area: f64) -> Vec<Polygon> {
    (pieces.into_iter())
        .flat_map(|piece| convex_pieces(&without_straight_corners(piece)))
        .filter(|piece| piece.area() > RELATIVE_TOLERANCE * RELATIVE_TOLERANCE * area)
        .collect()
}

/// The contact segments on face `index` (`plane`): edges among `near` (the edges near it) of
/// faces that stand in front of it, not in its plane, lying in its plane and crossing its
/// interior.
fn contact_segments(
    faces: &[Face],
    (index, plane): (usize, &FacePlane),
    near: &[(u32, u8)],
) -> Vec<Line> {
    let face = &faces[index].polygon;
    let (normal, corners, tolerance) = (plane.normal, plane.corners, plane.tolerance);
    let mut lines = Vec::new();
    for &(other, k) in near {
        let standing = &faces[other as usize].polygon;
        if other as usize == index || standing.normal().dot(normal).abs() > 1.0 - 1e-9 {
            continue;
        }
        let c = standing.corners();
        let (p, q) = (c[k as usize], c[(k as usize + 1) % c.len()]);
        // In the plane to a part in a million of the edge itself, not of the face: within a
        // million-metre face's tolerance, a lamp a metre above it lay "in" it.
        let flat = RELATIVE_TOLERANCE * p.distance(q).min(face.radius());
        let in_plane = plane.height(p).abs() <= flat && plane.height(q).abs() <= flat;
        let in_front = c.iter().any(|v| plane.height(*v) > tolerance);
        if in_plane && in_front && crosses_interior(corners, normal, p, q, tolerance) {
            lines.push(Line {
                point: p,
                direction: q - p,
            });
        }
    }
    lines
}

/// The convex `cell` (of a face with normal `normal`) cut along `segments` locally: quartered
/// while segments cross it and it is more than twice as wide as the longest of them, then cut
/// by the whole lines of those that cross each quarter. A box's footprint so cuts the floor
/// around it only; lines across the whole floor, one per edge of each piece of furniture,
/// cut a furnished room's floor into slivers by the thousand.
fn cut_locally(cell: Vec<DVec3>, normal: DVec3, segments: &[Line], depth: u32) -> Vec<Vec<DVec3>> {
    let centre = cell.iter().sum::<DVec3>() / cell.len() as f64;
    let radius = cell.iter().map(|c| c.distance(centre)).fold(0.0, f64::max);
    let tolerance = RELATIVE_TOLERANCE * radius;
    let crossing: Vec<Line> = segments
        .iter()
        .copied()
        .filter(|s| crosses_interior(&cell, normal, s.point, s.point + s.direction, tolerance))
        .collect();
    let longest = crossing
        .iter()
        .map(|s| s.direction.length())
        .fold(0.0, f64::max);
    if crossing.len() <= FEW_SEGMENTS || depth == MAX_CELL_DEPTH || radius <= 2.0 * longest {
        return cut_along(&cell, normal, &crossing, tolerance);
    }
    quarters(&cell)
        .into_iter()
        .flat_map(|quarter| cut_locally(quarter, normal, &crossing, depth + 1))
        .collect()
}

/// A triangle or quad in four: by its edges' midpoints (and a quad's centre).
fn quarters(cell: &[DVec3]) -> Vec<Vec<DVec3>> {
    let mid = |a: DVec3, b: DVec3| (a + b) / 2.0;
    match *cell {
        [a, b, c] => {
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            vec![
                vec![a, ab, ca],
                vec![ab, b, bc],
                vec![ca, bc, c],
                vec![ab, bc, ca],
            ]
        }
        [a, b, c, d] => {
            let (ab, bc, cd, da) = (mid(a, b), mid(b, c), mid(c, d), mid(d, a));
            let centre = (a + b + c + d) / 4.0;
            vec![
                vec![a, ab, centre, da],
                vec![ab, b, bc, centre],
                vec![centre, bc, c, cd],
                vec![da, centre, cd, d],
            ]
        }
        _ => vec![cell.to_vec()],
    }
}

/// The convex polygon `corners` cut by each of `lines` that crosses it: convex pieces, their
/// corners in the polygon's order. A cut that would leave a piece thinner than `tolerance` is
/// not made.
fn cut_along(corners: &[DVec3], normal: DVec3, lines: &[Line], tolerance: f64) -> Vec<Vec<DVec3>> {
    let mut pieces = vec![corners.to_vec()];
    for &line in lines {
        pieces = pieces
            .into_iter()
            .flat_map(|piece| {
                let sides: Vec<f64> = piece.iter().map(|c| side(line, normal, *c)).collect();
                let crosses =
                    sides.iter().any(|s| *s > tolerance) && sides.iter().any(|s| *s < -tolerance);
                if crosses {
                    vec![clip(&piece, &sides, 1.0), clip(&piece, &sides, -1.0)]
                } else {
                    vec![piece]
                }
            })
            .collect();
    }
    pieces
}

/// The part of `piece` where `sign * side >= 0` (Sutherland-Hodgman against one line), with
/// `sides` its corners' signed distances.
fn clip(piece: &[DVec3], sides: &[f64], sign: f64) -> Vec<DVec3> {
    let mut kept = Vec::with_capacity(piece.len() + 1);
    for k in 0..piece.len() {
        let next = (k + 1) % piece.len();
        let (a, b) = (sign * sides[k], sign * sides[next]);
        if a >= 0.0 {
            kept.push(piece[k]);
        }
        if (a > 0.0 && b < 0.0) || (a < 0.0 && b > 0.0) {
            kept.push(piece[k] + (piece[next] - piece[k]) * (a / (a - b)));
        }
    }
    kept
}

/// `piece` without the corners where it runs straight on (a cut's end on an edge leaves one):
/// whether such a corner turns a hair left or right is rounding, and it decided between a quad
/// and two triangles differently at different scales.
fn without_straight_corners(mut piece: Vec<DVec3>) -> Vec<DVec3> {
    let size = piece
        .iter()
        .map(|c| c.distance(piece[0]))
        .fold(0.0, f64::max);
    let mut k = 0;
    while piece.len() > 3 && k < piece.len() {
        let n = piece.len();
        let (before, corner, after) = (piece[(k + n - 1) % n], piece[k], piece[(k + 1) % n]);
        let chord = after - before;
        let off_line =
            chord.cross(corner - before).length() / chord.length().max(f64::MIN_POSITIVE);
        if off_line <= RELATIVE_TOLERANCE * size {
            piece.remove(k);
        } else {
            k += 1;
        }
    }
    piece
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Material, Rgb, Scene};
    use glam::dvec3;

    /// A 10 x 10 floor (face 0, facing +y) with a unit box standing on it from (2, 0, 3),
    /// four sides and a top, no bottom.
    fn box_on_a_floor() -> Scene {
        let mut scene = Scene::default();
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let floor = scene.add_object("floor");
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        let quad = |o: DVec3, u: DVec3, v: DVec3| [o, o + u, o + u + v, o + v];
        scene.add_polygon(floor, &quad(DVec3::ZERO, z * 10.0, x * 10.0), grey);
        let cube = scene.add_object("box");
        let lo = dvec3(2.0, 0.0, 3.0);
        for (o, u, v) in [
            (lo + y, z, x),
            (lo, z, y),
            (lo + x, y, z),
            (lo, y, x),
            (lo + z, x, y),
        ] {
            scene.add_polygon(cube, &quad(o, u, v), grey);
        }
        scene
    }

    #[test]
    fn a_floor_is_cut_along_the_footprint_of_a_box_standing_on_it() {
        let scene = box_on_a_floor();
        let floor = scene.faces[0].clone();
        let (faces, cut) = split_faces_at_contacts(scene.faces.clone());
        assert_eq!(cut, 1, "only the floor is cut");
        let pieces: Vec<&Face> = faces.iter().filter(|f| f.object == floor.object).collect();
        // Four segments, few enough to cut by their whole lines: a 3 x 3 grid of quads.
        assert_eq!(pieces.len(), 9);
        let area: f64 = pieces.iter().map(|f| f.polygon.area()).sum();
        assert!((area / floor.polygon.area() - 1.0).abs() < 1e-12, "{area}");
        for piece in &pieces {
            assert_eq!(piece.polygon.normal(), floor.polygon.normal());
            assert_eq!(
                (piece.reflectance, piece.emission),
                (floor.reflectance, floor.emission)
            );
            // No piece straddles the footprint: each lies wholly inside it or outside.
            let strictly_inside = |p: &DVec3| 2.0 < p.x && p.x < 3.0 && 3.0 < p.z && p.z < 4.0;
            let within = |p: &DVec3| (2.0..=3.0).contains(&p.x) && (3.0..=4.0).contains(&p.z);
            let c = piece.polygon.corners();
            if strictly_inside(&piece.polygon.centroid()) {
                assert!(c.iter().all(within), "{c:?}");
            } else {
                assert!(!c.iter().any(strictly_inside), "{c:?}");
            }
            assert_eq!(piece.source, 0);
        }
        let under: f64 = pieces
            .iter()
            .filter(|f| {
                let m = f.polygon.centroid();
                (2.0..3.0).contains(&m.x) && (3.0..4.0).contains(&m.z)
            })
            .map(|f| f.polygon.area())
            .sum();
        assert!(
            (under - 1.0).abs() < 1e-12,
            "the footprint is one piece: {under}"
        );
        // The box's own faces are left whole: they stand on nothing.
        assert_eq!(faces.len(), pieces.len() + 5);
    }

    #[test]
    fn faces_meeting_along_an_edge_cut_nothing() {
        // The closed cube of the hierarchy tests: every wall meets its neighbours at their
        // edges, and coplanar tiles of a tessellated floor meet likewise.
        let cube = crate::hierarchy::fixtures::closed_cube();
        let (faces, cut) = split_faces_at_contacts(cube.faces.clone());
        assert_eq!((cut, faces.len()), (0, cube.faces.len()));
        let mut tiles = Scene::default();
        let floor = tiles.add_object("floor");
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        for i in 0..3 {
            let o = dvec3(i as f64, 0.0, 0.0);
            tiles.add_polygon(
                floor,
                &[o, o + DVec3::Z, o + DVec3::Z + DVec3::X, o + DVec3::X],
                grey,
            );
        }
        assert_eq!(split_faces_at_contacts(tiles.faces.clone()).1, 0);
    }

    #[test]
    fn a_large_slanted_face_among_many_small_ones_is_searched_by_the_occupied_cells() {
        // Tiny triangles make the grid fine (1,024 cells a side); a sliver slanted across the
        // whole scene has a box of 1,024^3 cells and edges as long as the scene: their boxes
        // walked cell by cell would take minutes and gigabytes. Nothing stands on anything.
        let mut scene = Scene::default();
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let object = scene.add_object("dust");
        for i in 0..2_000 {
            let o = dvec3((i % 13) as f64, (i % 7) as f64, (i % 11) as f64) * 7.0;
            scene.add_polygon(object, &[o, o + DVec3::X * 1e-3, o + DVec3::Y * 1e-3], grey);
        }
        let sliver = scene.add_object("sliver");
        let far = dvec3(100.0, 100.0, 100.0);
        scene.add_polygon(sliver, &[DVec3::ZERO, far, far + DVec3::Z * 1e-3], grey);
        let (faces, cut) = split_faces_at_contacts(scene.faces.clone());
        assert_eq!((faces.len(), cut), (scene.faces.len(), 0));
    }

    #[test]
    fn pieces_of_no_area_are_dropped() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Z);
        // A triangle whose corners lie in line has no area and goes; a sliver 1e-5 wide, a
        // real piece, stays.
        let pieces = vec![
            vec![a, b, c],
            vec![a, b, b * 2.0],
            vec![a, b, dvec3(1.0, 0.0, 1e-5)],
        ];
        let kept = with_area(pieces, 0.5);
        assert_eq!(kept.len(), 2);
        assert_eq!(kept[0].area(), 0.5);
        assert!(
            (kept[1].area() - 0.5e-5).abs() < 1e-18,
            "{}",
            kept[1].area()
        );
    }

    #[test]
    fn a_line_near_a_corner_leaves_no_sliver() {
        let square = [DVec3::ZERO, DVec3::Z, DVec3::Z + DVec3::X, DVec3::X];
        let near_edge = Line {
            point: dvec3(1e-9, 0.0, 0.0),
            direction: DVec3::Z,
        };
        assert_eq!(cut_along(&square, DVec3::Y, &[near_edge], 1e-6).len(), 1);
        let middle = Line {
            point: dvec3(0.5, 0.0, 0.0),
            direction: DVec3::Z,
        };
        assert_eq!(cut_along(&square, DVec3::Y, &[middle], 1e-6).len(), 2);
    }
}
