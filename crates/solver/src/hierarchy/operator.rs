//! The link operator on the leaves: pull (area-weighted means up the trees), gather along the
//! links, push (sums down to the leaves). Linear in the leaves' radiosity, so it is a
//! [`Transport`] that GMRES and Jacobi solve as they would a dense matrix.

use super::Hierarchy;
use super::tree::NONE;
use crate::scene::Rgb;
use crate::transport::Transport;
use glam::DVec3;
use rayon::prelude::*;

/// A node's linear radiosity model about its children's reached-area centre, as weights on
/// their means (zero: flat).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Slope {
    /// Per child, its weight in the slope along (tangent, bitangent).
    child_weights: [[f64; 2]; 4],
    /// The node's centroid from the centre, in the tangent frame.
    shift: [f64; 2],
    /// How far from the centre the model is read, per axis: half the children's reach, less
    /// where a reading there would not be a convex mix of their (non-negative) means
    /// ([`Slope::read_as_a_mix`]), so that no link carries negative light or amplifies it.
    reach: [f64; 2],
}

impl Slope {
    /// This slope with its reach shrunk, where it must be, so that every reading is a convex
    /// mix of the children's means (`shares`: each child's share of the reached area, which
    /// weighs its mean in the node's). A reading at `p` weighs child `k` by
    /// `share_k + p . child_weights_k`, linear in `p`, so the reach's corners decide. A fit over
    /// children that are nearly in a row, or of very different reached areas, has a steep
    /// slope across them; read out to the reach there, it extrapolated and made the links'
    /// operator amplify light (a real model's faces cut where others cross them: GMRES's
    /// residual grew to 1e9, docs/BENCHMARKS.md).
    fn read_as_a_mix(mut self, shares: impl Iterator<Item = f64>) -> Slope {
        let mut scale = 1.0f64;
        for (share, weights) in shares.zip(&self.child_weights) {
            for corner in [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]] {
                let lean: f64 = (0..2).map(|k| corner[k] * self.reach[k] * weights[k]).sum();
                if share + scale * lean < 0.0 {
                    scale = share / -lean;
                }
            }
        }
        self.reach = self.reach.map(|r| r * scale.max(0.0));
        self
    }
}

/// One link as its receiver reads it: what the gather loop walks.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Incoming {
    pub(super) source: u32,
    pub(super) factor: f32,
    /// Where on the source its linear model is read ([`Hierarchy::reading_point`]).
    pub(super) reading: [f32; 2],
}

impl Hierarchy {
    /// The radiosity every node sends: the mean of its leaves' over the area light reaches.
    /// Buried area (under a box on the floor) is seen by nothing, and its link factors carry no
    /// share of it; counting its darkness in the mean ran every link from such a source low
    /// (the Cornell floor sent 4-9% too little, measured against dense factors on the same leaves).
    /// A node with no reached area sends nothing.
    pub(super) fn pull(&self, leaf_radiosity: &[Rgb]) -> Vec<Rgb> {
        let mut node_radiosity = vec![Rgb::ZERO; self.tree.nodes.len()];
        for (i, &leaf) in self.tree.leaves.iter().enumerate() {
            node_radiosity[leaf as usize] = leaf_radiosity[i];
        }
        for n in (0..self.tree.nodes.len()).rev() {
            let node = &self.tree.nodes[n];
            if node.child_count > 0 && self.reach.seen_area[n] > 0.0 {
                let sum = node.children().fold(Rgb::ZERO, |sum, c| {
                    sum + node_radiosity[c as usize] * self.reach.seen_area[c as usize]
                });
                node_radiosity[n] = sum / self.reach.seen_area[n];
            }
        }
        node_radiosity
    }

    /// Per node, its sent radiosity's slope along its tangent frame (see [`Slope`]). A link
    /// centred off the centre then gathers what that part of the source sends, not the mean:
    /// where a source is bright just where the receiver sees it best, the mean ran links low
    /// (the Cornell floor under its lamp; energy -2.3% at knob 0.02, -0.9% with slopes read
    /// within their reach).
    pub(super) fn slopes_of(&self, means: &[Rgb]) -> Vec<[Rgb; 2]> {
        (0..self.tree.nodes.len())
            .into_par_iter()
            .map(|n| {
                let mut gradient = [Rgb::ZERO; 2];
                for (c, weights) in self.tree.nodes[n]
                    .children()
                    .zip(&self.slopes[n].child_weights)
                {
                    gradient[0] += means[c as usize] * weights[0];
                    gradient[1] += means[c as usize] * weights[1];
                }
                gradient
            })
            .collect()
    }

