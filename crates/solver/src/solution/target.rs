//! Solving until the self-check says the answer is good enough: a hierarchy refined further
//! from where it is (nothing thrown away), or a dense mesh made finer, until the upper end of
//! the estimate's interval on the smooth RMS error is at most the target, or time runs out.

use super::pipeline::Solved;
use super::request::{SolveError, SolveRequest, starting_mesh};
use super::session::Session;
use crate::Progress;
use crate::check::{CheckSettings, Estimate};
use crate::hierarchy::HierarchySettings;
use crate::mesh::PatchTarget;
use crate::scene::Scene;
use serde::Serialize;
use std::time::Instant;

/// What `--target-error` asks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    /// The smooth RMS error (relative) the self-check's upper bound must reach.
    pub error: f64,
    /// Seconds the whole solve may take, about: a step is not started when the time spent
    /// plus the last step's would pass it.
    pub seconds: Option<f64>,
}

/// How a solve to a target went.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetReport {
    /// The error asked for.
    pub error: f64,
    /// Whether the last step's upper bound reached it.
    pub reached: bool,
    /// Why refinement stopped: `reached`, `time limit`, `finest knob` (the `--error` floor),
    /// `budget` (leaves or links) or `matrix limit` (a finer dense mesh does not fit).
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
    /// Patches (leaves) solved for.
    pub patches: usize,
    /// Seconds since the start when this step's check ended.
    pub seconds: f64,
    /// The estimated smooth RMS error.
    pub rms: f64,
    /// The upper end of its interval.
    pub high: f64,
}

/// The knob a hierarchical solve to a target starts at: coarse (the monastery piece is 3.4%
/// smooth RMS at 0.5), and halved at each step down to the `--error` floor.
pub const STARTING_KNOB: f64 = 0.4;

/// Solves `scene` as `request` says (its `--error` the finest knob, its `--patches` the
/// coarsest dense mesh), then refines until `target` is reached; every step's answer is
/// self-checked, and the last is returned with its estimate in the report.
pub fn solve_to_target(
    scene: Scene,
    request: &SolveRequest,
    target: &Target,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<(Solved, TargetReport), SolveError> {
    let (request, chosen) = &request.for_scene(&scene);
    if let Some(text) = chosen {
        progress(Progress::Notice { text });
    }
    let mut run = Run {
        target,
        clock: Instant::now(),
        report: TargetReport {
            error: target.error,
            reached: false,
            stopped: "reached",
            steps: Vec::new(),
        },
        progress,
    };
    let solved = match request.hierarchy {
        Some(settings) => run.hierarchical(scene, request, settings)?,
        None => run.dense(scene, request)?,
    };
    Ok((solved, run.report))
}

/// One solve to a target under way.
struct Run<'a> {
    target: &'a Target,
    clock: Instant,
    report: TargetReport,
    progress: &'a (dyn Fn(Progress) + Sync),
}

impl Run<'_> {
    /// Records a step checked as `estimate`; `Some(why)` when refinement stops here.
    fn step(
        &mut self,
        knob: Option<f64>,
        patches: usize,
        estimate: &Estimate,
    ) -> Option<&'static str> {
        let seconds = self.clock.elapsed().as_secs_f64();
        let last = self.report.steps.last().map_or(0.0, |s| s.seconds);
        self.report.steps.push(TargetStep {
            knob,
            patches,
            seconds,
            rms: estimate.smooth.rms,
            high: estimate.smooth.high,
        });
        if estimate.smooth.high <= self.target.error {
            self.report.reached = true;
            return Some("reached");
        }
        let step_seconds = seconds - last;
        self.target
            .seconds
            .filter(|limit| seconds + step_seconds > *limit)
            .map(|_| "time limit")
    }

    fn say_finer(&self, estimate: &Estimate, finer: &str) {
        let text = format!(
            "self-check: {:.1}% smooth RMS (up to {:.1}%), target {:.1}%: {finer}",
            100.0 * estimate.smooth.rms,
            100.0 * estimate.smooth.high,
            100.0 * self.target.error
        );
        (self.progress)(Progress::Notice { text: &text });
    }

    /// From [`STARTING_KNOB`] down to the request's knob, halving, refining the same hierarchy.
    fn hierarchical(
        &mut self,
        scene: Scene,
        request: &SolveRequest,
        settings: HierarchySettings,
    ) -> Result<Solved, SolveError> {
        let finest = settings.error;
        let mut knob = STARTING_KNOB.max(finest);
        let first = SolveRequest {
            hierarchy: Some(HierarchySettings {
                error: knob,
                ..settings
            }),
            ..*request
        };
        let mesh = starting_mesh(&scene, &first)?;
        let mut session = Session::start(&scene, &mesh, &first, self.progress)?;
        loop {
            let mut report = session.solve(self.progress);
            let estimate = session.self_check(&CheckSettings::after_solve(report.seconds.total));
            report.estimate = Some(estimate);
            // The knob refinement ended at: coarser than asked where a budget made it so.
            let used = report.hierarchy.map_or(knob, |h| h.knob_used);
            let stop = self
                .step(Some(used), report.patches, &estimate)
                .or((knob <= finest).then_some("finest knob"));
            if let Some(why) = stop {
                self.report.stopped = why;
                return Ok(Solved::kept(scene, session, report));
            }
            let next = (knob / 2.0).max(finest);
            self.say_finer(&estimate, &format!("refining on at error {next}"));
            let (refined, changed) = session.refine_further(next, self.progress)?;
            session = refined;
            if !changed {
                self.report.stopped = "budget";
                return Ok(Solved::kept(scene, session, report));
            }
            knob = next;
        }
    }

    /// From the request's patches, doubling, each mesh solved afresh: a dense solve costs the
    /// square of its patches, so the coarser ones add at most a third to the last.
    fn dense(&mut self, scene: Scene, request: &SolveRequest) -> Result<Solved, SolveError> {
        let mut request = *request;
        let mut solved = checked(super::pipeline::solve_scene(
            scene.clone(),
            &request,
            self.progress,
        )?);
        loop {
            let estimate = solved.report.estimate.expect("checked");
            if let Some(why) = self.step(None, solved.report.patches, &estimate) {
                self.report.stopped = why;
                return Ok(solved);
            }
            request.patches = match request.patches {
                PatchTarget::Count(n) => PatchTarget::Count(2 * n),
                PatchTarget::EdgeLength(l) => PatchTarget::EdgeLength(l / std::f64::consts::SQRT_2),
            };
            let finer = match request.patches {
                PatchTarget::Count(n) => format!("solving again on {n} patches"),
                PatchTarget::EdgeLength(l) => format!("solving again with patches of {l:.4}"),
            };
            self.say_finer(&estimate, &finer);
            match super::pipeline::solve_scene(scene.clone(), &request, self.progress) {
                Ok(finer) => solved = checked(finer),
                Err(SolveError::TooLarge { .. }) => {
                    self.report.stopped = "matrix limit";
                    return Ok(solved);
                }
                Err(other) => return Err(other),
            }
        }
    }
}

/// `solved` with its self-check in the report.
fn checked(mut solved: Solved) -> Solved {
    solved.report.estimate = Some(crate::check::self_check(
        &solved.scene,
        &crate::visibility::Occluders::new(&solved.scene),
        &solved.mesh,
        (&solved.radiosity, &solved.vertex_radiosity),
        &CheckSettings::after_solve(solved.report.seconds.total),
    ));
    solved
}
