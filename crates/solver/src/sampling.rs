//! Deterministic sample patterns: hashes that seed them per pair, a low-discrepancy sequence
//! on the unit square, and cosine-distributed directions. Every ray the solver casts comes from
//! here, so results are the same on any thread count.

use crate::geometry::clip_above_plane;
use glam::DVec3;
use std::f64::consts::PI;

/// SplitMix64 (Steele, Lea, Flood 2014): a well-mixed hash of the pair, so the sample pattern
/// is deterministic yet decorrelated between pairs.
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// A seed for the sample pattern of the ordered pair `(a, b)`: the same every time, different
/// between pairs.
pub fn pair_seed(a: usize, b: usize) -> u64 {
    splitmix64(((a as u64) << 32) | b as u64)
}

/// Which sample patterns the gathers at a solution's points draw: 0 is the default's, and any
/// other seed gives patterns independent of it, so that solving again under a few seeds shows
/// the spread sampling leaves in an answer (the 125k-triangle monastery read 6.25-6.73% smooth
/// RMS over seeds 0-4 on one hierarchy: docs/BENCHMARKS.md).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Seed(pub u64);

impl Seed {
    /// The seed of the sample pattern of the ordered pair `(a, b)` under this seed: the
    /// pair's own ([`pair_seed`]) for seed 0, moved by the seed's Weyl step (Steele, Lea,
    /// Flood 2014) for any other.
    pub fn pair(self, a: usize, b: usize) -> u64 {
        pair_seed(a, b) ^ self.0.wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }
}

