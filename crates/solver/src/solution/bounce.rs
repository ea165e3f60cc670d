//! The last bounces of indirect light gathered at each display corner: rays from the corner
//! read the solution's reflected light where they land, as viewers would see it there (where
//! they land is kept, and read once a pass of the last bounces: `vertices::LastBounces`).
//!
//! A corner's indirect light averaged from the patches around it carries every error the
//! patches' links make (a cluster's sampled factor, a pair dropped as hidden, a patch too
//! coarse for the light across it), and on real models those dominate what viewers see. One
//! more bounce, gathered at the corner with cosine-distributed rays (the "final gather" of
//! Reichert 1992 and Lischinski, Tampieri, Greenberg 1993), integrates that light again
//! against the visibility the corner itself has: what the patches got wrong is seen only
//! through one more reflection. Each ray reads the values viewers are shown where it lands
//! (direct light gathered at corners, interpolated), so the gather is linear in them: where
//! each ray landed is kept (8 bytes a ray), once per mesh, and serves every emission edit.

use super::gather_point::{GatherPoint, PointRows, Tally};
use super::locator::PatchLocator;
use crate::mesh::Mesh;
use crate::sampling::{Seed, cosine_direction, stratified_uv};
use crate::scene::Rgb;
use crate::visibility::Occluders;
use glam::DVec3;

/// Cosine-distributed rays of a gather point of the mean size: the area-weighted noise of the
/// gather is what this many rays at every point would give ([`ray_counts`]). The gather's
/// noise is the spread of what the rays see over the square root of the rays: at the vertices,
/// the Cornell box at knob 0.3 read 4.80 / 3.77 / 3.00% smooth RMS with 16 / 32 / 64 (one
/// bounce), and that noise is the floor of a hierarchy's error, near 1.6% there
/// (docs/BENCHMARKS.md).
pub(super) const MEAN_RAYS: f64 = 64.0;

/// The fewest and the most rays one gather point casts ([`ray_counts`]).
const RAYS_PER_POINT: (f64, f64) = (16.0, 256.0);

/// What seeds the gather's rays, apart from the direct light's at the same corner.
const BOUNCE_SEED: usize = 0xB0C3;

/// Where one of a corner's rays landed: the fan triangle `(c0, ck, ck+1)` of a patch and the
/// interpolation weights of its last two corners, in 8 bytes. A corner's rays are kept one by
/// one, so its memory is bounded by its rays, not by how many patches they meet (on soup,
/// where each ray meets another face, three corner weights a ray took three times this).
#[derive(Clone, Copy, Debug)]
struct Landing {
    /// The patch's index, with its fan triangle's `k - 1` in the top bit.
    patch_and_fan: u32,
    /// The weights of `ck` and `ck+1`, in units of 1/65535 (`c0` has the rest).
    weights: [u16; 2],
}

/// The top bit of [`Landing::patch_and_fan`].
const FAN_BIT: u32 = 1 << 31;

impl Landing {
    fn new(patch: usize, k: usize, weights: [f64; 3]) -> Landing {
        let unit = |w: f64| (w.clamp(0.0, 1.0) * f64::from(u16::MAX)).round() as u16;
        Landing {
            patch_and_fan: patch as u32 | if k == 2 { FAN_BIT } else { 0 },
            weights: [unit(weights[1]), unit(weights[2])],
        }
    }

    /// `values` (per mesh corner) interpolated where the ray landed, the mesh's patches given
    /// by their `corners` alone.
    fn read(self, corners: &[[u32; 4]], values: &[Rgb]) -> Rgb {
        let patch = &corners[(self.patch_and_fan & !FAN_BIT) as usize];
        let k = if self.patch_and_fan & FAN_BIT != 0 {
            2
        } else {
            1
        };
        let [w1, w2] = self.weights.map(|w| f64::from(w) / f64::from(u16::MAX));
        let [c0, c1, c2] = [patch[0], patch[k], patch[k + 1]].map(|c| values[c as usize]);
        c0 * (1.0 - w1 - w2) + c1 * w1 + c2 * w2
    }
}

/// Per gather point, where its rays landed on faces that reflect light, and how many it cast.
struct Landings {
    rows: PointRows<Landing>,
    rays: Vec<u16>,
}

/// Where the bounce's rays landed from each mesh corner and from each patch's centroid. The
/// centroids' gathers say what interpolating the corners' misses over each patch, as for the
/// direct light (`vertices`): a sliver of soup lit at its ends and shaded in its middle, or
/// the reverse, holds its light on average (the teddy bear: 2.66 -> 1.88% smooth RMS,
/// docs/BENCHMARKS.md).
pub(super) struct BounceLandings {
    corners: Landings,
    centres: Landings,
}

