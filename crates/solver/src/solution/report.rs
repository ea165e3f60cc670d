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
}
