//! The radiosity solver of radcast: scene in, radiosity per patch out. No networking.
//!
//! The flow, top to bottom: `input` (OBJ + MTL, glTF) reads files into a `scene` (the model);
//! `mesh` cuts it into patches; form factors with `visibility` (`form_factors`, dense, or
//! `hierarchy`) make a [`Transport`]; `solve` iterates on it; `solution` holds the vocabulary
//! ([`SolveRequest`], [`SolveReport`]), the live [`Session`], the vertex values viewers are sent
//! and the offline [`solve_file`]. The flow's types are re-exported here, one path each; the
//! modules below are the tools beside it.

pub mod accuracy;
#[cfg(feature = "clap")]
pub mod args;
pub mod check;
pub mod generate;
pub mod reference;
pub mod visibility;

mod form_factors;
mod geometry;
mod hierarchy;
mod input;
mod mesh;
mod pair;
mod sampling;
mod scene;
mod solution;
mod solve;
mod transport;

/// Which revision of the numerics this build solves with: bumped whenever the same scene and
/// settings come out with different values (a new reconstruction, a changed rule), so that
/// solutions cached by an earlier build are not served as this one's. 2: vertex values carry
/// what interpolation misses of the direct light (`solution::vertices`).
pub const SOLUTION_REVISION: u32 = 2;

pub use form_factors::{DenseFormFactors, UpdateStats};
pub use geometry::Polygon;
pub use hierarchy::{HierarchySettings, HierarchyStats};
pub use input::{
    MAX_SCENE_FILE_BYTES, SceneError, load_gltf, load_obj, load_scene, read_scene_file,
};
pub use mesh::{Mesh, Patch, PatchTarget};
pub use pair::FormFactorSettings;
pub use sampling::Seed;
pub use scene::motion::{Motion, Rotation};
pub use scene::texture::{Texture, TextureMap};
pub use scene::{
    Face, MAX_COORDINATE, MAX_EMISSION, MAX_REFLECTANCE, MAX_TEXTURE_COORDINATE, Material, Rgb,
    Scene, SceneObject, View, check_emission, check_translation,
};
pub use solution::pipeline::{Solved, solve_file, solve_mesh, solve_scene};
pub use solution::report::{ObjectRadiosity, SolveReport, StageSeconds};
pub use solution::report::{TargetReport, TargetStep};
pub use solution::request::{MethodChoice, SolveError, SolveRequest, Target, starting_mesh};
pub use solution::session::{EditError, MoveReport, MoveWork, Session, TermKey, VertexTerm};
pub use solution::target::{STARTING_KNOB, session_to_target};
pub use solve::{Method, SolveOutcome, SolverSettings, System, solve};
pub use transport::{Entries, Transport};

/// Where a long computation is, for progress displays and progressive streaming.
#[derive(Clone, Copy, Debug)]
pub enum Progress<'a> {
    /// Form-factor rows done out of total (two passes over every row).
    FormFactors {
        /// Rows finished.
        done: usize,
        /// Rows in all.
        total: usize,
    },
    /// Path-traced probes finished out of total.
    Probes {
        /// What the probes are for: a reference, or the self-check.
        purpose: &'a str,
        /// Probes finished.
        done: usize,
        /// Probes in all.
        total: usize,
    },
    /// A solver iteration finished with this relative residual.
    Solve {
        /// Iterations so far.
        iteration: usize,
        /// Relative residual (an estimate inside a GMRES cycle).
        residual: f64,
    },
    /// Light gathered at the corners and centroids viewers' values come from, after the
    /// patches are solved or refined: points done out of total for one pass of rays.
    Gathering {
        /// What this pass's rays gather.
        pass: &'a str,
        /// Points finished.
        done: usize,
        /// Points in all.
        total: usize,
    },
    /// Hierarchical refinement: one generation of link decisions done.
    Refining {
        /// The error knob this attempt refines to.
        knob: f64,
        /// Refinement round (0 on the first estimate, then one per new solution).
        round: usize,
        /// Leaves so far.
        leaves: usize,
        /// Links kept so far.
        links: usize,
        /// Pairs the next generation decides.
        undecided: usize,
    },
    /// A generation of refinement at `knob` would pass a budget: it is decided again, and
    /// refinement goes on, at `next_knob`.
    Coarsening {
        /// The knob the generation was first decided at.
        knob: f64,
        /// The knob tried next.
        next_knob: f64,
        /// The budget that was reached.
        limit: Limit,
    },
    /// A step begins that counts nothing of its own: loading and cutting the faces, the
    /// cluster tree, where light reaches. Shown as it begins, so that no minute passes unsaid.
    Stage {
        /// What begins, in a few words.
        name: &'a str,
    },
    /// What was chosen for the user, and why (`--method auto`).
    Notice {
        /// What, in one sentence.
        text: &'a str,
    },
    /// Something the user should know before waiting for the result.
    Warning {
        /// What, in one sentence.
        text: &'a str,
    },
    /// The solver's current estimate, between iterations.
    Estimate {
        /// Radiosity per patch, W/m^2; not yet converged.
        radiosity: Unconverged<'a>,
    },
}

/// A solver's estimate between iterations, worked out only when read: GMRES's iterate costs a
/// pass over its whole basis (up to 31 values a patch), which only a progressive display,
/// a few times a second, wants.
#[derive(Clone, Copy)]
pub struct Unconverged<'a>(&'a (dyn Fn() -> Vec<Rgb> + Sync));

