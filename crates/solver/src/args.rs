//! The solve settings as command-line flags, one definition for the `radcast` command and the
//! server (with the `clap` feature): each flag also reads an environment variable, and
//! [`SolveArgs::request`] checks every value once, naming the flag that is wrong.

use crate::hierarchy::{HierarchySettings, HierarchyStats};
use crate::mesh::PatchTarget;
use crate::pair::{FormFactorSettings, MAX_RAYS_PER_PAIR};
use crate::sampling::Seed;
use crate::solution::request::{DEFAULT_PATCHES, MethodChoice, SolveRequest, Target};
use crate::solve::SolverSettings;

/// Everything that decides a solution besides the scene, as flags.
#[derive(clap::Args, Clone, Debug)]
pub struct SolveArgs {
    /// Mesh, form factors and solver.
    #[command(flatten)]
    pub solver: SolverArgs,
    /// The hierarchical method's knob and budget.
    #[command(flatten)]
    pub hierarchy: HierarchyArgs,
    /// The self-check and the error it steers the solve to.
    #[command(flatten)]
    pub check: CheckArgs,
}

/// `--check`, `--target-error` and `--time-limit`.
#[derive(clap::Args, Clone, Debug)]
pub struct CheckArgs {
    /// After the solve (and on the server after each move), estimate the error of what
    /// viewers see against probes path-traced for it: 64 to 4,096 probes x 1,024 paths, as
    /// many as a tenth of the solve's time allows, a seed of their own (`estimate` in the JSON
    /// and in /api/solution, /metrics gauges, /healthz degraded past 5%). `off` skips it, and
    /// with it the default target.
    #[arg(long, env = "RADCAST_CHECK", value_enum, default_value_t = Check::On)]
    pub check: Check,
    /// Refine until the self-check's upper bound on the smooth RMS error is at most this
    /// (0.05 for 5%): a hierarchy from a coarse knob (0.8), halved each step down to --error,
    /// refined from where it is, until a step adds under 1% more leaves (the first step makes
    /// at most 8 n log2 n links for n faces, within --max-links, and goes on under
    /// --max-links where that stopped it short of the target); a dense mesh solved
    /// again at twice --patches each step. Says where it stopped and why (`target` in the
    /// JSON). The default, 0.05, holds while the check is on and no --patches, --patch-size
    /// or --error fixes the resolution; `off` solves once at the resolution asked.
    #[arg(long, env = "RADCAST_TARGET_ERROR", value_parser = parse_target_error)]
    pub target_error: Option<TargetError>,
    /// Seconds a solve to a target may take, about (a step is not started when the time spent
    /// plus the last step's would pass it).
    #[arg(long, env = "RADCAST_TIME_LIMIT")]
    pub time_limit: Option<f64>,
}

/// `--target-error`'s value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TargetError {
    /// No target: one solve at the resolution asked.
    Off,
    /// This relative smooth RMS error.
    At(f64),
}

/// `off`, or a number (checked for range by [`CheckArgs::target`], which names the flag).
fn parse_target_error(text: &str) -> Result<TargetError, String> {
    match text {
        "off" => Ok(TargetError::Off),
        _ => text
            .parse()
            .map(TargetError::At)
            .map_err(|_| format!("expected a number or `off`, got {text:?}")),
    }
}

impl CheckArgs {
    /// The target asked for, or the default one where the resolution is not `fixed` by a
    /// flag and the check is on; or the flag whose value is out of range or out of place.
    pub fn target(&self, fixed: bool) -> Result<Option<Target>, String> {
        let error = match (self.target_error, self.check) {
            (Some(TargetError::At(_)), Check::Off) => {
                return Err("--target-error needs the self-check: drop --check off".into());
            }
            (Some(TargetError::At(error)), Check::On) => Some(error),
            (None, Check::On) if !fixed => Some(Target::default().error),
            (Some(TargetError::Off), _) | (None, _) => None,
        };
        if let Some(error) = error.filter(|e| !(*e > 0.0 && *e < 1.0)) {
            return Err(format!("--target-error must be in (0, 1), got {error}"));
        }
        if let Some(limit) = self.time_limit.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(format!(
                "--time-limit must be a positive number of seconds, got {limit}"
            ));
        }
        match error {
            None if self.time_limit.is_some() => Err("--time-limit bounds a solve to a \
                target: give --target-error (no target is set by default once --patches, \
                --patch-size or --error fixes the resolution, or with --check off)"
                .into()),
            None => Ok(None),
            Some(error) => Ok(Some(Target {
                error,
                seconds: self.time_limit,
            })),
        }
    }
}

