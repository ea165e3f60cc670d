//! Error of a solution at probe points, against a reference or an exact answer.
//!
//! Two readings of a solution are measured: **flat** (the value of the patch holding the probe,
//! as the answer gives it: `Session::patch_values`, for a hierarchy the mean of what viewers
//! are shown over the patch) and **smooth** (what viewers show: the corner values they are sent, interpolated over the
//! patch's fan triangles, as `wire::display` does).
//! Only probes on non-emitting faces count: an emitter's own emission is exact and would
//! swamp the comparison. Probes inside solids (a beam's end through a wall, a floor under a
//! column: real models are full of faces that pass through one another) count, and are also
//! counted apart: no viewer outside the solid sees them, so the error at the others is the
//! error of what can be seen.

use crate::mesh::Mesh;
use crate::reference::Probe;
use crate::sampling::pair_seed;
use crate::scene::{Rgb, Scene};
use crate::solution::locator::{PatchLocator, Place, fan_corners};
use crate::visibility::Occluders;
use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

/// Errors of one reading, all relative.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ErrorStats {
    /// `sqrt(sum |B - B_ref|^2) / sqrt(sum |B_ref|^2)` over probes and channels.
    pub rms: f64,
    /// The largest probe error `|B - B_ref|`, relative to the reference's RMS probe value.
    pub max: f64,
    /// `sum B / sum B_ref - 1`: probes are spread by area, so this is the energy balance.
    pub energy: f64,
}

/// A solution's error at the probes.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SolutionError {
    /// Probes that counted (on non-emitting faces).
    pub probes: usize,
    /// Patch values.
    pub flat: ErrorStats,
    /// Interpolated values, as viewers show them.
    pub smooth: ErrorStats,
    /// Probes that counted and lie inside a solid ([`Occluders::is_buried`]: the backs of
    /// faces in almost every direction from them). Their reference is (near) zero, and no
    /// viewer outside the solid sees what is shown there.
    pub buried_probes: usize,
    /// The smooth reading at the other probes alone: the error of what viewers can see.
    pub visible_smooth: ErrorStats,
    /// The reference's own relative RMS standard error: the floor under `rms`.
    pub reference_noise: f64,
    /// The same readings object by object (those with counted probes, in scene order): where
    /// the error is.
    pub objects: Vec<ObjectError>,
    /// The probes whose smooth reading is furthest off, worst first, at most [`WORST_PROBES`]
    /// (none that is exact): on real models a few places (a face half inside another, a
    /// lit strip between covered corners) can hold most of the error, and this says where.
    pub worst: Vec<ProbeError>,
}

/// How many probes a [`SolutionError`] lists as the worst.
pub const WORST_PROBES: usize = 10;

/// One probe where the smooth reading is off.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ProbeError {
    /// Where it lies, scene units.
    pub position: [f64; 3],
    /// The scene file's face it lies on ([`Probe::face`]).
    pub face: u32,
    /// Its object's name.
    pub object: String,
    /// The reference's radiosity there, W/m^2.
    pub reference: [f64; 3],
    /// What viewers are shown there (the smooth reading), W/m^2.
    pub smooth: [f64; 3],
    /// The value of the patch holding it (the flat reading), W/m^2.
    pub flat: [f64; 3],
    /// Its part of the whole scene's squared smooth error.
    pub smooth_share: f64,
}

/// One object's share of a solution's error.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ObjectError {
    /// The object's name in the scene file.
    pub name: String,
    /// Probes on its faces that counted.
    pub probes: usize,
    /// Its own patch-value errors, relative to its own reference values.
    pub flat: ErrorStats,
    /// Its own interpolated-value errors, relative to its own reference values.
    pub smooth: ErrorStats,
    /// Its part of the whole scene's squared smooth error (the parts sum to one), so the
    /// object to work on is the one with the largest.
    pub smooth_share: f64,
}

