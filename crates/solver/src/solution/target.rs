//! Solving until the self-check says the answer is good enough: a hierarchy refined further
//! from where it is (nothing thrown away), or a dense mesh made finer, until the upper end of
//! the estimate's interval on the smooth RMS error is at most the target, or time runs out.

use super::report::{SolveReport, TargetReport, TargetStep};
use super::request::{SolveError, SolveRequest, Target, starting_mesh};
use super::session::Session;
use crate::Progress;
use crate::check::CheckSettings;
use crate::hierarchy::HierarchySettings;
use crate::mesh::PatchTarget;
use crate::scene::Scene;
use std::time::Instant;

/// The knob a hierarchical solve to a target starts at, halved at each step down to the
/// `--error` floor: the one large models' link budget brings refinement to anyway, so a
/// model that meets the target there pays for no finer leaves. Measured against 0.4 with the
/// default target (docs/BENCHMARKS.md): the monastery piece 12.5 -> 8.7 s (one step, 1.75 ->
/// 1.95% smooth RMS), the furnished room 75 -> 57 s (two steps, 3.04 -> 3.78%), the
/// monastery 36.4 -> 34.9 s (the budget's knob either way); the teddy bear and the Cornell
/// box take a second step (4.3 -> 5.3 s, 3.06 -> 2.30%; 0.05 -> 0.09 s).
pub const STARTING_KNOB: f64 = 0.8;

/// The least share of leaves a hierarchical step must add to the last for another to follow:
/// below it the budget has stopped refinement in all but name (the knob it asks is coarsened
/// back to the last one's) and a further step solves and gathers the same mesh again. The
/// furnished room's third step added 0.3% (269,989 -> 270,829 leaves, knob 0.8 each time) and
/// read 3.01% against 2.97%, its fourth 3.15%, 26 s each (docs/BENCHMARKS.md).
const MIN_LEAF_GROWTH_PERCENT: usize = 1;

/// Links a face may make at each level of the cluster tree in the first step of a
/// hierarchical solve to a target ([`coarse_link_budget`]). With clusters a face gathers from
/// a few clusters at each level of the tree, so links grow as `n log2 n` (Smits, Arvo,
/// Greenberg 1994); past that the first step keeps its pairs as they are, each on a sampled
/// factor, and the corners' gathers carry the answer (docs/BENCHMARKS.md). Measured with the
/// default target (faces counted after loading's cuts; seeds 0-2): the monastery piece (9,455
/// faces, a budget of 1.0M) 14.6 -> 4.8 s, 1.97 -> 3.41% smooth RMS, its first step within
/// the target (at 6, 4.0 s and 3.5%; from 9.4 up the budget no longer stops it). From 5.6 up
/// the furnished room's (107,689 faces), the monastery's and the village's budgets are over
/// `--max-links`' 10M, and at 8 neither the teddy bear nor the Cornell box meets its own:
/// all solve as before.
const COARSE_LINKS_PER_FACE_LEVEL: f64 = 8.0;

/// Solves toward `target` from the coarsest step, for a caller that keeps the session (the
/// server; [`super::pipeline::solve_scene`] for one that does not): `request` has its
/// method chosen already; `on_step` sees each step's solved session (its leaves or mesh, its
/// radiosity) before the check decides whether another follows.
pub fn session_to_target(
    scene: &Scene,
    request: &SolveRequest,
    target: &Target,
    progress: &(dyn Fn(Progress) + Sync),
    on_step: &mut dyn FnMut(&Session),
) -> Result<(Session, SolveReport), SolveError> {
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
        on_step,
    };
    let (session, mut report) = match request.hierarchy {
        Some(settings) => run.hierarchical(scene, request, settings)?,
        None => run.dense(scene, request)?,
    };
    report.target = Some(run.report);
    Ok((session, report))
}

/// One solve to a target under way.
struct Run<'a> {
    target: &'a Target,
    clock: Instant,
    report: TargetReport,
    progress: &'a (dyn Fn(Progress) + Sync),
    on_step: &'a mut dyn FnMut(&Session),
}

