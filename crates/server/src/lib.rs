//! radcast-server as a library: the HTTP/WebSocket routes over a [`hub::Hub`], and the
//! background solve that feeds it. `main.rs` only parses flags and binds a socket, so tests run
//! the same server on an ephemeral port.

pub mod edits;
pub mod hub;
pub mod metrics;
pub mod routes;
pub mod solving;
pub mod viewer;

use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// Limits that protect the server from viewers.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Viewers at once; more are refused with 503.
    pub max_viewers: usize,
    /// Viewers at once from one IP address; more are refused with 429.
    pub max_viewers_per_ip: usize,
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
            max_viewers_per_ip: 20_000,
            max_message_bytes: 1024,
            send_timeout: Duration::from_secs(10),
            ping_interval: Duration::from_secs(15),
            idle_timeout: Duration::from_secs(60),
        }
    }
}

/// What every route and viewer task shares.
pub struct Shared {
    /// The published solution.
    pub hub: Arc<hub::Hub>,
    /// Counters.
    pub metrics: metrics::Metrics,
    /// Viewer limits.
    pub limits: Limits,
    /// Cancelled on shutdown: viewers get a close frame and their tasks end.
    pub shutdown: CancellationToken,
    /// The last solve's report once the first is done, for `/api/solution`.
    pub report: std::sync::Mutex<Option<wire::summary::SolveReport>>,
    /// Edits waiting for the solver thread.
    pub edits: edits::Edits,
    /// The bearer token the control API requires.
    pub token: String,
    /// Viewers connected now, per IP address.
    pub viewers_per_ip: std::sync::Mutex<std::collections::HashMap<std::net::IpAddr, usize>>,
}
