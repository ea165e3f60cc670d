//! Loading, meshing and solving for the server, with a disk cache of finished solutions.

use crate::Shared;
use crate::hub::Hub;
use anyhow::Context;
use bincode::{Decode, Encode};
use glam::DVec3;
use sha2::{Digest, Sha256};
use solver::{Mesh, MoveWork, Progress, Rgb, Scene, Session, SolveRequest};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use wire::summary::{HierarchyCounts, ObjectRadiosity, SolveReport, StageSeconds};
use wire::{Camera, Geometry, geometry::NO_CORNER};

/// A scene loaded and meshed, ready to solve.
pub struct Prepared {
    /// The scene.
    pub scene: Scene,
    /// Its patches (what the server streams).
    pub mesh: Mesh,
    /// How to solve it.
    pub request: SolveRequest,
    /// Hash of the scene files and settings.
    pub scene_id: u64,
    /// The geometry viewers fetch.
    pub geometry: Geometry,
    /// A hierarchy built to find the patches (its leaves), kept for the solve.
    built: Mutex<Option<Session>>,
}

/// Progressive frames are published at most this often while the solver iterates.
const SNAPSHOT_INTERVAL: Duration = Duration::from_millis(100);

/// Loads and meshes `scene_path`; fails with the loader's message on bad input. The
/// hierarchical path refines here, since its leaves are the patches viewers fetch.
pub fn prepare(scene_path: &Path, request: SolveRequest) -> anyhow::Result<Prepared> {
    let scene = Scene::load_obj(scene_path)?;
    let scene_id = scene_id(scene_path, &request)?;
    let (mesh, built) = match &request.hierarchy {
        Some(_) => {
            let session = Session::hierarchical(&scene, &request, &solver::no_progress)?;
            (session.mesh().clone(), Some(session))
        }
        None => (Mesh::build(&scene, request.patches), None),
    };
    let geometry = geometry_of(&scene, &mesh);
    Ok(Prepared {
        scene,
        mesh,
        request,
        scene_id,
        geometry,
        built: Mutex::new(built),
    })
}

/// The session to solve with: the hierarchy `prepare` built, or form factors computed now.
fn session_for(
    prepared: &Prepared,
    progress: &(dyn Fn(Progress) + Sync),
) -> anyhow::Result<Session> {
    if let Some(session) = prepared.built.lock().expect("session lock").take() {
        return Ok(session);
    }
    Ok(match &prepared.request.hierarchy {
        Some(_) => Session::hierarchical(&prepared.scene, &prepared.request, progress)?,
        None => Session::new(&prepared.scene, &prepared.mesh, &prepared.request, progress)?,
    })
}

/// First 8 bytes of SHA-256 over the OBJ, its MTL libraries, the settings and this version.
fn scene_id(scene_path: &Path, request: &SolveRequest) -> anyhow::Result<u64> {
    let mut hasher = Sha256::new();
    let text = std::fs::read(scene_path)
        .with_context(|| format!("{}: cannot read", scene_path.display()))?;
    hasher.update(&text);
    let folder = scene_path.parent().unwrap_or(Path::new("."));
    for line in String::from_utf8_lossy(&text).lines() {
        if let Some(name) = line.trim().strip_prefix("mtllib ") {
            hasher.update(std::fs::read(folder.join(name.trim())).unwrap_or_default());
        }
    }
    hasher.update(format!("{request:?} {}", env!("CARGO_PKG_VERSION")));
    let digest = hasher.finalize();
    Ok(u64::from_le_bytes(
        digest[..8].try_into().expect("SHA-256 has 32 bytes"),
    ))
}

fn geometry_of(scene: &Scene, mesh: &Mesh) -> Geometry {
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
    }
}

fn to_f32(radiosity: &[Rgb]) -> Vec<[f32; 3]> {
    radiosity.iter().map(|b| b.as_vec3().to_array()).collect()
}

/// The state viewers see before the solve: every vertex at its face's emission.
pub fn emission_only(prepared: &Prepared) -> Vec<[f32; 3]> {
    let mesh = &prepared.mesh;
    to_f32(&mesh.corner_means(&mesh.patches.iter().map(|p| p.emission).collect::<Vec<_>>()))
}

/// Creates the hub for `prepared`, publishing its emission-only state.
pub fn hub_for(prepared: &Prepared) -> Hub {
    Hub::new(
        prepared.scene_id,
        &prepared.geometry,
        &emission_only(prepared),
    )
}

#[derive(Encode, Decode)]
struct CachedSolution {
    /// Per patch: what a session adopts when the first edit arrives.
    radiosity: Vec<[f32; 3]>,
    /// Per vertex: what viewers are sent.
    vertex_radiosity: Vec<[f32; 3]>,
    report_json: String,
}

