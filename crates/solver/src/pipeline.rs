//! The whole offline path, scene file to solution, with a timing per stage: what the `radcast`
//! command and the server both run.

use crate::Progress;
use crate::form_factors::{DenseFormFactors, FormFactorSettings};
use crate::mesh::{Mesh, PatchTarget};
use crate::scene::{Rgb, Scene, SceneError};
use crate::solve::{SolveOutcome, SolverSettings, System, solve};
use crate::visibility::Occluders;
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
}

impl Default for SolveRequest {
    fn default() -> Self {
        SolveRequest {
            patches: PatchTarget::Count(1000),
            form_factors: FormFactorSettings::default(),
            solver: SolverSettings::default(),
            max_matrix_bytes: 8 << 30,
        }
    }
}

/// Why a solve could not run.
#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    /// The scene file is bad.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The mesh is too fine for a dense matrix in the allowed memory.
    #[error("{patches} patches need {gib:.1} GiB for the dense form-factor matrix (limit {limit_gib:.1} GiB); ask for fewer patches")]
    TooLarge {
        /// Patches the mesh has.
        patches: usize,
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
}

/// A solved scene: the inputs, the patches and their radiosity.
pub struct Solved {
    /// The scene as loaded.
    pub scene: Scene,
    /// Its patches.
    pub mesh: Mesh,
    /// Radiosity per patch, W/m^2.
    pub radiosity: Vec<Rgb>,
    /// The summary.
    pub report: SolveReport,
}

/// Loads `path` and solves it.
pub fn solve_file(path: &Path, request: &SolveRequest, progress: &(dyn Fn(Progress) + Sync)) -> Result<Solved, SolveError> {
    let start = Instant::now();
    let scene = Scene::load_obj(path)?;
    let load = start.elapsed().as_secs_f64();
    let mut solved = solve_scene(scene, request, progress)?;
    solved.report.seconds.load = load;
    solved.report.seconds.total += load;
    Ok(solved)
}

/// Meshes, computes form factors and solves an already loaded scene.
pub fn solve_scene(scene: Scene, request: &SolveRequest, progress: &(dyn Fn(Progress) + Sync)) -> Result<Solved, SolveError> {
    let start = Instant::now();
    let mesh = Mesh::build(&scene, request.patches);
    let mesh_seconds = start.elapsed().as_secs_f64();
    let (radiosity, mut report) = solve_mesh(&scene, &mesh, request, progress)?;
    report.seconds.mesh += mesh_seconds;
    report.seconds.total += mesh_seconds;
    Ok(Solved { scene, mesh, radiosity, report })
}

/// Form factors and solve for a mesh already built from `scene` (the server meshes first so
/// that viewers get the geometry while it solves). `seconds.mesh` holds the BVH build only.
pub fn solve_mesh(scene: &Scene, mesh: &Mesh, request: &SolveRequest, progress: &(dyn Fn(Progress) + Sync)) -> Result<(Vec<Rgb>, SolveReport), SolveError> {
    let mut seconds = StageSeconds::default();
    let mut clock = Instant::now();
    let mut lap = |slot: &mut f64| {
        *slot = clock.elapsed().as_secs_f64();
        clock = Instant::now();
    };
    let n = mesh.patches.len();
    let bytes = DenseFormFactors::memory_bytes(n);
    if bytes > request.max_matrix_bytes {
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        return Err(SolveError::TooLarge { patches: n, gib: gib(bytes), limit_gib: gib(request.max_matrix_bytes) });
    }
    let occluders = Occluders::new(scene);
    lap(&mut seconds.mesh);

    let form_factors = DenseFormFactors::compute(mesh, &occluders, &request.form_factors, progress);
    lap(&mut seconds.form_factors);

    let column = |f: fn(&crate::mesh::Patch) -> Rgb| mesh.patches.iter().map(f).collect::<Vec<_>>();
    let (reflectance, emission) = (column(|p| p.reflectance), column(|p| p.emission));
    let area: Vec<f64> = mesh.patches.iter().map(|p| p.area).collect();
    let system = System { reflectance: &reflectance, emission: &emission, area: &area };
    let SolveOutcome { radiosity, iterations, residual, converged } = solve(&form_factors, &system, &request.solver, None, progress);
    lap(&mut seconds.solve);
    seconds.total = seconds.mesh + seconds.form_factors + seconds.solve;

    let report = SolveReport {
        patches: n,
        triangles: scene.triangle_count(),
        skipped_faces: scene.skipped_degenerate_faces,
        method: request.solver.method.name().into(),
        iterations,
        residual,
        converged,
        tolerance: request.solver.tolerance,
        rays: form_factors.rays_cast,
        seconds,
        objects: object_means(scene, mesh, &radiosity),
    };
    Ok((radiosity, report))
}

/// Area-weighted mean radiosity of every object.
pub fn object_means(scene: &Scene, mesh: &Mesh, radiosity: &[Rgb]) -> Vec<ObjectRadiosity> {
    let mut sums = vec![(0.0, Rgb::ZERO); scene.objects.len()];
    for (patch, b) in mesh.patches.iter().zip(radiosity) {
        let (area, power) = &mut sums[patch.object as usize];
        *area += patch.area;
        *power += *b * patch.area;
    }
    scene
        .objects
        .iter()
        .zip(sums)
        .map(|(object, (area, power))| ObjectRadiosity {
            name: object.name.clone(),
            area,
            radiosity: if area > 0.0 { (power / area).to_array() } else { [0.0; 3] },
        })
        .collect()
}
