//! The whole offline path, scene file to solution, with a timing per stage: what the `radcast`
//! command and the server both run. The live, editable form of a solution is [`crate::session`].

use crate::Progress;
use crate::hierarchy::{HierarchySettings, HierarchyStats};
use crate::mesh::{Mesh, PatchTarget};
use crate::pair::FormFactorSettings;
use crate::scene::{Rgb, Scene, SceneError};
use crate::session::Session;
use crate::solve::{NeedsEntries, SolverSettings};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Everything that decides a solution besides the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveRequest {
    /// Mesh resolution.
    pub patches: PatchTarget,
    /// Form-factor accuracy.
    pub form_factors: FormFactorSettings,
    /// Solver and stopping rule.
    pub solver: SolverSettings,
    /// Refuse meshes whose dense form-factor matrix would need more bytes than this.
    pub max_matrix_bytes: u64,
    /// `Some`: hierarchical radiosity with clustering instead of a dense matrix on a uniform
    /// mesh (`patches` is then unused: refinement decides the leaves).
    pub hierarchy: Option<HierarchySettings>,
}

impl Default for SolveRequest {
    fn default() -> Self {
        SolveRequest {
            patches: PatchTarget::Count(1000),
            form_factors: FormFactorSettings::default(),
            solver: SolverSettings::default(),
            max_matrix_bytes: 8 << 30,
            hierarchy: None,
        }
    }
}

/// How to solve: a solver on a dense matrix over a uniform mesh, or hierarchical radiosity
/// (elements and links, solved with GMRES).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodChoice {
    /// A uniform mesh and its dense form-factor matrix, solved with this method.
    Dense(crate::solve::Method),
    /// [`crate::hierarchy`].
    Hierarchical,
}

impl std::str::FromStr for MethodChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "hierarchical" {
            return Ok(MethodChoice::Hierarchical);
        }
        crate::solve::Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .map(MethodChoice::Dense)
            .ok_or_else(|| {
                let names: Vec<_> = crate::solve::Method::ALL.map(|m| m.name()).into();
                format!(
                    "unknown method '{s}' (expected hierarchical or one of: {})",
                    names.join(", ")
                )
            })
    }
}

impl std::fmt::Display for MethodChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MethodChoice::Dense(method) => method.fmt(f),
            MethodChoice::Hierarchical => f.write_str("hierarchical"),
        }
    }
}

impl SolveRequest {
    /// This request solved by `choice`; `hierarchy` applies if that is the hierarchical path.
    pub fn with_method(self, choice: MethodChoice, hierarchy: HierarchySettings) -> SolveRequest {
        let (method, hierarchy) = match choice {
            MethodChoice::Dense(method) => (method, None),
            MethodChoice::Hierarchical => (crate::solve::Method::Gmres, Some(hierarchy)),
        };
        SolveRequest {
            solver: SolverSettings {
                method,
                ..self.solver
            },
            hierarchy,
            ..self
        }
    }
}

/// The uniform mesh of `request`, refused before it is built when its dense matrix would not
/// fit `request.max_matrix_bytes` (a thin sliver at a fine edge length asks for millions).
pub fn dense_mesh(scene: &Scene, request: &SolveRequest) -> Result<Mesh, SolveError> {
    check_dense_size(
        Mesh::planned_count(scene, request.patches),
        scene.faces.len(),
        request,
    )?;
    Ok(Mesh::build(scene, request.patches))
}

/// `Err(TooLarge)` when a dense matrix over `patches` would exceed `request.max_matrix_bytes`.
pub fn check_dense_size(
    patches: usize,
    faces: usize,
    request: &SolveRequest,
) -> Result<(), SolveError> {
    let bytes = crate::DenseFormFactors::memory_bytes(patches);
    if bytes <= request.max_matrix_bytes {
        return Ok(());
    }
    let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
    Err(SolveError::TooLarge {
        patches,
        faces,
        gib: gib(bytes),
        limit_gib: gib(request.max_matrix_bytes),
    })
}

