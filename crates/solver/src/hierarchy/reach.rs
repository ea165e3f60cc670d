//! Where light can reach: a leaf point is buried when every cosine ray from it meets the back
//! of a face (under a box on the floor). Sources send their mean over the reached area, and
//! errors are measured against the mean over it.

use super::tree::Tree;
use crate::sampling::pair_seed;
use crate::scene::Rgb;
use crate::visibility::Occluders;
use rayon::prelude::*;

/// How much of each node light can reach.
#[derive(Default)]
pub(super) struct Reach {
    /// Per node ever a leaf, the share of its area not buried; NaN until measured.
    pub(super) seen_share: Vec<f64>,
    /// Per node, the area of its leaves that light can reach: what a source's mean is taken over.
    pub(super) seen_area: Vec<f64>,
}

impl Reach {
    /// Measures the leaves of `tree` not measured yet and sums the reached area up the trees.
    pub(super) fn measure(&mut self, tree: &Tree, occluders: &Occluders) {
        self.seen_share.resize(tree.nodes.len(), f64::NAN);
        let unmeasured: Vec<u32> = tree
            .leaves
            .iter()
            .copied()
            .filter(|&n| self.seen_share[n as usize].is_nan())
            .collect();
        let shares: Vec<f64> = unmeasured
            .par_iter()
            .map(|&n| {
                let patch = tree.element_patch(n);
                let mut share = 0.0;
                let mut point = 0;
                patch.polygon.for_each_quadrature_point(1, |x, weight| {
                    point += 1;
                    if !occluders.is_buried(
                        x,
                        patch.normal,
                        patch.face,
                        pair_seed(n as usize, point),
                    ) {
                        share += weight;
                    }
                });
                share
            })
            .collect();
        for (n, share) in unmeasured.into_iter().zip(shares) {
            self.seen_share[n as usize] = share;
        }
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
    use crate::hierarchy::fixtures::{build, room_with_a_box};

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
}
