//! Planar polygons (triangles and quads), their quadrature rules, and the analytic
//! point-to-polygon form factor.
//!
//! Everything here is in f64 and uses only tolerances relative to the sizes involved, so a scene
//! gives the same answer in millimetres or in kilometres.

use glam::{DAffine3, DVec3};
use std::f64::consts::PI;

/// A convex planar polygon with three or four corners, counter-clockwise seen from its front
/// (the side its normal points to).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polygon {
    corners: [DVec3; 4],
    arity: u8,
}

impl Polygon {
    /// A triangle `a, b, c`, counter-clockwise seen from its front.
    pub fn triangle(a: DVec3, b: DVec3, c: DVec3) -> Self {
        Polygon {
            corners: [a, b, c, c],
            arity: 3,
        }
    }

    /// A quad `a, b, c, d`, counter-clockwise seen from its front. The caller guarantees it is
    /// planar and convex (see [`Polygon::is_planar_convex_quad`]).
    pub fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Self {
        Polygon {
            corners: [a, b, c, d],
            arity: 4,
        }
    }

    /// The same polygon moved rigidly by `motion`.
    pub fn moved(&self, motion: &DAffine3) -> Polygon {
        Polygon {
            corners: self.corners.map(|c| motion.transform_point3(c)),
            arity: self.arity,
        }
    }

    /// The corners, three or four.
    pub fn corners(&self) -> &[DVec3] {
        &self.corners[..self.arity as usize]
    }

    /// True for a quad, false for a triangle.
    pub fn is_quad(&self) -> bool {
        self.arity == 4
    }

    /// Newell's vector: its direction is the normal and its length twice the area.
    fn newell(&self) -> DVec3 {
        let c = self.corners();
        (0..c.len()).map(|k| c[k].cross(c[(k + 1) % c.len()])).sum()
    }

    /// Area in scene units squared.
    pub fn area(&self) -> f64 {
        0.5 * self.newell().length()
    }

    /// Unit normal of the front side (zero for a degenerate polygon).
    pub fn normal(&self) -> DVec3 {
        self.newell().normalize_or_zero()
    }

    /// Area-weighted centroid.
    pub fn centroid(&self) -> DVec3 {
        let c = self.corners();
        if c.len() == 3 {
            return (c[0] + c[1] + c[2]) / 3.0;
        }
        let (a1, a2) = (
            triangle_area(c[0], c[1], c[2]),
            triangle_area(c[0], c[2], c[3]),
        );
        let (g1, g2) = ((c[0] + c[1] + c[2]) / 3.0, (c[0] + c[2] + c[3]) / 3.0);
        if a1 + a2 > 0.0 {
            (g1 * a1 + g2 * a2) / (a1 + a2)
        } else {
            (g1 + g2) * 0.5
        }
    }

    /// Largest distance from the centroid to a corner: the radius of a bounding sphere.
    pub fn radius(&self) -> f64 {
        let g = self.centroid();
        self.corners()
            .iter()
            .map(|c| c.distance(g))
            .fold(0.0, f64::max)
    }

    /// An upper bound on the solid angle, steradians, the polygon covers from `x`: each of its
    /// points' `cos / r^2` is at most one over the nearest one's squared distance (infinite on
    /// the polygon). Far cheaper than the solid angle itself, it settles that a lamp seen from
    /// afar covers little.
    pub fn solid_angle_bound(&self, x: DVec3) -> f64 {
        self.area() / self.closest_point(x).distance_squared(x)
    }

    /// The point of the (planar, convex) polygon nearest to `x`.
    pub fn closest_point(&self, x: DVec3) -> DVec3 {
        let (c, n) = (self.corners(), self.normal());
        let projected = x - n * n.dot(x - c[0]);
        let edges = || (0..c.len()).map(|k| (c[k], c[(k + 1) % c.len()]));
        if edges().all(|(a, b)| (b - a).cross(projected - a).dot(n) >= 0.0) {
            return projected;
        }
        edges()
            .map(|(a, b)| {
                let edge = b - a;
                let t = ((projected - a).dot(edge) / edge.length_squared().max(f64::MIN_POSITIVE))
                    .clamp(0.0, 1.0);
                a + edge * t
            })
            .min_by(|p, q| p.distance_squared(x).total_cmp(&q.distance_squared(x)))
            .unwrap_or(projected)
    }