impl Run<'_> {
    /// Solves and checks `session`'s step; `Some(why)` when refinement stops here.
    fn step(
        &mut self,
        session: &mut Session,
        knob: Option<f64>,
    ) -> (SolveReport, Option<&'static str>) {
        let mut report = session.solve(self.progress);
        (self.on_step)(session);
        let estimate = session.self_check(
            &CheckSettings::after_solve(report.seconds.total),
            self.progress,
        );
        report.estimate = Some(estimate);
        // The knob refinement ended at: coarser than asked where a budget made it so.
        let knob = knob.map(|k| report.hierarchy.map_or(k, |h| h.knob_used));
        let seconds = self.clock.elapsed().as_secs_f64();
        let last = self.report.steps.last().map_or(0.0, |s| s.seconds);
        self.report.steps.push(TargetStep {
            knob,
            max_links: session.link_budget(),
            patches: report.patches,
            seconds,
            rms: estimate.smooth.rms,
            high: estimate.smooth.high,
        });
        if estimate.smooth.high <= self.target.error {
            self.report.reached = true;
            return (report, Some("reached"));
        }
        let step_seconds = seconds - last;
        let late = self
            .target
            .seconds
            .filter(|limit| seconds + step_seconds > *limit)
            .map(|_| "time limit");
        (report, late)
    }

    fn say_finer(&self, report: &SolveReport, finer: &str) {
        let Some(estimate) = report.estimate else {
            return;
        };
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
        scene: &Scene,
        request: &SolveRequest,
        settings: HierarchySettings,
    ) -> Result<(Session, SolveReport), SolveError> {
        let finest = settings.error;
        let mut knob = STARTING_KNOB.max(finest);
        let first = SolveRequest {
            hierarchy: Some(HierarchySettings {
                error: knob,
                max_links: coarse_link_budget(scene.faces.len(), settings.max_links),
                ..settings
            }),
            ..*request
        };
        let mut session = Session::hierarchical(scene, &first, self.progress)?;
        loop {
            let (report, stop) = self.step(&mut session, Some(knob));
            // Past the first step, the whole link budget; a first step it stopped goes on at
            // the same knob.
            let raise = session.link_budget() < Some(settings.max_links);
            let again = raise && session.stopped_at_link_budget();
            let budget = (!again
                && (!session.can_refine_further() || added_little(&self.report.steps)))
            .then_some("budget");
            if let Some(why) = stop
                .or((!again && knob <= finest).then_some("finest knob"))
                .or(budget)
            {
                self.report.stopped = why;
                return Ok((session, report));
            }
            let (next, finer) = match again {
                true => (
                    knob,
                    format!("refining on with up to {} links", settings.max_links),
                ),
                false => {
                    let next = (knob / 2.0).max(finest);
                    (next, format!("refining on at error {next}"))
                }
            };
            if raise {
                session.raise_link_budget(settings.max_links);
            }
            self.say_finer(&report, &finer);
            let (refined, changed) = session.refine_further(next, self.progress)?;
            session = refined;
            if !changed {
                self.report.stopped = "budget";
                return Ok((session, report));
            }
            knob = next;
        }
    }

    /// From the request's patches, doubling, each mesh solved afresh: a dense solve costs the
    /// square of its patches, so the coarser ones add at most a third to the last.
    fn dense(
        &mut self,
        scene: &Scene,
        request: &SolveRequest,
    ) -> Result<(Session, SolveReport), SolveError> {
        let mut request = *request;
        let mesh = starting_mesh(scene, &request)?;
        let mut session = Session::start(scene, &mesh, &request, self.progress)?;
        loop {
            let (report, stop) = self.step(&mut session, None);
            if let Some(why) = stop {
                self.report.stopped = why;
                return Ok((session, report));
            }
            request.patches = match request.patches {
                PatchTarget::Count(n) => PatchTarget::Count(2 * n),
                PatchTarget::EdgeLength(l) => PatchTarget::EdgeLength(l / std::f64::consts::SQRT_2),
            };
            let finer = match request.patches {
                PatchTarget::Count(n) => format!("solving again on {n} patches"),
                PatchTarget::EdgeLength(l) => format!("solving again with patches of {l:.4}"),
            };
            self.say_finer(&report, &finer);
            let finer = starting_mesh(scene, &request)
                .and_then(|mesh| Session::start(scene, &mesh, &request, self.progress));
            match finer {
                Ok(finer) => session = finer,
                Err(SolveError::TooLarge { .. }) => {
                    self.report.stopped = "matrix limit";
                    return Ok((session, report));
                }
                Err(other) => return Err(other),
            }
        }
    }
}

/// The first step's link budget on a scene of `faces` faces: [`COARSE_LINKS_PER_FACE_LEVEL`]
/// a face and level of the cluster tree (`log2 faces` levels), at most `max_links`.
fn coarse_link_budget(faces: usize, max_links: usize) -> usize {
    let faces = faces.max(2) as f64;
    ((COARSE_LINKS_PER_FACE_LEVEL * faces * faces.log2()) as usize).min(max_links)
}

/// Whether the last of `steps` has less than [`MIN_LEAF_GROWTH_PERCENT`] per cent more leaves
/// than the one before it (counted in integers: the bound itself is exact).
fn added_little(steps: &[TargetStep]) -> bool {
    match steps {
        [.., before, last] => last.patches * 100 < before.patches * (100 + MIN_LEAF_GROWTH_PERCENT),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::{TargetStep, added_little, coarse_link_budget};

    fn step(patches: usize) -> TargetStep {
        TargetStep {
            knob: Some(0.8),
            max_links: Some(10_000_000),
            patches,
            seconds: 1.0,
            rms: 0.05,
            high: 0.07,
        }
    }

    #[test]
    fn a_step_stops_the_run_when_it_adds_under_one_percent_more_leaves() {
        // The furnished room's steps: 199,903, then 269,989 (+35%: on), then 270,829 (+0.3%).
        assert!(!added_little(&[step(199_903)]), "one step says nothing");
        assert!(!added_little(&[step(199_903), step(269_989)]));
        assert!(added_little(&[step(199_903), step(269_989), step(270_829)]));
        assert!(added_little(&[step(1000), step(1009)]));
        assert!(
            !added_little(&[step(1000), step(1010)]),
            "1% exactly is enough"
        );
    }

    #[test]
    fn the_first_steps_links_grow_as_faces_times_the_trees_depth_up_to_the_budget() {
        // Twice the faces, one level more.
        for faces in [1 << 10, 1 << 14] {
            let ratio = coarse_link_budget(2 * faces, usize::MAX) as f64
                / coarse_link_budget(faces, usize::MAX) as f64;
            let levels = (faces as f64).log2();
            assert!(
                (ratio - 2.0 * (levels + 1.0) / levels).abs() < 1e-6,
                "{ratio}"
            );
        }
        assert_eq!(coarse_link_budget(1 << 20, 10_000_000), 10_000_000);
        // A scene of one face (or none) still links.
        assert!(coarse_link_budget(0, 10_000_000) > 0);
        assert_eq!(
            coarse_link_budget(1, 10_000_000),
            coarse_link_budget(2, 10_000_000)
        );
    }
}