impl BounceLandings {
    /// Casts the bounce's rays from `corners` (one per corner of `mesh`; `None`: a corner no
    /// patch uses) and from `centroids` (one per patch), as many from each as [`ray_counts`]
    /// gives it, in the patterns `seed` draws, and records where they land, counting the
    /// points done in `tally`.
    pub(super) fn cast(
        mesh: &Mesh,
        (corners, centroids): (&[Option<GatherPoint>], &[Option<GatherPoint>]),
        occluders: &Occluders,
        (face_count, seed): (usize, Seed),
        tally: &Tally,
    ) -> BounceLandings {
        let locator = PatchLocator::new(mesh, face_count);
        let represented = (corners.iter().zip(corner_areas(mesh)))
            .chain(centroids.iter().zip(mesh.patches.iter().map(|p| p.area)))
            .map(|(point, area)| point.as_ref().map(|_| area));
        let mut rays = ray_counts(&represented.collect::<Vec<_>>());
        let centre_rays = rays.split_off(corners.len());
        let cast = |points, rays, first_index: usize| {
            let pattern = |index: usize| seed.pair(first_index + index, BOUNCE_SEED);
            Landings::cast(mesh, &locator, points, rays, &pattern, occluders, tally)
        };
        BounceLandings {
            corners: cast(corners, rays, 0),
            centres: cast(centroids, centre_rays, corners.len()),
        }
    }

    /// The rays corner `corner` cast.
    #[cfg(test)]
    pub(super) fn corner_rays(&self, corner: usize) -> u16 {
        self.corners.rays[corner]
    }

    /// Per corner and per patch centroid, the mean over its rays of `reflected` (per corner
    /// of the mesh whose [`patch_corners`] are `corners`) where they land: the irradiance it
    /// gathers from surfaces over pi, W/m^2.
    pub(super) fn read(&self, corners: &[[u32; 4]], reflected: &[Rgb]) -> (Vec<Rgb>, Vec<Rgb>) {
        (
            self.corners.read(corners, reflected),
            self.centres.read(corners, reflected),
        )
    }
}

/// Each patch's corners, the table [`BounceLandings::read`] looks landings up in: each pass of
/// the last bounces reads tens of millions of landings, and a patch's corners alone are 16
/// bytes of its more than 200, one cache line fewer missed a landing.
pub(super) fn patch_corners(mesh: &Mesh) -> Vec<[u32; 4]> {
    mesh.patches.iter().map(|p| p.corners).collect()
}

impl Landings {
    /// Casts `rays` from each of `points` (the `index`-th in the pattern `pattern(index)`) and
    /// records where they land. A ray that escapes, meets the back of a
    /// face (from inside a wall it reads nothing), or a face that reflects nothing (a sky, at
    /// any edit), gathers nothing. Each point counts as done in `tally`.
    fn cast(
        mesh: &Mesh,
        locator: &PatchLocator,
        points: &[Option<GatherPoint>],
        rays: Vec<u16>,
        pattern: &(dyn Fn(usize) -> u64 + Sync),
        occluders: &Occluders,
        tally: &Tally,
    ) -> Landings {
        let rows = PointRows::at_points(points, tally, |index, point| {
            let seed = pattern(index);
            let normal = snapped(point.normal);
            let mut landed = Vec::new();
            for k in 0..u32::from(rays[index]) {
                let (u, v) = stratified_uv(k, seed);
                let direction = cosine_direction(normal, u, v);
                let origin = point.insides[k as usize % point.insides.len()];
                let Some(hit) = occluders.closest_hit(origin, direction, point.face) else {
                    continue;
                };
                if !hit.front {
                    continue;
                }
                let landing = origin + direction * hit.distance;
                let Some(place) = locator.place(hit.face, landing) else {
                    continue;
                };
                if mesh.patches[place.patch].reflectance.max_element() > 0.0 {
                    landed.push(Landing::new(place.patch, place.fan, place.weights));
                }
            }
            landed.shrink_to_fit();
            landed
        });
        Landings { rows, rays }
    }

