//! The radiosity solver of radcast: scene in, radiosity per patch out. No networking.
//!
//! The flow is [`scene`] (OBJ + MTL) -> [`mesh`] (patches) -> [`form_factors`] (with
//! [`visibility`]) -> [`solve`]; [`pipeline`] runs it end to end with timings.

pub mod accuracy;
#[cfg(feature = "clap")]
pub mod args;
pub mod form_factors;
pub mod gather;
pub mod generate;
pub mod geometry;
pub mod hierarchy;
pub mod mesh;
pub mod pair;
pub mod pipeline;
pub mod reference;
pub mod sampling;
pub mod scene;
pub mod session;
pub mod solve;
pub mod transport;
pub mod visibility;

pub use form_factors::DenseFormFactors;
pub use hierarchy::{HierarchySettings, HierarchyStats};
pub use mesh::{Mesh, Patch, PatchTarget};
pub use pair::FormFactorSettings;
pub use pipeline::{
    MethodChoice, SolveError, SolveReport, SolveRequest, Solved, solve_file, solve_mesh,
    solve_scene,
};
pub use scene::{Material, Rgb, Scene, SceneError, View};
pub use session::{EditError, MoveReport, MoveWork, Session};
pub use solve::{Method, SolveOutcome, SolverSettings, System, solve};
pub use transport::{Entries, Transport};

/// Where a long computation is, for progress displays and progressive streaming.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Progress<'a> {
    /// Form-factor rows done out of total (two passes over every row).
    FormFactors {
        /// Rows finished.
        done: usize,
        /// Rows in all.
        total: usize,
    },
    /// Reference probes finished out of total.
    Probes {
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
    /// The solver's current estimate, between iterations (at GMRES restarts).
    Estimate {
        /// Radiosity per patch, W/m^2; not yet converged.
        radiosity: &'a [Rgb],
    },
}

/// A progress sink that ignores everything.
pub fn no_progress(_: Progress) {}
