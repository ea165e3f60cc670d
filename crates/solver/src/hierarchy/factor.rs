//! The factor a link carries: analytic between elements (Baum et al. 1989's point-to-polygon
//! factor at the receiver's quadrature points), with kernel-weighted shadow rays where a shaft
//! cannot decide visibility, and sampled from the cluster's side, onto the receiving element,
//! where a cluster sends.

use super::shaft::{Visibility, shaft_visibility};
use super::tree::{Bounds, Element, Node, SurfacePoint};
use super::{Hierarchy, Pair};
use crate::geometry::{Polygon, point_to_polygon_form_factor};
use crate::mesh::Patch;
use crate::pair::{
    FormFactorSettings, facing_kernel, far_point_to_patch_factor, mutually_facing, near_pair_level,
    rays_for_pair, unoccluded_form_factor, wholly_in_far_field,
};
use crate::sampling::{pair_seed, splitmix64, stratified_uv, unit_interval};
use crate::visibility::Occluders;
use glam::DVec3;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

/// How a cluster link's factor is sampled ([`LinkFactors::sampled_factor`]): cluster points
/// whose analytic factor onto the receiver it averages, and shadow rays for its visibility,
/// cast from those points in proportion to their factor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ClusterSampling {
    points: u32,
    rays: u32,
}

/// The sampling of a link kept within the knob's tolerance.
pub(super) const CLUSTER_SAMPLING: ClusterSampling = ClusterSampling {
    points: 16,
    rays: 4,
};

/// The sampling of a link kept past the link budget, where a pair is only kept or dropped and
/// no tolerance bounds its error: the same unbiased estimate from a quarter of the points and
/// rays. A link's factor reaches viewers only through the solution that starts the corners'
/// ten gathered bounces, of which about 1% is left after them (started from no indirect light
/// at all, the monastery piece read the same to three digits, docs/BENCHMARKS.md). On the
/// monastery these pairs are its last generation, 10.9M pairs that took 14 of its 21 s of
/// refinement with the finer sampling (5 s now), its errors the same to three digits.
pub(super) const KEPT_PAST_BUDGET: ClusterSampling = ClusterSampling { points: 4, rays: 1 };
/// Shadow rays at each of a partly hidden pair's first four (three) receiver points
/// ([`LinkFactors::measure_visibility`]).
const PROBE_RAYS_PER_POINT: u32 = 4;
/// Source points a ray of [`LinkFactors::one_ray_a_point_factor`] is aimed among.
const KERNEL_CANDIDATES: usize = 16;
/// Source points per receiver point for the transfer centre of a clear link ([`kernel_centre`]).
const CENTROID_SAMPLES: u32 = 8;

/// Shadow rays for a partly hidden pair ([`LinkFactors::measure_visibility`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Rays {
    /// Enough at each of the receiver's points to tell how visibility varies over it: the
    /// pair may split for that.
    ForSpread,
    /// One at each of the receiver's four (three) points: enough for the factor of a pair
    /// that is kept whatever visibility does.
    ForFactor,
}

/// A link's factor before refinement decides.
pub(super) struct Estimate {
    /// The factor between elements (unoccluded, with visibility once measured where partly
    /// hidden), or an upper bound with a cluster.
    pub(super) factor: f64,
    /// Its spread over the receiver, visibility included.
    pub(super) spread: f64,
    pub(super) visibility: Visibility,
    /// The kernel-weighted mean of the visible source points, when rays measured it.
    pub(super) centroid: Option<DVec3>,
    /// The unoccluded factor at the receiver's centroid, where the spread took it (near pairs).
    pub(super) at_centre: Option<f64>,
}

/// What shadow rays measured of a partly hidden pair.
struct PartlyHidden {
    /// The factor, visibility included.
    factor: f64,
    /// The least and the most kernel-weighted share of clear rays over the receiver's points,
    /// each moved in by its sampling noise (equal when every difference is within the noise).
    least_visible: f64,
    most_visible: f64,
    /// The kernel-weighted mean of the visible source points.
    centroid: DVec3,
    /// Whether every ray (one at least) was clear.
    all_clear: bool,
}

/// What computes link factors over one hierarchy, counting the rays it casts and the pairs
/// its shafts decide; shared by the threads deciding a generation of links.
pub(super) struct LinkFactors<'a> {
    pub(super) hierarchy: &'a Hierarchy,
    occluders: &'a Occluders,
    rays: FormFactorSettings,
    rays_cast: AtomicU64,
    shaft_decided: AtomicU64,
}

impl<'a> LinkFactors<'a> {
    /// Factors of `hierarchy`'s pairs with `occluders` between them, shadow rays as `rays` asks.
    pub(super) fn new(
        hierarchy: &'a Hierarchy,
        occluders: &'a Occluders,
        rays: FormFactorSettings,
    ) -> Self {
        LinkFactors {
            hierarchy,
            occluders,
            rays,
            rays_cast: AtomicU64::new(0),
            shaft_decided: AtomicU64::new(0),
        }
    }

