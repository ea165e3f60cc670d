//! The whole offline path, scene file to solution, with a timing per stage: what the `radcast`
//! command and the server both run.

use crate::form_factors::DenseFormFactors;
use crate::hierarchy::{Hierarchy, HierarchySettings, HierarchyStats, Refined};
use crate::mesh::{Mesh, PatchTarget};
use crate::pair::FormFactorSettings;
use crate::scene::{Rgb, Scene, SceneError};
use crate::solve::{NeedsEntries, SolveOutcome, SolverSettings, System, solve};
use crate::transport::Transport;
use crate::visibility::Occluders;
use crate::{Progress, no_progress};
use glam::DVec3;
use serde::Serialize;
use std::collections::BTreeMap;
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

/// `--method` of the command-line tools: a solver on a dense matrix over a uniform mesh, or
/// hierarchical radiosity (elements and links, solved with GMRES).
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
        s.parse().map(MethodChoice::Dense).map_err(|e: String| {
            e.replace("(expected one of: ", "(expected hierarchical or one of: ")
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
        "{patches} patches need {gib:.1} GiB for the dense form-factor matrix (limit {limit_gib:.1} GiB); ask for fewer patches"
    )]
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
    let scene = Scene::load_obj(path)?;
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
    let mut session = match &request.hierarchy {
        Some(_) => Session::hierarchical(&scene, request, progress)?,
        None => {
            let start = Instant::now();
            let mesh = Mesh::build(&scene, request.patches);
            let mesh_seconds = start.elapsed().as_secs_f64();
            let mut session = Session::new(&scene, &mesh, request, progress)?;
            session.seconds.mesh += mesh_seconds;
            session
        }
    };
    let report = session.solve(progress);
    Ok(Solved {
        scene,
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
) -> Result<(Vec<Rgb>, SolveReport), SolveError> {
    let mut session = Session::new(scene, mesh, request, progress)?;
    let report = session.solve(progress);
    Ok((session.radiosity, report))
}

/// How a session moves light between patches.
enum Transfer {
    Dense(DenseFormFactors),
    Hierarchy(Box<Hierarchy>),
}

impl Transfer {
    fn transport(&self) -> &dyn Transport {
        match self {
            Transfer::Dense(factors) => factors,
            Transfer::Hierarchy(hierarchy) => hierarchy.as_ref(),
        }
    }
}

/// A solved scene kept live for emission changes. Radiosity is linear in emission,
/// `B = (I - rho F)^-1 E`, so the session keeps, per edited object `k`, its response `G_k` to
/// unit emission on its patches and `R_k` to its original emission; after edits,
/// `B = B_base + sum_k (e_k * G_k - R_k)`: an O(n) sum per edit instead of a solve, exact to
/// the solver tolerance. Each object costs one or two solves, once.
pub struct Session {
    scene: Scene,
    mesh: Mesh,
    transfer: Transfer,
    /// The solution for the scene's own emission.
    base: Vec<Rgb>,
    /// Per object: (response to unit emission, response to its original emission).
    responses: BTreeMap<u32, (Vec<Rgb>, Vec<Rgb>)>,
    /// Current emission of every edited object.
    edited: BTreeMap<u32, Rgb>,
    objects: Vec<String>,
    patch_objects: Vec<u32>,
    reflectance: Vec<Rgb>,
    emission: Vec<Rgb>,
    area: Vec<f64>,
    request: SolveRequest,
    seconds: StageSeconds,
    triangles: usize,
    skipped_faces: usize,
    radiosity: Vec<Rgb>,
}

/// An emission change that cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EditError {
    /// No object has that name.
    #[error("no object named '{0}'")]
    UnknownObject(String),
    /// Emission must be finite and non-negative.
    #[error("emission {0:?} must have every channel finite and >= 0")]
    InvalidEmission([f64; 3]),
    /// A translation must be finite.
    #[error("translation {0:?} must be finite")]
    InvalidTranslation([f64; 3]),
}

/// What moving an object cost. A hierarchy is built again: `pairs` and `entries` are then its
/// links and `rows` its leaves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MoveReport {
    /// Patch pairs whose visibility was recomputed (of n(n-1)/2).
    pub pairs: usize,
    /// Rows with a changed entry (of n).
    pub rows: usize,
    /// Form-factor entries integrated again (of n^2).
    pub entries: usize,
    /// Seconds for the form-factor update.
    pub seconds: f64,
}

