//! Radiosity at the display vertices, with direct light gathered where it is seen.
//!
//! A solution holds one value per patch; viewers interpolate values at the patches' corners.
//! Averaging patch values into corners blurs the sharpest detail of a scene, the direct light:
//! its peaks are flattened and its shadow edges smeared over a patch. So each corner's value is
//! rebuilt as emission + direct + indirect, where the direct part is gathered at the corner
//! itself from every emitter with the exact point-to-polygon factor and sampled visibility, and
//! only the smooth indirect part is averaged from the patches around it (the "final gather" of
//! Lischinski, Tampieri, Greenberg 1993, "Combining Hierarchical Radiosity and Discontinuity
//! Meshing"). Everything is linear in each emitter's emission, so edits still superpose.

use crate::geometry::{Polygon, point_to_polygon_form_factor};
use crate::mesh::Mesh;
use crate::sampling::{pair_seed, stratified_uv};
use crate::scene::{Rgb, Scene};
use crate::transport::Transport;
use crate::visibility::Occluders;
use glam::DVec3;
use rayon::prelude::*;

/// Shadow rays per corner and emitter: the first ones decide alone when they all agree, the
/// rest sample a penumbra. An emitter that gives a corner less than [`MINOR_SHARE`] of its
/// unoccluded direct light gets the minor budget: its visibility error weighs that much less
/// (in the furnished room, 16 lamps a vertex mostly sees from afar).
const RAYS: RayBudget = RayBudget {
    first: 16,
    penumbra: 64,
};
/// The budget of an emitter that gives a corner little of its light.
const MINOR_RAYS: RayBudget = RayBudget {
    first: 4,
    penumbra: 16,
};
/// Below this share of a corner's unoccluded direct light an emitter is minor.
const MINOR_SHARE: f64 = 0.05;

/// Shadow rays for one corner and emitter.
struct RayBudget {
    first: u32,
    penumbra: u32,
}

/// Emitting faces beyond which corners gather none (their patches' values are averaged, as
/// without a gather): corners times emitters times rays would outgrow the solve itself.
pub const MAX_GATHERED_EMITTERS: usize = 256;
/// How far a shadow ray's origin moves from a corner toward the centre of a patch that uses
/// it, as a fraction of the distance. Visibility at a corner is so the mean over a small
/// neighbourhood, not a point sample: a corner a hair's breadth inside a contact line that
/// falls between lattice points would otherwise read fully dark while the probes just outside
/// are lit (measured on the Cornell box: 0.25 lowers the smooth RMS at every knob; 1e-3 raises
/// it at knob 0.05; 0.5 blurs penumbrae on the shadow slab).
const INSET: f64 = 0.25;
/// Where the unoccluded factor is evaluated: this fraction of the way from the corner toward
/// the centre of a patch that uses it. A corner on an edge shared with a perpendicular face
/// lies in that face's plane, where the factor drops to zero; just inside, it has its limit.
const LIMIT_INSET: f64 = 1e-6;

/// One emitting input face.
struct Emitter {
    polygon: Polygon,
    normal: DVec3,
    face: u32,
    /// Its largest emission channel as loaded, W/m^2: what ranks it among a corner's emitters.
    brightness: f64,
}

/// A mesh corner and the points just inside the patches around it.
struct Corner {
    /// The corner moved [`LIMIT_INSET`] into its first patch.
    limit: DVec3,
    normal: DVec3,
    face: u32,
    /// Up to four points, each [`INSET`] of the way into one patch that uses the corner: rays
    /// start from them in turn, so a corner on a contact line sees the mean of both sides.
    insides: Vec<DVec3>,
}

/// What a mesh's corners receive straight from the emitters, and which patches around each
/// corner light can reach. It depends on the geometry and on which faces emit, not on how
/// much: built once per mesh, it serves every emission edit.
pub struct CornerLight {
    /// Per corner, `factors[offsets[c]..offsets[c + 1]]`: (emitting face, form factor from the
    /// corner to it with visibility).
    offsets: Vec<u32>,
    factors: Vec<(u32, f32)>,
    /// Whether direct light is gathered at the corners (at most [`MAX_GATHERED_EMITTERS`]
    /// emitting faces); if not, corners average their patches' whole reflected radiosity.
    gathered: bool,
    /// Per patch and corner slot: whether light reaches the patch at the point [`INSET`] of the
    /// way in from that corner (not under a box standing on the floor:
    /// [`Occluders::is_buried`]).
    reached: Vec<[bool; 4]>,
}