/// The top 53 bits of `bits` as a number uniform in [0, 1): every `f64` step there is equally
/// likely.
pub fn unit_interval(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

/// Chooses an index with probability proportional to the weights whose running sums are
/// `cumulative` ([`running_sums`]), from a uniform `u` in [0, 1).
pub fn pick(cumulative: &[f64], u: f64) -> usize {
    let target = u * cumulative.last().copied().unwrap_or(0.0);
    cumulative
        .partition_point(|&c| c <= target)
        .min(cumulative.len().saturating_sub(1))
}

/// The running sums of `values`, for [`pick`].
pub fn running_sums(values: impl Iterator<Item = f64>) -> Vec<f64> {
    values
        .scan(0.0, |sum, v| {
            *sum += v;
            Some(*sum)
        })
        .collect()
}

/// The k-th point of Roberts' R2 sequence, rotated by `offset` (Cranley-Patterson), kept off the
/// patch border so that a ray never starts on a shared edge.
pub fn stratified_uv(k: u32, offset: u64) -> (f64, f64) {
    let inset = |x: f64| 1e-3 + (1.0 - 2e-3) * x;
    let (u, v) = roberts_point(k, offset);
    (inset(u), inset(v))
}

/// The k-th point of Roberts' R2 sequence, rotated by `offset` (Cranley-Patterson), over the
/// whole unit square: for draws whose border is no patch edge.
pub fn roberts_point(k: u32, offset: u64) -> (f64, f64) {
    // Roberts 2018, "The Unreasonable Effectiveness of Quasirandom Sequences": 1/phi_2, 1/phi_2^2.
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_2;
    let (u0, v0) = (
        unit_interval(offset),
        (offset & 0xFFFF_FFFF) as f64 / 4_294_967_296.0,
    );
    // x >= 0, so its fraction is x less its integer part, the same bits as `fract` without the
    // libm `trunc` call it becomes on baseline x86-64 (3.5% of a large town's solve).
    let fraction = |x: f64| x - x as u64 as f64;
    (fraction(u0 + k as f64 * A1), fraction(v0 + k as f64 * A2))
}

/// A unit direction about the unit `normal` with density `cos / pi`, from two uniform numbers
/// in [0, 1) (Malley's method: uniform on the disc, lifted to the hemisphere; pbrt 4e, 13.6).
pub fn cosine_direction(normal: DVec3, u: f64, v: f64) -> DVec3 {
    let (radius, angle) = (u.sqrt(), 2.0 * PI * v);
    let (tangent, bitangent) = normal.any_orthonormal_pair();
    (tangent * (radius * angle.cos())
        + bitangent * (radius * angle.sin())
        + normal * (1.0 - u).max(0.0).sqrt())
    .normalize()
}

/// Where the ray from `origin` along `direction` meets the plane through `on_plane` with
/// normal `normal` (not finite where the ray runs along the plane): the emitter point of a
/// direction drawn by solid angle.
pub fn onto_plane(origin: DVec3, direction: DVec3, on_plane: DVec3, normal: DVec3) -> DVec3 {
    origin + direction * ((on_plane - origin).dot(normal) / direction.dot(normal))
}

/// A polygon as seen from a point, set up to draw directions uniformly over the solid angle it
/// covers: each fan triangle by Arvo's stratified method (Arvo 1995, "Stratified Sampling of
/// Spherical Triangles", in the robust form of pbrt 4e, 6.5.4), picked by its share of the
/// solid angle. Drawn by area instead, points on a large emitter near the point weigh as
/// differently as their `cos / r^2` (a sky over a courtyard: a few points overhead carry the
/// estimate); drawn by solid angle, each weighs only the cosine at the point.
#[derive(Clone, Copy, Debug)]
pub struct SphericalPolygon {
    triangles: [SphericalTriangle; MAX_FAN_TRIANGLES],
    /// Fan triangles in use, each with some solid angle.
    count: usize,
}

/// Fan triangles of the largest polygon drawn from: a quad with a corner cut off by the
/// horizon ([`SphericalPolygon::seen_above`]) has five corners.
const MAX_FAN_TRIANGLES: usize = 3;

impl SphericalPolygon {
    /// The polygon with `corners` (three to five, convex) as seen from `origin`, or `None`
    /// where it has fewer or more corners, a corner lies on the origin or the polygon is seen
    /// edge-on. A fan triangle seen edge-on covers no solid angle and is left out.
    pub fn seen_from(origin: DVec3, corners: &[DVec3]) -> Option<SphericalPolygon> {
        if !(3..=MAX_FAN_TRIANGLES + 2).contains(&corners.len()) {
            return None;
        }
        let direction = |p: DVec3| (p - origin).try_normalize();
        let first = direction(corners[0])?;
        let mut triangles = [None; MAX_FAN_TRIANGLES];
        for (k, pair) in corners[1..].windows(2).enumerate() {
            let (b, c) = (direction(pair[0])?, direction(pair[1])?);
            triangles[k] = SphericalTriangle::new(first, b, c);
        }
        let mut kept = triangles.into_iter().flatten();
        let any = kept.next()?;
        let mut polygon = SphericalPolygon {
            triangles: [any; MAX_FAN_TRIANGLES],
            count: 1,
        };
        for triangle in kept {
            polygon.triangles[polygon.count] = triangle;
            polygon.count += 1;
        }
        Some(polygon)
    }

    /// The part of the polygon with `corners` (three or four, convex) in front of the plane
    /// through `origin` with normal `normal`, as seen from `origin`: what lies behind a point's
    /// tangent plane gives it no light, and drawn from there a direction is wasted (half the
    /// sky, from a wall).
    pub fn seen_above(origin: DVec3, normal: DVec3, corners: &[DVec3]) -> Option<SphericalPolygon> {
        let mut clipped = [DVec3::ZERO; 8];
        let count = clip_above_plane(corners, origin, normal, &mut clipped);
        (count >= 3)
            .then(|| SphericalPolygon::seen_from(origin, &clipped[..count]))
            .flatten()
    }

    /// The solid angle it covers, steradians.
    pub fn solid_angle(&self) -> f64 {
        self.triangles[..self.count]
            .iter()
            .map(SphericalTriangle::solid_angle)
            .sum()
    }

    /// A unit direction uniform over its solid angle, from two uniform numbers in [0, 1):
    /// `u` picks the triangle and then the sub-area within it, so stratified `(u, v)` stay
    /// stratified.
    pub fn direction(&self, u: f64, v: f64) -> DVec3 {
        let mut picked = u * self.solid_angle();
        let last = self.count - 1;
        for triangle in &self.triangles[..last] {
            let share = triangle.solid_angle();
            if picked < share {
                return triangle.direction(picked / share, v);
            }
            picked -= share;
        }
        let share = self.triangles[last].solid_angle();
        self.triangles[last].direction((picked / share).min(1.0), v)
    }
}

/// A spherical triangle: its vertices' unit directions, and what Arvo's map needs of it that
/// does not depend on the direction drawn (a corner in a penumbra draws up to 128 from one).
#[derive(Clone, Copy, Debug)]
struct SphericalTriangle {
    a: DVec3,
    b: DVec3,
    /// The unit vector from `a` toward `c`, perpendicular to `a`.
    c_across_a: DVec3,
    /// The sine and cosine of its angle at `a`.
    sin_alpha: f64,
    cos_alpha: f64,
    cos_ab: f64,
    /// The sum of its three angles: its solid angle plus pi.
    angle_sum: f64,
}

impl SphericalTriangle {
    fn new(a: DVec3, b: DVec3, c: DVec3) -> Option<SphericalTriangle> {
        let (n_ab, n_bc, n_ca) = (
            a.cross(b).try_normalize()?,
            b.cross(c).try_normalize()?,
            c.cross(a).try_normalize()?,
        );
        let alpha = angle_between(n_ab, -n_ca);
        let angle_sum = alpha + angle_between(n_bc, -n_ab) + angle_between(n_ca, -n_bc);
        let (sin_alpha, cos_alpha) = alpha.sin_cos();
        (angle_sum > PI).then_some(SphericalTriangle {
            a,
            b,
            c_across_a: across(c, a),
            sin_alpha,
            cos_alpha,
            cos_ab: a.dot(b),
            angle_sum,
        })
    }

    fn solid_angle(&self) -> f64 {
        self.angle_sum - PI
    }

    /// Arvo's map: `u` sets the sub-triangle's area, which fixes the point `c'` on the arc
    /// from `a` to `c`; `v` picks the point on the arc from `b` to `c'`.
    fn direction(&self, u: f64, v: f64) -> DVec3 {
        let (sin_alpha, cos_alpha) = (self.sin_alpha, self.cos_alpha);
        let (sin_area, cos_area) = (PI + u * (self.angle_sum - PI)).sin_cos();
        let sin_phi = sin_area * cos_alpha - cos_area * sin_alpha;
        let cos_phi = cos_area * cos_alpha + sin_area * sin_alpha;
        let k1 = cos_phi + cos_alpha;
        let k2 = sin_phi - sin_alpha * self.cos_ab;
        let cos_b = ((k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha)
            / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha))
            .clamp(-1.0, 1.0);
        let c_prime = self.a * cos_b + self.c_across_a * (1.0 - cos_b * cos_b).max(0.0).sqrt();
        let cos_theta = 1.0 - v * (1.0 - c_prime.dot(self.b));
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        (self.b * cos_theta + across(c_prime, self.b) * sin_theta).normalize()
    }
}