/// The mesh, form-factor and solver flags: all of [`SolveArgs`] but the hierarchy's.
#[derive(clap::Args, Clone, Debug)]
pub struct SolverArgs {
    /// Target number of patches (dense methods) [default: 1000; given, it fixes the
    /// resolution: no default --target-error].
    #[arg(long, env = "RADCAST_PATCHES", conflicts_with = "patch_size")]
    pub patches: Option<usize>,
    /// Target patch edge length in scene units (instead of --patches).
    #[arg(long, env = "RADCAST_PATCH_SIZE")]
    pub patch_size: Option<f64>,
    /// Solver on a uniform mesh with a dense matrix (jacobi, gauss-seidel, progressive, gmres),
    /// hierarchical: adaptive elements and links, solved with GMRES (--error sets accuracy), or
    /// auto: dense GMRES where --patches gives every face at least 4 patches and its matrix
    /// fits, hierarchical otherwise (said when it runs).
    #[arg(long, env = "RADCAST_METHOD", default_value = "auto")]
    pub method: MethodChoice,
    /// Stop when the relative residual is at most this.
    #[arg(long, env = "RADCAST_TOLERANCE", default_value_t = SolverSettings::default().tolerance)]
    pub tolerance: f64,
    /// Give up after this many iterations.
    #[arg(long, env = "RADCAST_MAX_ITERATIONS", default_value_t = SolverSettings::default().max_iterations)]
    pub max_iterations: usize,
    /// SOR relaxation factor for gauss-seidel, in (0, 2).
    #[arg(long, env = "RADCAST_OMEGA", default_value_t = SolverSettings::default().relaxation)]
    pub omega: f64,
    /// Shadow rays per far patch pair (near pairs get more).
    #[arg(long, env = "RADCAST_RAYS", default_value_t = FormFactorSettings::default().rays_per_pair)]
    pub rays: u32,
    /// Sample patterns of the gathers at corners and centroids: another seed shows the spread
    /// their sampling leaves in the answer.
    #[arg(long, env = "RADCAST_SEED", default_value_t = 0)]
    pub seed: u64,
}

/// The hierarchical method's flags.
#[derive(clap::Args, Clone, Debug)]
pub struct HierarchyArgs {
    /// With --method hierarchical: the relative error a link may carry; smaller refines more
    /// [default: 0.03; given, it fixes the resolution: no default --target-error; with one,
    /// the finest knob a solve to it may reach].
    #[arg(long, env = "RADCAST_ERROR")]
    pub error: Option<f64>,
    /// With --method hierarchical: leaves at most (bounds memory, about 2.3 KB a leaf)
    /// [default: 500000, or 2 a face of the scene where that is more]; the JSON says
    /// `leaf_budget_reached` when refinement stopped there.
    #[arg(long, env = "RADCAST_MAX_LEAVES")]
    pub max_leaves: Option<usize>,
    /// With --method hierarchical: links at most, about (bounds memory where links per leaf
    /// run high, about 250 bytes a link); the JSON says `link_budget_reached` when refinement
    /// stopped there.
    #[arg(long, env = "RADCAST_MAX_LINKS", default_value_t = HierarchySettings::default().max_links)]
    pub max_links: usize,
}

/// Whether a solve checks its answer (see [`crate::check`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Check {
    /// Estimate the error against probes path-traced for it, after the solve.
    On,
    /// Skip the check.
    Off,
}

impl SolveArgs {
    /// The request these flags ask for, or the first flag whose value is out of range.
    pub fn request(&self) -> Result<SolveRequest, String> {
        let fixed = self.solver.patches.is_some()
            || self.solver.patch_size.is_some()
            || self.hierarchy.error.is_some();
        Ok(SolveRequest {
            target: self.check.target(fixed)?,
            ..self.solver.request(self.hierarchy.settings()?)?
        })
    }

    /// Whether the solve is to be checked ([`CheckArgs::check`]).
    pub fn checked(&self) -> bool {
        self.check.check == Check::On
    }
}

impl HierarchyArgs {
    /// The hierarchy's settings, or the first flag whose value is out of range.
    pub fn settings(&self) -> Result<HierarchySettings, String> {
        let error = self.error.unwrap_or(HierarchySettings::default().error);
        if !(error > 0.0 && error < 1.0) {
            return Err(format!("--error must be in (0, 1), got {error}"));
        }
        if self.max_leaves == Some(0) {
            return Err("--max-leaves must be at least 1".into());
        }
        if self.max_links == 0 {
            return Err("--max-links must be at least 1".into());
        }
        let default = HierarchySettings::default();
        // A budget asked for holds as it is; the default one is fitted to the scene.
        let (max_leaves, leaves_per_face) = match self.max_leaves {
            Some(asked) => (asked, 0),
            None => (default.max_leaves, default.leaves_per_face),
        };
        Ok(HierarchySettings {
            error,
            max_leaves,
            leaves_per_face,
            max_links: self.max_links,
            ..default
        })
    }
}