    /// Rays cast and pairs decided by a shaft alone, with the factors given up.
    pub(super) fn into_counts(self) -> (u64, u64) {
        (self.rays_cast.into_inner(), self.shaft_decided.into_inner())
    }

    pub(super) fn node(&self, n: u32) -> &Node {
        &self.hierarchy.tree.nodes[n as usize]
    }

    /// The patches of a pair of elements.
    fn element_patches(&self, receiver: u32, source: u32) -> (&Patch, &Patch) {
        let tree = &self.hierarchy.tree;
        (tree.element_patch(receiver), tree.element_patch(source))
    }

    /// The factor of a pair before refinement decides, with its spread over the receiver
    /// and how the shaft saw it (unoccluded where partly hidden: no rays yet); `None` when no
    /// light can pass between them.
    pub(super) fn estimate(&self, pair: Pair) -> Option<Estimate> {
        let (r, s) = (self.node(pair.receiver), self.node(pair.source));
        if let (Some(er), Some(es)) = (&r.element, &s.element) {
            let (p, q) = (&er.patch, &es.patch);
            if p.face == q.face || !mutually_facing(p, q) {
                return None;
            }
            // The mean from the analytic factor at the receiver's Gauss points; the spread from
            // those, its corners and its centroid, where a smooth kernel's extremes lie (Gauss
            // points alone are symmetric and miss a source straight above the centre).
            let at = |x: DVec3| point_to_polygon_form_factor(x, p.normal, &q.polygon, q.normal);
            let (mut factor, mut low, mut high) = (0.0, f64::INFINITY, 0.0f64);
            let mut extend = |f: f64| {
                low = low.min(f);
                high = high.max(f);
            };
            p.polygon.for_each_quadrature_point(1, |x, weight| {
                let f = at(x);
                factor += weight * f;
                extend(f);
            });
            let mut at_centre = None;
            if !wholly_in_far_field(p, q) {
                p.polygon.corners().iter().for_each(|c| extend(at(*c)));
                at_centre = Some(at(p.centroid));
                at_centre.into_iter().for_each(&mut extend);
                extend(at(nearest_in_front(p, q)));
            } else {
                // In the far field the factor is linear over the receiver to within (radius /
                // distance)^2: its spread is the Gauss points' stretched out to the corners,
                // plus the curvature they cannot see (symmetric about a source straight above
                // the centre, they agree): on the axis the kernel falls like
                // `(1 + x^2/d^2)^-2`, by `2 (r/d)^2` of itself at the receiver's edge.
                let gap = p.centroid.distance(q.centroid) - q.radius;
                high = low
                    + (high - low) * gauss_to_corner_span(&p.polygon)
                    + 2.0 * high * (p.radius / gap).powi(2);
            }
            let visibility = match pair.clear {
                true => Visibility::Clear,
                false => shaft_visibility(&self.hierarchy.tree, p, q),
            };
            if visibility != Visibility::Partial {
                self.shaft_decided.fetch_add(1, Ordering::Relaxed);
            }
            // Partly hidden: unoccluded until [`LinkFactors::measure_visibility`] casts rays.
            return Some(Estimate {
                factor,
                spread: high - low,
                visibility,
                centroid: None,
                at_centre,
            });
        }
        // A cluster takes part: cull by facing, then bound the factor by the source's area seen
        // from the nearest the two bounding spheres come.
        let in_front = |bounds: Bounds, e: &Element| {
            let (lo, hi) = bounds;
            (0..8).any(|k| {
                let corner = DVec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                (corner - e.patch.centroid).dot(e.patch.normal) > 0.0
            })
        };
        if r.element.as_ref().is_some_and(|e| !in_front(s.bounds, e))
            || s.element.as_ref().is_some_and(|e| !in_front(r.bounds, e))
        {
            return None;
        }
        let gap = (r.centroid.distance(s.centroid) - r.radius - s.radius).max(0.0);
        let bound = (s.area / (PI * gap * gap)).min(1.0);
        Some(Estimate {
            factor: bound,
            spread: bound,
            visibility: Visibility::Sampled,
            centroid: None,
            at_centre: None,
        })
    }