    /// Where link `offset` reads its source's model: from the centre, within the reach.
    pub(super) fn reading_point(&self, source: u32, offset: [f32; 2]) -> [f32; 2] {
        let slope = &self.slopes[source as usize];
        [0, 1].map(|k| {
            (offset[k] as f64 + slope.shift[k]).clamp(-slope.reach[k], slope.reach[k]) as f32
        })
    }

    /// The weighted least-squares slope of each element node's children's means (weights: their
    /// reached area), as weights on those means; zero for leaves, clusters and degenerate fits.
    /// Read only where it is a convex mix of the children's means ([`Slope::read_as_a_mix`]).
    pub(super) fn fit_slopes(&mut self) {
        self.slopes = (0..self.tree.nodes.len())
            .into_par_iter()
            .map(|n| {
                let shares = self.tree.nodes[n]
                    .children()
                    .map(|c| self.reach.seen_area[c as usize] / self.reach.seen_area[n]);
                self.fit_slope(n).read_as_a_mix(shares)
            })
            .collect();
    }

    /// [`Hierarchy::fit_slopes`] for node `n`, before its reach is bounded.
    fn fit_slope(&self, n: usize) -> Slope {
        let node = &self.tree.nodes[n];
        let (Some(element), true) = (&node.element, self.reach.seen_area[n] > 0.0) else {
            return Slope::default();
        };
        let (tangent, bitangent) = element.patch.normal.any_orthonormal_pair();
        let frame = |p: DVec3| [p.dot(tangent), p.dot(bitangent)];
        let children: Vec<(f64, DVec3)> = node
            .children()
            .map(|c| {
                (
                    self.reach.seen_area[c as usize],
                    self.tree.nodes[c as usize].centroid,
                )
            })
            .collect();
        let mean_centre =
            children.iter().map(|(w, c)| *c * *w).sum::<DVec3>() / self.reach.seen_area[n];
        let offsets: Vec<[f64; 2]> = children
            .iter()
            .map(|(_, c)| frame(*c - mean_centre))
            .collect();
        let (mut m00, mut m01, mut m11) = (0.0, 0.0, 0.0);
        for ((w, _), d) in children.iter().zip(&offsets) {
            (m00, m01, m11) = (
                m00 + w * d[0] * d[0],
                m01 + w * d[0] * d[1],
                m11 + w * d[1] * d[1],
            );
        }
        let determinant = m00 * m11 - m01 * m01;
        if m00 + m11 <= 0.0 {
            return Slope::default();
        }
        if determinant <= 1e-9 * (m00 + m11) * (m00 + m11) {
            let shift = frame(node.centroid - mean_centre);
            let weights = children.iter().map(|(w, _)| *w);
            return slope_along_a_row(weights.zip(offsets), [m00, m01, m11], shift);
        }
        let reach = [0, 1].map(|k| 0.5 * offsets.iter().map(|d| d[k].abs()).fold(0.0, f64::max));
        let mut slope = Slope {
            shift: frame(node.centroid - mean_centre),
            reach,
            ..Slope::default()
        };
        for (k, ((w, _), d)) in children.iter().zip(&offsets).enumerate() {
            // (M^-1 w d): the slope is linear in the children's means.
            slope.child_weights[k] = [
                w * (m11 * d[0] - m01 * d[1]) / determinant,
                w * (m00 * d[1] - m01 * d[0]) / determinant,
            ];
        }
        slope
    }

