//! The last bounces of indirect light gathered at each display corner: rays from the corner
//! read the solution's reflected light where they land, as viewers would see it there (where
//! they land is kept, and read once per bounce gathered: `vertices::GATHERED_BOUNCES`).
//!
//! A corner's indirect light averaged from the patches around it carries every error the
//! patches' links make (a cluster's sampled factor, a pair dropped as hidden, a patch too
//! coarse for the light across it), and on real models those dominate what viewers see. One
//! more bounce, gathered at the corner with cosine-distributed rays (the "final gather" of
//! Reichert 1992 and Lischinski, Tampieri, Greenberg 1993), integrates that light again
//! against the visibility the corner itself has: what the patches got wrong is seen only
//! through one more reflection. Each ray reads the values viewers are shown where it lands
//! (direct light gathered at corners, interpolated), so the gather is linear in them: a fixed
//! sparse matrix from corners to corners, built once per mesh, that serves every emission edit.

use super::gather_point::{GatherPoint, PointWeights};
use super::locator::PatchLocator;
use crate::mesh::Mesh;
use crate::sampling::{cosine_direction, pair_seed, stratified_uv};
use crate::visibility::Occluders;
use glam::DVec3;

/// Cosine-distributed rays per corner. The gather's noise is the spread of what the rays see
/// over the square root of this: at the vertices, the Cornell box at knob 0.3 read 4.80 /
/// 3.77 / 3.00% smooth RMS with 16 / 32 / 64 (one bounce), and that noise is the floor of a
/// hierarchy's error, near 1.6% there; the monastery at the reference probes themselves read
/// the same with 64 and 512 (docs/BENCHMARKS.md).
pub(super) const BOUNCE_RAYS: u32 = 64;

/// What seeds the gather's rays, apart from the direct light's at the same corner.
const BOUNCE_SEED: usize = 0xB0C3;

/// Casts the bounce's rays from each of `points` (one per corner of `mesh`; `None`: a corner
/// no patch uses) and records where they land: per corner, the corners it reads and with what
/// weight (summing to the share of rays that met the front of a reflecting face), so that
/// reading the corners' reflected light gives the irradiance it gathers from surfaces over pi,
/// W/m^2. A ray that escapes, or meets the back of a face (from inside a wall it reads
/// nothing), gathers nothing.
pub(super) fn landings(
    mesh: &Mesh,
    points: &[Option<GatherPoint>],
    occluders: &Occluders,
    face_count: usize,
) -> PointWeights {
    let locator = PatchLocator::new(mesh, face_count);
    PointWeights::at_points(points, |index, point| {
        let seed = pair_seed(index, BOUNCE_SEED);
        let normal = snapped(point.normal);
        let mut read: Vec<(u32, f32)> = Vec::with_capacity(3 * BOUNCE_RAYS as usize);
        for k in 0..BOUNCE_RAYS {
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
            let Some(place) = locator.place(mesh, hit.face, landing) else {
                continue;
            };
            // A face that reflects nothing (a sky) sends no reflected light at any edit.
            if mesh.patches[place.patch].reflectance.max_element() > 0.0 {
                for (&c, &w) in place.corners.iter().zip(&place.weights) {
                    read.push((c, (w / BOUNCE_RAYS as f64) as f32));
                }
            }
        }
        merged(read)
    })
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

/// `read` with the weights of each corner summed, by corner, in no more memory than that
/// takes (a corner's rays mostly land on a few patches).
fn merged(mut read: Vec<(u32, f32)>) -> Vec<(u32, f32)> {
    read.sort_unstable_by_key(|&(c, _)| c);
    read.dedup_by(|next, kept| {
        let same = next.0 == kept.0;
        if same {
            kept.1 += next.1;
        }
        same
    });
    read.shrink_to_fit();
    read
}
