//! Solver values as the wire carries them: the only place solver and wire types meet.

use super::hub::Hub;
use glam::DVec3;
use solver::{Mesh, Rgb, Scene, Session, TermKey};
use std::collections::BTreeMap;
use wire::geometry::{NO_CORNER, NO_TEXTURE, SurfaceTextures};
use wire::responses::{Response, Term};
use wire::summary::{
    ErrorEstimate, HierarchyCounts, ObjectRadiosity, ReadingError, SolveReport, StageSeconds,
    TargetOutcome, TargetStepOutcome,
};
use wire::{Camera, Geometry};

/// Radiosity as the hub takes it.
pub fn to_f32(radiosity: &[Rgb]) -> Vec<[f32; 3]> {
    radiosity.iter().map(|b| b.as_vec3().to_array()).collect()
}

/// The most responses a sum may add up. Each costs a viewer one full frame's bytes once and
/// then 16 bytes an edit where a light's edit changes nearly every vertex (a frame's bytes
/// each time), so it pays after a few edits; past this, a viewer's work per edit (terms times
/// vertices) and its memory (12 bytes a vertex a term) outgrow a frame's decoding.
pub const MAX_SUM_TERMS: usize = 16;

/// The responses the hub holds for the session's [`Session::vertex_terms`], by the term they
/// serve: each response is quantised and given an id once, until the session says its
/// responses changed (a move, a new light).
#[derive(Default)]
pub struct ResponseIds {
    epoch: Option<u64>,
    ids: BTreeMap<TermKey, u32>,
    next_id: u32,
}

impl ResponseIds {
    /// The session's current values as terms of responses the hub holds (adding those it
    /// lacks), or `None` when they are not a sum of responses yet or have too many terms.
    pub fn terms(&mut self, session: &Session, hub: &Hub) -> Option<Vec<Term>> {
        let (epoch, terms) = session.vertex_terms()?;
        if terms.len() > MAX_SUM_TERMS {
            return None;
        }
        if self.epoch != Some(epoch) {
            hub.clear_responses();
            self.ids.clear();
            self.epoch = Some(epoch);
        }
        Some(
            terms
                .iter()
                .map(|term| {
                    let id = *self.ids.entry(term.key).or_insert_with(|| {
                        let id = self.next_id;
                        hub.add_response(Response::quantise(id, &to_f32(term.values)));
                        self.next_id += 1;
                        id
                    });
                    Term {
                        response_id: id,
                        weight: term.weight.as_vec3().to_array(),
                    }
                })
                .collect(),
        )
    }
}

/// The geometry viewers fetch for `mesh`.
pub fn geometry_of(scene: &Scene, mesh: &Mesh) -> Geometry {
    let to_f32 = |v: DVec3| v.as_vec3().to_array();
    Geometry {
        positions: mesh.positions.iter().map(|p| to_f32(*p)).collect(),
        patches: mesh
            .patches
            .iter()
            .map(|p| {
                if p.corner_count() == 4 {
                    p.corners
                } else {
                    [p.corners[0], p.corners[1], p.corners[2], NO_CORNER]
                }
            })
            .collect(),
        patch_objects: mesh.patches.iter().map(|p| p.object).collect(),
        objects: scene.objects.iter().map(|o| o.name.clone()).collect(),
        camera: scene.view.map(|v| Camera {
            eye: to_f32(v.eye),
            target: to_f32(v.target),
            up: to_f32(v.up),
            vertical_fov_degrees: v.vertical_fov_degrees as f32,
        }),
        textures: surface_textures(scene, mesh),
    }
}

/// Each patch's texture and each corner's coordinates in it, for a scene with textures.
fn surface_textures(scene: &Scene, mesh: &Mesh) -> Option<SurfaceTextures> {
    if scene.textures.is_empty() {
        return None;
    }
    let mut uvs = vec![[0.0f32; 2]; mesh.positions.len()];
    let patch_textures = mesh
        .patches
        .iter()
        .map(|patch| match &scene.faces[patch.face as usize].texture {
            Some(map) => {
                for &c in &patch.corners[..patch.corner_count()] {
                    let uv = map.uv_at(mesh.positions[c as usize]).map(|x| x as f32);
                    // Bounded at load (±1e6), so finite; viewers would refuse the whole
                    // geometry for one that is not.
                    uvs[c as usize] = uv.map(|x| if x.is_finite() { x } else { 0.0 });
                }
                map.texture
            }
            None => NO_TEXTURE,
        })
        .collect();
    Some(SurfaceTextures {
        means: scene
            .textures
            .iter()
            .map(|t| t.mean.as_vec3().to_array())
            .collect(),
        patch_textures,
        uvs,
    })
}