    /// Groups the links by receiver and measures each leaf's row sum: a leaf of a face whose
    /// view is closed sends all its light to surfaces, so its row is scaled to sum to one.
    pub(super) fn index_links(&mut self) {
        // Links grouped by receiver (a counting sort).
        let mut offsets = vec![0u32; self.tree.nodes.len() + 1];
        for link in &self.links {
            offsets[link.receiver as usize + 1] += 1;
        }
        for n in 0..self.tree.nodes.len() {
            offsets[n + 1] += offsets[n];
        }
        let mut cursor = offsets.clone();
        let mut incoming = vec![Incoming::default(); self.links.len()];
        for link in &self.links {
            let slot = &mut cursor[link.receiver as usize];
            incoming[*slot as usize] = Incoming {
                source: link.source,
                factor: link.factor,
                reading: self.reading_point(link.source, link.offset),
            };
            *slot += 1;
        }
        self.offsets = offsets;
        self.incoming = incoming;
        // Row sums: what each leaf gathers when every radiosity is one. A leaf of a face whose
        // view is closed sends all its light to surfaces, so its row must sum to the share of
        // it that light reaches (one, but where a box stands on it).
        self.row_scale = vec![1.0; self.tree.leaves.len()];
        let mut sums = vec![Rgb::ZERO; self.tree.leaves.len()];
        self.gather(&vec![Rgb::ONE; self.tree.leaves.len()], &mut sums);
        for (i, &leaf) in self.tree.leaves.iter().enumerate() {
            let face = self.tree.element_patch(leaf).face;
            if self.face_closed[face as usize] && sums[i].x > 0.0 {
                self.row_scale[i] = self.reach.seen_share[leaf as usize] / sums[i].x;
            }
        }
    }

    /// Per leaf, the value of `node_values` (taken before refinement added nodes from `before`
    /// on): a new leaf starts from its parent's value.
    pub(super) fn inherit(&self, mut node_values: Vec<Rgb>, before: usize) -> Vec<Rgb> {
        node_values.resize(self.tree.nodes.len(), Rgb::ZERO);
        for n in before..self.tree.nodes.len() {
            node_values[n] = node_values[self.tree.nodes[n].parent as usize];
        }
        self.tree
            .leaves
            .iter()
            .map(|&n| node_values[n as usize])
            .collect()
    }
}

/// The slope of children whose centres lie in a row (a long element split in two across its
/// length), given their (reached area, offset from the centre) and the weighted second
/// moments `[m00, m01, m11]` of the offsets: along the row, and none across it. It is read
/// only as far out along the row as the nearer end of the children's centres, so each reading
/// is a convex mix of their means (read further, extrapolated, it made the monastery's
/// solve diverge).
fn slope_along_a_row(
    children: impl Iterator<Item = (f64, [f64; 2])> + Clone,
    [m00, m01, m11]: [f64; 3],
    shift: [f64; 2],
) -> Slope {
    // M's one non-zero eigenvector: either of its rows, the larger for round-off.
    let along = if m00 >= m11 { [m00, m01] } else { [m01, m11] };
    let norm = along[0].hypot(along[1]);
    let e = [along[0] / norm, along[1] / norm];
    let spread = m00 * e[0] * e[0] + 2.0 * m01 * e[0] * e[1] + m11 * e[1] * e[1];
    let on_row = |d: [f64; 2]| d[0] * e[0] + d[1] * e[1];
    let (low, high) = children
        .clone()
        .fold((0.0f64, 0.0f64), |(low, high), (_, d)| {
            (low.min(on_row(d)), high.max(on_row(d)))
        });
    let nearer_end = high.min(-low);
    let mut slope = Slope {
        shift,
        reach: [nearer_end * e[0].abs(), nearer_end * e[1].abs()],
        ..Slope::default()
    };
    for (k, (w, d)) in children.enumerate() {
        let weight = w * on_row(d) / spread;
        slope.child_weights[k] = [weight * e[0], weight * e[1]];
    }
    slope
}

impl Transport for Hierarchy {
    fn patch_count(&self) -> usize {
        self.tree.leaves.len()
    }

