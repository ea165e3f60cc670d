//! Counters for `/metrics`, in the Prometheus text format.

use crate::health::{Fault, Status};
use crate::http::admission::{Gate, Refusal};
use crate::{Process, Shared};
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// Why the server closed a viewer's connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DropReason {
    /// A send did not complete within the send timeout: the viewer stopped reading.
    Slow,
    /// The viewer sent something that is not a protocol message, or too large a one.
    BadMessage,
    /// Nothing (not even a pong) arrived within the idle timeout.
    Idle,
}

impl DropReason {
    const ALL: [DropReason; 3] = [DropReason::Slow, DropReason::BadMessage, DropReason::Idle];

    fn label(self) -> &'static str {
        match self {
            DropReason::Slow => "slow",
            DropReason::BadMessage => "bad_message",
            DropReason::Idle => "idle",
        }
    }
}

/// The server's counters; all updates are lock-free except the solve timings. Viewer and
/// connection counts live in their [`crate::http::admission::Gate`]s, faults in [`crate::health`].
#[derive(Debug, Default)]
pub struct Metrics {
    /// Frames (full and delta) sent.
    pub frames_sent: AtomicU64,
    /// Bytes of frames sent.
    pub bytes_sent: AtomicU64,
    /// Versions a viewer never saw because a newer one replaced them first.
    pub versions_skipped: AtomicU64,
    /// Full frames sent where a delta could not be used (skips, resyncs, scale changes).
    pub full_resyncs: AtomicU64,
    dropped: [AtomicU64; 3],
    /// Seconds per solve stage, once the solve is done.
    pub solve_seconds: Mutex<Vec<(&'static str, f64)>>,
}

impl Metrics {
    /// Counts a dropped viewer.
    pub fn dropped(&self, reason: DropReason) {
        self.dropped[reason as usize].fetch_add(1, Ordering::Relaxed);
    }

    /// Viewers dropped for `reason` so far.
    pub fn dropped_count(&self, reason: DropReason) -> u64 {
        self.dropped[reason as usize].load(Ordering::Relaxed)
    }

