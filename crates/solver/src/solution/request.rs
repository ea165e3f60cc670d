//! What a solve is asked for ([`SolveRequest`], [`MethodChoice`]) and why one cannot run
//! ([`SolveError`]).

use crate::hierarchy::HierarchySettings;
use crate::input::SceneError;
use crate::mesh::{Mesh, PatchTarget};
use crate::pair::FormFactorSettings;
use crate::scene::Scene;
use crate::solve::{Method, NeedsEntries, SolverSettings};

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
    Dense(Method),
    /// Hierarchical radiosity with clustering (the `hierarchy` module).
    Hierarchical,
}

impl std::str::FromStr for MethodChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "hierarchical" {
            return Ok(MethodChoice::Hierarchical);
        }
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .map(MethodChoice::Dense)
            .ok_or_else(|| {
                let names: Vec<_> = Method::ALL.map(|m| m.name()).into();
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
            MethodChoice::Hierarchical => (Method::Gmres, Some(hierarchy)),
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

/// The mesh a solve of `request` starts from: the uniform mesh (`dense_mesh`), or one patch
/// per face for a hierarchy, whose refinement decides the leaves later.
pub fn starting_mesh(scene: &Scene, request: &SolveRequest) -> Result<Mesh, SolveError> {
    match request.hierarchy {
        Some(_) => Ok(Mesh::build(scene, PatchTarget::EdgeLength(f64::INFINITY))),
        None => dense_mesh(scene, request),
    }
}

/// `Err(TooLarge)` when a dense matrix over `patches` would exceed `request.max_matrix_bytes`.
pub fn check_dense_size(
    patches: usize,
    faces: usize,
    request: &SolveRequest,
) -> Result<(), SolveError> {
    let bytes = crate::form_factors::DenseFormFactors::memory_bytes(patches);
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
