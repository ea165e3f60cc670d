//! Where light can reach: a leaf point is buried when all but one of the cosine rays from it
//! meet the back of a face (under a box on the floor, inside a wall that cuts through it).
//! Sources send their mean over the reached area, errors are measured against the mean over
//! it, what an element gathers is pushed down to its reached parts only, leaves whose points
//! disagree, or that a face crosses between them, straddle the edge of the reach (refinement
//! splits them), and a leaf's corners are shared only with leaves on the same side of it.

use super::tree::{NONE, Tree};
use crate::mesh::{Patch, corner_reading_point};
use crate::sampling::pair_seed;
use crate::scene::Rgb;
use crate::visibility::Occluders;
use glam::DVec3;
use rayon::prelude::*;

/// How much of each node light can reach.
#[derive(Default)]
pub(super) struct Reach {
    /// Per node ever a leaf, the share of its area not buried; NaN until measured.
    pub(super) seen_share: Vec<f64>,
    /// Per node, the area of its leaves that light can reach: what a source's mean is taken over.
    pub(super) seen_area: Vec<f64>,
    /// Per node, the factor on the irradiance its parent element gathered as it is pushed down
    /// to it ([`Reach::push_weights`]); 1 below a cluster.
    pub(super) push_weight: Vec<f64>,
    /// Per node ever a leaf, whether some of its points are buried and some reached: it
    /// straddles the edge of where light reaches.
    pub(super) straddles: Vec<bool>,
    /// Per node ever a leaf, whether each corner's reading point ([`corner_insets`]) is
    /// buried: viewers' corner values on either side of where light reaches are kept apart.
    pub(super) buried_corners: Vec<[bool; 4]>,
    /// How far apart, about, a large leaf's test points lie ([`Reach::spaced`]); `None`: one
    /// quadrature cell a leaf, whatever its size.
    point_spacing: Option<f64>,
}

/// The most quadrature cells along a side a leaf is tested with ([`Reach::spaced`]): 256
/// points on a quad, 192 on a triangle, each [`Occluders::is_buried`]'s rays.
const MOST_TEST_CELLS: f64 = 8.0;

/// How far above a leaf the segments that look for a face crossing it run, as a fraction of
/// its radius: above round-off and coplanar duplicates, below any real solid's thickness.
const CROSSING_LIFT: f64 = 1e-3;

/// The points of `patch` where viewers' corner values are read
/// ([`corner_reading_point`], toward the centroid).
fn corner_insets(patch: &Patch) -> Vec<DVec3> {
    let centroid = patch.centroid;
    (patch.polygon.corners().iter())
        .map(|&c| corner_reading_point(c, centroid))
        .collect()
}

/// Whether some face crosses or stands on `patch` (radius `radius`) between its corner insets
/// ([`corner_insets`]): a segment just above its surface from each inset to the next and to
/// the centroid meets a face. Such a face bounds a buried part the leaf's test points all
/// missed, or a contact line, where light changes at once.
fn a_face_crosses(patch: &Patch, insets: &[DVec3], radius: f64, occluders: &Occluders) -> bool {
    let lift = patch.normal * (radius * CROSSING_LIFT);
    let centroid = patch.centroid + lift;
    let own = [patch.face, patch.face];
    (0..insets.len()).any(|k| {
        let (inset, next) = (insets[k] + lift, insets[(k + 1) % insets.len()] + lift);
        !occluders.segment_is_clear(inset, next, own)
            || !occluders.segment_is_clear(inset, centroid, own)
    })
}

impl Reach {
    /// Nothing measured yet; each leaf tested at points about `spacing` apart along its
    /// sides (at most [`MOST_TEST_CELLS`] cells a side), the corners' reading points among
    /// them. Tested at one cell's points alone, a 41 x 44 m leaf of the monastery's ground
    /// missed the 3 m strip of it under a platform, where no light reaches: nothing split it,
    /// and its corners' light, interpolated, lit the ground under the platform (0.22 where
    /// the reference reads 0.006) unless a display split happened to catch it.
    pub(super) fn spaced(spacing: f64) -> Reach {
        Reach {
            point_spacing: Some(spacing),
            ..Reach::default()
        }
    }

