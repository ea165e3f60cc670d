//! Where light can reach: a leaf point is buried when every cosine ray from it meets the back
//! of a face (under a box on the floor). Sources send their mean over the reached area, and
//! errors are measured against the mean over it.

use super::Hierarchy;
use crate::sampling::pair_seed;
use crate::scene::Rgb;
use crate::visibility::Occluders;
use rayon::prelude::*;

impl Hierarchy {
    /// Measures the leaves not measured yet and sums the reached area up the trees.
    pub(super) fn measure_seen_area(&mut self, occluders: &Occluders) {
        self.seen_share.resize(self.nodes.len(), f64::NAN);
        let unmeasured: Vec<u32> = self
            .leaves
            .iter()
            .copied()
            .filter(|&n| self.seen_share[n as usize].is_nan())
            .collect();
        let shares: Vec<f64> = unmeasured
            .par_iter()
            .map(|&n| {
                let patch = self.element_patch(n);
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
        self.seen_area = vec![0.0; self.nodes.len()];
        for &leaf in &self.leaves {
            self.seen_area[leaf as usize] =
                self.nodes[leaf as usize].area * self.seen_share[leaf as usize];
        }
        for n in (0..self.nodes.len()).rev() {
            let reached: f64 = self.nodes[n]
                .children()
                .map(|c| self.seen_area[c as usize])
                .sum();
            self.seen_area[n] += reached;
        }
    }

    /// Mean over the reached area of the leaves of the largest channel of reflected radiosity
    /// (`B - E`): the scale errors are measured against, which a small bright lamp does not
    /// inflate.
    pub(super) fn mean_reflected(&self, radiosity: &[Rgb]) -> f64 {
        let (sum, area) = radiosity
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(sum, area), (i, b)| {
                let (patch, reached) =
                    (self.leaf_patch(i), self.seen_area[self.leaves[i] as usize]);
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
        let floor = hierarchy.face_node[0] as usize;
        let floor_area = hierarchy.nodes[floor].area;
        println!(
            "floor reached area {} of {floor_area}",
            hierarchy.seen_area[floor]
        );
        assert!(
            (hierarchy.seen_area[floor] - (floor_area - 1.0)).abs() < 1e-9,
            "{}",
            hierarchy.seen_area[floor]
        );
        for (face, &n) in hierarchy.face_node.iter().enumerate().skip(1) {
            let node = n as usize;
            assert!(
                (hierarchy.seen_area[node] - hierarchy.nodes[node].area).abs() < 1e-9,
                "face {face}: {}",
                hierarchy.seen_area[node]
            );
        }
    }
}
