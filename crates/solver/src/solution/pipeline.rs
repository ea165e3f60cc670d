//! The whole offline path, scene file to solution, with a timing per stage: what the `radcast`
//! command and the server both run. The live, editable form of a solution is [`Session`].

use super::report::SolveReport;
use super::request::{SolveError, SolveRequest, starting_mesh};
use super::session::Session;
use crate::Progress;
use crate::mesh::Mesh;
use crate::scene::{Rgb, Scene};
use std::path::Path;
use std::time::Instant;

/// A solved scene: the inputs, the patches and their radiosity.
pub struct Solved {
    /// The scene as loaded.
    pub scene: Scene,
    /// Its patches.
    pub mesh: Mesh,
    /// Radiosity per patch, W/m^2.
    pub radiosity: Vec<Rgb>,
    /// Radiosity per mesh corner, W/m^2: what viewers are sent ([`Session::vertex_radiosity`]).
    pub vertex_radiosity: Vec<Rgb>,
    /// The summary.
    pub report: SolveReport,
}

impl Solved {
    /// Solves `session` and keeps what it solved.
    fn from_session(
        scene: Scene,
        mut session: Session,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Solved {
        let report = session.solve(progress);
        Solved::kept(scene, session, report)
    }

    /// What `session` solved, as `report` says, kept.
    pub(crate) fn kept(scene: Scene, session: Session, report: SolveReport) -> Solved {
        let vertex_radiosity = session.vertex_radiosity();
        let (mesh, radiosity) = session.into_solution(&vertex_radiosity);
        Solved {
            scene,
            mesh,
            radiosity,
            vertex_radiosity,
            report,
        }
    }
}

/// Loads `path` and solves it.
pub fn solve_file(
    path: &Path,
    request: &SolveRequest,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Solved, SolveError> {
    let start = Instant::now();
    let name = format!(
        "loading {}: faces cut at contacts and sections",
        path.display()
    );
    progress(Progress::Stage { name: &name });
    let scene = crate::input::load_scene(path)?;
    let load = start.elapsed().as_secs_f64();
    let mut solved = solve_scene(scene, request, progress)?;
    solved.report.seconds.load = load;
    solved.report.seconds.total += load;
    Ok(solved)
}

/// Meshes, computes form factors (or builds the hierarchy) and solves an already loaded scene.
pub fn solve_scene(
    scene: Scene,
    request: &SolveRequest,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Solved, SolveError> {
    if !scene.has_emitter() {
        progress(Progress::Warning {
            text: "no material emits light (no positive Ke): every radiosity is 0",
        });
    }
    let (request, chosen) = &request.for_scene(&scene);
    if let Some(text) = chosen {
        progress(Progress::Notice { text });
    }
    if let Some(target) = &request.target {
        let (session, report) =
            super::target::session_to_target(&scene, request, target, progress, &mut |_| {})?;
        return Ok(Solved::kept(scene, session, report));
    }
    let session = match request.hierarchy {
        // A hierarchy decides its own leaves: a mesh of one patch a face would go unused.
        Some(_) => Session::hierarchical(&scene, request, progress)?,
        None => {
            let start = Instant::now();
            let mesh = starting_mesh(&scene, request)?;
            let mesh_seconds = start.elapsed().as_secs_f64();
            let mut session = Session::new(&scene, &mesh, request, progress)?;
            session.add_mesh_seconds(mesh_seconds);
            session
        }
    };
    Ok(Solved::from_session(scene, session, progress))
}

/// Form factors and solve for a mesh already built from `scene` (the server meshes first so
/// that viewers get the geometry while it solves). `seconds.mesh` holds the BVH build only.
pub fn solve_mesh(
    scene: &Scene,
    mesh: &Mesh,
    request: &SolveRequest,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Solved, SolveError> {
    let session = Session::new(scene, mesh, request, progress)?;
    Ok(Solved::from_session(scene.clone(), session, progress))
}