    /// The quadrature level a leaf of radius `radius` is tested at ([`Reach::spaced`]).
    fn test_level(&self, radius: f64) -> u32 {
        self.point_spacing.map_or(1, |spacing| {
            (radius / spacing).ceil().clamp(1.0, MOST_TEST_CELLS) as u32
        })
    }

    /// Measures the leaves of `tree` not measured yet and sums the reached area up the trees.
    pub(super) fn measure(&mut self, tree: &Tree, occluders: &Occluders) {
        self.measure_leaves(tree, &self.unmeasured(tree), occluders);
        self.sum_reached_area(tree);
    }

    /// The leaves of `tree` not measured yet.
    pub(super) fn unmeasured(&self, tree: &Tree) -> Vec<u32> {
        (tree.leaves.iter().copied())
            .filter(|&n| self.seen_share.get(n as usize).is_none_or(|s| s.is_nan()))
            .collect()
    }

    /// Measures the leaves `leaves` of `tree`: their reached share, whether they straddle the
    /// edge of the reach, and which corners are buried. The reached areas are summed up the
    /// trees apart ([`Reach::sum_reached_area`]), once a run of splits is over.
    pub(super) fn measure_leaves(&mut self, tree: &Tree, leaves: &[u32], occluders: &Occluders) {
        self.seen_share.resize(tree.nodes.len(), f64::NAN);
        self.straddles.resize(tree.nodes.len(), false);
        self.buried_corners.resize(tree.nodes.len(), [false; 4]);
        let measured: Vec<(f64, bool, [bool; 4])> = leaves
            .par_iter()
            .map(|&n| {
                let patch = tree.element_patch(n);
                let level = self.test_level(tree.nodes[n as usize].radius);
                let mut quadrature = Vec::with_capacity(4 * (level * level) as usize);
                patch
                    .polygon
                    .for_each_quadrature_point(level, |x, weight| quadrature.push((x, weight)));
                // Also where viewers' corner values are read: a corner of a sliver can lie
                // inside a wall its quadrature points miss.
                let insets = corner_insets(patch);
                let unweighted = insets.iter().map(|&x| (x, 0.0));
                let first_inset = quadrature.len();
                let (mut reached_weight, mut buried_weight) = (0.0, 0.0);
                let (mut buried, mut points) = (0, 0);
                let mut buried_corners = [false; 4];
                for (k, (x, weight)) in quadrature.into_iter().chain(unweighted).enumerate() {
                    points += 1;
                    let seed = pair_seed(n as usize, k + 1);
                    if occluders.is_buried(x, patch.normal, patch.face, seed) {
                        buried += 1;
                        buried_weight += weight;
                        if let Some(corner) = k.checked_sub(first_inset) {
                            buried_corners[corner] = true;
                        }
                    } else {
                        reached_weight += weight;
                    }
                }
                // A ratio, so that a leaf reached (or buried) at every point holds exactly
                // one (or none) of its area, though many weights sum to one only up to
                // round-off.
                let share = reached_weight / (reached_weight + buried_weight);
                // Every point reached, a face may still cross the leaf between them: a column
                // through a strip of wall 24 cm high, narrower than the strip's leaves.
                let straddles = if buried == 0 {
                    a_face_crosses(patch, &insets, tree.nodes[n as usize].radius, occluders)
                } else {
                    buried < points
                };
                (share, straddles, buried_corners)
            })
            .collect();
        for (&n, (share, straddles, corners)) in leaves.iter().zip(measured) {
            self.seen_share[n as usize] = share;
            self.straddles[n as usize] = straddles;
            self.buried_corners[n as usize] = corners;
        }
    }

    /// Sums the leaves' reached areas up the trees of `tree` (its leaves all measured) and
    /// weighs what each node's parent gathers for it ([`Reach::push_weights`]).
    pub(super) fn sum_reached_area(&mut self, tree: &Tree) {
        self.seen_area = vec![0.0; tree.nodes.len()];
        for &leaf in &tree.leaves {
            self.seen_area[leaf as usize] =
                tree.nodes[leaf as usize].area * self.seen_share[leaf as usize];
        }
        for n in (0..tree.nodes.len()).rev() {
            let reached: f64 = tree.nodes[n]
                .children()
                .map(|c| self.seen_area[c as usize])
                .sum();
            self.seen_area[n] += reached;
        }
        self.push_weight = self.push_weights(tree);
    }