/// The unit vector along the part of `v` perpendicular to the unit `w` (Gram-Schmidt); zero
/// where `v` lies along `w`.
fn across(v: DVec3, w: DVec3) -> DVec3 {
    (v - w * v.dot(w)).normalize_or_zero()
}

/// The angle between unit vectors, accurate near 0 and pi too (pbrt 4e, 3.3.1).
fn angle_between(v: DVec3, w: DVec3) -> f64 {
    if v.dot(w) < 0.0 {
        PI - 2.0 * ((v + w).length() / 2.0).min(1.0).asin()
    } else {
        2.0 * ((w - v).length() / 2.0).min(1.0).asin()
    }
}

#[cfg(test)]
mod tests {
    use super::{SphericalPolygon, splitmix64, stratified_uv, unit_interval};
    use crate::geometry::{Polygon, point_to_polygon_form_factor};
    use glam::{DVec3, dvec3};
    use std::f64::consts::PI;

    /// A square, a long sliver, a tilted quad and a triangle, each seen from points near and
    /// far, beside and over it.
    fn polygons_and_points() -> Vec<(Polygon, DVec3, DVec3)> {
        let square = Polygon::quad(
            dvec3(-1.0, -1.0, 2.0),
            dvec3(-1.0, 1.0, 2.0),
            dvec3(1.0, 1.0, 2.0),
            dvec3(1.0, -1.0, 2.0),
        );
        let sliver = Polygon::quad(
            dvec3(-50.0, 0.0, 0.3),
            dvec3(-50.0, 0.05, 0.3),
            dvec3(50.0, 0.05, 0.3),
            dvec3(50.0, 0.0, 0.3),
        );
        let tilted = Polygon::quad(
            dvec3(0.0, 0.0, 1.0),
            dvec3(0.0, 2.0, 1.5),
            dvec3(3.0, 2.0, 2.5),
            dvec3(3.0, 0.0, 2.0),
        );
        let triangle = Polygon::triangle(
            dvec3(0.5, 0.0, 1.0),
            dvec3(0.0, 0.7, 1.2),
            dvec3(-0.6, -0.4, 0.9),
        );
        let mut cases = Vec::new();
        for polygon in [square, sliver, tilted, triangle] {
            for (point, normal) in [
                (DVec3::ZERO, DVec3::Z),
                (dvec3(0.3, -0.2, 0.0), dvec3(0.3, 0.1, 1.0).normalize()),
                (dvec3(4.0, 1.0, 0.0), dvec3(-1.0, 0.0, 1.0).normalize()),
                (dvec3(0.1, 0.1, -20.0), DVec3::Z),
            ] {
                cases.push((polygon, point, normal));
            }
        }
        cases
    }