    /// Per point, the mean over its rays of `reflected` (per corner of the mesh whose patches
    /// have `corners`) where they land.
    fn read(&self, corners: &[[u32; 4]], reflected: &[Rgb]) -> Vec<Rgb> {
        let sums = (self.rows).map_rows(|row| row.iter().map(|l| l.read(corners, reflected)).sum());
        (sums.into_iter().zip(&self.rays))
            .map(|(sum, &rays)| sum / f64::from(rays.max(1)))
            .collect()
    }
}

/// Per corner of `mesh`, the area it stands for in what viewers see: its share of each patch
/// around it (a third of a triangle, a quarter of a quad).
pub(super) fn corner_areas(mesh: &Mesh) -> Vec<f64> {
    let mut areas = vec![0.0; mesh.positions.len()];
    for patch in &mesh.patches {
        let corners = &patch.corners[..patch.corner_count()];
        for &c in corners {
            areas[c as usize] += patch.area / corners.len() as f64;
        }
    }
    areas
}

/// Rays for each gather point of `represented` (the area it stands for; `None`: a point that
/// casts none). A point's noise shows over its area, so what viewers see of it all is the
/// area-weighted variance `sum A_i s^2 / N_i`; for a given total of rays it is least with
/// `N_i` in proportion to `sqrt(A_i)` (Lagrange), scaled here so that it equals that of
/// [`MEAN_RAYS`] at every point, then bounded by [`RAYS_PER_POINT`]. A refined model's points
/// are mostly small (the leaves where the direct light changes): the monastery's 1.03M
/// points cast 16 a point on average, the furnished room's 18, the teddy bear's 30
/// (docs/BENCHMARKS.md).
fn ray_counts(represented: &[Option<f64>]) -> Vec<u16> {
    let (area, root_area) = (represented.iter().flatten())
        .fold((0.0, 0.0), |(sum, roots), &a| (sum + a, roots + a.sqrt()));
    let per_root_area = if area > 0.0 {
        MEAN_RAYS * root_area / area
    } else {
        0.0
    };
    let (fewest, most) = RAYS_PER_POINT;
    (represented.iter())
        .map(|a| {
            a.map_or(0, |a| {
                (per_root_area * a.sqrt()).round().clamp(fewest, most) as u16
            })
        })
        .collect()
}

/// `normal` with the components that are zero up to rounding made exactly zero: the frame the
/// rays are drawn in turns with the sign of the normal's last component, and the rounding of an
/// axis-aligned wall's normal (+0, -0 or 1e-17 at one scale or another) must not choose its
/// rays.
fn snapped(normal: DVec3) -> DVec3 {
    const ROUNDING: f64 = 1e-12;
    DVec3::select(
        normal.abs().cmplt(DVec3::splat(ROUNDING)),
        DVec3::ZERO,
        normal,
    )
}

#[cfg(test)]
mod tests {
    use super::{MEAN_RAYS, RAYS_PER_POINT, ray_counts};

    #[test]
    fn points_of_one_area_each_cast_the_mean_rays() {
        assert_eq!(ray_counts(&[Some(0.3); 5]), vec![MEAN_RAYS as u16; 5]);
    }

    #[test]
    fn rays_go_with_the_root_of_the_area_and_keep_the_mean_rays_noise() {
        let areas = [1.0, 4.0, 0.25, 2.25];
        let rays = ray_counts(&areas.map(Some));
        // sum A = 7.5 and sum sqrt(A) = 5: 42.67 rays per unit root area.
        assert_eq!(rays, vec![43, 85, 21, 64]);
        // The area-weighted variance sum A / N, as with the mean rays at every point, from
        // fewer rays in all.
        let allocated: f64 = (areas.iter().zip(&rays))
            .map(|(a, &n)| a / f64::from(n))
            .sum();
        let uniform = areas.iter().sum::<f64>() / MEAN_RAYS;
        assert!(
            (allocated / uniform - 1.0).abs() < 0.01,
            "{allocated} against {uniform}"
        );
        let total: f64 = rays.iter().map(|&n| f64::from(n)).sum();
        assert!(total < MEAN_RAYS * 4.0, "{total}");
    }

    #[test]
    fn rays_stay_within_their_bounds_and_a_point_that_casts_none_gets_none() {
        // A thousand points of 1e-4 and one of 1: 640 rays per unit root area, 6.4 for each
        // small point and 640 for the large one, unbounded.
        let mut represented = vec![Some(1e-4); 1000];
        represented.extend([Some(1.0), None]);
        let rays = ray_counts(&represented);
        let (fewest, most) = RAYS_PER_POINT;
        assert_eq!(
            (rays[0], rays[1000], rays[1001]),
            (fewest as u16, most as u16, 0)
        );
    }
}
