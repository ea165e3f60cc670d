//! The solver thread: the first solve (or a proven cache entry), then edits as they come, each
//! publishing one new version. Faults are reported through [`crate::health`], never swallowed:
//! a refused edit or a failed cache write degrades `/healthz`, and a solver that stops says why.

use super::cache::{self, CachedSolution, Rejected};
use super::prepare::Prepared;
use super::to_wire::{
    ResponseIds, emission_only, estimate_for_viewers, geometry_of, report_for_viewers, to_f32,
};
use crate::Shared;
use crate::health::Fault;
use solver::check::{CheckSettings, Estimate};
use solver::{MoveWork, Progress, ProgressLine, ProgressThrottle, Rgb, Session};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use wire::summary::SolveReport;

/// Progressive frames are published at most this often while the solver iterates.
const SNAPSHOT_INTERVAL: Duration = Duration::from_millis(100);

/// Progress of a long solve in the log: a line at most every [`PROGRESS_LOG_INTERVAL`],
/// warnings (a coarser knob than asked) always.
struct ProgressLog(ProgressThrottle);

impl Default for ProgressLog {
    fn default() -> Self {
        ProgressLog(ProgressThrottle::new(PROGRESS_LOG_INTERVAL))
    }
}

/// How often a long solve logs where it is.
const PROGRESS_LOG_INTERVAL: Duration = Duration::from_secs(2);

impl ProgressLog {
    fn report(&self, progress: Progress) {
        match self.0.admit(progress) {
            Some(ProgressLine::Warning(line)) => tracing::warn!("{line}"),
            Some(ProgressLine::Status(line) | ProgressLine::Notice(line)) => {
                tracing::info!("{line}")
            }
            None => {}
        }
    }
}

/// Starts the solver thread: [`solve_and_publish`], then [`serve_edits`] until
/// [`crate::control::edits::Edits::close`]. An error or a panic in it is reported as
/// [`Fault::SolverStopped`]; viewers keep the last published version. A plain thread, not
/// tokio's blocking pool, so that shutdown never waits for a long solve.
pub fn start(
    prepared: Prepared,
    shared: Arc<Shared>,
    cache_dir: Option<PathBuf>,
) -> std::thread::JoinHandle<()> {
    std::thread::Builder::new()
        .name("solver".into())
        .spawn(move || {
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                let base = solve_and_publish(&prepared, &shared, cache_dir.as_deref())?;
                serve_edits(&prepared, &shared, base)
            }));
            let reason = match run {
                Ok(Ok(())) => return,
                Ok(Err(error)) => format!("{error:#}"),
                Err(panic) => panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "a panic".into()),
            };
            shared.health.fault(
                Fault::SolverStopped,
                format!(
                    "the solver stopped ({reason}): serving the last solution, edits are refused"
                ),
            );
        })
        .expect("a thread for the solver")
}

/// What the first solve leaves for later edits: the live session, or (after a cache hit) the
/// cached radiosity to warm-start one from when the first edit arrives.
pub enum EditBase {
    /// Form factors in memory.
    Live(Box<Session>),
    /// Read from the cache; form factors not computed yet.
    Cached(Vec<[f32; 3]>),
}