const CACHE_MAGIC: &[u8; 8] = b"RCCACHE2";

fn cache_path(dir: &Path, scene_id: u64) -> PathBuf {
    dir.join(format!("{scene_id:016x}.radcast"))
}

/// The cached solution and its report, if the file holds one for `mesh`'s patches and vertices.
fn read_cache(path: &Path, mesh: &Mesh) -> Option<(CachedSolution, SolveReport)> {
    let bytes = std::fs::read(path).ok()?;
    let body = bytes.strip_prefix(CACHE_MAGIC.as_slice())?;
    let (cached, _): (CachedSolution, usize) =
        bincode::decode_from_slice(body, bincode::config::standard()).ok()?;
    let report = serde_json::from_str(&cached.report_json).ok()?;
    (cached.radiosity.len() == mesh.patches.len()
        && cached.vertex_radiosity.len() == mesh.positions.len()
        && cached
            .radiosity
            .iter()
            .chain(&cached.vertex_radiosity)
            .flatten()
            .all(|c| c.is_finite() && *c >= 0.0))
    .then_some((cached, report))
}

/// Writes atomically: a temporary file in the same folder, renamed over the target.
fn write_cache(dir: &Path, path: &Path, cached: &CachedSolution) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut file = tempfile::NamedTempFile::new_in(dir)?;
    file.write_all(CACHE_MAGIC)?;
    bincode::encode_into_std_write(cached, &mut file, bincode::config::standard())?;
    file.as_file().sync_all()?;
    file.persist(path)
        .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(())
}

/// What the first solve leaves for later edits: the live session, or (after a cache hit) the
/// cached radiosity to warm-start one from when the first edit arrives.
pub enum Solution {
    /// Form factors in memory.
    Live(Box<Session>),
    /// Read from the cache; form factors not computed yet.
    Cached(Vec<[f32; 3]>),
}

/// Solves (or reads the cache), publishing progressive frames and then the final one.
/// Blocking: run it on a blocking thread.
pub fn solve_and_publish(
    prepared: &Prepared,
    shared: &Shared,
    cache_dir: Option<&Path>,
) -> anyhow::Result<Solution> {
    let hub = &shared.hub;
    // A hierarchy is built before viewers connect (its leaves are the patches): a cached
    // solution would save only its last solve.
    let cache = cache_dir
        .filter(|_| prepared.request.hierarchy.is_none())
        .map(|dir| (dir, cache_path(dir, prepared.scene_id)));
    if let Some((cached, report)) = cache
        .as_ref()
        .and_then(|(_, path)| read_cache(path, &prepared.mesh))
    {
        tracing::info!("solution read from the cache");
        *shared.report.lock().expect("report lock") = Some(report);
        hub.publish(&cached.vertex_radiosity, true);
        return Ok(Solution::Cached(cached.radiosity));
    }
    let last_snapshot = Mutex::new(Instant::now());
    let progress = |p: Progress| {
        if let Progress::Estimate { radiosity } = p
            && let Ok(mut last) = last_snapshot.try_lock()
            && last.elapsed() >= SNAPSHOT_INTERVAL
        {
            *last = Instant::now();
            // Not final: the patches' means at the corners will do until the direct gather.
            hub.publish(&to_f32(&prepared.mesh.corner_means(radiosity)), false);
        }
    };
    let mut session = session_for(prepared, &progress)?;
    let report = session.solve(&progress);
    let radiosity = to_f32(session.radiosity());
    let vertex_radiosity = to_f32(&session.vertex_radiosity());
    let s = report.seconds;
    *shared.metrics.solve_seconds.lock().expect("metrics lock") = vec![
        ("mesh", s.mesh),
        ("form_factors", s.form_factors),
        ("solve", s.solve),
        ("total", s.total),
    ];
    tracing::info!(
        patches = report.patches,
        iterations = report.iterations,
        residual = report.residual,
        seconds = s.total,
        "solved"
    );
    if let (Some(asked), Some(stats)) = (&prepared.request.hierarchy, &report.hierarchy) {
        solver::args::budget_warnings(asked, stats)
            .iter()
            .for_each(|warning| tracing::warn!("{warning}"));
    }
    let report = report_for_viewers(&report);
    let report_json = serde_json::to_string(&report)?;
    // The report goes in before the final frame: a viewer that sees "final" may ask for it at once.
    *shared.report.lock().expect("report lock") = Some(report);
    hub.publish(&vertex_radiosity, true);
    if let Some((dir, path)) = cache {
        write_cache(
            dir,
            &path,
            &CachedSolution {
                radiosity,
                vertex_radiosity,
                report_json,
            },
        )?;
    }
    Ok(Solution::Live(Box::new(session)))
}

