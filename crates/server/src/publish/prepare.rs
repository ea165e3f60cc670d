//! A scene made ready to serve: loaded, meshed, its geometry encoded for viewers, and the
//! shared state that routes and the solver thread work on.

use super::to_wire::{emission_only, geometry_of};
use crate::Shared;
use crate::publish::hub::Hub;
use solver::{Mesh, Progress, Scene, Session, SolveRequest};
use std::path::Path;
use std::sync::Arc;
use wire::Geometry;

/// A scene loaded and meshed, ready to solve.
pub struct Prepared {
    /// The scene.
    pub scene: Scene,
    /// Its patches (what the server streams).
    pub mesh: Mesh,
    /// How to solve it.
    pub request: SolveRequest,
    /// [`crate::publish::cache::scene_digest`] of the scene and settings.
    pub digest: [u8; 32],
    /// The digest's first 8 bytes: the scene id viewers see.
    pub scene_id: u64,
    /// The geometry viewers fetch first.
    pub geometry: Geometry,
    /// Whether each solve is followed by its self-check ([`solver::check`]): on unless the
    /// operator turns it off.
    pub check: bool,
}

/// Loads and meshes `scene_path`; fails with the loader's message on bad input. Quick: a
/// hierarchy is refined later, on the solver thread, so the port opens at once; until then
/// viewers see one patch per input face, then a geometry change to the leaves.
pub fn prepare(scene_path: &Path, request: SolveRequest) -> anyhow::Result<Prepared> {
    let scene = solver::load_scene(scene_path)?;
    for warning in &scene.load_warnings {
        tracing::warn!("{warning}");
    }
    let (request, chosen) = request.for_scene(&scene);
    if let Some(text) = chosen {
        tracing::info!("{text}");
    }
    let digest = crate::publish::cache::scene_digest(&scene, &request);
    let scene_id = crate::publish::cache::scene_id(&digest);
    let mesh = solver::starting_mesh(&scene, &request)?;
    let geometry = geometry_of(&scene, &mesh);
    Ok(Prepared {
        scene,
        mesh,
        request,
        digest,
        scene_id,
        geometry,
        check: true,
    })
}

impl Prepared {
    /// A session to solve with: the hierarchy refined, or the dense form factors computed.
    pub fn session(&self, progress: &(dyn Fn(Progress) + Sync)) -> anyhow::Result<Session> {
        Ok(Session::start(
            &self.scene,
            &self.mesh,
            &self.request,
            progress,
        )?)
    }
}

/// Creates the hub for `prepared`, publishing its emission-only state.
pub fn hub_for(prepared: &Prepared) -> Hub {
    Hub::new(
        prepared.scene_id,
        &prepared.geometry,
        prepared
            .scene
            .textures
            .iter()
            .map(|t| bytes::Bytes::from(t.png.to_vec()))
            .collect(),
        &emission_only(&prepared.mesh),
    )
}

/// Everything a server needs for one scene: the shared state, ready for [`crate::http::routes::router`].
pub fn shared_for(prepared: &Prepared, limits: crate::Limits, token: String) -> Arc<Shared> {
    let shared = Shared::new(hub_for(prepared), limits, token);
    *shared.emissions.lock().expect("emissions lock") = object_emissions(prepared);
    shared
}

/// Every object's emission as loaded (its first face's; W/m^2), in scene order.
fn object_emissions(prepared: &Prepared) -> Vec<(String, [f64; 3])> {
    let scene = &prepared.scene;
    let mut emissions: Vec<(String, [f64; 3])> = scene
        .objects
        .iter()
        .map(|o| (o.name.clone(), [0.0; 3]))
        .collect();
    let mut seen = vec![false; scene.objects.len()];
    for face in &scene.faces {
        let object = face.object as usize;
        if !std::mem::replace(&mut seen[object], true) {
            emissions[object].1 = face.emission.to_array();
        }
    }
    emissions
}

#[cfg(test)]
mod tests {
    use super::*;
    use solver::{HierarchySettings, MethodChoice, PatchTarget};

    #[test]
    fn an_auto_request_is_chosen_for_the_scene_before_it_is_meshed_or_cached() {
        let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.obj");
        let auto = |patches| {
            SolveRequest {
                patches: PatchTarget::Count(patches),
                ..SolveRequest::default()
            }
            .with_method(MethodChoice::Auto, HierarchySettings::default())
        };
        let dense = prepare(&scene, auto(1000)).unwrap();
        assert_eq!((dense.request.hierarchy, dense.request.auto), (None, false));
        assert!(
            dense.mesh.patches.len() > 900,
            "{}",
            dense.mesh.patches.len()
        );
        // Too few patches for 4 a face: the hierarchy, starting from one patch a face.
        let hierarchical = prepare(&scene, auto(100)).unwrap();
        assert!(hierarchical.request.hierarchy.is_some() && !hierarchical.request.auto);
        assert_eq!(
            hierarchical.mesh.patches.len(),
            hierarchical.scene.faces.len()
        );
        assert_ne!(dense.digest, hierarchical.digest);
    }
}