    /// The integral of the cosine at `point` (about `normal`; below its horizon, zero) over
    /// `view` of `polygon`, from 2^16 directions drawn uniformly over it, each checked to meet
    /// the polygon; and the least cosine drawn.
    fn integrated_cosine(
        view: &SphericalPolygon,
        polygon: &Polygon,
        point: DVec3,
        normal: DVec3,
    ) -> (f64, f64) {
        let n: u32 = 1 << 16;
        let (plane_normal, on_plane) = (polygon.normal(), polygon.corners()[0]);
        let (mut cosines, mut least) = (0.0, f64::INFINITY);
        for k in 0..n {
            // Independent uniform numbers: unbiased on any polygon (a sliver's map is too
            // uneven near its ends for a grid's midpoints to integrate within 0.1%).
            let uniform = |j: u64| unit_interval(splitmix64(2 * u64::from(k) + j));
            let w = view.direction(uniform(0), uniform(1));
            assert!((w.length() - 1.0).abs() < 1e-12);
            let hit = point + w * (on_plane - point).dot(plane_normal) / w.dot(plane_normal);
            let closest = polygon.closest_point(hit);
            assert!(
                closest.distance(hit) < 1e-9 * (1.0 + hit.distance(point)),
                "{w} from {point} leaves the polygon at {hit}"
            );
            cosines += normal.dot(w).max(0.0);
            least = least.min(normal.dot(w));
        }
        (cosines / f64::from(n) * view.solid_angle(), least)
    }

    /// Pi times Lambert's exact factor from `point` (facing `normal`) to `polygon`, whichever
    /// side of it the point is on: the integral of the cosine over the solid angle it covers.
    fn exact_integral(polygon: &Polygon, point: DVec3, normal: DVec3) -> f64 {
        let (plane_normal, on_plane) = (polygon.normal(), polygon.corners()[0]);
        let facing = if plane_normal.dot(point - on_plane) > 0.0 {
            plane_normal
        } else {
            -plane_normal
        };
        PI * point_to_polygon_form_factor(point, normal, polygon, facing)
    }

    #[test]
    fn directions_over_a_polygons_solid_angle_integrate_its_form_factor() {
        // Uniform over the solid angle, the mean cosine at the point times the solid angle is
        // the integral of cos d(omega), pi times Lambert's exact factor (the polygon's facing
        // does not enter), and every direction meets the polygon.
        for (polygon, point, normal) in polygons_and_points() {
            let view = SphericalPolygon::seen_from(point, polygon.corners()).expect("seen");
            let (integral, _) = integrated_cosine(&view, &polygon, point, normal);
            let exact = exact_integral(&polygon, point, normal);
            assert!(
                (integral - exact).abs() < 1e-2 * exact,
                "{integral} against {exact} from {point}"
            );
        }
    }