/// Solves (or reads the cache), publishing progressive frames and then the final one.
/// Blocking: run it on a blocking thread.
pub fn solve_and_publish(
    prepared: &Prepared,
    shared: &Shared,
    cache_dir: Option<&Path>,
) -> anyhow::Result<EditBase> {
    let hub = &shared.hub;
    if let Some(radiosity) = cache_dir.and_then(|dir| publish_cached(prepared, shared, dir)) {
        return Ok(EditBase::Cached(radiosity));
    }
    let log = ProgressLog::default();
    let (session, mut report) = match &prepared.request.target {
        Some(target) => steps_to_target(prepared, shared, &log, target)?,
        None => first_solve(prepared, shared, &log)?,
    };
    match &report.estimate {
        // A solve to a target checked its last step.
        Some(estimate) => judge(shared, estimate.smooth.rms, estimate.smooth.low),
        None if prepared.check => {
            report.estimate = Some(check(&session, shared, report.seconds.total));
        }
        None => {}
    }
    let radiosity = to_f32(session.radiosity());
    let vertex_radiosity = finite(to_f32(&session.vertex_radiosity()))?;
    let s = report.seconds;
    *shared.metrics.solve_seconds.lock().expect("metrics lock") = vec![
        ("mesh", s.mesh),
        ("form_factors", s.form_factors),
        ("solve", s.solve),
        ("total", s.total),
    ];
    tracing::info!(
        patches = report.patches,
        iterations = report.iterations,
        residual = report.residual,
        seconds = s.total,
        "solved"
    );
    if let (Some(asked), Some(stats)) = (&prepared.request.hierarchy, &report.hierarchy) {
        solver::args::budget_warnings(asked, stats)
            .iter()
            .for_each(|warning| tracing::warn!("{warning}"));
    }
    report_convergence(shared, &report);
    let report = report_for_viewers(&report);
    let report_json = serde_json::to_string(&report)?;
    let converged = report.converged;
    // The report goes in before the final frame: a viewer that sees "final" may ask for it at once.
    *shared.report.lock().expect("report lock") = Some(report);
    // Final only when converged; an unconverged solution is served, never cached as an answer.
    hub.publish(&vertex_radiosity, converged);
    if let Some(dir) = cache_dir.filter(|_| converged) {
        let cached = CachedSolution {
            geometry: hub.geometry().encoded.to_vec(),
            radiosity,
            vertex_radiosity,
            report_json,
        };
        match cache::write(dir, &prepared.digest, &cached) {
            Ok(path) => {
                tracing::info!(path = %path.display(), "solution cached");
                shared.health.recovered(Fault::CacheWrite);
            }
            Err(error) => shared.health.fault(
                Fault::CacheWrite,
                format!("the solution was not cached ({error:#}): a restart solves again"),
            ),
        }
    }
    Ok(EditBase::Live(Box::new(session)))
}

/// The first solve at the settings asked, its progress served as frames that are not final.
fn first_solve(
    prepared: &Prepared,
    shared: &Shared,
    log: &ProgressLog,
) -> anyhow::Result<(Session, solver::SolveReport)> {
    let hub = &shared.hub;
    let mut session = prepared.session(&|p| log.report(p))?;
    if prepared.request.hierarchy.is_some() {
        // The leaves replace the input faces viewers have held while refinement ran.
        hub.replace_geometry(geometry_of(&prepared.scene, session.mesh()));
        hub.publish(&emission_only(session.mesh()), false);
    }
    let mesh = session.mesh().clone();
    let last_snapshot = Mutex::new(Instant::now());
    let progress = |p: Progress| {
        log.report(p);
        if let Progress::Estimate { radiosity } = p
            && let Ok(mut last) = last_snapshot.try_lock()
            && last.elapsed() >= SNAPSHOT_INTERVAL
        {
            *last = Instant::now();
            // Not final: the patches' means at the corners will do until the direct gather.
            hub.publish(&to_f32(&mesh.corner_means(&radiosity.read())), false);
        }
    };
    let report = session.solve(&progress);
    Ok((session, report))
}

/// Solves toward `target` ([`solver::session_to_target`]), serving each step's answer as it
/// comes, not final, with its leaves or mesh: viewers see the picture sharpen.
fn steps_to_target(
    prepared: &Prepared,
    shared: &Shared,
    log: &ProgressLog,
    target: &solver::Target,
) -> anyhow::Result<(Session, solver::SolveReport)> {
    let hub = &shared.hub;
    let mut publish_step = |session: &Session| {
        let geometry = geometry_of(&prepared.scene, session.mesh());
        if geometry != *hub.geometry().model {
            hub.replace_geometry(geometry);
        }
        if let Ok(values) = finite(to_f32(&session.vertex_radiosity())) {
            hub.publish(&values, false);
        }
    };
    Ok(solver::session_to_target(
        &prepared.scene,
        &prepared.request,
        target,
        &|p| log.report(p),
        &mut publish_step,
    )?)
}

/// Publishes `prepared`'s solution from the cache in `dir` when an entry proves to be this
/// scene's and intact; returns its patch radiosity for later edits.
fn publish_cached(prepared: &Prepared, shared: &Shared, dir: &Path) -> Option<Vec<[f32; 3]>> {
    let hub = &shared.hub;
    let path = cache::entry_path(dir, &prepared.digest);
    let entry = cache::read(dir, &prepared.digest).and_then(|(cached, geometry)| {
        serde_json::from_str::<SolveReport>(&cached.report_json)
            .map(|report| (cached, geometry, report))
            .map_err(|_| Rejected::Corrupt("its report does not parse"))
    });
    match entry {
        Ok((cached, geometry, report)) => {
            tracing::info!(path = %path.display(), "solution read from the cache");
            if let Some(estimate) = &report.estimate {
                judge(shared, estimate.smooth.rms, estimate.smooth.low);
            }
            *shared.report.lock().expect("report lock") = Some(report);
            if geometry != *hub.geometry().model {
                // A hierarchy's leaves, without refining again.
                hub.replace_geometry(geometry);
            }
            hub.publish(&cached.vertex_radiosity, true);
            Some(cached.radiosity)
        }
        Err(Rejected::Missing) => {
            tracing::info!(path = %path.display(), "no cached solution: solving");
            None
        }
        Err(why) => {
            tracing::warn!(path = %path.display(), "cache entry not used, {why}: solving again");
            None
        }
    }
}