impl<'a> Unconverged<'a> {
    /// The estimate `read` works out.
    pub fn new(read: &'a (dyn Fn() -> Vec<Rgb> + Sync)) -> Self {
        Unconverged(read)
    }

    /// Radiosity per patch, W/m^2.
    pub fn read(&self) -> Vec<Rgb> {
        (self.0)()
    }
}

impl std::fmt::Debug for Unconverged<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Unconverged(..)")
    }
}

/// A budget of hierarchical refinement ([`HierarchySettings`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// Leaves at most.
    Leaves(usize),
    /// Links at most.
    Links(usize),
}

impl std::fmt::Display for Limit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Limit::Leaves(n) => write!(f, "{n} leaves (--max-leaves)"),
            Limit::Links(n) => write!(f, "{n} links (--max-links)"),
        }
    }
}

impl Progress<'_> {
    /// One line for a person watching, or `None` for what is not worth a line (estimates).
    pub fn describe(&self) -> Option<String> {
        let percent = |done: usize, total: usize| 100.0 * done as f64 / total.max(1) as f64;
        Some(match *self {
            Progress::FormFactors { done, total } => {
                format!("form factors {:5.1}%", percent(done, total))
            }
            Progress::Probes {
                purpose,
                done,
                total,
            } => format!("{purpose}: {done} of {total} probes"),
            Progress::Gathering { pass, done, total } => {
                format!("vertex light: {pass} at {done} of {total} points")
            }
            Progress::Solve {
                iteration,
                residual,
            } => format!("solve: iteration {iteration}, residual {residual:.3e}"),
            Progress::Refining {
                knob,
                round,
                leaves,
                links,
                undecided,
            } => format!(
                "refining at error {knob}: round {}, {leaves} leaves, {links} links, {undecided} pairs to decide",
                round + 1
            ),
            Progress::Coarsening {
                knob,
                next_knob,
                limit,
            } => {
                format!("refinement at error {knob} would pass {limit}: going on at {next_knob}")
            }
            Progress::Stage { name: text }
            | Progress::Warning { text }
            | Progress::Notice { text } => text.to_string(),
            Progress::Estimate { .. } => return None,
        })
    }

    /// Whether this must be shown even when progress lines are thinned out: it changes what
    /// the user gets (a coarser knob than asked, a black result).
    pub fn is_warning(&self) -> bool {
        matches!(self, Progress::Coarsening { .. } | Progress::Warning { .. })
    }
}

/// What a person watching a long computation is shown: every warning and every stage as it
/// begins, and at most one other line per interval (the first after one interval has passed).
pub struct ProgressThrottle {
    interval: std::time::Duration,
    last: std::sync::Mutex<std::time::Instant>,
}

/// A progress line to show.
pub enum ProgressLine {
    /// Changes what the user gets: show it always.
    Warning(String),
    /// What was chosen for the user: show it always, as information.
    Notice(String),
    /// Where the computation is.
    Status(String),
}

impl ProgressThrottle {
    /// A throttle letting one status line through per `interval`.
    pub fn new(interval: std::time::Duration) -> Self {
        ProgressThrottle {
            interval,
            last: std::sync::Mutex::new(std::time::Instant::now()),
        }
    }

    /// The line to show for `progress` now, if any.
    pub fn admit(&self, progress: Progress) -> Option<ProgressLine> {
        let line = progress.describe()?;
        if progress.is_warning() {
            return Some(ProgressLine::Warning(line));
        }
        if matches!(progress, Progress::Notice { .. }) {
            return Some(ProgressLine::Notice(line));
        }
        // Progress comes from many threads: a contended lock means a line is being shown.
        let mut last = self.last.try_lock().ok()?;
        let begins = matches!(progress, Progress::Stage { .. });
        if last.elapsed() < self.interval && !begins {
            return None;
        }
        *last = std::time::Instant::now();
        Some(ProgressLine::Status(line))
    }
}

/// A progress sink that ignores everything.
pub fn no_progress(_: Progress) {}

#[cfg(test)]
mod progress_tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_throttle_lets_warnings_and_stages_through_always_and_status_once_per_interval() {
        let status = Progress::Solve {
            iteration: 3,
            residual: 0.5,
        };
        let warning = Progress::Warning { text: "no light" };
        let slow = ProgressThrottle::new(Duration::from_secs(3600));
        assert!(
            slow.admit(status).is_none(),
            "not before an interval has passed"
        );
        assert!(matches!(slow.admit(warning), Some(ProgressLine::Warning(t)) if t == "no light"));
        let none = Vec::new;
        let estimate = Progress::Estimate {
            radiosity: Unconverged::new(&none),
        };
        assert!(slow.admit(estimate).is_none());
        let stage = Progress::Stage {
            name: "cluster tree",
        };
        assert!(
            matches!(slow.admit(stage), Some(ProgressLine::Status(t)) if t == "cluster tree"),
            "a stage is shown as it begins"
        );
        assert!(slow.admit(status).is_none(), "the interval starts again");
        let eager = ProgressThrottle::new(Duration::ZERO);
        assert!(matches!(
            eager.admit(status),
            Some(ProgressLine::Status(t)) if t == "solve: iteration 3, residual 5.000e-1"
        ));
    }
}