    #[test]
    fn directions_over_the_part_above_a_points_horizon_face_it_and_integrate_its_form_factor() {
        // The same integral, with no direction drawn below the point's tangent plane; and from
        // a wall under a square sky, centred, the part above its horizon is half the square.
        let wall = (DVec3::ZERO, DVec3::X);
        for (polygon, point, normal) in
            polygons_and_points()
                .into_iter()
                .chain([(polygons_and_points()[0].0, wall.0, wall.1)])
        {
            let Some(view) = SphericalPolygon::seen_above(point, normal, polygon.corners()) else {
                assert_eq!(exact_integral(&polygon, point, normal), 0.0, "{point}");
                continue;
            };
            let whole = SphericalPolygon::seen_from(point, polygon.corners()).expect("seen");
            assert!(view.solid_angle() <= whole.solid_angle() * (1.0 + 1e-12));
            let (integral, least) = integrated_cosine(&view, &polygon, point, normal);
            let exact = exact_integral(&polygon, point, normal);
            assert!(
                least >= -1e-12,
                "a direction {least} below the horizon at {point}"
            );
            assert!(
                (integral - exact).abs() < 1e-2 * exact,
                "{integral} against {exact} from {point}"
            );
        }
        let square = polygons_and_points()[0].0;
        let above = SphericalPolygon::seen_above(wall.0, wall.1, square.corners()).expect("seen");
        let whole = SphericalPolygon::seen_from(wall.0, square.corners()).expect("seen");
        assert!((above.solid_angle() - whole.solid_angle() / 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_polygons_solid_angle_bound_holds_everywhere_and_is_tight_from_afar() {
        for (polygon, point, _) in polygons_and_points() {
            let bound = polygon.solid_angle_bound(point);
            let view = SphericalPolygon::seen_from(point, polygon.corners()).expect("seen");
            assert!(view.solid_angle() <= bound, "{bound} from {point}");
        }
        // Straight over a square's centre at a distance d it covers `A / d^2 (1 - O(A / d^2))`,
        // on either side of its plane.
        let square = polygons_and_points()[0].0;
        let centre = square.centroid() + square.normal() * 100.0;
        for point in [centre, centre - square.normal() * 200.0] {
            let view = SphericalPolygon::seen_from(point, square.corners()).expect("seen");
            let bound = square.solid_angle_bound(point);
            assert!(bound >= view.solid_angle() && bound < view.solid_angle() * 1.001);
        }
        assert_eq!(square.solid_angle_bound(square.centroid()), f64::INFINITY);
    }

    #[test]
    fn a_cube_face_covers_a_sixth_of_the_sphere_from_the_cube_centre() {
        let face = [
            dvec3(-1.0, -1.0, 1.0),
            dvec3(1.0, -1.0, 1.0),
            dvec3(1.0, 1.0, 1.0),
            dvec3(-1.0, 1.0, 1.0),
        ];
        let view = SphericalPolygon::seen_from(DVec3::ZERO, &face).expect("seen");
        assert!((view.solid_angle() - 4.0 * PI / 6.0).abs() < 1e-12);
        // Seen edge-on, a polygon has no solid angle to draw from.
        assert!(SphericalPolygon::seen_from(dvec3(0.0, 0.0, 1.0), &face).is_none());
        // Nor with corners a fan of three triangles cannot hold.
        assert!(SphericalPolygon::seen_from(DVec3::ZERO, &face[..2]).is_none());
        let hexagon = [face.as_slice(), &[dvec3(-1.0, 0.0, 1.0); 2]].concat();
        assert!(SphericalPolygon::seen_from(DVec3::ZERO, &hexagon).is_none());
    }

    #[test]
    fn stratified_points_are_roberts_sequence_kept_off_the_border() {
        for seed in 0..200u64 {
            let offset = splitmix64(seed);
            for k in [0, 1, 2, 15, 16, 63, 1000, u32::MAX] {
                let (u, v) = stratified_uv(k, offset);
                let u0 = (offset >> 11) as f64 / (1u64 << 53) as f64;
                let v0 = (offset & 0xFFFF_FFFF) as f64 / 4_294_967_296.0;
                let expected = |x: f64| 1e-3 + (1.0 - 2e-3) * x.fract();
                assert_eq!(u, expected(u0 + k as f64 * 0.754_877_666_246_692_7));
                assert_eq!(v, expected(v0 + k as f64 * 0.569_840_290_998_053_2));
                assert!((1e-3..=1.0 - 1e-3).contains(&u) && (1e-3..=1.0 - 1e-3).contains(&v));
            }
        }
    }
}