/// Applies edits as they come until shutdown: each batch re-solves from the current answer
/// (form factors unchanged) and publishes one new version. Blocking.
pub fn serve_edits(prepared: &Prepared, shared: &Shared, base: EditBase) -> anyhow::Result<()> {
    let mut ids = ResponseIds::default();
    let session = match base {
        EditBase::Live(session) => *session,
        EditBase::Cached(radiosity) => {
            // Form factors are computed on the first edit only: a cached scene nobody edits
            // never pays for them.
            let Some(batch) = shared.edits.wait() else {
                return Ok(());
            };
            let log = ProgressLog::default();
            let mut session = prepared.session(&|p| log.report(p))?;
            let fresh = geometry_of(&prepared.scene, session.mesh());
            if fresh == *shared.hub.geometry().model {
                session.adopt_solution(
                    radiosity
                        .iter()
                        .map(|c| Rgb::new(c[0] as f64, c[1] as f64, c[2] as f64))
                        .collect(),
                );
            } else {
                // Refinement found other leaves than the cached ones (another build, another
                // machine's rounding): theirs are served from this edit on, solved afresh.
                tracing::warn!("the refined leaves differ from the cached ones: solving afresh");
                shared.hub.replace_geometry(fresh);
                session.solve(&solver::no_progress);
            }
            apply(&mut session, shared, batch, prepared.check, &mut ids)?;
            session
        }
    };
    edit_on(session, shared, prepared.check, ids)
}

/// Prepares the lights' responses (so that the first edit of a light is as fast as the rest,
/// and protocol-3 viewers can fetch them before it), then applies edits until shutdown.
fn edit_on(
    mut session: Session,
    shared: &Shared,
    check_moves: bool,
    mut ids: ResponseIds,
) -> anyhow::Result<()> {
    let iterations = session.prepare_emitters();
    offer_sum(&session, shared, &mut ids)?;
    tracing::info!(iterations, "emitter responses ready");
    while let Some(batch) = shared.edits.wait() {
        apply(&mut session, shared, batch, check_moves, &mut ids)?;
    }
    Ok(())
}

/// Gives the version viewers hold its sum of responses, once the session has them.
fn offer_sum(session: &Session, shared: &Shared, ids: &mut ResponseIds) -> anyhow::Result<()> {
    if let Some(terms) = ids.terms(session, &shared.hub) {
        let vertex_radiosity = finite(to_f32(&session.vertex_radiosity()))?;
        shared.hub.attach_sum(&vertex_radiosity, terms);
    }
    Ok(())
}

/// Applies one batch and publishes the result. An edit the solver refuses (a move that would
/// carry an object past the coordinate bound, say: each PUT was valid, their sum is not) is
/// reported as [`Fault::Edit`] while the rest of the batch is applied; a solve that gives
/// non-finite values is an error, and nothing of it is published. With `check_moves`, a batch
/// with a move is self-checked before its frame is published.
fn apply(
    session: &mut Session,
    shared: &Shared,
    batch: crate::control::edits::Batch,
    check_moves: bool,
    ids: &mut ResponseIds,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let mut refused = Vec::new();
    let moved = apply_moves(session, &batch, &mut refused);
    // The moved scene from the current answer, then its new geometry for viewers.
    let moved_report = moved.then(|| session.solve(&solver::no_progress));
    if moved {
        shared
            .hub
            .replace_geometry(geometry_of(session.scene(), session.mesh()));
    }
    let mut emitted = false;
    for (object, emission) in &batch.emissions {
        match session.set_emission(object, Rgb::from(*emission)) {
            Ok(()) => {
                emitted = true;
                let mut emissions = shared.emissions.lock().expect("emissions lock");
                if let Some(entry) = emissions.iter_mut().find(|(name, _)| name == object) {
                    entry.1 = *emission;
                }
            }
            Err(error) => refused.push(format!("the emission of '{object}' was refused: {error}")),
        }
    }
    // A batch of moves alone is solved already; emissions are summed onto it.
    let report = match moved_report {
        Some(report) if !emitted => report,
        _ => session.solve(&solver::no_progress),
    };
    let vertex_radiosity = finite(to_f32(&session.vertex_radiosity()))?;
    report_convergence(shared, &report);
    let mut served = report_for_viewers(&report);
    // A move is measured again before its frame goes out (the report and the frame travel
    // together, to edges too); emissions scale the light the last check measured and keep it.
    served.estimate = match moved {
        true if check_moves => Some(estimate_for_viewers(&check(
            session,
            shared,
            report.seconds.total,
        ))),
        true => None,
        false => shared
            .report
            .lock()
            .expect("report lock")
            .as_ref()
            .and_then(|r| r.estimate),
    };
    *shared.report.lock().expect("report lock") = Some(served);
    // Health before the frame: a viewer that sees the new version sees its health too.
    match refused.is_empty() {
        true => shared.health.recovered(Fault::Edit),
        false => shared.health.fault(Fault::Edit, refused.join("; ")),
    }
    let terms = ids.terms(session, &shared.hub);
    let version = shared
        .hub
        .publish_with_sum(&vertex_radiosity, report.converged, terms);
    tracing::info!(
        version,
        emissions = batch.emissions.len(),
        moves = batch.moves.len(),
        iterations = report.iterations,
        ms = started.elapsed().as_secs_f64() * 1e3,
        "re-solved"
    );
    shared.edits.finish_batch();
    if moved {
        // Keep the lights' next edits instant on the moved scene.
        session.prepare_emitters();
        offer_sum(session, shared, ids)?;
    }
    Ok(())
}