    /// Per node, its reached share over its parent element's: a link to an element gathers
    /// the mean irradiance over all of it, and none of it falls where light cannot reach (under
    /// a box, inside a wall that cuts through it), so the parts light reaches receive that mean
    /// over the reached share, and a buried part nothing. Area times weight sums to the
    /// parent's area over its children: pushing keeps what the parent gathered.
    fn push_weights(&self, tree: &Tree) -> Vec<f64> {
        let share = |n: usize| {
            let area = tree.nodes[n].area;
            if area > 0.0 {
                self.seen_area[n] / area
            } else {
                0.0
            }
        };
        (0..tree.nodes.len())
            .map(|n| {
                let parent = tree.nodes[n].parent;
                if parent == NONE || tree.nodes[parent as usize].element.is_none() {
                    return 1.0;
                }
                let parent_share = share(parent as usize);
                if parent_share > 0.0 {
                    share(n) / parent_share
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Whether light reaches no part of node `n`, as last measured (a node made since is not
    /// known to be buried).
    pub(super) fn reaches_nothing_of(&self, n: u32) -> bool {
        self.seen_area
            .get(n as usize)
            .is_some_and(|&area| area == 0.0)
    }

    /// Whether light reaches some part of both ends of a link from `source` to `receiver`:
    /// one with an end light reaches nowhere would gather light where no one sees it, or send
    /// light from inside a solid.
    pub(super) fn reaches_both(&self, receiver: u32, source: u32) -> bool {
        !self.reaches_nothing_of(receiver) && !self.reaches_nothing_of(source)
    }

    /// Mean over the reached area of the leaves of the largest channel of reflected radiosity
    /// (`B - E`): the scale errors are measured against, which a small bright lamp does not
    /// inflate.
    pub(super) fn mean_reflected(&self, tree: &Tree, radiosity: &[Rgb]) -> f64 {
        let (sum, area) = radiosity
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(sum, area), (i, b)| {
                let (patch, reached) =
                    (tree.leaf_patch(i), self.seen_area[tree.leaves[i] as usize]);
                (
                    sum + (*b - patch.emission).max(Rgb::ZERO).max_element() * reached,
                    area + reached,
                )
            });
        if area > 0.0 { sum / area } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::Reach;
    use crate::hierarchy::fixtures::{
        add_parallelogram, build, build_and_solve, floor_and_a_box, floor_cut_by_a_box,
        room_with_a_box,
    };
    use crate::hierarchy::refine::{can_split_to, finest_radius};
    use crate::hierarchy::tree::Tree;
    use crate::hierarchy::{Hierarchy, HierarchySettings, receiving_area};
    use crate::mesh::corner_reading_point;
    use crate::scene::{Material, Rgb};
    use crate::visibility::Occluders;
    use glam::{DVec3, dvec3};

    #[test]
    fn a_box_on_the_floor_buries_its_footprint_and_nothing_else() {
        let scene = room_with_a_box();
        let hierarchy = build(&scene, 0.1);
        let floor = hierarchy.tree.face_node[0] as usize;
        let floor_area = hierarchy.tree.nodes[floor].area;
        println!(
            "floor reached area {} of {floor_area}",
            hierarchy.reach.seen_area[floor]
        );
        assert!(
            (hierarchy.reach.seen_area[floor] - (floor_area - 1.0)).abs() < 1e-9,
            "{}",
            hierarchy.reach.seen_area[floor]
        );
        for (face, &n) in hierarchy.tree.face_node.iter().enumerate().skip(1) {
            let node = n as usize;
            assert!(
                (hierarchy.reach.seen_area[node] - hierarchy.tree.nodes[node].area).abs() < 1e-9,
                "face {face}: {}",
                hierarchy.reach.seen_area[node]
            );
        }
    }

    #[test]
    fn no_link_gathers_onto_or_sends_from_what_light_reaches_nowhere() {
        // Light reaches no part of the floor's leaves under the box, though a small lamp
        // inside the box faces them: no link ends there (one would gather light no one sees,
        // or send light from inside the box), and solved, they hold their emission alone.
        let mut scene = room_with_a_box();
        let lamp = Material {
            reflectance: Rgb::ZERO,
            emission: Rgb::ONE,
        };
        let plate = (dvec3(1.45, 0.9, 1.45), DVec3::X * 0.1, DVec3::Z * 0.1);
        add_parallelogram(&mut scene, "lamp inside", plate, lamp);
        let built = build_and_solve(&scene, 0.1);
        let (hierarchy, radiosity) = (&built.hierarchy, &built.radiosity);
        let reach = &hierarchy.reach;
        for link in &hierarchy.links {
            assert!(!reach.reaches_nothing_of(link.receiver), "{link:?}");
            assert!(!reach.reaches_nothing_of(link.source), "{link:?}");
        }
        let buried: Vec<usize> = (0..hierarchy.tree.leaves.len())
            .filter(|&i| reach.reaches_nothing_of(hierarchy.tree.leaves[i]))
            .collect();
        assert!(!buried.is_empty());
        for &i in &buried {
            assert_eq!(
                hierarchy.tree.leaf_patch(i).face,
                0,
                "only the floor is buried"
            );
            assert_eq!(radiosity[i], hierarchy.tree.leaf_patch(i).emission);
        }
    }

    /// Whether the unsplit floor of [`floor_and_a_box`] with a post 10 cm x 11 cm across,
    /// whose foot is at `foot`, straddles the edge of where light reaches.
    fn unsplit_floor_straddles(foot: f64) -> bool {
        // Across the segment from inset corner (0.125, 0.125) to (0.875, 0.125) (and those of
        // the floor's quarters and their quarters), off the floor's centre, diagonals and
        // quadrature points: no test point lies inside it.
        let scene = floor_and_a_box(dvec3(0.2, foot, 0.05), dvec3(0.1, 0.6, 0.11));
        let occluders = Occluders::new(&scene);
        let mut tree = Tree::over(&scene);
        tree.collect_leaves();
        let mut reach = Reach::default();
        reach.measure(&tree, &occluders);
        let floor = tree.face_node[0] as usize;
        assert_eq!(reach.seen_share[floor], 1.0, "every test point is reached");
        reach.straddles[floor]
    }

    #[test]
    fn a_post_through_a_leaf_between_its_test_points_makes_it_straddle() {
        assert!(unsplit_floor_straddles(-0.5), "a post through the floor");
        assert!(unsplit_floor_straddles(0.0), "a post standing on the floor");
        assert!(
            !unsplit_floor_straddles(0.05),
            "a post 5 cm above the floor"
        );
    }

    #[test]
    fn a_large_leaf_is_tested_at_points_spaced_by_its_size() {
        // A box 20 x 10 cm through the unit floor, in the strip between its edge and the ring
        // of its corners' reading points: off every point of one quadrature cell, and off the
        // segments that look for a face crossing the leaf. Tested at points 0.2 apart (four
        // cells a side), the floor is found to straddle the edge of where light reaches.
        let scene = floor_and_a_box(dvec3(0.4, -0.5, 0.0), dvec3(0.2, 0.6, 0.1));
        let occluders = Occluders::new(&scene);
        let mut tree = Tree::over(&scene);
        tree.collect_leaves();
        let floor = tree.face_node[0] as usize;
        let measured = |mut reach: Reach| {
            reach.measure(&tree, &occluders);
            (reach.seen_share[floor], reach.straddles[floor])
        };
        assert_eq!(measured(Reach::default()), (1.0, false));
        assert_eq!(Reach::spaced(0.2).test_level(tree.nodes[floor].radius), 4);
        let (share, straddles) = measured(Reach::spaced(0.2));
        // Two of the 64 points fall inside the box.
        assert!(straddles);
        assert!((share - (1.0 - 2.0 / 64.0)).abs() < 1e-12, "{share}");
    }

    #[test]
    fn a_posts_footprint_is_buried_once_the_floor_splits_around_it() {
        let footprint = 0.1 * 0.11;
        let scene = floor_and_a_box(dvec3(0.2, -0.5, 0.05), dvec3(0.1, 0.6, 0.11));
        let hierarchy = build(&scene, 0.5);
        let floor = hierarchy.tree.face_node[0] as usize;
        let reached = hierarchy.reach.seen_area[floor];
        println!("floor reached area {reached}, exact {}", 1.0 - footprint);
        // The pieces over the post's sides split to the finest element; each is read at a few
        // points, so the area they add or take is at most theirs.
        let finest = finest_radius(
            receiving_area(&scene),
            HierarchySettings::default().max_leaves,
        );
        let edge_pieces = 2.0 * (0.1 + 0.11) / (2.0 * finest) + 4.0;
        let slack = edge_pieces * (2.0 * finest).powi(2);
        assert!(
            (reached - (1.0 - footprint)).abs() < slack,
            "{reached} vs {}",
            1.0 - footprint
        );
    }

    #[test]
    fn a_floor_corner_is_reached_on_the_lit_side_of_a_wall_and_the_mesh_shares_it_on_that_side_alone()
     {
        // The box's side at x = 0.6 runs through the floor: light reaches where a corner's
        // light is read ([`corner_reading_point`]) exactly where that point lies at x < 0.6 on
        // a leaf it reaches somewhere (a leaf whose test points are all in the box receives
        // nothing, and shows it at every corner), and a corner the leaf mesh shares between
        // leaves is read on one side for all of them.
        let edge = 0.6;
        let scene = floor_cut_by_a_box(edge);
        let hierarchy = build(&scene, 0.5);
        let (mesh, reached) = (hierarchy.leaf_mesh(), hierarchy.reached_corners());
        assert_eq!(reached.len(), mesh.patches.len());
        let mut side_of_corner = std::collections::HashMap::new();
        let (mut lit, mut dark) = (0, 0);
        for (i, (patch, flags)) in mesh.patches.iter().zip(&reached).enumerate() {
            let corners = &patch.corners[..patch.corner_count()];
            for (&c, &reaches) in corners.iter().zip(flags) {
                let side = side_of_corner.entry(c).or_insert(reaches);
                assert_eq!(*side, reaches, "corner {c} is shared across the wall");
                if patch.face != 0 {
                    continue;
                }
                let read_at = corner_reading_point(mesh.positions[c as usize], patch.centroid);
                let lit_leaf = hierarchy.reach.seen_share[hierarchy.tree.leaves[i] as usize] > 0.0;
                assert_eq!(
                    reaches,
                    read_at.x < edge && lit_leaf,
                    "corner read at {read_at}"
                );
                if reaches { lit += 1 } else { dark += 1 }
            }
        }
        println!("floor corners: {lit} reached, {dark} buried");
        assert!(lit > 0 && dark > 0);
    }

    #[test]
    fn leaves_across_a_wall_through_the_floor_split_to_the_finest_elements() {
        // The box's side at x = 0.6 crosses no lattice line of the floor: every leaf over it
        // is split down to the smallest element the leaf budget allows, and every other floor
        // leaf lies wholly inside the box (no light) or wholly outside it (all of it).
        let edge = 0.6;
        let scene = floor_cut_by_a_box(edge);
        let hierarchy: Hierarchy = build(&scene, 0.5);
        let finest = super::super::refine::finest_radius(
            receiving_area(&scene),
            crate::hierarchy::HierarchySettings::default().max_leaves,
        );
        let (mut across, mut whole) = (0, 0);
        for &leaf in &hierarchy.tree.leaves {
            let node = &hierarchy.tree.nodes[leaf as usize];
            let patch = hierarchy.tree.element_patch(leaf);
            if patch.face != 0 {
                continue;
            }
            let xs = patch.polygon.corners().iter().map(|c| c.x);
            let (low, high) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
                (l.min(x), h.max(x))
            });
            let share = hierarchy.reach.seen_share[leaf as usize];
            if low < edge && high > edge {
                across += 1;
                assert!(
                    !can_split_to(node, finest),
                    "a leaf over x in [{low}, {high}] of radius {} stayed whole",
                    node.radius
                );
            } else {
                whole += 1;
                let expected = if high <= edge { 1.0 } else { 0.0 };
                assert_eq!(share, expected, "leaf over x in [{low}, {high}]");
            }
        }
        println!("{across} floor leaves across the box's side, {whole} on one side");
        assert!(across > 0 && whole > across);
    }
}
