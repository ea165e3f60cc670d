//! radcast-server as a library, in the order data flows through it: [`publish`] (a scene made
//! ready, the solver thread, the one conversion of solver values to wire types, the cache and
//! the hub every viewer reads), [`http`] (accept, routes, one task per viewer, the page,
//! metrics), [`control`] (edits in) and [`fanout`] (past one machine, through NATS); [`health`]
//! is what they report. `main.rs` only parses flags and binds a socket, so tests run the same
//! server on an ephemeral port.

pub mod control;
pub mod fanout;
pub mod health;
pub mod http;
pub mod publish;

use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// How long a request in progress may still run once shutdown begins; viewers get their
/// close frame on their own (see [`http::viewer`]).
pub const SHUTDOWN_GRACE: Duration = Duration::from_secs(1);

/// Limits that protect the server from viewers.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Viewers at once; more are refused with 503.
    pub max_viewers: usize,
    /// Viewers at once from one IP address; more are refused with 429.
    pub max_viewers_per_ip: usize,
    /// Open TCP connections at once (viewers and HTTP requests); more are refused with 503
    /// before anything is read. Keep it under the open-file limit.
    pub max_connections: usize,
    /// Open TCP connections at once from one IP address; more are refused with 429.
    pub max_connections_per_ip: usize,
    /// A connection that has not sent a whole request head within this long is closed.
    pub header_timeout: Duration,
    /// Largest message a viewer may send, bytes.
    pub max_message_bytes: usize,
    /// A send that takes longer drops the viewer (it stopped reading).
    pub send_timeout: Duration,
    /// How often the server pings each viewer.
    pub ping_interval: Duration,
    /// A viewer that sends nothing, not even a pong, for this long is dropped.
    pub idle_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_viewers: 20_000,
            // One address (a NAT, a load tester) may hold 5% of the viewers: twenty are needed
            // to fill the server. Local load tests raise it.
            max_viewers_per_ip: 1_000,
            // Viewers plus room for HTTP requests, so /healthz answers with the viewers full.
            max_connections: 21_000,
            max_connections_per_ip: 1_100,
            header_timeout: Duration::from_secs(10),
            max_message_bytes: 1024,
            send_timeout: Duration::from_secs(10),
            ping_interval: Duration::from_secs(15),
            idle_timeout: Duration::from_secs(60),
        }
    }
}

/// What every scene served by one process shares: the limits, the caps on viewers and
/// connections, shutdown and the tasks to wait for. An origin serves one scene; an edge
/// ([`fanout::edge`]) serves every scene published to its NATS.
pub struct Process {
    /// Viewer limits.
    pub limits: Limits,
    /// Cancelled on shutdown: viewers get a close frame and their tasks end.
    pub shutdown: CancellationToken,
    /// Every connection and viewer task, so shutdown can wait for their close frames.
    pub tasks: tokio_util::task::TaskTracker,
    /// Viewers connected now, under the viewer caps.
    pub viewers: Arc<http::admission::Gate>,
    /// TCP connections open now (viewers included), under the connection caps.
    pub connections: Arc<http::admission::Gate>,
}

impl Process {
    /// A process with nothing connected yet.
    pub fn new(limits: Limits) -> Arc<Process> {
        Arc::new(Process {
            limits,
            shutdown: Default::default(),
            tasks: Default::default(),
            viewers: http::admission::Gate::new(limits.max_viewers, limits.max_viewers_per_ip),
            connections: http::admission::Gate::new(
                limits.max_connections,
                limits.max_connections_per_ip,
            ),
        })
    }
}

/// What every route and viewer task of one scene shares.
pub struct Shared {
    /// The process this scene is served by.
    pub process: Arc<Process>,
    /// The published solution.
    pub hub: Arc<publish::hub::Hub>,
    /// Counters.
    pub metrics: http::metrics::Metrics,
    /// The last solve's report once the first is done, for `/api/solution`.
    pub report: std::sync::Mutex<Option<wire::summary::SolveReport>>,
    /// Edits waiting for the solver thread.
    pub edits: control::edits::Edits,
    /// The bearer token the control API requires (never empty).
    pub token: String,
    /// Faults the solver thread (or, on an edge, the feed) reported.
    pub health: health::Health,
    /// Every object's emission as the published solution has it (W/m^2), in scene order.
    pub emissions: std::sync::Mutex<Vec<(String, [f64; 3])>>,
    /// On an edge: where control requests go instead of [`Shared::edits`].
    pub upstream: Option<fanout::Upstream>,
    /// Cancelled when this scene stops being served (shutdown, or on an edge a restarted
    /// origin): its viewers get a close frame.
    pub retired: CancellationToken,
}

impl Shared {
    /// Shared state over `hub` in a process of its own, with nothing connected, no report yet
    /// and no faults.
    pub fn new(hub: publish::hub::Hub, limits: Limits, token: String) -> Arc<Shared> {
        Self::in_process(Process::new(limits), hub, token, None)
    }

    /// Shared state over `hub` for one of the scenes `process` serves.
    pub fn in_process(
        process: Arc<Process>,
        hub: publish::hub::Hub,
        token: String,
        upstream: Option<fanout::Upstream>,
    ) -> Arc<Shared> {
        Arc::new(Shared {
            retired: process.shutdown.child_token(),
            process,
            hub: Arc::new(hub),
            metrics: Default::default(),
            report: Default::default(),
            edits: Default::default(),
            token,
            health: Default::default(),
            emissions: Default::default(),
            upstream,
        })
    }
}