    /// Counts one sent frame of `bytes` bytes.
    pub fn sent(&self, bytes: usize) {
        self.frames_sent.fetch_add(1, Ordering::Relaxed);
        self.bytes_sent.fetch_add(bytes as u64, Ordering::Relaxed);
    }
}

/// The text served at `/metrics`.
pub fn render(shared: &Shared) -> String {
    let mut out = Exposition::default();
    admission_metrics(&mut out, &shared.process);
    stream_metrics(&mut out, shared);
    solver_metrics(&mut out, shared);
    if let Some(upstream) = &shared.upstream {
        edge_metrics(&mut out, upstream);
    }
    out.0
}

/// Prometheus text exposition, metric by metric.
#[derive(Default)]
struct Exposition(String);

impl Exposition {
    /// One metric: its help and type lines, then a line per sample (labels, value).
    fn metric(&mut self, name: &str, kind: &str, help: &str, samples: &[(String, f64)]) {
        let _ = writeln!(self.0, "# HELP {name} {help}\n# TYPE {name} {kind}");
        for (labels, value) in samples {
            let _ = writeln!(self.0, "{name}{labels} {value}");
        }
    }
}

/// One unlabelled sample.
fn plain(value: u64) -> Vec<(String, f64)> {
    vec![(String::new(), value as f64)]
}

fn get(counter: &AtomicU64) -> u64 {
    counter.load(Ordering::Relaxed)
}

/// Refusals at a gate, by the cap that refused.
fn refusals(gate: &Gate) -> Vec<(String, f64)> {
    vec![
        (
            "{limit=\"server\"}".to_string(),
            gate.refused(Refusal::ServerFull) as f64,
        ),
        (
            "{limit=\"per_ip\"}".to_string(),
            gate.refused(Refusal::AddressFull) as f64,
        ),
    ]
}

/// Viewers and connections against their caps.
fn admission_metrics(out: &mut Exposition, process: &Process) {
    out.metric(
        "radcast_viewers",
        "gauge",
        "Viewers connected now.",
        &plain(process.viewers.open() as u64),
    );
    out.metric(
        "radcast_viewers_refused_total",
        "counter",
        "Viewers refused at a viewer cap.",
        &refusals(&process.viewers),
    );
    out.metric(
        "radcast_connections",
        "gauge",
        "TCP connections open now, viewers included.",
        &plain(process.connections.open() as u64),
    );
    out.metric(
        "radcast_connected_addresses",
        "gauge",
        "Distinct peer addresses with a connection open now.",
        &plain(process.connections.addresses() as u64),
    );
    out.metric(
        "radcast_connections_refused_total",
        "counter",
        "TCP connections refused at a connection cap before any byte was read.",
        &refusals(&process.connections),
    );
}

/// What viewers were sent, and the version they follow.
fn stream_metrics(out: &mut Exposition, shared: &Shared) {
    let current = shared.hub.current();
    let counters = &shared.metrics;
    let dropped: Vec<_> = DropReason::ALL
        .iter()
        .map(|r| {
            (
                format!("{{reason=\"{}\"}}", r.label()),
                counters.dropped_count(*r) as f64,
            )
        })
        .collect();
    out.metric(
        "radcast_viewers_dropped_total",
        "counter",
        "Viewers disconnected by the server, by reason.",
        &dropped,
    );
    out.metric(
        "radcast_frames_sent_total",
        "counter",
        "Frames sent to viewers.",
        &plain(get(&counters.frames_sent)),
    );
    out.metric(
        "radcast_bytes_sent_total",
        "counter",
        "Frame bytes sent to viewers.",
        &plain(get(&counters.bytes_sent)),
    );
    out.metric(
        "radcast_versions_skipped_total",
        "counter",
        "Solution versions a slow viewer skipped.",
        &plain(get(&counters.versions_skipped)),
    );
    out.metric(
        "radcast_full_resyncs_total",
        "counter",
        "Full frames sent where a delta did not apply.",
        &plain(get(&counters.full_resyncs)),
    );
    out.metric(
        "radcast_vertices",
        "gauge",
        "Colours per frame: the geometry's vertices.",
        &plain(current.colours.len() as u64),
    );
    out.metric(
        "radcast_solution_version",
        "gauge",
        "Current solution version.",
        &plain(current.version),
    );
    out.metric(
        "radcast_solution_final",
        "gauge",
        "1 once the solver converged.",
        &plain(current.is_final as u64),
    );
}

/// The solver thread: its stages, faults and edits.
fn solver_metrics(out: &mut Exposition, shared: &Shared) {
    let counters = &shared.metrics;
    let stages: Vec<_> = counters
        .solve_seconds
        .lock()
        .map(|s| {
            s.iter()
                .map(|(stage, v)| (format!("{{stage=\"{stage}\"}}"), *v))
                .collect()
        })
        .unwrap_or_default();
    out.metric(
        "radcast_solve_seconds",
        "gauge",
        "Seconds per solve stage.",
        &stages,
    );
    let faults: Vec<_> = Fault::ALL
        .iter()
        .map(|f| {
            (
                format!("{{kind=\"{}\"}}", f.label()),
                shared.health.total(*f) as f64,
            )
        })
        .collect();
    out.metric(
        "radcast_faults_total",
        "counter",
        "Faults that began, by kind (see /healthz for those present now).",
        &faults,
    );
    out.metric(
        "radcast_edit_batches_total",
        "counter",
        "Batches of edits the solver finished (applied, or refused and reported).",
        &plain(*shared.edits.finished().borrow()),
    );
    estimate_metrics(out, shared);
    let up = !matches!(shared.health.status(), Status::Down(_));
    out.metric(
        "radcast_solver_up",
        "gauge",
        "1 while the solver thread applies edits.",
        &plain(up as u64),
    );
}

/// The self-check of the answer served, once there is one: per reading (smooth, flat), the
/// estimated relative RMS error with its interval and the energy balance.
fn estimate_metrics(out: &mut Exposition, shared: &Shared) {
    let Some(estimate) = shared
        .report
        .lock()
        .ok()
        .and_then(|r| r.as_ref().and_then(|r| r.estimate))
    else {
        return;
    };
    let readings = [("smooth", estimate.smooth), ("flat", estimate.flat)];
    let rms: Vec<_> = readings
        .iter()
        .flat_map(|(reading, e)| {
            [("estimate", e.rms), ("low", e.low), ("high", e.high)].map(|(bound, value)| {
                (
                    format!("{{reading=\"{reading}\",bound=\"{bound}\"}}"),
                    value,
                )
            })
        })
        .collect();
    out.metric(
        "radcast_estimated_error_ratio",
        "gauge",
        "Self-check: relative RMS error of the answer served, with its interval (3 standard errors).",
        &rms,
    );
    let energy: Vec<_> = readings
        .iter()
        .map(|(reading, e)| (format!("{{reading=\"{reading}\"}}"), e.energy))
        .collect();
    out.metric(
        "radcast_estimated_energy_ratio",
        "gauge",
        "Self-check: the answer's total over the traced total at the probes, minus 1.",
        &energy,
    );
    out.metric(
        "radcast_estimate_probes",
        "gauge",
        "Self-check: probes traced.",
        &plain(estimate.probes as u64),
    );
}

/// On an edge: whether its origin and NATS are heard.
fn edge_metrics(out: &mut Exposition, upstream: &crate::fanout::Upstream) {
    let silent = upstream.silent_for();
    out.metric(
        "radcast_edge_origin_up",
        "gauge",
        "On an edge: 1 while the origin is heard on NATS, 0 once it is silent.",
        &plain((silent <= crate::fanout::SILENT_AFTER) as u64),
    );
    out.metric(
        "radcast_edge_origin_silent_seconds",
        "gauge",
        "On an edge: seconds since the origin was last heard.",
        &[(String::new(), silent.as_secs_f64())],
    );
    out.metric(
        "radcast_edge_nats_connected",
        "gauge",
        "On an edge: 1 while connected to NATS.",
        &plain(upstream.nats.is_connected() as u64),
    );
}
