//! A scene made ready to serve: loaded, meshed, its geometry encoded for viewers, and the
//! shared state that routes and the solver thread work on.

use crate::Shared;
use crate::hub::Hub;
use glam::DVec3;
use solver::{Mesh, PatchTarget, Progress, Scene, Session, SolveRequest};
use std::path::Path;
use std::sync::Arc;
use wire::geometry::{NO_CORNER, NO_TEXTURE, SurfaceTextures};
use wire::{Camera, Geometry};

/// A scene loaded and meshed, ready to solve.
pub struct Prepared {
    /// The scene.
    pub scene: Scene,
    /// Its patches (what the server streams).
    pub mesh: Mesh,
    /// How to solve it.
    pub request: SolveRequest,
    /// [`crate::cache::scene_digest`] of the scene and settings.
    pub digest: [u8; 32],
    /// The digest's first 8 bytes: the scene id viewers see.
    pub scene_id: u64,
    /// The geometry viewers fetch first.
    pub geometry: Geometry,
}

/// Loads and meshes `scene_path`; fails with the loader's message on bad input. Quick: a
/// hierarchy is refined later, on the solver thread, so the port opens at once; until then
/// viewers see one patch per input face, then a geometry change to the leaves.
pub fn prepare(scene_path: &Path, request: SolveRequest) -> anyhow::Result<Prepared> {
    let scene = solver::load_scene(scene_path)?;
    let digest = crate::cache::scene_digest(&scene, &request);
    let scene_id = crate::cache::scene_id(&digest);
    let mesh = match &request.hierarchy {
        Some(_) => Mesh::build(&scene, PatchTarget::EdgeLength(f64::INFINITY)),
        None => solver::dense_mesh(&scene, &request)?,
    };
    let geometry = geometry_of(&scene, &mesh);
    Ok(Prepared {
        scene,
        mesh,
        request,
        digest,
        scene_id,
        geometry,
    })
}

impl Prepared {
    /// A session to solve with: the hierarchy refined, or the dense form factors computed.
    pub fn session(&self, progress: &(dyn Fn(Progress) + Sync)) -> anyhow::Result<Session> {
        Ok(match &self.request.hierarchy {
            Some(_) => Session::hierarchical(&self.scene, &self.request, progress)?,
            None => Session::new(&self.scene, &self.mesh, &self.request, progress)?,
        })
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
    crate::solving::to_f32(
        &mesh.corner_means(&mesh.patches.iter().map(|p| p.emission).collect::<Vec<_>>()),
    )
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

/// Everything a server needs for one scene: the shared state, ready for [`crate::routes::router`].
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
