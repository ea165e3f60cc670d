//! Light between two patches: which pairs can exchange any, the receiver quadrature a pair
//! needs, the shadow rays it gets, and the unoccluded factor. The dense matrix and the
//! hierarchy's links integrate pairs with the same rules.

use crate::geometry::point_to_polygon_form_factor;
use crate::mesh::Patch;
use glam::DVec3;

/// Accuracy knobs of the form-factor computation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FormFactorSettings {
    /// Shadow rays between a far pair of patches; near pairs get this many per receiver
    /// quadrature cell (at most [`MAX_RAYS_PER_PAIR`]).
    pub rays_per_pair: u32,
}

impl Default for FormFactorSettings {
    fn default() -> Self {
        FormFactorSettings { rays_per_pair: 2 }
    }
}

/// Upper bound on the shadow rays one pair of patches gets.
pub const MAX_RAYS_PER_PAIR: u32 = 64;

/// Sources farther than this many receiver radii are integrated at the receiver's centroid;
/// that rule's relative error falls like (radius / distance)^2 (about 0.5% at 8 radii).
const NEAR_FIELD_RADII: f64 = 8.0;
/// Cells of a near-pair quadrature are about `1 / QUADRATURE_DENSITY` of the gap they look across.
const QUADRATURE_DENSITY: f64 = 1.5;
/// The finest rule for one pair (`4 * 6^2` points on a quad), reached by touching patches.
pub const MAX_PAIR_LEVEL: u32 = 6;

/// The quadrature level (see [`Polygon::for_each_quadrature_point`]) receiver `p` needs for
/// source `q`: `None` in the far field (the centroid serves), else finer the smaller the gap
/// between `p`'s centroid and the nearest the source can come (zero for touching patches).
///
/// [`Polygon::for_each_quadrature_point`]: crate::geometry::Polygon::for_each_quadrature_point
pub fn near_pair_level(p: &Patch, q: &Patch) -> Option<u32> {
    let distance = p.centroid.distance(q.centroid);
    if distance >= NEAR_FIELD_RADII * p.radius {
        return None;
    }
    let gap = distance - q.radius;
    let level = if gap <= 0.0 {
        MAX_PAIR_LEVEL
    } else {
        ((QUADRATURE_DENSITY * p.radius / gap).ceil() as u32).clamp(1, MAX_PAIR_LEVEL)
    };
    Some(level)
}

/// The factor from a point `y` (unit normal `normal`) to patch `r` where `r` is at least
/// [`NEAR_FIELD_RADII`] of its radii away and wholly on one side of `y`'s tangent plane: from
/// `r`'s centroid, `A cos cos / (pi d^2 + A)` (Wallace, Elmquist, Haines 1989's disc, exact on
/// a disc's axis; elsewhere within `(radius / distance)^2` of `A / (pi d^2)` of Lambert's
/// factor), or zero where `r` lies below the plane or `y` behind `r`. `None` nearer, or where
/// `r` straddles the plane: only the exact factor, which clips `r` there, holds. Cluster links
/// take millions of point factors; this one costs no trigonometry.
pub fn far_point_to_patch_factor(y: DVec3, normal: DVec3, r: &Patch) -> Option<f64> {
    let d = r.centroid - y;
    let distance_sq = d.length_squared();
    if distance_sq < (NEAR_FIELD_RADII * r.radius).powi(2) {
        return None;
    }
    let distance = distance_sq.sqrt();
    let (cos_y, cos_r) = (normal.dot(d) / distance, -r.normal.dot(d) / distance);
    // The sine of the angle `r`'s bounding sphere subtends.
    let spread = r.radius / distance;
    if cos_y <= -spread || cos_r <= 0.0 {
        return Some(0.0);
    }
    if cos_y < spread {
        return None;
    }
    Some(r.area * cos_y * cos_r / (std::f64::consts::PI * distance_sq + r.area))
}

/// Whether every point of source `q` (by its bounding sphere) lies at least
/// [`NEAR_FIELD_RADII`] of receiver `p`'s radii from `p`'s centroid: there the factor from
/// `p`'s points to `q` is linear over `p` to within `(radius / distance)^2` of itself. (A
/// large source whose centroid is far can still pass close by: [`near_pair_level`] looks at
/// the centroid, for patches of one size.)
pub fn wholly_in_far_field(p: &Patch, q: &Patch) -> bool {
    p.centroid.distance(q.centroid) - q.radius >= NEAR_FIELD_RADII * p.radius
}

