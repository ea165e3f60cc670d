//! What a solve is asked for ([`SolveRequest`], [`MethodChoice`]) and why one cannot run
//! ([`SolveError`]).

use crate::hierarchy::HierarchySettings;
use crate::input::SceneError;
use crate::mesh::{Mesh, PatchTarget};
use crate::pair::FormFactorSettings;
use crate::sampling::Seed;
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
    /// The method is chosen from the scene once it is loaded ([`SolveRequest::for_scene`]):
    /// dense with `solver` on `patches`, or hierarchical with `hierarchy`.
    pub auto: bool,
    /// Refine until the self-check says the answer is within this ([`super::target`]); then
    /// `hierarchy.error` is the finest knob and `patches` the coarsest mesh.
    pub target: Option<Target>,
    /// The sample patterns of the gathers at the patches' corners and centroids (the direct
    /// light's shadow rays, the bounce's rays, the test for a buried point).
    pub seed: Seed,
}

/// What `--target-error` asks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    /// The smooth RMS error (relative) the self-check's upper bound must reach.
    pub error: f64,
    /// Seconds the whole solve may take, about: a step is not started when the time spent
    /// plus the last step's would pass it.
    pub seconds: Option<f64>,
}

/// The target of a solve whose resolution no flag fixes: the 5% smooth RMS the project holds
/// real models to (docs/BENCHMARKS.md, "Solving to a target"), no time limit.
impl Default for Target {
    fn default() -> Self {
        Target {
            error: 0.05,
            seconds: None,
        }
    }
}

/// Patches a dense solve starts from when no count or size is asked for.
pub const DEFAULT_PATCHES: usize = 1000;

impl Default for SolveRequest {
    fn default() -> Self {
        SolveRequest {
            patches: PatchTarget::Count(DEFAULT_PATCHES),
            form_factors: FormFactorSettings::default(),
            solver: SolverSettings::default(),
            max_matrix_bytes: 8 << 30,
            hierarchy: None,
            auto: false,
            target: None,
            seed: Seed::default(),
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
    /// One of the two, chosen from the scene ([`SolveRequest::for_scene`]).
    Auto,
}

impl std::str::FromStr for MethodChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "hierarchical" => return Ok(MethodChoice::Hierarchical),
            "auto" => return Ok(MethodChoice::Auto),
            _ => {}
        }
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .map(MethodChoice::Dense)
            .ok_or_else(|| {
                let names: Vec<_> = Method::ALL.map(|m| m.name()).into();
                format!(
                    "unknown method '{s}' (expected auto, hierarchical or one of: {})",
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
            MethodChoice::Auto => f.write_str("auto"),
        }
    }
}

impl SolveRequest {
    /// This request solved by `choice`; `hierarchy` applies if that is the hierarchical path.
    pub fn with_method(self, choice: MethodChoice, hierarchy: HierarchySettings) -> SolveRequest {
        let (method, hierarchy) = match choice {
            MethodChoice::Dense(method) => (method, None),
            MethodChoice::Hierarchical | MethodChoice::Auto => (Method::Gmres, Some(hierarchy)),
        };
        SolveRequest {
            solver: SolverSettings {
                method,
                ..self.solver
            },
            hierarchy,
            auto: choice == MethodChoice::Auto,
            ..self
        }
    }

    /// This request with its method chosen for `scene`, and what was chosen and why, when
    /// [`SolveRequest::auto`] asks for a choice. Dense when the uniform mesh gives every face
    /// at least [`AUTO_PATCHES_PER_FACE`] patches and its matrix fits: on a scene of few faces
    /// it reaches a given error first (the Cornell box: 3.2% smooth RMS in 0.07 s at 602
    /// patches, docs/speed-vs-error.md). Else hierarchical: a mesh of one patch a face leaves
    /// large faces unresolved (a 6.7k-triangle real model, dense at 6,112 patches: 60% smooth
    /// RMS), and one fine enough for them does not fit (125k triangles: 74 GiB).
    /// A hierarchy's leaf budget is fitted to the scene ([`HierarchySettings::fitted_to`]).
    pub fn for_scene(&self, scene: &Scene) -> (SolveRequest, Option<String>) {
        if !self.auto {
            let fitted = SolveRequest {
                hierarchy: self.hierarchy.map(|h| h.fitted_to(scene)),
                ..*self
            };
            return (fitted, None);
        }
        let faces = scene.faces.len();
        let patches = Mesh::planned_count(scene, self.patches);
        let fits = check_dense_size(patches, faces, self).is_ok();
        let resolved = |hierarchy| SolveRequest {
            hierarchy,
            auto: false,
            ..*self
        };
        if fits && patches >= AUTO_PATCHES_PER_FACE * faces {
            let why = format!(
                "method: auto chose dense {} on {patches} patches ({faces} faces, at least {AUTO_PATCHES_PER_FACE} patches a face)",
                self.solver.method
            );
            return (resolved(None), Some(why));
        }
        let hierarchy = self.hierarchy.unwrap_or_default().fitted_to(scene);
        let why = format!(
            "method: auto chose hierarchical at --error {} ({faces} faces: a dense mesh of {patches} patches {})",
            hierarchy.error,
            match fits {
                true => format!("gives fewer than {AUTO_PATCHES_PER_FACE} a face"),
                false => "does not fit in memory".to_string(),
            }
        );
        (resolved(Some(hierarchy)), Some(why))
    }
}

/// The fewest patches a face the dense path may give a scene for `--method auto` to choose it.
pub const AUTO_PATCHES_PER_FACE: usize = 4;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::fixtures::closed_cube;

    #[test]
    fn auto_is_dense_with_four_patches_a_face_that_fit_and_hierarchical_otherwise() {
        let cube = closed_cube();
        let auto = |patches: usize, max_matrix_bytes: u64| {
            SolveRequest {
                patches: PatchTarget::Count(patches),
                max_matrix_bytes,
                ..SolveRequest::default()
            }
            .with_method(MethodChoice::Auto, HierarchySettings::default())
            .for_scene(&cube)
        };
        let (dense, why) = auto(1000, 8 << 30);
        assert_eq!((dense.hierarchy, dense.auto), (None, false));
        let planned = Mesh::planned_count(&cube, PatchTarget::Count(1000));
        assert_eq!(
            why.as_deref(),
            Some(
                format!(
                    "method: auto chose dense gmres on {planned} patches (6 faces, at least 4 patches a face)"
                )
                .as_str()
            )
        );
        let (few, why) = auto(6, 8 << 30);
        assert_eq!(few.hierarchy, Some(HierarchySettings::default()));
        assert_eq!(
            why.as_deref(),
            Some(
                "method: auto chose hierarchical at --error 0.03 (6 faces: a dense mesh of 6 patches gives fewer than 4 a face)"
            )
        );
        let (big, why) = auto(1000, 1);
        assert!(big.hierarchy.is_some() && !big.auto);
        assert!(why.unwrap().ends_with("does not fit in memory)"));
        // Asked for by name, a method stays, with nothing to say.
        let named = SolveRequest::default();
        assert_eq!(named.for_scene(&cube), (named, None));
    }
}