impl CornerLight {
    /// Gathers the emitters of `scene` at the corners of `mesh` (built from it).
    pub fn new(scene: &Scene, mesh: &Mesh, occluders: &Occluders) -> CornerLight {
        let emitters: Vec<Emitter> = scene
            .faces
            .iter()
            .enumerate()
            .filter(|(_, f)| f.emission.max_element() > 0.0)
            .map(|(i, f)| Emitter {
                polygon: f.polygon,
                normal: f.polygon.normal(),
                face: i as u32,
                brightness: f.emission.max_element(),
            })
            .collect();
        let gathered = emitters.len() <= MAX_GATHERED_EMITTERS;
        let corners = corners_of(mesh);
        let per_corner: Vec<Vec<(u32, f32)>> = corners
            .par_iter()
            .enumerate()
            .map(|(index, corner)| match corner {
                Some(corner) if gathered => {
                    let unoccluded: Vec<f64> = emitters
                        .iter()
                        .map(|e| unoccluded_factor(corner, e))
                        .collect();
                    let total: f64 = unoccluded
                        .iter()
                        .zip(&emitters)
                        .map(|(f, e)| f * e.brightness)
                        .sum();
                    emitters
                        .iter()
                        .zip(&unoccluded)
                        .filter(|(_, f)| **f > 0.0)
                        .filter_map(|(e, &f)| {
                            let budget = if f * e.brightness < MINOR_SHARE * total {
                                &MINOR_RAYS
                            } else {
                                &RAYS
                            };
                            let factor = f * seen_share(corner, e, occluders, index, budget);
                            (factor > 0.0).then_some((e.face, factor as f32))
                        })
                        .collect()
                }
                _ => Vec::new(),
            })
            .collect();
        let mut offsets = Vec::with_capacity(per_corner.len() + 1);
        offsets.push(0);
        for list in &per_corner {
            offsets.push(offsets.last().copied().unwrap_or(0) + list.len() as u32);
        }
        let reached = mesh
            .patches
            .par_iter()
            .enumerate()
            .map(|(i, patch)| {
                let mut reached = [true; 4];
                for (slot, &c) in patch.corners[..patch.corner_count()].iter().enumerate() {
                    let inside = inset(mesh.positions[c as usize], patch.centroid);
                    let seed = pair_seed(i, slot);
                    reached[slot] = !occluders.is_buried(inside, patch.normal, patch.face, seed);
                }
                reached
            })
            .collect();
        CornerLight {
            offsets,
            factors: per_corner.into_iter().flatten().collect(),
            gathered,
            reached,
        }
    }

    /// Radiosity at every corner of `mesh`, W/m^2, for the patch solution `radiosity` under
    /// the patches' current `emission` (`transport` is the one that solution came from): the
    /// corner's emission, its reflectance times the direct irradiance gathered there, and the
    /// area-weighted mean, over the patches around it that light reaches, of their indirect
    /// reflected radiosity. A patch's indirect part is its reflected radiosity less what
    /// `transport` carries straight from the emitters, so the errors the transport makes in
    /// direct light cancel instead of adding up.
    pub fn corner_radiosity(
        &self,
        mesh: &Mesh,
        transport: &dyn Transport,
        radiosity: &[Rgb],
        emission: &[Rgb],
    ) -> Vec<Rgb> {
        let mut direct_gathered = vec![Rgb::ZERO; emission.len()];
        if self.gathered {
            transport.gather(emission, &mut direct_gathered);
        }
        let mut face_emission = vec![
            Rgb::ZERO;
            mesh.patches
                .iter()
                .map(|p| p.face as usize + 1)
                .max()
                .unwrap_or(0)
        ];
        let mut sums = vec![(Rgb::ZERO, 0.0); mesh.positions.len()];
        // Per corner, its face's emission and reflectance; `None` for a corner no patch uses.
        let mut surface = vec![None; mesh.positions.len()];
        for (i, patch) in mesh.patches.iter().enumerate() {
            face_emission[patch.face as usize] = emission[i];
            let indirect = radiosity[i] - emission[i] - patch.reflectance * direct_gathered[i];
            for (slot, &c) in patch.corners[..patch.corner_count()].iter().enumerate() {
                let sum = &mut sums[c as usize];
                if self.reached[i][slot] {
                    sum.0 += indirect * patch.area;
                    sum.1 += patch.area;
                }
                surface[c as usize] = Some((emission[i], patch.reflectance));
            }
        }
        (0..mesh.positions.len())
            .map(|c| {
                let Some((own_emission, reflectance)) = surface[c] else {
                    return Rgb::ZERO;
                };
                // Buried on every side: no light arrives, only the face's own emission leaves.
                let (sum, area) = sums[c];
                let indirect = if area > 0.0 { sum / area } else { Rgb::ZERO };
                let direct: Rgb = self.factors
                    [self.offsets[c] as usize..self.offsets[c + 1] as usize]
                    .iter()
                    .map(|&(face, factor)| face_emission[face as usize] * factor as f64)
                    .sum();
                (own_emission + reflectance * direct + indirect).max(Rgb::ZERO)
            })
            .collect()
    }
}