    /// `estimate` of a partly hidden pair (unoccluded as [`LinkFactors::estimate`] gives it)
    /// with visibility measured by shadow rays, as many as `rays` asks: what counts then is how
    /// much visibility varies over the receiver, not the whole factor (a source hidden alike
    /// from every receiver point needs no split).
    pub(super) fn measure_visibility(
        &self,
        receiver: u32,
        source: u32,
        estimate: Estimate,
        rays: Rays,
    ) -> Estimate {
        let (p, q) = self.element_patches(receiver, source);
        let (factor, kernel_spread) = (estimate.factor, estimate.spread);
        // With visibility measured: `factor`, the visible source's `centroid`, and how much the
        // visible share varies over the receiver.
        let measured = |factor_seen: f64, centroid: DVec3, visibility_spread: f64| Estimate {
            factor: factor_seen,
            spread: kernel_spread + factor * visibility_spread,
            centroid: Some(centroid),
            ..estimate
        };
        if rays == Rays::ForFactor {
            // One ray a point: a visible share's sampling error is at most half the factor
            // over the root of the rays, and a pair kept whatever visibility does has a factor
            // within four times the allowance of [`LinkFactors::factor`] (a quarter of the
            // link's budget), so four rays keep it within that. The spread is not measured:
            // as wide as it can be, so that a later round whose source is brighter measures
            // it before keeping the link again.
            let (factor_seen, centroid) = self.one_ray_a_point_factor(receiver, source);
            return measured(factor_seen, centroid, 1.0);
        }
        // A few rays first: where they all pass, the source is taken as seen whole from the
        // whole receiver (a shadow over a tenth of the pair escapes 16 rays one time in five,
        // and moves its light by a tenth), and more rays are cast only where one is blocked.
        // All blocked is not taken as hidden: that dropped the light of pairs seen through a
        // gap (on the monastery piece, 0.15 points of energy and 0.2 of RMS more).
        let probe = self.partly_hidden_factor(receiver, source, 1, PROBE_RAYS_PER_POINT);
        if probe.all_clear {
            return measured(probe.factor, probe.centroid, 0.0);
        }
        let level = integration_level(p, q, factor, kernel_spread).min(2);
        let per_point = rays_for_pair(p, q, &self.rays).max(PROBE_RAYS_PER_POINT);
        let hidden = self.partly_hidden_factor(receiver, source, level, per_point);
        let spread = hidden.most_visible - hidden.least_visible;
        measured(hidden.factor, hidden.centroid, spread)
    }

    /// The factor a kept link carries, visibility included (measured, where partly hidden).
    /// Between elements in view of each other the receiver's quadrature is refined (levels 1,
    /// 2, 4, ... up to the one [`integration_level`] allows) until two successive levels agree
    /// within `allowed`, the factor error the link can afford: near pairs stop as soon as their
    /// factor is as accurate as the knob asks, instead of all taking the finest rule. A cluster
    /// source's factor is sampled as `sampling` says.
    pub(super) fn factor(
        &self,
        receiver: u32,
        source: u32,
        estimate: &Estimate,
        (allowed, sampling): (f64, ClusterSampling),
    ) -> f64 {
        let (r, s) = (self.node(receiver), self.node(source));
        let (Some(er), Some(es)) = (&r.element, &s.element) else {
            let seed = pair_seed(receiver as usize, source as usize);
            return self.sampled_factor(receiver, source, seed, sampling);
        };
        let (p, q) = (&er.patch, &es.patch);
        if estimate.visibility == Visibility::Partial {
            return estimate.factor;
        }
        let finest = integration_level(p, q, estimate.factor, estimate.spread);
        let (mut level, mut factor) = (1, estimate.factor);
        // The centroid rule against the four-point one first: they come free with the spread.
        if estimate
            .at_centre
            .is_some_and(|centre| (centre - factor).abs() <= allowed)
        {
            return factor;
        }
        while level < finest {
            let finer = (2 * level).min(finest);
            let refined = unoccluded_form_factor(p, q, finer);
            // The difference between successive rules as the coarser one's error (the
            // embedded-rule estimate of adaptive quadrature), kept conservative by returning
            // the finer value.
            let settled = (refined - factor).abs() <= allowed;
            (level, factor) = (finer, refined);
            if settled {
                break;
            }
        }
        factor
    }