/// Where a probe falls: its patch and the smooth value there.
struct Located {
    patch: usize,
    smooth: Rgb,
}

/// Where `probe` falls: of the patches of its face's pieces, the fan triangle that holds it
/// best (the largest smallest barycentric weight; inside when it is at least zero).
fn locate(
    (mesh, locator): (&Mesh, &PatchLocator),
    pieces: &[Vec<u32>],
    corners: &[Rgb],
    probe: &Probe,
) -> Located {
    let p = DVec3::from(probe.position);
    let inside = |place: &Place| place.weights.iter().copied().fold(f64::INFINITY, f64::min);
    let best = (pieces.get(probe.face as usize).into_iter().flatten())
        .filter_map(|&piece| locator.place(piece, p))
        .max_by(|a, b| inside(a).total_cmp(&inside(b)));
    let Some(place) = best else {
        return Located {
            patch: 0,
            smooth: Rgb::ZERO,
        };
    };
    let triangle = fan_corners(&mesh.patches[place.patch], place.fan);
    Located {
        patch: place.patch,
        smooth: (0..3)
            .map(|i| corners[triangle[i] as usize] * place.weights[i])
            .sum(),
    }
}

/// How far a probe may lie from the face it names, relative to the scene's diagonal: its
/// position makes JSON's exact round trip and the pieces loading cuts its face into cover it,
/// but a sliver's plane, taken from its corners, tilts by round-off (a shelf of the furnished
/// room: 2.4e-7 off on a 10 m scene at 1e-9 would have refused its own reference). Faces that
/// another numbering puts in a probe's place lie centimetres to metres off.
const PROBE_OFF_FACE: f64 = 1e-6;

/// `Err` naming the first of `probes` that does not lie on the face and object it names in
/// `scene`: they were traced for another scene (a face added before it shifts every later
/// face's number), and read here they would measure other faces' light.
pub fn check_probes_match(scene: &Scene, probes: &[Probe]) -> Result<(), String> {
    let pieces = pieces_by_source(scene);
    let diagonal = scene.bounds().map_or(0.0, |(lo, hi)| (hi - lo).length());
    let off = |probe: &Probe| {
        let p = DVec3::from(probe.position);
        let face_pieces = pieces.get(probe.face as usize).into_iter().flatten();
        let distance = face_pieces
            .map(|&f| scene.faces[f as usize].polygon.closest_point(p).distance(p))
            .fold(f64::INFINITY, f64::min);
        let object = (pieces.get(probe.face as usize))
            .and_then(|p| p.first())
            .map(|&f| &scene.objects[scene.faces[f as usize].object as usize].name);
        let on_face = distance <= PROBE_OFF_FACE * diagonal;
        (!on_face || object != Some(&probe.object)).then_some((distance, object))
    };
    match probes
        .iter()
        .enumerate()
        .find_map(|(i, p)| off(p).map(|o| (i, p, o)))
    {
        None => Ok(()),
        Some((index, probe, (distance, object))) => {
            let here = match object {
                None => "does not exist".to_string(),
                Some(name) if *name != probe.object => {
                    format!("is of object '{name}', {distance:.3e} from the probe")
                }
                Some(_) => format!("lies {distance:.3e} from the probe"),
            };
            Err(format!(
                "probe {index} at {:?} lies on face {} of object '{}' where the reference was \
                 traced, but here that face {here}: the reference was traced for another \
                 scene (trace one for this scene with `radcast reference`)",
                probe.position, probe.face, probe.object,
            ))
        }
    }
}

/// The scene faces each face of the scene file was cut into ([`crate::scene::Face::source`]).
fn pieces_by_source(scene: &Scene) -> Vec<Vec<u32>> {
    let mut pieces = vec![Vec::new(); scene.source_face_count()];
    for (index, face) in scene.faces.iter().enumerate() {
        pieces[face.source as usize].push(index as u32);
    }
    pieces
}