/// The point a fraction [`INSET`] of the way from `corner` to `inside`.
fn inset(corner: DVec3, inside: DVec3) -> DVec3 {
    corner + (inside - corner) * INSET
}

fn corners_of(mesh: &Mesh) -> Vec<Option<Corner>> {
    let mut corners: Vec<Option<Corner>> = (0..mesh.positions.len()).map(|_| None).collect();
    for patch in &mesh.patches {
        for &c in &patch.corners[..patch.corner_count()] {
            let position = mesh.positions[c as usize];
            let corner = corners[c as usize].get_or_insert_with(|| Corner {
                limit: position + (patch.centroid - position) * LIMIT_INSET,
                normal: patch.normal,
                face: patch.face,
                insides: Vec::new(),
            });
            if corner.insides.len() < 4 {
                corner.insides.push(inset(position, patch.centroid));
            }
        }
    }
    corners
}

/// Lambert's exact form factor from the corner to the emitter, unoccluded.
fn unoccluded_factor(corner: &Corner, emitter: &Emitter) -> f64 {
    if corner.face == emitter.face {
        return 0.0;
    }
    point_to_polygon_form_factor(
        corner.limit,
        corner.normal,
        &emitter.polygon,
        emitter.normal,
    )
}

/// The share of the corner's unoccluded factor to the emitter that visibility lets through:
/// the kernel-weighted share of stratified emitter points seen from just inside the patches
/// around the corner (the first rays of `budget` alone where they all agree).
fn seen_share(
    corner: &Corner,
    emitter: &Emitter,
    occluders: &Occluders,
    index: usize,
    budget: &RayBudget,
) -> f64 {
    let seed = pair_seed(index, emitter.face as usize);
    let (mut seen, mut total) = (0.0, 0.0);
    let mut sample = |k: u32| {
        let (u, v) = stratified_uv(k, seed);
        let target = emitter.polygon.point_at(u, v);
        let origin = corner.insides[k as usize % corner.insides.len()];
        let d = target - origin;
        // cos cos / r^2, the point-to-point kernel up to 1/pi: what each point contributes.
        let kernel = corner.normal.dot(d).max(0.0) * (-emitter.normal).dot(d).max(0.0)
            / d.length_squared().powi(2);
        let clear = occluders.segment_is_clear(origin, target, [corner.face, emitter.face]);
        total += kernel;
        if clear {
            seen += kernel;
        }
        clear
    };
    let first: Vec<bool> = (0..budget.first).map(&mut sample).collect();
    if first.iter().all(|&clear| clear) {
        return 1.0;
    }
    if first.iter().all(|&clear| !clear) {
        return 0.0;
    }
    (budget.first..budget.penumbra).for_each(|k| {
        sample(k);
    });
    if total > 0.0 { seen / total } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use crate::hierarchy::fixtures::{add_parallelogram, closed_cube, room_with_a_box};
    use crate::scene::{Material, Rgb, Scene};
    use crate::{
        HierarchySettings, Method, PatchTarget, SolveRequest, SolverSettings, solve_scene,
    };
    use glam::{DVec3, dvec3};
    use std::f64::consts::PI;

    fn request(hierarchical: bool) -> SolveRequest {
        SolveRequest {
            patches: PatchTarget::EdgeLength(0.5),
            solver: SolverSettings {
                method: Method::Gmres,
                tolerance: 1e-10,
                ..Default::default()
            },
            hierarchy: hierarchical.then(|| HierarchySettings {
                error: 0.1,
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// Howell's catalog B-3: from a differential element to a parallel a x b rectangle at
    /// distance c, the element under one of its corners.
    fn howell_b3(a: f64, b: f64, c: f64) -> f64 {
        let (x, y) = (a / c, b / c);
        let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
        (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * PI)
    }

    #[test]
    fn a_vertex_under_a_rectangular_lamp_gets_howells_factor_exactly() {
        // A 2 x 2 floor meshed at 0.5 (a vertex at (1, 0, 1)) under a black 0.6 x 0.4 lamp
        // whose corner is 0.5 above that vertex: nothing reflects light back, so the vertex
        // holds the direct light alone.
        let mut scene = Scene::default();
        let floor = Material {
            reflectance: Rgb::new(0.5, 0.25, 0.125),
            emission: Rgb::ZERO,
        };
        let lamp = Material {
            reflectance: Rgb::ZERO,
            emission: Rgb::splat(10.0),
        };
        let (x, z) = (DVec3::X, DVec3::Z);
        add_parallelogram(&mut scene, "floor", (DVec3::ZERO, z * 2.0, x * 2.0), floor);
        add_parallelogram(
            &mut scene,
            "lamp",
            (dvec3(1.0, 0.5, 1.0), x * 0.6, z * 0.4),
            lamp,
        );
        let expected = floor.reflectance * 10.0 * howell_b3(0.6, 0.4, 0.5);
        for hierarchical in [false, true] {
            let solved = solve_scene(scene.clone(), &request(hierarchical), &crate::no_progress)
                .expect("solves");
            let corner = solved
                .mesh
                .positions
                .iter()
                .position(|p| p.distance(dvec3(1.0, 0.0, 1.0)) < 1e-12)
                .expect("a floor vertex under the lamp's corner");
            let got = solved.vertex_radiosity[corner];
            println!("hierarchical {hierarchical}: {got} against Howell B-3 {expected}");
            assert!(
                ((got - expected).abs() / expected).max_element() < 1e-5,
                "hierarchical {hierarchical}: {got} against Howell B-3 {expected}"
            );
        }
    }

    #[test]
    fn every_vertex_of_a_closed_furnace_holds_e_over_one_minus_rho() {
        // Every face emits 1 with reflectance 0.5: B = 2 everywhere (REFERENCE.md). The
        // gathered direct light sums Lambert's factors of five faces to one at every vertex.
        for hierarchical in [false, true] {
            let solved = solve_scene(closed_cube(), &request(hierarchical), &crate::no_progress)
                .expect("solves");
            let worst = solved
                .vertex_radiosity
                .iter()
                .map(|b| (*b - Rgb::splat(2.0)).abs().max_element())
                .fold(0.0, f64::max);
            println!("hierarchical {hierarchical}: worst vertex off by {worst}");
            assert!(worst < 1e-6, "hierarchical {hierarchical}: off by {worst}");
        }
    }

    #[test]
    fn a_furnace_with_a_box_inside_is_exact_on_patches_and_within_sampling_at_vertices() {
        // B = 2 wherever light reaches. The patches are exact (rows of closed views sum to
        // one); the vertices gather each face's visibility apart, so the factors they see sum
        // to one only up to that sampling (measured: RMS 0.15%, worst 1.6%).
        let mut scene = room_with_a_box();
        scene.faces.iter_mut().for_each(|f| f.emission = Rgb::ONE);
        let under_the_box =
            |p: &DVec3| p.y == 0.0 && (1.0..=2.0).contains(&p.x) && (1.0..=2.0).contains(&p.z);
        for hierarchical in [false, true] {
            let solved =
                solve_scene(scene.clone(), &request(hierarchical), &crate::no_progress).unwrap();
            let patch_worst = solved
                .mesh
                .patches
                .iter()
                .zip(&solved.radiosity)
                .filter(|(p, _)| !under_the_box(&p.centroid))
                .map(|(_, b)| (*b - Rgb::splat(2.0)).abs().max_element())
                .fold(0.0, f64::max);
            assert!(
                patch_worst < 1e-6,
                "hierarchical {hierarchical}: patches off by {patch_worst}"
            );
            let errors: Vec<f64> = solved
                .mesh
                .positions
                .iter()
                .zip(&solved.vertex_radiosity)
                .filter(|(p, _)| !under_the_box(p))
                .map(|(_, b)| (*b - Rgb::splat(2.0)).abs().max_element() / 2.0)
                .collect();
            let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
            let worst = errors.iter().cloned().fold(0.0, f64::max);
            println!(
                "hierarchical {hierarchical}: patches {patch_worst}, vertices RMS {rms} worst {worst}"
            );
            assert!(
                rms < 0.003 && worst < 0.03,
                "hierarchical {hierarchical}: vertices off by {rms} RMS, {worst} at worst"
            );
        }
    }
}