    /// The factor of a partly hidden pair (see [`PartlyHidden`]): at each receiver
    /// quadrature point, the analytic factor times the kernel-weighted share of clear rays to
    /// stratified source points. The weights matter: where a receiver meets a wall the kernel
    /// peaks just where nothing blocks, and `unoccluded factor x clear share` ran 16-30% low
    /// there (measured on the Cornell box, docs/ACCURACY.md).
    fn partly_hidden_factor(
        &self,
        receiver: u32,
        source: u32,
        level: u32,
        rays_per_point: u32,
    ) -> PartlyHidden {
        let (p, q) = self.element_patches(receiver, source);
        let seed = pair_seed(receiver as usize, source as usize);
        let (mut factor, mut point, mut cast, mut cleared, mut least, mut most) =
            (0.0, 0u32, 0u64, 0u64, 1.0f64, 0.0f64);
        let (mut centroid_sum, mut centroid_weight) = (DVec3::ZERO, 0.0);
        // The unoccluded factor at the points some ray informed, and at those none did.
        let (mut measured, mut unmeasured) = (0.0, 0.0);
        p.polygon.for_each_quadrature_point(level, |x, weight| {
            point += 1;
            let unoccluded = point_to_polygon_form_factor(x, p.normal, &q.polygon, q.normal);
            if unoccluded == 0.0 {
                return;
            }
            let (mut clear, mut total, mut squares, mut clear_points) =
                (0.0, 0.0, 0.0, DVec3::ZERO);
            // Rays that can carry light, from up to four times as many source points (16 at
            // least): where part of the source lies behind the receiver's plane, a point whose
            // few rays all fell there learns nothing of what it sees.
            let mut candidates = 0..4 * rays_per_point.max(4);
            let mut carrying = 0;
            while let (true, Some(k)) = (carrying < rays_per_point, candidates.next()) {
                let (s, t) = stratified_uv(k, splitmix64(seed ^ point as u64));
                let y = q.polygon.point_at(s, t);
                let d = y - x;
                let kernel = facing_kernel(p.normal, q.normal, d);
                if kernel == 0.0 {
                    continue;
                }
                carrying += 1;
                total += kernel;
                squares += kernel * kernel;
                cast += 1;
                if self.occluders.segment_is_clear(x, y, [p.face, q.face]) {
                    cleared += 1;
                    clear += kernel;
                    clear_points += y * kernel;
                }
            }
            if total == 0.0 {
                unmeasured += weight * unoccluded;
            } else {
                let visible = clear / total;
                factor += weight * unoccluded * visible;
                measured += weight * unoccluded;
                // Only differences beyond the share's sampling noise count as spread: its
                // standard error as a weighted binomial estimate (Kish's effective sample size
                // (sum w)^2 / sum w^2; zero where every ray agrees). Counted as spread, the
                // noise split receivers under a wide source (a sky) down to the smallest
                // elements wherever anything stood near (issue 16).
                let noise = (visible * (1.0 - visible) * squares).sqrt() / total;
                (least, most) = (least.min(visible + noise), most.max(visible - noise));
                // This point's share of the transfer, spread over the source points it sees.
                centroid_sum += clear_points * (weight * unoccluded / total);
                centroid_weight += weight * unoccluded * visible;
            }
        });
        self.rays_cast.fetch_add(cast, Ordering::Relaxed);
        // A point no ray informed sees what the others see, on average.
        if measured > 0.0 {
            factor += unmeasured * factor / measured;
        }
        let centroid = if centroid_weight > 0.0 {
            centroid_sum / centroid_weight
        } else {
            q.centroid
        };
        PartlyHidden {
            factor,
            least_visible: least.min(most.max(0.0)),
            most_visible: most.max(0.0),
            centroid,
            all_clear: cast > 0 && cleared == cast,
        }
    }

    /// The factor of a partly hidden pair from one shadow ray at each of the receiver's
    /// level-1 points, and the kernel-weighted mean of the source points it saw: each ray is
    /// aimed at one of [`KERNEL_CANDIDATES`] source points drawn in proportion to the kernel,
    /// so that whether it passes estimates the kernel-weighted visible share the factor needs
    /// (aimed uniformly over the source, one ray estimates the area-weighted share: the teddy
    /// bear's light ran 1% low, the parts of a lamp seen past a neighbour being the near ones).
    fn one_ray_a_point_factor(&self, receiver: u32, source: u32) -> (f64, DVec3) {
        let (p, q) = self.element_patches(receiver, source);
        let seed = pair_seed(receiver as usize, source as usize);
        let (mut factor, mut measured, mut unmeasured) = (0.0, 0.0, 0.0);
        let (mut centroid_sum, mut point, mut cast) = (DVec3::ZERO, 0u64, 0u64);
        p.polygon.for_each_quadrature_point(1, |x, weight| {
            point += 1;
            let unoccluded = point_to_polygon_form_factor(x, p.normal, &q.polygon, q.normal);
            if unoccluded == 0.0 {
                return;
            }
            let point_seed = splitmix64(seed ^ point);
            let candidates: [(DVec3, f64); KERNEL_CANDIDATES] = std::array::from_fn(|k| {
                let (s, t) = stratified_uv(k as u32, point_seed);
                let y = q.polygon.point_at(s, t);
                (y, facing_kernel(p.normal, q.normal, y - x))
            });
            let total: f64 = candidates.iter().map(|(_, kernel)| kernel).sum();
            if total == 0.0 {
                unmeasured += weight * unoccluded;
                return;
            }
            let mut left = unit_interval(splitmix64(point_seed ^ 0x5EED)) * total;
            let mut carrying = candidates.iter().filter(|(_, kernel)| *kernel > 0.0);
            let (y, _) = carrying
                .clone()
                .find(|(_, kernel)| {
                    left -= kernel;
                    left < 0.0
                })
                .or(carrying.next_back())
                .expect("a carrying candidate");
            cast += 1;
            measured += weight * unoccluded;
            if self.occluders.segment_is_clear(x, *y, [p.face, q.face]) {
                factor += weight * unoccluded;
                centroid_sum += *y * (weight * unoccluded);
            }
        });
        self.rays_cast.fetch_add(cast, Ordering::Relaxed);
        let centroid = if factor > 0.0 {
            centroid_sum / factor
        } else {
            q.centroid
        };
        // A point no ray informed sees what the others see, on average.
        if measured > 0.0 {
            factor += unmeasured * factor / measured;
        }
        (factor, centroid)
    }