    /// The point at parameters `(u, v)` in the unit square: bilinear for a quad; for a triangle
    /// the square is folded onto it, so uniform `(u, v)` gives uniform points.
    pub fn point_at(&self, u: f64, v: f64) -> DVec3 {
        let c = &self.corners;
        if self.is_quad() {
            c[0].lerp(c[1], u).lerp(c[3].lerp(c[2], u), v)
        } else {
            let (s, t) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            c[0] + (c[1] - c[0]) * s + (c[2] - c[0]) * t
        }
    }

    /// A point distributed uniformly by area, from three uniform numbers in [0, 1).
    pub fn uniform_point(&self, u: f64, v: f64, pick: f64) -> DVec3 {
        let c = &self.corners;
        let fold = |a: DVec3, b: DVec3, d: DVec3| {
            let (s, t) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            a + (b - a) * s + (d - a) * t
        };
        if !self.is_quad() {
            return fold(c[0], c[1], c[2]);
        }
        let first = triangle_area(c[0], c[1], c[2]);
        if pick * self.area() < first {
            fold(c[0], c[1], c[2])
        } else {
            fold(c[0], c[2], c[3])
        }
    }

    /// Quadrature over the polygon: calls `visit(point, weight)` with weights summing to 1.
    /// Level 0 is the centroid alone; level `m >= 1` splits a quad into `m x m` cells with 2 x 2
    /// Gauss-Legendre points each (exact for bicubics), and a triangle into `m^2` similar
    /// triangles with the 3-point Strang-Fix rule each (exact for quadratics).
    pub fn for_each_quadrature_point(&self, level: u32, mut visit: impl FnMut(DVec3, f64)) {
        if level == 0 {
            visit(self.centroid(), 1.0);
            return;
        }
        let step = 1.0 / level as f64;
        let c = &self.corners;
        if self.is_quad() {
            // Points at the cell's centre +- half / sqrt(3); weights carry the bilinear map's
            // Jacobian, whose integral is exactly the area, so they sum to one.
            let offset = 0.5 * step / 3f64.sqrt();
            let jacobian = |u: f64, v: f64| {
                let du = (c[1] - c[0]) * (1.0 - v) + (c[2] - c[3]) * v;
                let dv = (c[3] - c[0]) * (1.0 - u) + (c[2] - c[1]) * u;
                du.cross(dv).length()
            };
            let scale = 0.25 * step * step / self.area();
            for a in 0..level {
                for b in 0..level {
                    let (uc, vc) = ((a as f64 + 0.5) * step, (b as f64 + 0.5) * step);
                    for (u, v) in [
                        (uc - offset, vc - offset),
                        (uc + offset, vc - offset),
                        (uc - offset, vc + offset),
                        (uc + offset, vc + offset),
                    ] {
                        visit(self.point_at(u, v), jacobian(u, v) * scale);
                    }
                }
            }
        } else {
            let weight = step * step / 3.0;
            let (e1, e2) = ((c[1] - c[0]) * step, (c[2] - c[0]) * step);
            // Strang-Fix: barycentric (2/3, 1/6, 1/6) and its permutations, on each small
            // triangle with corners `base`, `base + d1`, `base + d2`.
            let mut rule = |base: DVec3, d1: DVec3, d2: DVec3| {
                for (s, t) in [
                    (1.0 / 6.0, 1.0 / 6.0),
                    (2.0 / 3.0, 1.0 / 6.0),
                    (1.0 / 6.0, 2.0 / 3.0),
                ] {
                    visit(base + d1 * s + d2 * t, weight);
                }
            };
            for a in 0..level {
                for b in 0..level - a {
                    let base = c[0] + e1 * a as f64 + e2 * b as f64;
                    rule(base, e1, e2);
                    if a + b + 1 < level {
                        // The inverted triangle between three upright ones.
                        rule(base + e1 + e2, -e1, -e2);
                    }
                }
            }
        }
    }