/// The errors of (solution, reference) `pairs`.
pub(crate) fn stats(pairs: &[(Rgb, Rgb)]) -> ErrorStats {
    let reference_sq: f64 = pairs.iter().map(|(_, r)| r.length_squared()).sum();
    let error_sq = squared_error(pairs);
    let reference_rms = (reference_sq / pairs.len().max(1) as f64).sqrt();
    let largest = pairs
        .iter()
        .map(|(e, r)| (*e - *r).length())
        .fold(0.0, f64::max);
    let (estimated_sum, reference_sum) = pairs.iter().fold((0.0, 0.0), |(a, b), (e, r)| {
        (a + e.element_sum(), b + r.element_sum())
    });
    let ratio = |x: f64, y: f64| if y > 0.0 { x / y } else { 0.0 };
    ErrorStats {
        rms: ratio(error_sq.sqrt(), reference_sq.sqrt()),
        max: ratio(largest, reference_rms),
        energy: if reference_sum > 0.0 {
            estimated_sum / reference_sum - 1.0
        } else {
            0.0
        },
    }
}

/// A solution read at the probes that count: per probe, (solution, reference) for each
/// reading, and the reference's variance there (its standard errors squared, summed over
/// channels).
pub(crate) struct Readings {
    pub(crate) flat: Vec<(Rgb, Rgb)>,
    pub(crate) smooth: Vec<(Rgb, Rgb)>,
    pub(crate) variance: Vec<f64>,
    /// The object each probe lies on.
    pub(crate) objects: Vec<u32>,
    /// Each probe's index among the probes read.
    pub(crate) indices: Vec<usize>,
}

/// Measures a solution on `mesh` (built from `scene`) at the probes: `radiosity` per patch for
/// the flat reading, `corners` per mesh corner (what viewers are sent) for the smooth one.
pub fn evaluate(
    scene: &Scene,
    mesh: &Mesh,
    radiosity: &[Rgb],
    corners: &[Rgb],
    probes: &[Probe],
) -> SolutionError {
    let readings = read_at(scene, mesh, radiosity, corners, probes);
    let buried = inside_solids(scene, probes, &readings.indices);
    let visible: Vec<(Rgb, Rgb)> = (readings.smooth.iter().zip(&buried))
        .filter_map(|(&pair, &buried)| (!buried).then_some(pair))
        .collect();
    SolutionError {
        probes: readings.flat.len(),
        flat: stats(&readings.flat),
        smooth: stats(&readings.smooth),
        buried_probes: readings.flat.len() - visible.len(),
        visible_smooth: stats(&visible),
        reference_noise: readings.noise(),
        objects: readings.by_object(scene),
        worst: readings.worst(scene, probes),
    }
}

/// Per probe read (`indices` into `probes`), whether it lies inside a solid of `scene`, by
/// the test where light reaches uses ([`Occluders::is_buried`]), seeded by the probe's index.
fn inside_solids(scene: &Scene, probes: &[Probe], indices: &[usize]) -> Vec<bool> {
    let (occluders, pieces) = (Occluders::new(scene), pieces_by_source(scene));
    (indices.par_iter())
        .map(|&i| {
            let probe = &probes[i];
            // The pieces of a source face share its plane: any of them gives the normal.
            let Some(&face) = pieces.get(probe.face as usize).and_then(|p| p.first()) else {
                return false;
            };
            let normal = scene.faces[face as usize].polygon.normal();
            let x = DVec3::from(probe.position);
            occluders.is_buried(x, normal, face, pair_seed(i, 0))
        })
        .collect()
}

/// Squared error of (solution, reference) `pairs`.
fn squared_error(pairs: &[(Rgb, Rgb)]) -> f64 {
    pairs.iter().map(|(e, r)| (*e - *r).length_squared()).sum()
}

impl Readings {
    /// The reference's own relative RMS standard error at these probes.
    pub(crate) fn noise(&self) -> f64 {
        let noise_sq: f64 = self.variance.iter().sum();
        let reference_sq: f64 = self.flat.iter().map(|(_, r)| r.length_squared()).sum();
        if reference_sq > 0.0 {
            (noise_sq / reference_sq).sqrt()
        } else {
            0.0
        }
    }