/// Shadow rays between two patches: more for pairs that are near against their size, where
/// visibility varies most across the pair. Symmetric in the pair.
pub fn rays_for_pair(p: &Patch, q: &Patch, settings: &FormFactorSettings) -> u32 {
    let distance = p.centroid.distance(q.centroid).max(f64::MIN_POSITIVE);
    let closeness = ((2.0 * p.radius.max(q.radius) / distance).ceil() as u32).clamp(1, 4);
    (settings.rays_per_pair.max(1) * closeness * closeness).min(MAX_RAYS_PER_PAIR)
}

/// True when each patch has part of itself strictly in front of the other: otherwise no light
/// passes between them in either direction (surfaces are one-sided).
pub fn mutually_facing(p: &Patch, q: &Patch) -> bool {
    let tolerance = 1e-12 * (p.radius + q.radius);
    let in_front = |of: &Patch, other: &Patch| {
        other
            .polygon
            .corners()
            .iter()
            .any(|c| (*c - of.centroid).dot(of.normal) > tolerance)
    };
    in_front(p, q) && in_front(q, p)
}

/// Unoccluded form factor from receiver `p` to source `q`: the area average over `p` of the
/// analytic point-to-polygon factor, with the receiver's quadrature `level`.
pub fn unoccluded_form_factor(p: &Patch, q: &Patch, level: u32) -> f64 {
    let mut sum = 0.0;
    p.polygon.for_each_quadrature_point(level, |x, weight| {
        sum += weight * point_to_polygon_form_factor(x, p.normal, &q.polygon, q.normal)
    });
    sum
}

/// `cos_p cos_q / d^2` between points with normals `np` and `nq` and `d` from the first to the
/// second (the form factor kernel without its 1/pi), from unnormalised dot products; zero when
/// either faces away.
pub fn facing_kernel(np: DVec3, nq: DVec3, d: DVec3) -> f64 {
    np.dot(d).max(0.0) * (-nq.dot(d)).max(0.0) / d.length_squared().powi(2)
}

#[cfg(test)]
mod tests {
    use super::{NEAR_FIELD_RADII, far_point_to_patch_factor};
    use crate::geometry::point_to_polygon_form_factor;
    use crate::hierarchy::fixtures::{GREY, add_parallelogram};
    use crate::mesh::{Mesh, PatchTarget};
    use crate::scene::Scene;
    use glam::{DVec3, dvec3};
    use std::f64::consts::PI;

    /// `count` directions spread over the sphere (a Fibonacci lattice).
    fn directions(count: usize) -> impl Iterator<Item = DVec3> {
        let golden = PI * (3.0 - 5.0f64.sqrt());
        (0..count).map(move |k| {
            let z = 1.0 - (2 * k + 1) as f64 / count as f64;
            let ring = (1.0 - z * z).sqrt();
            let angle = golden * k as f64;
            dvec3(ring * angle.cos(), ring * angle.sin(), z)
        })
    }

    #[test]
    fn a_far_patch_takes_its_centroids_factor_within_its_angular_size_squared() {
        // A tilted 1 x 0.5 plate seen from points all around it, 8 to 40 of its radii away,
        // each facing one of a spread of directions: where the disc rule answers, it lies
        // within (radius / distance)^2 of the normal-incidence factor A / (pi d^2) of
        // Lambert's exact factor, and it answers everywhere but where the plate straddles
        // the point's tangent plane.
        let mut scene = Scene::default();
        let (u, v) = (dvec3(1.0, 0.0, 0.3), dvec3(0.0, 0.5, 0.1));
        add_parallelogram(&mut scene, "plate", (dvec3(0.2, -0.1, 0.4), u, v), GREY);
        let mesh = Mesh::build(&scene, PatchTarget::EdgeLength(10.0));
        let [plate] = &mesh.patches[..] else {
            panic!("one patch")
        };
        let (mut answered, mut asked) = (0, 0);
        for radii in [NEAR_FIELD_RADII * 1.001, 12.0, 20.0, 40.0] {
            let distance = radii * plate.radius;
            for (k, direction) in directions(96).enumerate() {
                let y = plate.centroid + direction * distance;
                for normal in directions(24).skip(k % 3) {
                    asked += 1;
                    let exact =
                        point_to_polygon_form_factor(y, normal, &plate.polygon, plate.normal);
                    let Some(far) = far_point_to_patch_factor(y, normal, plate) else {
                        let spread = plate.radius / distance;
                        let cos_y = -normal.dot(direction);
                        assert!(cos_y.abs() < spread, "{cos_y} at {y} facing {normal}");
                        continue;
                    };
                    answered += 1;
                    let scale = plate.area / (PI * distance * distance);
                    let bound = scale / (radii * radii);
                    assert!(
                        (far - exact).abs() <= bound,
                        "{far} against {exact} at {y} facing {normal} (bound {bound})"
                    );
                }
            }
        }
        assert!(answered * 10 > asked * 9, "{answered} of {asked}");
    }
}