    /// For a quad: the largest distance of a corner from the plane of the other three, relative
    /// to the quad's diameter, and whether the corners turn the same way (convexity).
    pub fn is_planar_convex_quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> bool {
        const MAX_RELATIVE_WARP: f64 = 1e-6;
        let q = Polygon::quad(a, b, c, d);
        let normal = q.normal();
        let diameter = a.distance(c).max(b.distance(d));
        if normal == DVec3::ZERO || diameter == 0.0 {
            return false;
        }
        let warp = q
            .corners()
            .iter()
            .map(|p| (*p - q.centroid()).dot(normal).abs())
            .fold(0.0, f64::max);
        let corners = q.corners();
        let turns_left = (0..4).all(|k| {
            let (p, n, nn) = (corners[k], corners[(k + 1) % 4], corners[(k + 2) % 4]);
            (n - p).cross(nn - n).dot(normal) > 0.0
        });
        warp <= MAX_RELATIVE_WARP * diameter && turns_left
    }
}

/// The axis-aligned box around `points` as (min corner, max corner); inverted (+inf, -inf)
/// when there are none.
pub fn bounds(points: impl IntoIterator<Item = DVec3>) -> (DVec3, DVec3) {
    points.into_iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p), hi.max(p)),
    )
}

/// Area of the triangle `a, b, c`.
pub fn triangle_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    0.5 * (b - a).cross(c - a).length()
}

/// The differential form factor from a point `x` with unit normal `normal` to the front of
/// `source` (whose unit normal is `source_normal`), without occlusion: the fraction of the
/// energy leaving a Lambertian `dA` at `x` that arrives on `source`.
///
/// Zero when `x` is behind `source` (one-sided emitters and receivers); the part of `source`
/// below `x`'s tangent plane is clipped away first, so touching and perpendicular neighbours stay
/// exact instead of blowing up like the point-to-point `cos cos / (pi r^2)` kernel.
pub fn point_to_polygon_form_factor(
    x: DVec3,
    normal: DVec3,
    source: &Polygon,
    source_normal: DVec3,
) -> f64 {
    let corners = source.corners();
    // x must be strictly in front of the source's plane, relative to its distance.
    let offset = x - corners[0];
    if offset.dot(source_normal) <= 1e-12 * offset.length() {
        return 0.0;
    }
    let mut clipped = [DVec3::ZERO; 8];
    let count = clip_above_plane(corners, x, normal, &mut clipped);
    if count < 3 {
        return 0.0;
    }
    lambert_polygon(x, normal, &clipped[..count])
}

/// Lambert's formula for a polygon entirely above the tangent plane at `x` (Baum, Rushmeier,
/// Winget 1989, "Improving Radiosity Solutions Through the Use of Analytically Determined
/// Form-Factors", eq. 5): F = 1/(2 pi) * sum_k gamma_k * n . unit(R_k x R_k+1).
fn lambert_polygon(x: DVec3, normal: DVec3, polygon: &[DVec3]) -> f64 {
    let mut sum = 0.0;
    for k in 0..polygon.len() {
        let a = polygon[k] - x;
        let b = polygon[(k + 1) % polygon.len()] - x;
        let cross = a.cross(b);
        let cross_length = cross.length();
        // A vanishing cross product means x is on the edge's line: the edge subtends no angle.
        if cross_length <= 1e-15 * a.length() * b.length() {
            continue;
        }
        let gamma = angle_from(cross_length, a.dot(b));
        sum += gamma * normal.dot(cross) / cross_length;
    }
    // Winding decides the sign; a valid configuration has one sign, so take its magnitude.
    (sum.abs() / (2.0 * PI)).min(1.0)
}

/// The angle between two vectors from the length of their cross product (`sine`, positive)
/// and their dot product (`cosine`), radians in (0, pi]: `sine.atan2(cosine)`, with the
/// arctangent as Hart et al. 1968 ("Computer Approximations", ATAN 5077, 19.56 digits on
/// [0, tan(pi/8)]) give it after reducing the argument there. Lambert's formula takes one
/// per polygon edge, and libm's atan2 was half its time.
#[allow(clippy::excessive_precision)] // the catalog's coefficients, digit for digit
fn angle_from(sine: f64, cosine: f64) -> f64 {
    // tan(pi/8) and tan(3 pi/8): past them atan t = pi/4 + atan((t-1)/(t+1)), pi/2 - atan(1/t).
    const TAN_PI_8: f64 = std::f64::consts::SQRT_2 - 1.0;
    const TAN_3_PI_8: f64 = std::f64::consts::SQRT_2 + 1.0;
    let reduced_atan = |t: f64| {
        let t2 = t * t;
        let p = (((16.1536412982230228262 * t2 + 268.42548195503973794141) * t2
            + 1153.0293515404850115428136)
            * t2
            + 1780.40631643319697105464587)
            * t2
            + 896.78597403663861959987488;
        let q = ((((t2 + 58.95697050844462222791) * t2 + 536.265374031215315104235) * t2
            + 1666.7838148816337184521798)
            * t2
            + 2079.33497444540981287275926)
            * t2
            + 896.78597403663861962481162;
        t * p / q
    };
    let t = sine / cosine.abs();
    let first_quadrant = if t < TAN_PI_8 {
        reduced_atan(t)
    } else if t > TAN_3_PI_8 {
        PI / 2.0 - reduced_atan(cosine.abs() / sine)
    } else {
        PI / 4.0 + reduced_atan((t - 1.0) / (t + 1.0))
    };
    match cosine < 0.0 {
        true => PI - first_quadrant,
        false => first_quadrant,
    }
}