/// The state viewers see before the solve: every vertex at its face's emission.
pub fn emission_only(mesh: &Mesh) -> Vec<[f32; 3]> {
    to_f32(&mesh.corner_means(&mesh.patches.iter().map(|p| p.emission).collect::<Vec<_>>()))
}

/// The solver's report as `/api/solution` gives it.
pub fn report_for_viewers(report: &solver::SolveReport) -> SolveReport {
    let s = report.seconds;
    SolveReport {
        patches: report.patches,
        triangles: report.triangles,
        skipped_faces: report.skipped_faces,
        warnings: report.warnings.clone(),
        method: report.method.clone(),
        iterations: report.iterations,
        residual: report.residual,
        converged: report.converged,
        tolerance: report.tolerance,
        rays: report.rays,
        ray_backend: report.ray_backend.into(),
        seed: report.seed,
        seconds: StageSeconds {
            load: s.load,
            mesh: s.mesh,
            form_factors: s.form_factors,
            solve: s.solve,
            total: s.total,
        },
        objects: report
            .objects
            .iter()
            .map(|o| ObjectRadiosity {
                name: o.name.clone(),
                area: o.area,
                radiosity: o.radiosity,
            })
            .collect(),
        hierarchy: report.hierarchy.map(|h| HierarchyCounts {
            elements: h.elements,
            links: h.links,
            clusters: h.clusters,
            rounds: h.rounds,
            shaft_decided: h.shaft_decided,
            refinement_iterations: h.refinement_iterations,
            knob_used: h.knob_used,
            leaf_budget_reached: h.leaf_budget_reached,
            link_budget_reached: h.link_budget_reached,
            deferred_pairs: h.deferred_pairs,
        }),
        estimate: report.estimate.as_ref().map(estimate_for_viewers),
        target: report.target.as_ref().map(|t| TargetOutcome {
            error: t.error,
            reached: t.reached,
            stopped: t.stopped.to_string(),
            steps: t
                .steps
                .iter()
                .map(|s| TargetStepOutcome {
                    knob: s.knob,
                    patches: s.patches,
                    seconds: s.seconds,
                    rms: s.rms,
                    high: s.high,
                })
                .collect(),
        }),
    }
}

/// The self-check as `/api/solution` gives it.
pub fn estimate_for_viewers(e: &solver::check::Estimate) -> ErrorEstimate {
    let reading = |r: &solver::check::ReadingEstimate| ReadingError {
        rms: r.rms,
        low: r.low,
        high: r.high,
        energy: r.energy,
    };
    ErrorEstimate {
        smooth: reading(&e.smooth),
        flat: reading(&e.flat),
        noise: e.noise,
        probes: e.probes,
        seconds: e.seconds,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use solver::{HierarchySettings, MethodChoice, SolveRequest, solve_file};
    use std::path::Path;

    /// What `radcast solve --json` prints and what `/api/solution` carries as `report`: one
    /// schema, key for key and value for value, for both methods, the self-check included.
    #[test]
    fn the_report_viewers_get_is_the_solver_report_key_for_key() {
        let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.obj");
        let coarse = HierarchySettings {
            error: 0.5,
            ..HierarchySettings::default()
        };
        for method in [
            MethodChoice::Dense(solver::Method::Gmres),
            MethodChoice::Hierarchical,
        ] {
            let request = SolveRequest {
                patches: solver::PatchTarget::Count(100),
                ..SolveRequest::default()
            }
            .with_method(method, coarse);
            let solved = solve_file(&scene, &request, &solver::no_progress)
                .expect("the shipped scene solves");
            let mut report = solved.report;
            report.estimate = Some(solver::check::self_check(
                &solved.scene,
                &solver::visibility::Occluders::new(&solved.scene),
                &solved.mesh,
                (&solved.radiosity, &solved.vertex_radiosity),
                &solver::check::CheckSettings::after_solve(0.0),
                &solver::no_progress,
            ));
            let printed = serde_json::to_value(&report).expect("the report serialises");
            let served = serde_json::to_value(report_for_viewers(&report)).expect("serialises");
            assert_eq!(printed, served, "{method}");
            assert!(
                printed["estimate"]["smooth"]["rms"].is_number(),
                "{printed}"
            );
            assert_eq!(
                printed.get("elements").is_some(),
                method == MethodChoice::Hierarchical,
                "hierarchy counts only for the hierarchy: {printed}"
            );
        }
    }
}
