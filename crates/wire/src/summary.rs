//! The JSON of `GET /api/solution`: what a viewer checks its buffer against, and the solver's
//! report. Typed here so that the server writes and every client reads one definition
//! (docs/PROTOCOL.md gives the same fields).

use serde::{Deserialize, Serialize};

/// The body of `GET /api/solution`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SolutionSummary {
    /// Scene content and solve settings, as 16 lower-case hex digits (the hello's `scene_id`).
    pub scene_id: String,
    /// Vertices of the current geometry: every frame of this version has this many codes.
    pub vertex_count: u32,
    /// The geometry these colours belong to (the hello's and `/api/scene`'s version).
    pub geometry_version: u64,
    /// The current solution version.
    pub solution_version: u64,
    /// Whether the solver converged for it.
    pub is_final: bool,
    /// [`crate::checksum`] of the current codes.
    pub checksum: u32,
    /// The current frame scale, W/m^2 per decoded unit (a power of two, as an f32).
    pub scale: f32,
    /// Protocol 3, when this version is also served as a sum of responses:
    /// [`crate::responses::sum_checksum`] of the values the sum gives (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sum_checksum: Option<u32>,
    /// The solver's report once the first solve is done (`null` before).
    pub report: Option<SolveReport>,
}

/// What the last solve did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SolveReport {
    /// Patches solved for (the leaves, for the hierarchical method).
    pub patches: usize,
    /// Triangles of the input scene (a quad counts two).
    pub triangles: usize,
    /// Input faces dropped for zero area.
    pub skipped_faces: usize,
    /// What loading changed to solve the scene file as shipped, each naming the material or
    /// file: a `Kd` of 1 read as 0.99, a texture file that is not there (absent when nothing).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// The method: `jacobi`, `gauss-seidel`, `progressive`, `gmres` or `hierarchical`.
    pub method: String,
    /// Solver iterations.
    pub iterations: usize,
    /// Final relative residual.
    pub residual: f64,
    /// Whether the residual reached the tolerance.
    pub converged: bool,
    /// The tolerance asked for.
    pub tolerance: f64,
    /// Shadow rays cast.
    pub rays: u64,
    /// What cast them: `embree` or `obvhs-cwbvh` (empty from a server that did not say).
    #[serde(default)]
    pub ray_backend: String,
    /// The seed of the gathers' sample patterns the solve drew (0, the default, from a server
    /// that did not say).
    #[serde(default)]
    pub seed: u64,
    /// Wall-clock seconds per stage.
    pub seconds: StageSeconds,
    /// Per object of the scene, in file order.
    pub objects: Vec<ObjectRadiosity>,
    /// Elements and links, for the hierarchical method (absent otherwise).
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub hierarchy: Option<HierarchyCounts>,
    /// The self-check of the answer now served: of the last solve or move (an emission edit
    /// keeps it); absent when the check is off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<ErrorEstimate>,
    /// How the solve to `--target-error` went, when the server was started with one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<TargetOutcome>,
}

/// Wall-clock seconds per stage of a solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageSeconds {
    /// Reading the scene file.
    pub load: f64,
    /// Meshing and building the ray-casting index.
    pub mesh: f64,
    /// Form factors, or the hierarchy's refinement.
    pub form_factors: f64,
    /// The linear solve.
    pub solve: f64,
    /// All of the above.
    pub total: f64,
}

/// One object's share of the answer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectRadiosity {
    /// The object's name from the scene file.
    pub name: String,
    /// Its area, scene units squared.
    pub area: f64,
    /// Its area-weighted mean radiosity, W/m^2 per channel.
    pub radiosity: [f64; 3],
}

/// What the hierarchical method built.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HierarchyCounts {
    /// Leaf elements (= patches).
    pub elements: usize,
    /// Links kept.
    pub links: usize,
    /// Cluster nodes above the input faces.
    pub clusters: usize,
    /// Refinement-and-solve rounds run.
    pub rounds: usize,
    /// Links whose visibility a shaft decided without rays.
    pub shaft_decided: u64,
    /// Solver iterations spent in the refinement rounds.
    pub refinement_iterations: usize,
    /// The error knob refined to (coarser than asked when the leaf budget forced it).
    pub knob_used: f64,
    /// Whether refinement stopped at the leaf budget.
    pub leaf_budget_reached: bool,
    /// Whether refinement stopped at the link budget (absent from servers before it existed).
    #[serde(default)]
    pub link_budget_reached: bool,
    /// The pairs it left undecided there, to the vertices' own gathers (absent from servers
    /// before it existed).
    #[serde(default)]
    pub deferred_pairs: usize,
}

/// A solution's error estimated against probes path-traced for it, the tracing's noise taken
/// out: what `radcast solve` prints as `estimate`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorEstimate {
    /// What viewers see: values interpolated from the vertices.
    pub smooth: ReadingError,
    /// Patch values.
    pub flat: ReadingError,
    /// The tracing's own relative RMS noise, taken out of both.
    pub noise: f64,
    /// Probes that counted.
    pub probes: usize,
    /// Seconds the check took.
    pub seconds: f64,
}

/// One reading's estimated error, relative to the RMS radiosity at the probes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReadingError {
    /// The relative RMS error.
    pub rms: f64,
    /// The low end of its interval (three standard errors).
    pub low: f64,
    /// The high end of its interval.
    pub high: f64,
    /// `sum B / sum B_traced - 1` over the probes: the energy balance.
    pub energy: f64,
}

/// How a solve to a target went: each step's self-check, and why refinement stopped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetOutcome {
    /// The smooth RMS error asked for.
    pub error: f64,
    /// Whether the last step's upper bound reached it.
    pub reached: bool,
    /// `reached`, `time limit`, `finest knob`, `budget` or `matrix limit`.
    pub stopped: String,
    /// Each solve and its check, coarsest first.
    pub steps: Vec<TargetStepOutcome>,
}

/// One step toward a target.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetStepOutcome {
    /// The hierarchy's knob (absent for a dense step).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub knob: Option<f64>,
    /// Patches (leaves) solved for.
    pub patches: usize,
    /// Seconds from the start to the end of this step's check.
    pub seconds: f64,
    /// The estimated smooth RMS error.
    pub rms: f64,
    /// The upper end of its interval.
    pub high: f64,
}
