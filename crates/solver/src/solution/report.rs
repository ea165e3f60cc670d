//! What a solve reports: one schema, serialised as `radcast solve --json` prints it and as
//! `/api/solution` carries it.

use crate::check::Estimate;
use crate::hierarchy::HierarchyStats;
use serde::Serialize;

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
    /// What loading changed to solve the file as shipped ([`crate::Scene::load_warnings`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
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
    /// What cast every ray: `embree` where Intel Embree 3 was installed at build time, else
    /// `obvhs-cwbvh` (`crates/solver/build.rs`).
    pub ray_backend: &'static str,
    /// The seed of the gathers' sample patterns (`--seed`): with the scene and the other
    /// settings, what reproduces this answer.
    pub seed: u64,
    /// Seconds per stage.
    pub seconds: StageSeconds,
    /// Per object, in scene order.
    pub objects: Vec<ObjectRadiosity>,
    /// Elements, links and refinement rounds of a hierarchical solve (absent for dense).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub hierarchy: Option<HierarchyStats>,
    /// The self-check of this answer ([`crate::check`]), when one was run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Estimate>,
    /// How a solve to a target went ([`super::target`]), when one was asked.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<TargetReport>,
}

/// How a solve to a target went.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetReport {
    /// The error asked for.
    pub error: f64,
    /// Whether the last step's upper bound reached it.
    pub reached: bool,
    /// Why refinement stopped: `reached`, `time limit`, `finest knob` (the `--error` floor),
    /// `budget` (leaves or links, or a step that added under 1% more leaves) or `matrix limit`
    /// (a finer dense mesh does not fit).
    pub stopped: &'static str,
    /// Each solve and its check, coarsest first.
    pub steps: Vec<TargetStep>,
}

/// One solve on the way to a target, and what its check said.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TargetStep {
    /// The hierarchy's error knob as refinement ended it (coarser than the step asked where
    /// a budget made it so; absent for dense steps).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub knob: Option<f64>,
    /// The link budget the hierarchy refined under (absent for dense steps).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_links: Option<usize>,
    /// Patches (leaves) solved for.
    pub patches: usize,
    /// Seconds since the start when this step's check ended.
    pub seconds: f64,
    /// The estimated smooth RMS error.
    pub rms: f64,
    /// The upper end of its interval.
    pub high: f64,
}