impl SolverArgs {
    /// The request these flags ask for, solved hierarchically with `hierarchy` if the method
    /// says so; or the first flag whose value is out of range.
    pub fn request(&self, hierarchy: HierarchySettings) -> Result<SolveRequest, String> {
        let patches = match self.patch_size {
            Some(size) if size.is_finite() && size > 0.0 => PatchTarget::EdgeLength(size),
            Some(size) => {
                return Err(format!(
                    "--patch-size must be a positive length, got {size}"
                ));
            }
            None => match self.patches.unwrap_or(DEFAULT_PATCHES) {
                0 => return Err("--patches must be at least 1".into()),
                count => PatchTarget::Count(count),
            },
        };
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(format!(
                "--tolerance must be in (0, 1), got {}",
                self.tolerance
            ));
        }
        if self.max_iterations == 0 {
            return Err("--max-iterations must be at least 1".into());
        }
        if !(self.omega > 0.0 && self.omega < 2.0) {
            return Err(format!("--omega must be in (0, 2), got {}", self.omega));
        }
        if self.rays == 0 || self.rays > MAX_RAYS_PER_PAIR {
            return Err(format!(
                "--rays must be in 1..={MAX_RAYS_PER_PAIR}, got {}",
                self.rays
            ));
        }
        let request = SolveRequest {
            patches,
            form_factors: FormFactorSettings {
                rays_per_pair: self.rays,
            },
            solver: SolverSettings {
                tolerance: self.tolerance,
                max_iterations: self.max_iterations,
                relaxation: self.omega,
                ..SolverSettings::default()
            },
            seed: Seed(self.seed),
            ..SolveRequest::default()
        };
        Ok(request.with_method(self.method, hierarchy))
    }
}

/// What the user who asked for `asked` should be told about the leaf budget after a
/// hierarchical solve: that the knob was coarsened to fit it, or that refinement stopped at it
/// (in the flags' words, as both commands spell them).
pub fn budget_warnings(asked: &HierarchySettings, stats: &HierarchyStats) -> Vec<String> {
    let mut warnings = Vec::new();
    if stats.knob_used > asked.error {
        warnings.push(format!(
            "--error {} needs more than --max-leaves {} leaves or --max-links {} links here; refinement went on at --error {} where it would have passed them",
            asked.error, asked.max_leaves, asked.max_links, stats.knob_used
        ));
    }
    if stats.leaf_budget_reached {
        warnings.push(format!(
            "element splits stopped at {} leaves, where the next ones would have passed \
             --max-leaves {} even at --error {}; some links carry more error than that",
            stats.elements, asked.max_leaves, stats.knob_used
        ));
    }
    if stats.link_budget_reached {
        let left = match stats.deferred_pairs {
            0 => "some carry more error than that".to_string(),
            pairs => format!(
                "the {pairs} pairs still to decide were left to the corners' own gathers \
                 (the patches' own system lacks their light)"
            ),
        };
        warnings.push(format!(
            "links stopped splitting at {} links, where splitting the pairs still to decide would have passed \
             --max-links {} even at --error {}; {left}",
            stats.links, asked.max_links, stats.knob_used
        ));
    }
    warnings
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Command {
        #[command(flatten)]
        solve: SolveArgs,
    }

    fn parse(flags: &[&str]) -> SolveArgs {
        Command::parse_from([&["radcast"], flags].concat()).solve
    }

    #[test]
    fn defaults_ask_for_the_library_defaults_with_the_method_chosen_from_the_scene() {
        let request = parse(&[]).request().expect("defaults are valid");
        let library =
            SolveRequest::default().with_method(MethodChoice::Auto, HierarchySettings::default());
        assert_eq!(
            request,
            SolveRequest {
                target: Some(Target::default()),
                ..library
            }
        );
        assert!(request.auto);
        // Asked for as they are, the defaults fix the resolution: one solve at it.
        let fixed = parse(&["--patches", "1000", "--error", "0.03"]).request();
        assert_eq!(fixed, Ok(library));
    }

    #[test]
    fn every_out_of_range_value_names_its_flag() {
        for (flags, message) in [
            (&["--error", "1"][..], "--error must be in (0, 1), got 1"),
            (&["--max-leaves", "0"], "--max-leaves must be at least 1"),
            (&["--patches", "0"], "--patches must be at least 1"),
            (
                &["--patch-size=-2"],
                "--patch-size must be a positive length, got -2",
            ),
            (
                &["--tolerance", "NaN"],
                "--tolerance must be in (0, 1), got NaN",
            ),
            (
                &["--max-iterations", "0"],
                "--max-iterations must be at least 1",
            ),
            (&["--omega", "2"], "--omega must be in (0, 2), got 2"),
            (&["--rays", "65"], "--rays must be in 1..=64, got 65"),
        ] {
            assert_eq!(
                parse(flags).request(),
                Err(message.to_string()),
                "{flags:?}"
            );
        }
    }

    #[test]
    fn the_hierarchical_method_carries_its_knob_and_budget() {
        let request = parse(&[
            "--method",
            "hierarchical",
            "--error",
            "0.1",
            "--max-leaves",
            "9",
        ])
        .request()
        .expect("valid");
        let hierarchy = request.hierarchy.expect("hierarchical");
        assert_eq!((hierarchy.error, hierarchy.max_leaves), (0.1, 9));
        // Asked for, the budget is not fitted to the scene's faces.
        assert_eq!(hierarchy.leaves_per_face, 0);
    }
}