/// Applies the moves of `batch` in order; returns whether any was applied, and adds why to
/// `refused` for each the session refused.
fn apply_moves(
    session: &mut Session,
    batch: &crate::control::edits::Batch,
    refused: &mut Vec<String>,
) -> bool {
    let mut moved = false;
    for (object, motion) in batch
        .moves
        .iter()
        .flat_map(|(object, moves)| moves.iter().map(move |m| (object, *m)))
    {
        match session.move_object(object, motion) {
            Ok(report) => {
                moved = true;
                let ms = report.seconds * 1e3;
                match report.work {
                    MoveWork::Dense(work) => {
                        tracing::info!(object, work.pairs, work.entries, ms, "moved")
                    }
                    MoveWork::Rebuilt(hierarchy) => {
                        tracing::info!(object, hierarchy.elements, hierarchy.links, ms, "moved")
                    }
                }
            }
            Err(error) => refused.push(format!("the move of '{object}' was refused: {error}")),
        }
    }
    moved
}

/// The self-check of `session`'s answer after a solve of `solve_seconds`, logged, its
/// verdict in [`Fault::Inaccurate`].
fn check(session: &Session, shared: &Shared, solve_seconds: f64) -> Estimate {
    let estimate = session.self_check(
        &CheckSettings::after_solve(solve_seconds),
        &solver::no_progress,
    );
    tracing::info!(
        smooth_rms = estimate.smooth.rms,
        smooth_low = estimate.smooth.low,
        smooth_high = estimate.smooth.high,
        energy = estimate.smooth.energy,
        probes = estimate.probes,
        seconds = estimate.seconds,
        "self-check"
    );
    judge(shared, estimate.smooth.rms, estimate.smooth.low);
    estimate
}

/// `/healthz` degraded while the self-check says the answer served is bad
/// ([`solver::check::warning`]).
fn judge(shared: &Shared, smooth_rms: f64, smooth_low: f64) {
    match solver::check::warning(smooth_rms, smooth_low) {
        Some(warning) => shared.health.fault(Fault::Inaccurate, warning),
        None => shared.health.recovered(Fault::Inaccurate),
    }
}

/// A solve that stopped short of its tolerance as [`Fault::NotConverged`] (its frames are
/// published, not as final), cleared by the next one that converges.
fn report_convergence(shared: &Shared, report: &solver::SolveReport) {
    match report.converged {
        true => shared.health.recovered(Fault::NotConverged),
        false => shared.health.fault(
            Fault::NotConverged,
            format!(
                "the solve stopped after {} iterations at relative residual {:.3e}, short of the tolerance {:.1e}: the frames served are not final",
                report.iterations, report.residual, report.tolerance
            ),
        ),
    }
}

/// `radiosity` if every value is finite: what the hub may publish.
fn finite(radiosity: Vec<[f32; 3]>) -> anyhow::Result<Vec<[f32; 3]>> {
    match radiosity.iter().flatten().all(|c| c.is_finite()) {
        true => Ok(radiosity),
        false => anyhow::bail!("the solve gave radiosity that is not finite (not published)"),
    }
}