    /// The [`WORST_PROBES`] of `probes` (those read) whose smooth reading is furthest off,
    /// worst first, leaving out those it reads exactly.
    fn worst(&self, scene: &Scene, probes: &[Probe]) -> Vec<ProbeError> {
        let total = squared_error(&self.smooth);
        let off = |i: usize| (self.smooth[i].0 - self.smooth[i].1).length_squared();
        let mut order: Vec<usize> = (0..self.smooth.len()).filter(|&i| off(i) > 0.0).collect();
        order.sort_by(|&a, &b| off(b).total_cmp(&off(a)));
        order.truncate(WORST_PROBES);
        order
            .into_iter()
            .map(|i| {
                let probe = &probes[self.indices[i]];
                ProbeError {
                    position: probe.position,
                    face: probe.face,
                    object: scene.objects[self.objects[i] as usize].name.clone(),
                    reference: probe.radiosity,
                    smooth: self.smooth[i].0.to_array(),
                    flat: self.flat[i].0.to_array(),
                    smooth_share: off(i) / total,
                }
            })
            .collect()
    }

    /// The readings split by the object each probe lies on, in one pass over the probes.
    fn by_object(&self, scene: &Scene) -> Vec<ObjectError> {
        let total = squared_error(&self.smooth);
        let ratio = |x: f64, y: f64| if y > 0.0 { x / y } else { 0.0 };
        let mut on = vec![(Vec::new(), Vec::new()); scene.objects.len()];
        for ((flat, smooth), &object) in self.flat.iter().zip(&self.smooth).zip(&self.objects) {
            let (flats, smooths) = &mut on[object as usize];
            flats.push(*flat);
            smooths.push(*smooth);
        }
        on.iter()
            .zip(&scene.objects)
            .filter(|((flat, _), _)| !flat.is_empty())
            .map(|((flat, smooth), object)| ObjectError {
                name: object.name.clone(),
                probes: flat.len(),
                flat: stats(flat),
                smooth: stats(smooth),
                smooth_share: ratio(squared_error(smooth), total),
            })
            .collect()
    }
}

/// Both readings of a solution at the probes on non-emitting faces ([`Readings`]).
pub(crate) fn read_at(
    scene: &Scene,
    mesh: &Mesh,
    radiosity: &[Rgb],
    corners: &[Rgb],
    probes: &[Probe],
) -> Readings {
    let (locator, pieces) = (
        PatchLocator::new(mesh, scene.faces.len()),
        pieces_by_source(scene),
    );
    // The pieces of a source face share its material: any of them tells whether it emits.
    let sources = pieces.len();
    let (mut source_emits, mut source_object) = (vec![None; sources], vec![0; sources]);
    for face in &scene.faces {
        source_emits[face.source as usize] = Some(face.emission != Rgb::ZERO);
        source_object[face.source as usize] = face.object;
    }
    let indices: Vec<usize> = (0..probes.len())
        .filter(|&i| source_emits.get(probes[i].face as usize) == Some(&Some(false)))
        .collect();
    let counted: Vec<&Probe> = indices.iter().map(|&i| &probes[i]).collect();
    let (mut flat, mut smooth) = (Vec::new(), Vec::new());
    for probe in &counted {
        let reference = Rgb::from(probe.radiosity);
        let located = locate((mesh, &locator), &pieces, corners, probe);
        flat.push((radiosity[located.patch], reference));
        smooth.push((located.smooth, reference));
    }
    Readings {
        flat,
        smooth,
        variance: counted
            .iter()
            .map(|p| Rgb::from(p.standard_error).length_squared())
            .collect(),
        objects: counted
            .iter()
            .map(|p| source_object[p.face as usize])
            .collect(),
        indices,
    }
}