/// Why a solve could not run.
#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    /// The scene file is bad.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The solver method cannot run on the chosen transport.
    #[error(transparent)]
    Method(#[from] NeedsEntries),
    /// The mesh is too fine for a dense matrix in the allowed memory.
    #[error(
        "{patches} patches need {gib:.1} GiB for the dense form-factor matrix (limit {limit_gib:.1} GiB); ask for fewer patches (the scene's {faces} faces are the fewest a mesh can have) or use the hierarchical method"
    )]
    TooLarge {
        /// Patches the mesh has.
        patches: usize,
        /// Faces of the scene: one patch each at least.
        faces: usize,
        /// GiB the matrix would take.
        gib: f64,
        /// GiB allowed.
        limit_gib: f64,
    },
}

/// Wall-clock seconds per stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageSeconds {
    /// Reading and checking the scene file.
    pub load: f64,
    /// Splitting faces into patches (and building the BVH).
    pub mesh: f64,
    /// Form factors with visibility.
    pub form_factors: f64,
    /// The linear solve.
    pub solve: f64,
    /// All of the above.
    pub total: f64,
}

/// One object's share of the answer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObjectRadiosity {
    /// The object's name from the scene file.
    pub name: String,
    /// Total area, scene units squared.
    pub area: f64,
    /// Area-weighted mean radiosity, W/m^2 per channel.
    pub radiosity: [f64; 3],
}

/// The summary `radcast solve --json` prints.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolveReport {
    /// Patches solved for.
    pub patches: usize,
    /// Triangles of the input scene (a quad counts two).
    pub triangles: usize,
    /// Input faces dropped for zero area.
    pub skipped_faces: usize,
    /// The solver method.
    pub method: String,
    /// Iterations the solver ran.
    pub iterations: usize,
    /// Final relative residual.
    pub residual: f64,
    /// Whether the residual reached the tolerance.
    pub converged: bool,
    /// The tolerance asked for.
    pub tolerance: f64,
    /// Shadow rays cast for form factors.
    pub rays: u64,
    /// Seconds per stage.
    pub seconds: StageSeconds,
    /// Per object, in scene order.
    pub objects: Vec<ObjectRadiosity>,
    /// Elements, links and refinement rounds of a hierarchical solve (absent for dense).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub hierarchy: Option<HierarchyStats>,
}

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

/// Loads `path` and solves it.
pub fn solve_file(
    path: &Path,
    request: &SolveRequest,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Solved, SolveError> {
    let start = Instant::now();
    let scene = Scene::load(path)?;
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
    let mut session = match &request.hierarchy {
        Some(_) => Session::hierarchical(&scene, request, progress)?,
        None => {
            let start = Instant::now();
            let mesh = dense_mesh(&scene, request)?;
            let mesh_seconds = start.elapsed().as_secs_f64();
            let mut session = Session::new(&scene, &mesh, request, progress)?;
            session.seconds.mesh += mesh_seconds;
            session
        }
    };
    let report = session.solve(progress);
    Ok(Solved {
        scene,
        vertex_radiosity: session.vertex_radiosity(),
        mesh: session.mesh,
        radiosity: session.radiosity,
        report,
    })
}

/// Form factors and solve for a mesh already built from `scene` (the server meshes first so
/// that viewers get the geometry while it solves). `seconds.mesh` holds the BVH build only.
pub fn solve_mesh(
    scene: &Scene,
    mesh: &Mesh,
    request: &SolveRequest,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Solved, SolveError> {
    let mut session = Session::new(scene, mesh, request, progress)?;
    let report = session.solve(progress);
    Ok(Solved {
        scene: scene.clone(),
        vertex_radiosity: session.vertex_radiosity(),
        mesh: session.mesh,
        radiosity: session.radiosity,
        report,
    })
}