    /// The factor from element `receiver` to cluster `source`, visibility included, by
    /// reciprocity from the source's side: `F_RS = (A_S / A_R) E_y[F_{y->R} V]` over points `y`
    /// spread by area on the source's faces, `F_{y->R}` the analytic point-to-polygon factor
    /// onto the receiver and `V` whether a shadow ray reaches a point of it (`seed` picks the
    /// sample stream). Each term is bounded; the point-to-point kernel `cos cos / (pi d^2)`
    /// sampled at both ends was not, and capped at one it ran a real model's indirect light
    /// 25% low (the monastery's walls). The analytic part is cheap and the rays are not: the
    /// sampling's rays go to points drawn in proportion to their factor (systematic
    /// sampling), so their share of clear rays is the factor-weighted visibility.
    fn sampled_factor(
        &self,
        receiver: u32,
        source: u32,
        seed: u64,
        sampling: ClusterSampling,
    ) -> f64 {
        let r = self.hierarchy.tree.element_patch(receiver);
        // On the stack: this runs once for each of millions of cluster links.
        let mut points: [Option<(SurfacePoint, f64)>; CLUSTER_SAMPLING.points as usize] =
            Default::default();
        for (k, point) in points.iter_mut().enumerate().take(sampling.points as usize) {
            let y = self
                .hierarchy
                .tree
                .sample(source, k as u32, splitmix64(seed));
            let onto = far_point_to_patch_factor(y.position, y.normal, r).unwrap_or_else(|| {
                point_to_polygon_form_factor(y.position, y.normal, &r.polygon, r.normal)
            });
            *point = Some((y, onto));
        }
        let drawn = || points.iter().flatten();
        let unoccluded: f64 = drawn().map(|(_, f)| f).sum();
        if unoccluded == 0.0 {
            return 0.0;
        }
        // Ray j goes to the point where the running sum of factors passes (j + jitter) / M of
        // the total.
        let jitter = unit_interval(splitmix64(seed ^ 0x5EED));
        let threshold = |j: u32| (j as f64 + jitter) / sampling.rays as f64 * unoccluded;
        let (mut clear, mut cast, mut running) = (0, 0, 0.0);
        for (k, (y, onto)) in drawn().enumerate() {
            running += onto;
            while cast < sampling.rays && threshold(cast) <= running {
                let (u, v) = stratified_uv(cast, seed ^ k as u64);
                let x = r.polygon.point_at(u, v);
                if self
                    .occluders
                    .segment_is_clear(x, y.position, [r.face, y.face])
                {
                    clear += 1;
                }
                cast += 1;
            }
        }
        // Counted once a pair: an atomic add a ray had both threads fight over its cache line.
        self.rays_cast.fetch_add(cast as u64, Ordering::Relaxed);
        let visible = clear as f64 / sampling.rays as f64;
        let mean = unoccluded / sampling.points as f64;
        (self.node(source).area / r.area * mean * visible).min(1.0)
    }
}

/// The kernel-weighted mean of `q`'s points seen from `p` with nothing between: the receiver's
/// quadrature points against [`CENTROID_SAMPLES`] stratified source points each.
pub(super) fn kernel_centre(p: &Patch, q: &Patch, seed: u64) -> DVec3 {
    let (mut sum, mut total, mut point) = (DVec3::ZERO, 0.0, 0u64);
    p.polygon.for_each_quadrature_point(1, |x, weight| {
        point += 1;
        for k in 0..CENTROID_SAMPLES {
            let (s, t) = stratified_uv(k, splitmix64(seed ^ point));
            let y = q.polygon.point_at(s, t);
            let d = y - x;
            let kernel = weight * facing_kernel(p.normal, q.normal, d);
            (sum, total) = (sum + y * kernel, total + kernel);
        }
    });
    if total > 0.0 { sum / total } else { q.centroid }
}

/// `point` relative to `patch`'s centroid in the patch's tangent frame.
pub(super) fn tangent_coordinates(patch: &Patch, point: DVec3) -> [f32; 2] {
    let (tangent, bitangent) = patch.normal.any_orthonormal_pair();
    let d = point - patch.centroid;
    [d.dot(tangent) as f32, d.dot(bitangent) as f32]
}

/// The receiver's point nearest the source's centroid, moved a little toward the side the
/// source faces: where a source close beside a large receiver (a box standing on the floor)
/// sends the most. Gauss points, corners and centroid all lie far from such a source and saw
/// a floor lit evenly by the box beside it (the floor next to it was 16% dark in a furnace).
fn nearest_in_front(p: &Patch, q: &Patch) -> DVec3 {
    let toward_front = q.normal - p.normal * p.normal.dot(q.normal);
    let nearest = p.polygon.closest_point(q.centroid);
    p.polygon
        .closest_point(nearest + toward_front.normalize_or_zero() * (1e-3 * p.radius))
}

/// How much farther from the centroid a polygon's corners lie than its level-1 quadrature
/// points: the factor a linear function's spread over the points grows by at the corners
/// (Gauss points at `1/2 +- 1/(2 sqrt 3)` of a quad's sides; Strang-Fix points halfway from a
/// triangle's centroid to its corners).
fn gauss_to_corner_span(polygon: &Polygon) -> f64 {
    if polygon.is_quad() { 3f64.sqrt() } else { 2.0 }
}