impl Session {
    /// Computes the form factors of `mesh`; nothing is solved yet.
    pub fn new(
        scene: &Scene,
        mesh: &Mesh,
        request: &SolveRequest,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<Session, SolveError> {
        let n = mesh.patches.len();
        let bytes = DenseFormFactors::memory_bytes(n);
        if bytes > request.max_matrix_bytes {
            let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
            return Err(SolveError::TooLarge {
                patches: n,
                gib: gib(bytes),
                limit_gib: gib(request.max_matrix_bytes),
            });
        }
        let mut seconds = StageSeconds::default();
        let clock = Instant::now();
        let occluders = Occluders::new(scene);
        seconds.mesh = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let form_factors =
            DenseFormFactors::compute(mesh, &occluders, &request.form_factors, progress);
        seconds.form_factors = clock.elapsed().as_secs_f64();
        Ok(Session::assemble(
            scene.clone(),
            mesh.clone(),
            Transfer::Dense(form_factors),
            request,
            seconds,
            vec![Rgb::ZERO; n],
        ))
    }

    /// Builds the element and link hierarchy of `scene` with `request.hierarchy`'s settings (the
    /// defaults if it names none), which also decides the patches: the leaves.
    /// [`Session::solve`] then finishes from the refinement's last solution.
    pub fn hierarchical(
        scene: &Scene,
        request: &SolveRequest,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<Session, SolveError> {
        let settings = request.hierarchy.unwrap_or_default();
        let request = &SolveRequest {
            hierarchy: Some(settings),
            ..*request
        };
        if request.solver.method.needs_entries() {
            return Err(NeedsEntries(request.solver.method).into());
        }
        let mut seconds = StageSeconds::default();
        let clock = Instant::now();
        let occluders = Occluders::new(scene);
        seconds.mesh = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let Refined {
            hierarchy,
            radiosity,
        } = Hierarchy::build(
            scene,
            &occluders,
            &settings,
            request.form_factors,
            &request.solver,
            progress,
        )?;
        seconds.form_factors = clock.elapsed().as_secs_f64();
        let mesh = hierarchy.leaf_mesh();
        Ok(Session::assemble(
            scene.clone(),
            mesh,
            Transfer::Hierarchy(Box::new(hierarchy)),
            request,
            seconds,
            radiosity,
        ))
    }

    fn assemble(
        scene: Scene,
        mesh: Mesh,
        transfer: Transfer,
        request: &SolveRequest,
        seconds: StageSeconds,
        radiosity: Vec<Rgb>,
    ) -> Session {
        let column =
            |f: fn(&crate::mesh::Patch) -> Rgb| mesh.patches.iter().map(f).collect::<Vec<_>>();
        Session {
            objects: scene.objects.iter().map(|o| o.name.clone()).collect(),
            patch_objects: mesh.patches.iter().map(|p| p.object).collect(),
            reflectance: column(|p| p.reflectance),
            emission: column(|p| p.emission),
            area: mesh.patches.iter().map(|p| p.area).collect(),
            request: *request,
            base: radiosity.clone(),
            responses: BTreeMap::new(),
            edited: BTreeMap::new(),
            seconds,
            triangles: scene.triangle_count(),
            skipped_faces: scene.skipped_degenerate_faces,
            radiosity,
            scene,
            mesh,
            transfer,
        }
    }

    /// The scene as it is now (after moves).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The patches as they are now (after moves).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The hierarchy's statistics, for a hierarchical session.
    fn hierarchy_stats(&self) -> Option<HierarchyStats> {
        match &self.transfer {
            Transfer::Dense(_) => None,
            Transfer::Hierarchy(hierarchy) => Some(hierarchy.stats()),
        }
    }

    fn object_index(&self, name: &str) -> Result<u32, EditError> {
        self.objects
            .iter()
            .position(|o| o == name)
            .map(|i| i as u32)
            .ok_or_else(|| EditError::UnknownObject(name.into()))
    }

    /// Moves object `name` by `offset`, recomputing only the form factors it can affect. The
    /// next [`Session::solve`] solves the moved scene in full (with the current emission).
    pub fn translate(&mut self, name: &str, offset: DVec3) -> Result<MoveReport, EditError> {
        let object = self.object_index(name)?;
        if !offset.is_finite() {
            return Err(EditError::InvalidTranslation(offset.to_array()));
        }
        let clock = Instant::now();
        // The responses were for the old transport: fold the edits into the emission (of the
        // patches, and of the scene, which a hierarchy is rebuilt from) and let the next solve
        // start over from it.
        for (object, emission) in std::mem::take(&mut self.edited) {
            for (e, _) in self
                .emission
                .iter_mut()
                .zip(&self.patch_objects)
                .filter(|(_, o)| **o == object)
            {
                *e = emission;
            }
            self.scene
                .faces
                .iter_mut()
                .filter(|f| f.object == object)
                .for_each(|f| f.emission = emission);
        }
        self.responses.clear();
        let corners = |scene: &Scene| {
            scene
                .faces
                .iter()
                .filter(|f| f.object == object)
                .flat_map(|f| f.polygon.corners().to_vec())
                .collect::<Vec<_>>()
        };
        let mut swept = corners(&self.scene);
        self.scene.translate_object(object, offset);
        swept.extend(corners(&self.scene));
        match &mut self.transfer {
            Transfer::Dense(form_factors) => {
                let occluders = Occluders::new(&self.scene);
                self.mesh.translate_object(object, offset);
                let moved: Vec<bool> = self.patch_objects.iter().map(|o| *o == object).collect();
                let stats = form_factors.update_moved(
                    &self.mesh,
                    &occluders,
                    &moved,
                    crate::geometry::bounds(swept),
                );
                Ok(MoveReport {
                    pairs: stats.pairs,
                    rows: stats.rows,
                    entries: stats.entries,
                    seconds: clock.elapsed().as_secs_f64(),
                })
            }
            Transfer::Hierarchy(_) => {
                // Refinement depends on where light falls, so the hierarchy is built again: new
                // leaves, which viewers get as a new geometry.
                let seconds = self.seconds;
                *self = Session::hierarchical(&self.scene, &self.request, &no_progress)
                    .expect("this session's method already ran on a hierarchy");
                self.seconds = seconds;
                let stats = self.hierarchy_stats().expect("a hierarchical session");
                Ok(MoveReport {
                    pairs: stats.links,
                    rows: stats.elements,
                    entries: stats.links,
                    seconds: clock.elapsed().as_secs_f64(),
                })
            }
        }
    }

    /// Radiosity per patch, W/m^2: zero until the first [`Session::solve`].
    pub fn radiosity(&self) -> &[Rgb] {
        &self.radiosity
    }

    /// Takes `radiosity` as the solution for the scene's own emission (a cached solve), so that
    /// edits can be applied without solving it again.
    pub fn adopt_solution(&mut self, radiosity: Vec<Rgb>) {
        assert_eq!(radiosity.len(), self.base.len(), "one radiosity per patch");
        self.base.clone_from(&radiosity);
        self.radiosity = radiosity;
    }

    /// Sets the emission of every patch of object `name`; [`Session::solve`] applies it.
    pub fn set_emission(&mut self, name: &str, emission: Rgb) -> Result<(), EditError> {
        let object = self.object_index(name)?;
        if !emission.is_finite() || emission.min_element() < 0.0 {
            return Err(EditError::InvalidEmission(emission.to_array()));
        }
        self.edited.insert(object, emission);
        Ok(())
    }

    /// Solves for `emission` from `initial` (or zero).
    fn solve_for(
        &self,
        emission: &[Rgb],
        initial: Option<&[Rgb]>,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> SolveOutcome {
        let system = System {
            reflectance: &self.reflectance,
            emission,
            area: &self.area,
        };
        // Both constructors refuse a method the transport cannot run.
        solve(
            self.transfer.transport(),
            &system,
            &self.request.solver,
            initial,
            progress,
        )
        .expect("method checked when the session was made")
    }

    /// Computes the responses of `object` unless known; returns the solver iterations spent.
    fn ensure_response(&mut self, object: u32) -> usize {
        if self.responses.contains_key(&object) {
            return 0;
        }
        let mask = |value: &dyn Fn(usize) -> Rgb| -> Vec<Rgb> {
            (0..self.emission.len())
                .map(|i| {
                    if self.patch_objects[i] == object {
                        value(i)
                    } else {
                        Rgb::ZERO
                    }
                })
                .collect()
        };
        let unit = self.solve_for(&mask(&|_| Rgb::ONE), None, &no_progress);
        let original_emission = mask(&|i| self.emission[i]);
        let mut iterations = unit.iterations;
        // Uniform original emission needs no second solve: its response is e * G.
        let first = original_emission
            .iter()
            .zip(&self.patch_objects)
            .find(|(_, o)| **o == object)
            .map(|(e, _)| *e)
            .unwrap_or(Rgb::ZERO);
        let uniform = original_emission
            .iter()
            .zip(&self.patch_objects)
            .all(|(e, o)| *o != object || *e == first);
        let original = if uniform {
            unit.radiosity.iter().map(|g| *g * first).collect()
        } else {
            let solved = self.solve_for(&original_emission, None, &no_progress);
            iterations += solved.iterations;
            solved.radiosity
        };
        self.responses.insert(object, (unit.radiosity, original));
        iterations
    }

    /// Prepares the responses of every object that emits in the scene, so that edits of the
    /// scene's lights apply at once. Returns the solver iterations spent.
    pub fn prepare_emitters(&mut self) -> usize {
        let emitting: std::collections::BTreeSet<u32> = self
            .emission
            .iter()
            .zip(&self.patch_objects)
            .filter(|(e, _)| e.max_element() > 0.0)
            .map(|(_, o)| *o)
            .collect();
        emitting.into_iter().map(|o| self.ensure_response(o)).sum()
    }

    /// Solves: the first time (or with no edits) from zero, afterwards by superposing the
    /// responses of the edited objects on the base solution.
    pub fn solve(&mut self, progress: &(dyn Fn(Progress) + Sync)) -> SolveReport {
        let clock = Instant::now();
        let (iterations, residual, converged) = if self.edited.is_empty() {
            // From the current answer: after a move, most of it still holds.
            let outcome = self.solve_for(&self.emission, Some(&self.radiosity), progress);
            self.base.clone_from(&outcome.radiosity);
            self.radiosity = outcome.radiosity;
            (outcome.iterations, outcome.residual, outcome.converged)
        } else {
            let edited: Vec<(u32, Rgb)> = self.edited.iter().map(|(o, e)| (*o, *e)).collect();
            let iterations = edited.iter().map(|(o, _)| self.ensure_response(*o)).sum();
            let mut radiosity = self.base.clone();
            for (object, emission) in edited {
                let (unit, original) = &self.responses[&object];
                for ((b, g), r) in radiosity.iter_mut().zip(unit).zip(original) {
                    *b += *g * emission - *r;
                }
            }
            // Clamp round-off below zero, as the solver does.
            radiosity.iter_mut().for_each(|b| *b = b.max(Rgb::ZERO));
            self.radiosity = radiosity;
            (iterations, self.request.solver.tolerance, true)
        };
        self.seconds.solve = clock.elapsed().as_secs_f64();
        self.seconds.total = self.seconds.mesh + self.seconds.form_factors + self.seconds.solve;
        let (mut area, mut power) = (
            vec![0.0; self.objects.len()],
            vec![Rgb::ZERO; self.objects.len()],
        );
        for ((o, a), b) in self
            .patch_objects
            .iter()
            .zip(&self.area)
            .zip(&self.radiosity)
        {
            area[*o as usize] += a;
            power[*o as usize] += *b * *a;
        }
        SolveReport {
            patches: self.radiosity.len(),
            triangles: self.triangles,
            skipped_faces: self.skipped_faces,
            method: if self.request.hierarchy.is_some() {
                "hierarchical".into()
            } else {
                self.request.solver.method.name().into()
            },
            iterations,
            residual,
            converged,
            tolerance: self.request.solver.tolerance,
            rays: match &self.transfer {
                Transfer::Dense(factors) => factors.rays_cast,
                Transfer::Hierarchy(hierarchy) => hierarchy.stats().rays,
            },
            seconds: self.seconds,
            objects: self
                .objects
                .iter()
                .zip(area.iter().zip(&power))
                .map(|(name, (a, p))| ObjectRadiosity {
                    name: name.clone(),
                    area: *a,
                    radiosity: if *a > 0.0 {
                        (*p / *a).to_array()
                    } else {
                        [0.0; 3]
                    },
                })
                .collect(),
            hierarchy: self.hierarchy_stats(),
        }
    }
}