/// Sutherland-Hodgman clip of `polygon` to the half-space in front of the plane through `origin`
/// with normal `normal`; writes the result to `out` and returns its corner count.
pub(crate) fn clip_above_plane(
    polygon: &[DVec3],
    origin: DVec3,
    normal: DVec3,
    out: &mut [DVec3; 8],
) -> usize {
    let mut count = 0;
    for k in 0..polygon.len() {
        let (p, q) = (polygon[k], polygon[(k + 1) % polygon.len()]);
        let (dp, dq) = ((p - origin).dot(normal), (q - origin).dot(normal));
        if dp >= 0.0 {
            out[count] = p;
            count += 1;
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            out[count] = p + (q - p) * (dp / (dp - dq));
            count += 1;
        }
    }
    count
}

/// A convex polygon as faces: a planar convex quad stays one, anything else becomes a fan of
/// triangles.
pub(crate) fn convex_pieces(corners: &[DVec3]) -> Vec<Polygon> {
    if let [a, b, c, d] = *corners
        && Polygon::is_planar_convex_quad(a, b, c, d)
    {
        return vec![Polygon::quad(a, b, c, d)];
    }
    (1..corners.len().saturating_sub(1))
        .map(|k| Polygon::triangle(corners[0], corners[k], corners[k + 1]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::dvec3;

    #[test]
    fn the_edge_angle_is_atan2_to_the_last_bits() {
        let mut worst: f64 = 0.0;
        for i in 1..20_000 {
            // Angles over (0, pi], each at lengths from 1e-9 to 1e9.
            let angle = PI * i as f64 / 20_000.0;
            let length = 10f64.powi(i % 19 - 9);
            let (sine, cosine) = (length * angle.sin(), length * angle.cos());
            let exact = sine.atan2(cosine);
            worst = worst.max((angle_from(sine, cosine) - exact).abs() / exact);
        }
        assert!(worst < 4.0 * f64::EPSILON, "relative error {worst:e}");
        // Straight up (cosine 0) and nearly straight back.
        assert_eq!(angle_from(1.0, 0.0), PI / 2.0);
        assert!((angle_from(1e-300, -1.0) - PI).abs() <= f64::EPSILON * PI);
    }

    fn unit_square_at_height(z: f64) -> Polygon {
        // Faces down (-z), towards a receiver below it.
        Polygon::quad(
            dvec3(0.0, 0.0, z),
            dvec3(0.0, 1.0, z),
            dvec3(1.0, 1.0, z),
            dvec3(1.0, 0.0, z),
        )
    }

    #[test]
    fn point_below_infinite_plane_sees_form_factor_one() {
        let huge = 1e6;
        let plane = Polygon::quad(
            dvec3(-huge, -huge, 1.0),
            dvec3(-huge, huge, 1.0),
            dvec3(huge, huge, 1.0),
            dvec3(huge, -huge, 1.0),
        );
        let f = point_to_polygon_form_factor(DVec3::ZERO, DVec3::Z, &plane, plane.normal());
        assert!((f - 1.0).abs() < 1e-5, "{f}");
    }

    #[test]
    fn point_to_coaxial_square_matches_closed_form() {
        // Howell catalog B-3: dA to a parallel a x b rectangle with the normal through a corner,
        // F = 1/(2 pi) [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) + B/sqrt(1+B^2) atan(A/sqrt(1+B^2))].
        let (a, b) = (1.0f64, 1.0f64);
        let expected = (a / (1.0 + a * a).sqrt() * (b / (1.0 + a * a).sqrt()).atan()
            + b / (1.0 + b * b).sqrt() * (a / (1.0 + b * b).sqrt()).atan())
            / (2.0 * PI);
        let f = point_to_polygon_form_factor(
            DVec3::ZERO,
            DVec3::Z,
            &unit_square_at_height(1.0),
            -DVec3::Z,
        );
        assert!((f - expected).abs() < 1e-12, "{f} vs {expected}");
    }

    #[test]
    fn source_behind_receiver_or_facing_away_gives_zero() {
        let square = unit_square_at_height(1.0);
        assert_eq!(
            point_to_polygon_form_factor(DVec3::ZERO, -DVec3::Z, &square, square.normal()),
            0.0
        );
        assert_eq!(
            point_to_polygon_form_factor(dvec3(0.5, 0.5, 2.0), -DVec3::Z, &square, square.normal()),
            0.0
        );
    }

    #[test]
    fn clipping_keeps_only_the_part_above_the_tangent_plane() {
        // A square straddling the receiver's plane sees exactly the half above it.
        // Both face -y, towards the receiver at the origin.
        let straddling = Polygon::quad(
            dvec3(-1.0, 1.0, -1.0),
            dvec3(1.0, 1.0, -1.0),
            dvec3(1.0, 1.0, 1.0),
            dvec3(-1.0, 1.0, 1.0),
        );
        let upper_half = Polygon::quad(
            dvec3(-1.0, 1.0, 0.0),
            dvec3(1.0, 1.0, 0.0),
            dvec3(1.0, 1.0, 1.0),
            dvec3(-1.0, 1.0, 1.0),
        );
        let f =
            point_to_polygon_form_factor(DVec3::ZERO, DVec3::Z, &straddling, straddling.normal());
        let g =
            point_to_polygon_form_factor(DVec3::ZERO, DVec3::Z, &upper_half, upper_half.normal());
        assert!(f > 0.0 && (f - g).abs() < 1e-12, "{f} vs {g}");
    }

    #[test]
    fn quadrature_weights_sum_to_one_and_points_lie_inside() {
        let skewed = Polygon::quad(
            dvec3(0.0, 0.0, 0.0),
            dvec3(3.0, 0.0, 0.0),
            dvec3(2.0, 1.0, 0.0),
            dvec3(0.5, 1.0, 0.0),
        );
        let triangle = Polygon::triangle(DVec3::ZERO, DVec3::X, DVec3::Y);
        for polygon in [skewed, triangle] {
            let points_per_cell = if polygon.is_quad() { 4 } else { 3 };
            for m in 0..6 {
                let (mut total, mut count, mut mean) = (0.0, 0, DVec3::ZERO);
                polygon.for_each_quadrature_point(m, |p, w| {
                    total += w;
                    count += 1;
                    mean += p * w;
                });
                assert!((total - 1.0).abs() < 1e-12);
                assert_eq!(count, (m * m * points_per_cell).max(1));
                // Every level integrates linear functions exactly: the mean is the centroid.
                assert!(
                    mean.distance(polygon.centroid()) < 1e-12 * polygon.radius(),
                    "m={m}"
                );
            }
        }
    }

    #[test]
    fn the_closest_point_is_the_projection_inside_and_on_the_border_outside() {
        let square = unit_square_at_height(0.0);
        let near = |a: DVec3, b: DVec3| a.distance(b) < 1e-12;
        assert!(near(
            square.closest_point(DVec3::new(0.25, 0.5, 3.0)),
            DVec3::new(0.25, 0.5, 0.0)
        ));
        assert!(near(
            square.closest_point(DVec3::new(2.0, 0.5, -1.0)),
            DVec3::new(1.0, 0.5, 0.0)
        ));
        assert!(near(
            square.closest_point(DVec3::new(-1.0, -2.0, 1.0)),
            DVec3::ZERO
        ));
    }

    #[test]
    fn planarity_and_convexity_of_quads() {
        let (a, b, c, d) = (DVec3::ZERO, DVec3::X, dvec3(1.0, 1.0, 0.0), DVec3::Y);
        assert!(Polygon::is_planar_convex_quad(a, b, c, d));
        assert!(!Polygon::is_planar_convex_quad(
            a,
            b,
            dvec3(1.0, 1.0, 0.1),
            d
        ));
        assert!(!Polygon::is_planar_convex_quad(
            a,
            b,
            dvec3(0.2, 0.2, 0.0),
            d
        ));
    }
}