/// The receiver quadrature level for the factor between elements `p` and `q`: the dense
/// path's near-field rule, and at least 3 when the factor varies over the receiver more than its
/// four-point mean (a source seen from only part of the receiver, which those points can miss).
fn integration_level(p: &Patch, q: &Patch, mean: f64, spread: f64) -> u32 {
    let near = near_pair_level(p, q).unwrap_or(1);
    if spread > mean { near.max(3) } else { near }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::fixtures::{GREY, add_parallelogram, screened_lamp};
    use crate::pair::MAX_PAIR_LEVEL;
    use crate::scene::{Material, Rgb, Scene};
    use glam::dvec3;

    /// Unit squares at z = 0 (facing +z) and z = `height` (facing -z), `shift` apart in x.
    fn facing_squares(height: f64, shift: f64) -> Hierarchy {
        let mut scene = Scene::default();
        let material = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ONE,
        };
        for (x, z, u, v) in [
            (0.0, 0.0, DVec3::X, DVec3::Y),
            (shift, height, DVec3::Y, DVec3::X),
        ] {
            add_parallelogram(&mut scene, "square", (dvec3(x, 0.0, z), u, v), material);
        }
        Hierarchy::cluster_tree(&scene)
    }

    /// How much the visible share of the lamp varies over the floor (as [`PartlyHidden`]
    /// reports it) under a [`screened_lamp`].
    fn visibility_spread(height: f64, edge: f64) -> f64 {
        let scene = screened_lamp(height, edge);
        let hierarchy = Hierarchy::cluster_tree(&scene);
        let occluders = Occluders::new(&scene);
        let factors = LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default());
        let (floor, lamp) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        let hidden = factors.partly_hidden_factor(floor, lamp, 2, 16);
        hidden.most_visible - hidden.least_visible
    }

    /// The floor's factor to the lamp of a [`screened_lamp`] measured with `rays`: the
    /// unoccluded estimate, the measured one, and the shadow rays cast.
    fn measured(height: f64, edge: f64, rays: Rays) -> (Estimate, Estimate, u64) {
        let scene = screened_lamp(height, edge);
        let hierarchy = Hierarchy::cluster_tree(&scene);
        let occluders = Occluders::new(&scene);
        let factors = LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default());
        let (floor, lamp) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        let unoccluded = factors
            .estimate(Pair::new(floor, lamp))
            .expect("they face each other");
        let copy = Estimate {
            visibility: Visibility::Partial,
            centroid: None,
            ..unoccluded
        };
        let measured = factors.measure_visibility(floor, lamp, copy, rays);
        let (cast, _) = factors.into_counts();
        (unoccluded, measured, cast)
    }

    #[test]
    fn a_near_factor_is_integrated_until_it_is_as_accurate_as_the_link_can_afford() {
        // A 0.2 x 0.2 square 0.1 above a unit floor, facing it: the factor peaks under the
        // square, between the floor's four Gauss points. By reciprocity the exact factor is the
        // square's area over the floor's times the mean of its points' factors onto the floor.
        let mut scene = Scene::default();
        let (x, y) = (DVec3::X, DVec3::Y);
        add_parallelogram(&mut scene, "floor", (DVec3::ZERO, x, y), GREY);
        add_parallelogram(
            &mut scene,
            "tile",
            (dvec3(0.3, 0.3, 0.1), y * 0.2, x * 0.2),
            GREY,
        );
        let hierarchy = Hierarchy::cluster_tree(&scene);
        let occluders = Occluders::new(&scene);
        let factors = LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default());
        let (floor, tile) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        let (p, q) = (
            hierarchy.tree.element_patch(floor),
            hierarchy.tree.element_patch(tile),
        );
        let exact = q.area / p.area * unoccluded_form_factor(q, p, 12);
        let estimate = factors
            .estimate(Pair::new(floor, tile))
            .expect("they face each other");
        assert!(estimate.visibility == Visibility::Clear);
        assert!(
            (estimate.factor / exact - 1.0).abs() > 0.1,
            "{}",
            estimate.factor
        );
        // None allowed gives the finest rule; each allowance is met.
        let finest = unoccluded_form_factor(p, q, MAX_PAIR_LEVEL);
        assert_eq!(
            factors.factor(floor, tile, &estimate, (0.0, CLUSTER_SAMPLING)),
            finest
        );
        for share in [0.2, 0.05, 0.01] {
            let allowed = share * exact;
            let factor = factors.factor(floor, tile, &estimate, (allowed, CLUSTER_SAMPLING));
            assert!((factor - exact).abs() <= allowed, "{factor} at {allowed}");
        }
    }

    #[test]
    fn a_far_source_spreads_over_the_receiver_as_its_corners_see_it() {
        // A unit square 10 above the receiver, straight above and 3 aside: the factor's spread
        // over the receiver, from its four Gauss points stretched to the corners plus the
        // curvature they cannot see, bounds the spread of the exact factor at the corners and
        // centre, and passes it by no more than the curvature term and the (radius /
        // distance) the linear extrapolation is good to.
        for shift in [0.0, 3.0] {
            let hierarchy = facing_squares(10.0, shift);
            let (receiver, source) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
            let (p, q) = (
                hierarchy.tree.element_patch(receiver),
                hierarchy.tree.element_patch(source),
            );
            assert!(wholly_in_far_field(p, q));
            let exact: Vec<f64> = p
                .polygon
                .corners()
                .iter()
                .chain([&p.centroid])
                .map(|x| point_to_polygon_form_factor(*x, p.normal, &q.polygon, q.normal))
                .collect();
            let (low, high) = exact
                .iter()
                .fold((f64::INFINITY, 0.0f64), |(l, h), &f| (l.min(f), h.max(f)));
            let occluders = Occluders::new(&Scene::default());
            let factors = LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default());
            let estimate = factors
                .estimate(Pair::new(receiver, source))
                .expect("facing");
            let distance = p.centroid.distance(q.centroid);
            let (linear, curvature) = (
                q.radius / distance,
                2.0 * high * (p.radius / (distance - q.radius)).powi(2),
            );
            let spread = estimate.spread;
            assert!(high - low <= spread * (1.0 + linear), "{spread} at {shift}");
            assert!(
                spread <= (high - low) * (1.0 + linear) + curvature,
                "{spread} against {} at {shift}",
                high - low
            );
        }
    }

    #[test]
    fn a_pair_whose_first_rays_all_pass_is_measured_by_them_and_a_shadowed_one_by_more() {
        // A screen off to the side blocks nothing: the 16 probe rays all pass, and the factor
        // is the unoccluded one at the same points, to rounding.
        let (unoccluded, clear, cast) = measured(5.0, -1.0, Rays::ForSpread);
        assert_eq!(cast, 16);
        assert!((clear.factor - unoccluded.factor).abs() < 1e-15 * unoccluded.factor);
        assert_eq!(clear.spread, unoccluded.spread);
        // Just above the floor it casts a hard shadow over 37% of it: a probe ray is blocked,
        // more follow, and the spread shows the shadow's edge. (The floor's four points, as a
        // far lamp gets, see the edge as coarsely as four points can: two in the shadow.)
        let (unoccluded, shadowed, cast) = measured(0.01, 0.37, Rays::ForSpread);
        assert!(cast > 16, "{cast}");
        let visible = shadowed.factor / unoccluded.factor;
        assert!((visible - 0.5).abs() < 0.02, "{visible}");
        assert!(shadowed.spread - unoccluded.spread > 0.9 * unoccluded.factor);
        // For a pair kept whatever visibility does, one ray a point gives the factor (the two
        // shadowed points' rays are blocked, the others' pass), and the spread is the widest
        // visibility can make it, for a later round to measure.
        let (unoccluded, kept, cast) = measured(0.01, 0.37, Rays::ForFactor);
        assert_eq!(cast, 4);
        assert!((kept.factor / unoccluded.factor - 0.5).abs() < 0.02);
        assert_eq!(kept.spread, unoccluded.spread + unoccluded.factor);
    }

    #[test]
    fn one_ray_a_point_sees_the_near_part_of_a_source_as_the_kernel_weighs_it() {
        // A unit floor 1 under a 4 x 4 lamp centred over it, a frame just under the lamp
        // leaving only the part straight above the floor open: that part is a sixteenth of the
        // lamp's area but a quarter of its factor. Over the floor's 256 pieces (1,024 rays) the
        // one-ray factors add up to the exact factor onto the opening; rays aimed uniformly
        // over the lamp would read the area's share and fall far short.
        let mut scene = Scene::default();
        let (x, y) = (DVec3::X, DVec3::Y);
        add_parallelogram(&mut scene, "floor", (DVec3::ZERO, x, y), GREY);
        let lamp = Material {
            emission: Rgb::ONE,
            ..GREY
        };
        add_parallelogram(
            &mut scene,
            "lamp",
            (dvec3(-1.5, -1.5, 1.0), y * 4.0, x * 4.0),
            lamp,
        );
        for (corner, u, v) in [
            (dvec3(-1.5, -1.5, 0.999), x * 1.5, y * 4.0),
            (dvec3(1.0, -1.5, 0.999), x * 1.5, y * 4.0),
            (dvec3(0.0, -1.5, 0.999), x, y * 1.5),
            (dvec3(0.0, 1.0, 0.999), x, y * 1.5),
        ] {
            add_parallelogram(&mut scene, "frame", (corner, u, v), GREY);
        }
        let mut hierarchy = Hierarchy::cluster_tree(&scene);
        let (floor, lamp) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        let mut pieces = vec![floor];
        for _ in 0..4 {
            pieces.iter().for_each(|&n| hierarchy.tree.subdivide(n));
            let node = |n: u32| &hierarchy.tree.nodes[n as usize];
            pieces = pieces.iter().flat_map(|&n| node(n).children()).collect();
        }
        assert_eq!(pieces.len(), 256);
        let occluders = Occluders::new(&scene);
        let factors = LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default());
        let area = |n: u32| hierarchy.tree.nodes[n as usize].area;
        let estimated: f64 = pieces
            .iter()
            .map(|&n| factors.one_ray_a_point_factor(n, lamp).0 * area(n))
            .sum::<f64>()
            / area(floor);
        let opening = Polygon::quad(
            dvec3(0.0, 0.0, 1.0),
            dvec3(0.0, 1.0, 1.0),
            dvec3(1.0, 1.0, 1.0),
            dvec3(1.0, 0.0, 1.0),
        );
        let floor_patch = hierarchy.tree.element_patch(floor);
        let mut exact = 0.0;
        floor_patch
            .polygon
            .for_each_quadrature_point(16, |x, weight| {
                exact += weight * point_to_polygon_form_factor(x, DVec3::Z, &opening, -DVec3::Z);
            });
        let whole = unoccluded_form_factor(floor_patch, hierarchy.tree.element_patch(lamp), 16);
        assert!(exact > 3.0 * whole / 16.0, "{exact} of {whole}");
        assert_eq!(factors.into_counts().0, 1024);
        assert!(
            (estimated / exact - 1.0).abs() < 0.12,
            "{estimated} for {exact}"
        );
    }

    #[test]
    fn visibility_differences_within_the_sampling_noise_are_no_spread() {
        // Just under the lamp, the screen hides 37% of it alike from every floor point: the
        // shares differ only by which jittered rays cross the edge, and no split can help.
        assert!(visibility_spread(9.99, 0.37) < 0.02);
        // Just above the floor it casts a hard shadow over 37% of it: all or nothing.
        assert!(visibility_spread(0.01, 0.37) > 0.95);
    }

    #[test]
    fn a_cluster_a_hair_above_a_floor_sends_its_exact_factor_on_average_however_sampled() {
        // A 2 x 2 floor under two 0.5 x 0.5 squares facing it 5 cm up, one cluster with it: the
        // point-to-point kernel between them reaches 1 / (pi 0.05^2), so a 16-sample estimate
        // of it capped at one ran far low. By reciprocity the exact factor is the squares'
        // area over the floor's times the mean of their points' analytic factors onto it.
        let mut scene = Scene::default();
        let (x, y) = (DVec3::X, DVec3::Y);
        add_parallelogram(&mut scene, "floor", (DVec3::ZERO, x * 2.0, y * 2.0), GREY);
        for corner in [dvec3(0.25, 0.25, 0.05), dvec3(1.25, 1.25, 0.05)] {
            add_parallelogram(&mut scene, "square", (corner, y * 0.5, x * 0.5), GREY);
        }
        let hierarchy = Hierarchy::cluster_tree(&scene);
        let occluders = Occluders::new(&scene);
        let factors = LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default());
        let (floor, root) = (hierarchy.tree.face_node[0], 0);
        assert!(hierarchy.tree.nodes[root as usize].element.is_none());
        let floor_patch = hierarchy.tree.element_patch(floor);
        let exact: f64 = hierarchy.tree.face_node[1..]
            .iter()
            .map(|&n| {
                let square = hierarchy.tree.element_patch(n);
                let mut mean = 0.0;
                square
                    .polygon
                    .for_each_quadrature_point(8, |point, weight| {
                        mean += weight
                            * point_to_polygon_form_factor(
                                point,
                                square.normal,
                                &floor_patch.polygon,
                                floor_patch.normal,
                            );
                    });
                square.area / floor_patch.area * mean
            })
            .sum();
        // Both samplings, the one past the link budget with four times the streams for a
        // quarter of the points: the mean of the estimates has a standard error of about 1.1%.
        for (sampling, streams) in [(CLUSTER_SAMPLING, 4096), (KEPT_PAST_BUDGET, 16384)] {
            let estimates: Vec<f64> = (0..streams)
                .map(|seed| factors.sampled_factor(floor, root, seed, sampling))
                .collect();
            assert!(estimates.iter().all(|f| (0.0..=1.0).contains(f)));
            let mean = estimates.iter().sum::<f64>() / streams as f64;
            let off = mean / exact - 1.0;
            assert!(off.abs() < 0.04, "{sampling:?}: {mean} against {exact}");
        }
    }

    #[test]
    fn the_transfer_centre_is_the_source_centroid_for_an_aligned_pair_and_leans_when_shifted() {
        let aligned = facing_squares(1.0, 0.0);
        let (p, q) = (
            aligned.tree.element_patch(aligned.tree.face_node[0]),
            aligned.tree.element_patch(aligned.tree.face_node[1]),
        );
        let centre = kernel_centre(p, q, 1);
        // Symmetric up to the sample pattern: within a few per cent of the half-width.
        assert!(centre.distance(q.centroid) < 0.05, "{centre}");
        assert_eq!(tangent_coordinates(q, q.centroid), [0.0, 0.0]);
        // Shifted by +x, the part of the source nearest the receiver (its -x side) weighs most.
        let shifted = facing_squares(0.5, 1.0);
        let (p, q) = (
            shifted.tree.element_patch(shifted.tree.face_node[0]),
            shifted.tree.element_patch(shifted.tree.face_node[1]),
        );
        assert!(kernel_centre(p, q, 1).x < q.centroid.x - 0.05);
    }
}