    fn gather(&self, radiosity: &[Rgb], out: &mut [Rgb]) {
        let means = self.pull(radiosity);
        let slopes = self.slopes_of(&means);
        let mut down: Vec<Rgb> = (0..self.tree.nodes.len())
            .into_par_iter()
            .map(|n| {
                let links = &self.incoming[self.offsets[n] as usize..self.offsets[n + 1] as usize];
                links
                    .iter()
                    .map(|link| {
                        let s = link.source as usize;
                        let ([du, dv], [u, v]) = (slopes[s], link.reading);
                        (means[s] + du * u as f64 + dv * v as f64) * link.factor as f64
                    })
                    .sum()
            })
            .collect();
        // Push: parents come before children, so one forward pass sums each leaf's ancestors.
        for n in 0..self.tree.nodes.len() {
            let parent = self.tree.nodes[n].parent;
            if parent != NONE {
                down[n] = down[n] + down[parent as usize] * self.reach.push_weight[n];
            }
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = down[self.tree.leaves[i] as usize] * self.row_scale[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::Link;
    use crate::hierarchy::fixtures::{
        GREY, add_parallelogram, build, closed_cube, floor_cut_by_a_box, room_with_a_box,
    };
    use crate::scene::Rgb;
    use crate::scene::Scene;
    use crate::visibility::Occluders;
    use glam::dvec3;

    #[test]
    fn rows_of_a_closed_box_sum_to_one_before_normalisation() {
        let scene = closed_cube();
        for error in [0.1, 0.03] {
            let hierarchy = build(&scene, error);
            assert!(hierarchy.face_closed.iter().all(|c| *c));
            let mut sums = vec![Rgb::ZERO; hierarchy.tree.leaves.len()];
            hierarchy.gather(&vec![Rgb::ONE; hierarchy.tree.leaves.len()], &mut sums);
            let worst = sums
                .iter()
                .zip(&hierarchy.row_scale)
                .map(|(s, k)| (s.x / k - 1.0).abs())
                .fold(0.0, f64::max);
            println!(
                "error {error}: {} leaves, {} links, worst raw row sum off by {worst:.4}",
                hierarchy.tree.leaves.len(),
                hierarchy.links.len()
            );
            assert!(
                worst < 2.0 * error,
                "error {error}: worst row sum off by {worst}"
            );
        }
    }

    #[test]
    fn rows_beside_a_box_standing_on_the_floor_are_whole_before_normalisation() {
        // A box's side links the whole floor at first; the floor beside it must still split
        // until it gets the box's light, not a share spread over the whole floor.
        let mut scene = room_with_a_box();
        scene.faces.iter_mut().for_each(|f| f.emission = Rgb::ONE);
        for error in [0.1, 0.05] {
            let hierarchy = build(&scene, error);
            let mut sums = vec![Rgb::ZERO; hierarchy.tree.leaves.len()];
            hierarchy.gather(&vec![Rgb::ONE; hierarchy.tree.leaves.len()], &mut sums);
            let worst = sums
                .iter()
                .zip(&hierarchy.row_scale)
                .enumerate()
                .filter(|(i, _)| {
                    hierarchy.reach.seen_share[hierarchy.tree.leaves[*i] as usize] > 0.0
                })
                .map(|(_, (s, k))| (s.x / k - 1.0).abs())
                .fold(0.0, f64::max);
            // What remains is the ray sampling of partly hidden pairs (wall leaves level with
            // the box's top: 11% at worst); before, the floor beside the box was 32% short.
            assert!(worst < 0.15, "error {error}: worst row sum off by {worst}");
        }
    }

    #[test]
    fn every_slope_is_read_as_a_mix_of_its_childrens_means() {
        // Beside and under a box standing on a floor, the floor's children are reached
        // unevenly, and the triangles of a slanted roof split into children whose centres
        // do not sit on the axes: a reading anywhere in a slope's reach must weigh every child
        // by at least zero (the weights sum to one by construction).
        let mut roof = room_with_a_box();
        let a = roof.add_object("roof");
        let (p, q, r) = (
            dvec3(0.0, 3.0, 0.0),
            dvec3(4.0, 3.5, 0.3),
            dvec3(1.0, 3.2, 4.0),
        );
        roof.add_polygon(a, &[p, r, q], GREY);
        let mut checked = 0;
        for scene in [floor_cut_by_a_box(0.37), roof] {
            let hierarchy = build(&scene, 0.05);
            for (n, slope) in hierarchy.slopes.iter().enumerate() {
                let node = &hierarchy.tree.nodes[n];
                if slope.child_weights.iter().all(|w| *w == [0.0; 2]) {
                    continue;
                }
                checked += 1;
                let reached = hierarchy.reach.seen_area[n];
                for (c, weights) in node.children().zip(&slope.child_weights) {
                    let share = hierarchy.reach.seen_area[c as usize] / reached;
                    for corner in [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]] {
                        let lean: f64 = (0..2)
                            .map(|k| corner[k] * slope.reach[k] * weights[k])
                            .sum();
                        assert!(share + lean >= -1e-12, "node {n}: {share} + {lean}");
                    }
                }
            }
        }
        assert!(checked > 10, "{checked} slopes");
    }

    #[test]
    fn a_linear_radiosity_is_read_exactly_and_one_bright_quarter_never_below_zero() {
        let scene = room_with_a_box();
        let mut hierarchy = Hierarchy::cluster_tree(&scene);
        let wall = hierarchy.tree.face_node[2];
        hierarchy.tree.subdivide(wall);
        for child in hierarchy.tree.nodes[wall as usize].children() {
            hierarchy.tree.subdivide(child);
        }
        hierarchy.index(&Occluders::new(&scene));
        let (tangent, bitangent) = hierarchy
            .tree
            .element_patch(wall)
            .normal
            .any_orthonormal_pair();
        let centroid = hierarchy.tree.nodes[wall as usize].centroid;
        let linear = |p: DVec3| {
            3.0 + 0.5 * (p - centroid).dot(tangent) - 0.25 * (p - centroid).dot(bitangent)
        };
        let radiosity: Vec<Rgb> = hierarchy
            .tree
            .leaves
            .iter()
            .map(|&n| Rgb::splat(linear(hierarchy.tree.nodes[n as usize].centroid)))
            .collect();
        let means = hierarchy.pull(&radiosity);
        let slopes = hierarchy.slopes_of(&means);
        for offset in [[0.0, 0.0], [0.3, -0.7], [-0.9, 0.4]] {
            let [u, v] = hierarchy.reading_point(wall, offset);
            let read = means[wall as usize]
                + slopes[wall as usize][0] * u as f64
                + slopes[wall as usize][1] * v as f64;
            let expected = linear(centroid + tangent * u as f64 + bitangent * v as f64);
            assert!(
                (read.x - expected).abs() < 1e-6,
                "at {offset:?}: {} vs {expected}",
                read.x
            );
        }
        // One bright grandchild quarter: every reading stays a mix of non-negative means.
        let bright = hierarchy.tree.nodes[wall as usize].first_child;
        let radiosity: Vec<Rgb> = hierarchy
            .tree
            .leaves
            .iter()
            .map(|&n| {
                if hierarchy.tree.nodes[n as usize].parent == bright {
                    Rgb::ONE
                } else {
                    Rgb::ZERO
                }
            })
            .collect();
        let means = hierarchy.pull(&radiosity);
        let slopes = hierarchy.slopes_of(&means);
        for offset in [[-5.0, -5.0], [5.0, -5.0], [-5.0, 5.0], [5.0, 5.0]] {
            let [u, v] = hierarchy.reading_point(wall, offset);
            let read = means[wall as usize]
                + slopes[wall as usize][0] * u as f64
                + slopes[wall as usize][1] * v as f64;
            assert!(read.x >= -1e-12, "at {offset:?}: {}", read.x);
        }
    }

    #[test]
    fn a_row_of_children_reads_a_linear_radiosity_exactly_and_one_bright_half_within_bounds() {
        // A 4 x 1 strip splits across its length into two halves, and each of those (2 x 1)
        // into four quarters: the strip's children lie in a row, where only the slope along it can be
        // fitted (before, such a node read flat). Linear along the strip, its radiosity is
        // read exactly wherever the model reaches; one half bright and the other dark, no
        // reading leaves [0, 1], however far out it is asked for.
        let mut scene = Scene::default();
        let strip_sides = (DVec3::ZERO, DVec3::X * 4.0, DVec3::Y);
        add_parallelogram(&mut scene, "strip", strip_sides, GREY);
        let mut hierarchy = Hierarchy::cluster_tree(&scene);
        let strip = hierarchy.tree.face_node[0];
        hierarchy.tree.subdivide(strip);
        for half in hierarchy.tree.nodes[strip as usize].children() {
            hierarchy.tree.subdivide(half);
        }
        hierarchy.index(&Occluders::new(&scene));
        assert_eq!(hierarchy.tree.nodes[strip as usize].child_count, 2);
        assert_eq!(hierarchy.tree.leaves.len(), 8);
        let centroid = hierarchy.tree.nodes[strip as usize].centroid;
        let normal = hierarchy.tree.element_patch(strip).normal;
        let (tangent, bitangent) = normal.any_orthonormal_pair();
        let s = strip as usize;
        let read = |radiosity: &[Rgb], offset: [f32; 2]| {
            let (means, [u, v]) = (
                hierarchy.pull(radiosity),
                hierarchy.reading_point(strip, offset),
            );
            let slopes = hierarchy.slopes_of(&means);
            let value = means[s] + slopes[s][0] * u as f64 + slopes[s][1] * v as f64;
            (
                value.x,
                centroid + tangent * u as f64 + bitangent * v as f64,
            )
        };
        let offsets = [
            [0.0, 0.0],
            [0.7, -0.2],
            [-1.3, 0.4],
            [5.0, 5.0],
            [-5.0, 5.0],
        ];
        let linear = |p: DVec3| 3.0 + 0.5 * (p - centroid).x;
        let at_leaves = |f: &dyn Fn(DVec3) -> f64| -> Vec<Rgb> {
            (hierarchy.tree.leaves.iter())
                .map(|&n| Rgb::splat(f(hierarchy.tree.nodes[n as usize].centroid)))
                .collect()
        };
        let radiosity = at_leaves(&linear);
        for offset in offsets {
            let (value, at) = read(&radiosity, offset);
            assert!((value - linear(at)).abs() < 1e-6, "at {offset:?}: {value}");
        }
        let one_bright_half = at_leaves(&|p: DVec3| if p.x < 2.0 { 1.0 } else { 0.0 });
        for offset in offsets {
            let (value, _) = read(&one_bright_half, offset);
            assert!(
                (-1e-12..=1.0 + 1e-12).contains(&value),
                "at {offset:?}: {value}"
            );
        }
    }

    #[test]
    fn what_a_floor_gathers_falls_only_where_light_reaches_and_keeps_its_total() {
        // A box cuts through the floor's half beyond x = 0.5 (a lattice line). One link to the
        // whole floor gathers its mean irradiance, a factor of 0.01 from a lamp sending 1: the
        // open half receives twice that, the half inside the box nothing, the floor the same
        // total (before, every quarter got the mean, inside the box too).
        let scene = floor_cut_by_a_box(0.5);
        let mut hierarchy = Hierarchy::cluster_tree(&scene);
        let (floor, lamp) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        hierarchy.tree.subdivide(floor);
        for child in hierarchy.tree.nodes[floor as usize].children() {
            hierarchy.tree.subdivide(child);
        }
        hierarchy.links.push(Link {
            receiver: floor,
            source: lamp,
            factor: 0.01,
            spread: 0.0,
            offset: [0.0; 2],
        });
        hierarchy.index(&Occluders::new(&scene));
        let leaves = &hierarchy.tree.leaves;
        let radiosity: Vec<Rgb> = leaves
            .iter()
            .map(|&n| {
                let sends = hierarchy.tree.element_patch(n).face == 1;
                Rgb::splat(if sends { 1.0 } else { 0.0 })
            })
            .collect();
        let mut gathered = vec![Rgb::ZERO; leaves.len()];
        hierarchy.gather(&radiosity, &mut gathered);
        let mut total = 0.0;
        for (i, &n) in leaves.iter().enumerate() {
            let patch = hierarchy.tree.element_patch(n);
            if patch.face != 0 {
                continue;
            }
            let inside = patch.polygon.centroid().x > 0.5;
            let expected = if inside { 0.0 } else { 0.02 };
            assert!(
                (gathered[i].x - expected).abs() < 1e-7,
                "leaf at {}: {} instead of {expected}",
                patch.polygon.centroid(),
                gathered[i].x
            );
            total += gathered[i].x * patch.area;
        }
        assert!((total - 0.01).abs() < 1e-7, "{total}");
    }
}