/// Applies edits as they come until shutdown: each batch re-solves from the current answer
/// (form factors unchanged) and publishes one new version. Blocking.
pub fn serve_edits(prepared: &Prepared, shared: &Shared, solution: Solution) -> anyhow::Result<()> {
    let mut session = match solution {
        Solution::Live(session) => *session,
        Solution::Cached(radiosity) => {
            // Form factors are computed on the first edit only: a cached scene nobody edits
            // never pays for them.
            let Some(batch) = shared.edits.wait() else {
                return Ok(());
            };
            let mut session = session_for(prepared, &solver::no_progress)?;
            session.adopt_solution(
                radiosity
                    .iter()
                    .map(|c| Rgb::new(c[0] as f64, c[1] as f64, c[2] as f64))
                    .collect(),
            );
            apply(&mut session, shared, batch);
            session
        }
    };
    // The lights' responses, so that the first edit of a light is as fast as the rest.
    let iterations = session.prepare_emitters();
    tracing::info!(iterations, "emitter responses ready");
    while let Some(batch) = shared.edits.wait() {
        apply(&mut session, shared, batch);
    }
    Ok(())
}

fn apply(session: &mut Session, shared: &Shared, batch: crate::edits::Batch) {
    let started = Instant::now();
    let mut moved = false;
    for (object, offset) in &batch.moves {
        match session.translate(object, DVec3::from(*offset)) {
            Ok(report) => {
                moved = true;
                let ms = report.seconds * 1e3;
                match report.work {
                    MoveWork::Dense(work) => {
                        tracing::info!(object, work.pairs, work.entries, ms, "moved")
                    }
                    MoveWork::Rebuilt(hierarchy) => {
                        tracing::info!(object, hierarchy.elements, hierarchy.links, ms, "moved")
                    }
                }
            }
            Err(error) => tracing::warn!("move refused: {error}"),
        }
    }
    let mut report = None;
    if moved {
        // The moved scene from the current answer, then its new geometry for viewers.
        report = Some(session.solve(&solver::no_progress));
        shared
            .hub
            .replace_geometry(geometry_of(session.scene(), session.mesh()));
    }
    if !batch.emissions.is_empty() {
        for (object, emission) in &batch.emissions {
            if let Err(error) = session.set_emission(object, Rgb::from(*emission)) {
                tracing::warn!("edit refused: {error}");
            }
        }
        report = Some(session.solve(&solver::no_progress));
    }
    let report = report.unwrap_or_else(|| session.solve(&solver::no_progress));
    *shared.report.lock().expect("report lock") = Some(report_for_viewers(&report));
    let version = shared
        .hub
        .publish(&to_f32(&session.vertex_radiosity()), report.converged);
    tracing::info!(
        version,
        emissions = batch.emissions.len(),
        moves = batch.moves.len(),
        iterations = report.iterations,
        ms = started.elapsed().as_secs_f64() * 1e3,
        "re-solved"
    );
    if moved {
        // Keep the lights' next edits instant on the moved scene.
        session.prepare_emitters();
    }
}

/// The solver's report as `/api/solution` gives it.
fn report_for_viewers(report: &solver::SolveReport) -> SolveReport {
    let s = report.seconds;
    SolveReport {
        patches: report.patches,
        triangles: report.triangles,
        skipped_faces: report.skipped_faces,
        method: report.method.clone(),
        iterations: report.iterations,
        residual: report.residual,
        converged: report.converged,
        tolerance: report.tolerance,
        rays: report.rays,
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
        }),
    }
}

/// Everything a server needs for one scene: the shared state, ready for [`crate::routes::router`].
pub fn shared_for(prepared: &Prepared, limits: crate::Limits, token: String) -> Arc<Shared> {
    Arc::new(Shared {
        hub: Arc::new(hub_for(prepared)),
        metrics: Default::default(),
        limits,
        shutdown: Default::default(),
        report: Mutex::new(None),
        edits: Default::default(),
        token,
        viewers_per_ip: Default::default(),
    })
}

/// The emitting objects and their emission as loaded, for animations.
pub fn emitters(prepared: &Prepared) -> Vec<(String, [f64; 3])> {
    let mut found: Vec<(String, [f64; 3])> = Vec::new();
    for patch in prepared
        .mesh
        .patches
        .iter()
        .filter(|p| p.emission.max_element() > 0.0)
    {
        let name = &prepared.scene.objects[patch.object as usize].name;
        if !found.iter().any(|(n, _)| n == name) {
            found.push((name.clone(), patch.emission.to_array()));
        }
    }
    found
}
