//! `radcast-client load`: many viewers in one process, each decoding and applying every frame
//! like a real one, with latency measured from the server's send stamp in each frame.

use crate::session::{next_binary, request_full};
use crate::viewer::{Step, Viewer};
use serde::Serialize;
use std::time::{Duration, Instant};

/// What one viewer saw.
#[derive(Debug, Default)]
pub struct ViewerStats {
    /// Connected at all.
    pub connected: bool,
    /// The reason it failed, if it did.
    pub failure: Option<String>,
    /// Time to complete the WebSocket handshake.
    pub connect: Duration,
    /// Time from connecting to the first full frame.
    pub first_frame: Option<Duration>,
    /// Frames applied.
    pub frames: u64,
    /// Bytes received in frames.
    pub bytes: u64,
    /// Full frames asked for after a delta with a foreign base.
    pub resyncs: u64,
    /// Every applied frame as (send stamp, receive time), microseconds since the Unix epoch.
    pub arrivals: Vec<(u64, u64)>,
    /// Every message as (receive time, bytes), responses and hellos included.
    pub received: Vec<(u64, u64)>,
    /// Frames whose version was below the one held before (a version going back).
    pub out_of_order: u64,
    /// The version of the last frame applied.
    pub last_version: u64,
    /// What the viewer held when the run ended.
    pub last: Option<wire::ColourBuffer>,
    /// Frame latencies, microseconds (receive time minus the frame's send stamp), for frames
    /// published after the viewer connected: the frame a viewer joins with carries the stamp
    /// of a state published earlier, which measures its age, not delivery.
    pub latencies_us: Vec<u64>,
}

/// Connects with buffers sized for one viewer of many: tungstenite's 128 KiB defaults, times
/// thousands of viewers in one process, cost more than the frames themselves.
async fn connect(url: &str, protocol: u16) -> anyhow::Result<crate::session::Socket> {
    let config = tokio_tungstenite::tungstenite::protocol::WebSocketConfig::default()
        .read_buffer_size(16 * 1024)
        .write_buffer_size(0);
    crate::session::connect(url, protocol, Some(config)).await
}

/// One viewer speaking `protocol`: connect after `delay`, follow frames until `deadline`.
pub async fn run_viewer(
    url: String,
    protocol: u16,
    delay: Duration,
    deadline: Instant,
) -> ViewerStats {
    tokio::time::sleep(delay).await; // the ramp: spreads connection attempts, not synchronisation
    let mut stats = ViewerStats::default();
    let start = Instant::now();
    let connected = tokio::time::timeout(
        deadline.saturating_duration_since(Instant::now()),
        connect(&url, protocol),
    )
    .await;
    let mut socket = match connected {
        Ok(Ok(socket)) => socket,
        Ok(Err(error)) => {
            stats.failure = Some(format!("{error:#}"));
            return stats;
        }
        Err(_) => {
            stats.failure = Some("connect timed out".into());
            return stats;
        }
    };
    stats.connected = true;
    stats.connect = start.elapsed();
    let joined_at = wire::unix_micros_now();
    let mut viewer = Viewer::default();
    loop {
        let next = tokio::time::timeout(
            deadline.saturating_duration_since(Instant::now()),
            next_binary(&mut socket),
        )
        .await;
        let data = match next {
            Err(_) => break, // the run is over
            Ok(None) => {
                stats.failure = Some("the connection ended".into());
                break;
            }
            Ok(Some(Err(error))) => {
                stats.failure = Some(error.to_string());
                break;
            }
            Ok(Some(Ok(data))) => data,
        };
        let received = wire::unix_micros_now();
        stats.received.push((received, data.len() as u64));
        match viewer.receive(&data) {
            Err(error) => {
                stats.failure = Some(error.to_string());
                break;
            }
            Ok(Step::Hello(_) | Step::GeometryChanged { .. } | Step::Response { .. }) => {}
            Ok(Step::Applied { info, .. }) => {
                let sent_at = info.sent_at_unix_micros;
                // A sum may bring the version held as frames again (it gained its sum).
                if stats.frames > 0 && info.solution_version < stats.last_version {
                    stats.out_of_order += 1;
                }
                stats.last_version = info.solution_version;
                stats.frames += 1;
                stats.bytes += data.len() as u64;
                stats.arrivals.push((sent_at, received));
                if sent_at >= joined_at {
                    stats.latencies_us.push(received.saturating_sub(sent_at));
                }
                stats.first_frame.get_or_insert_with(|| start.elapsed());
            }
            Ok(Step::NeedsFull) => {
                stats.resyncs += 1;
                if request_full(&mut socket).await.is_err() {
                    break;
                }
            }
        }
    }
    let _ = socket.close(None).await;
    stats.last = Some(viewer.into_buffer());
    stats
}

/// Percentiles in milliseconds.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles of `values` (microseconds), in milliseconds.
    pub fn of(mut values: Vec<u64>) -> Percentiles {
        if values.is_empty() {
            return Percentiles::default();
        }
        values.sort_unstable();
        let rank = |q: f64| {
            values[((q * values.len() as f64).ceil() as usize).clamp(1, values.len()) - 1] as f64
                / 1e3
        };
        Percentiles {
            p50: rank(0.50),
            p90: rank(0.90),
            p99: rank(0.99),
            max: *values.last().unwrap_or(&0) as f64 / 1e3,
        }
    }
}

/// The summary `load --json` prints.
#[derive(Debug, Serialize)]
pub struct LoadReport {
    /// Viewers asked for.
    pub clients: usize,
    /// Viewers that connected.
    pub connected: usize,
    /// Viewers that failed to connect or were disconnected.
    pub failed: usize,
    /// The most common failure reasons, with counts.
    pub failures: Vec<(String, usize)>,
    /// WebSocket handshake time.
    pub connect_ms: Percentiles,
    /// Time from connecting to the first full frame.
    pub first_frame_ms: Percentiles,
    /// Frame latency from the server's send stamp.
    pub latency_ms: Percentiles,
    /// Frames applied, all viewers.
    pub frames: u64,
    /// Frame bytes received, all viewers.
    pub bytes: u64,
    /// Frames per connected viewer, fewest and most.
    pub frames_per_viewer: [u64; 2],
    /// Full frames requested after foreign deltas.
    pub resyncs: u64,
    /// Per edit issued with `--edit`: milliseconds from the PUT until the last viewer applied a
    /// frame published after it (the frame carrying the edit).
    pub edit_to_last_viewer_ms: Vec<f64>,
    /// With `--edit`: bytes each connected viewer received from the first edit on, per edit
    /// (every message: frames, sums and the responses they need).
    pub bytes_per_viewer_per_edit: Option<f64>,
    /// The server's version when the run ended (`/api/solution`).
    pub final_version: u64,
    /// Connected viewers that ended holding exactly it (its checksum, or its sum's).
    pub viewers_on_final_version: usize,
    /// Frames, over all viewers, whose version was below the one the viewer held.
    pub versions_out_of_order: u64,
    /// CPU this load tester used during the run, percent of one core (Linux; absent elsewhere):
    /// on one machine it competes with the server, which bounds what latency can show.
    pub load_tester_cpu_percent: Option<f64>,
    /// The server's `/metrics` after the run (name with labels -> value).
    pub server: Vec<(String, f64)>,
}

/// CPU seconds this process has used (user + system), from `/proc/self/stat` (Linux reports
/// them in USER_HZ, 100 per second on every mainstream kernel).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are the 12th and 13th.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// For each edit time (µs since the epoch), the time until the last connected viewer applied a
/// frame sent at or after it; edits some viewer never saw are left out.
pub fn edit_latencies(stats: &[ViewerStats], edits_us: &[u64]) -> Vec<f64> {
    edits_us
        .iter()
        .filter_map(|&edit| {
            let per_viewer: Option<Vec<u64>> = stats
                .iter()
                .filter(|s| s.connected)
                .map(|s| {
                    s.arrivals
                        .iter()
                        .find(|(sent, _)| *sent >= edit)
                        .map(|(_, received)| received.saturating_sub(edit))
                })
                .collect();
            per_viewer
                .and_then(|v| v.into_iter().max())
                .map(|us| us as f64 / 1e3)
        })
        .collect()
}

/// Aggregates per-viewer stats.
pub fn summarize(
    stats: Vec<ViewerStats>,
    server: Vec<(String, f64)>,
    load_tester_cpu_percent: Option<f64>,
    edits_us: &[u64],
    solution: &wire::SolutionSummary,
) -> LoadReport {
    let clients = stats.len();
    let connected: Vec<&ViewerStats> = stats.iter().filter(|s| s.connected).collect();
    let mut failures: Vec<(String, usize)> = Vec::new();
    for reason in stats.iter().filter_map(|s| s.failure.clone()) {
        match failures.iter_mut().find(|(r, _)| *r == reason) {
            Some((_, n)) => *n += 1,
            None => failures.push((reason, 1)),
        }
    }
    failures.sort_by_key(|(_, count)| std::cmp::Reverse(*count));
    failures.truncate(5);
    let micros = |d: Duration| d.as_micros() as u64;
    LoadReport {
        clients,
        connected: connected.len(),
        failed: stats.iter().filter(|s| s.failure.is_some()).count(),
        failures,
        connect_ms: Percentiles::of(connected.iter().map(|s| micros(s.connect)).collect()),
        first_frame_ms: Percentiles::of(
            connected
                .iter()
                .filter_map(|s| s.first_frame.map(micros))
                .collect(),
        ),
        latency_ms: Percentiles::of(
            stats
                .iter()
                .flat_map(|s| s.latencies_us.iter().copied())
                .collect(),
        ),
        frames: stats.iter().map(|s| s.frames).sum(),
        bytes: stats.iter().map(|s| s.bytes).sum(),
        frames_per_viewer: [
            connected.iter().map(|s| s.frames).min().unwrap_or(0),
            connected.iter().map(|s| s.frames).max().unwrap_or(0),
        ],
        resyncs: stats.iter().map(|s| s.resyncs).sum(),
        edit_to_last_viewer_ms: edit_latencies(&stats, edits_us),
        bytes_per_viewer_per_edit: edits_us.first().map(|&first| {
            let bytes: u64 = connected
                .iter()
                .flat_map(|s| &s.received)
                .filter(|(at, _)| *at >= first)
                .map(|(_, bytes)| bytes)
                .sum();
            bytes as f64 / (connected.len().max(1) * edits_us.len()) as f64
        }),
        final_version: solution.solution_version,
        viewers_on_final_version: connected
            .iter()
            .filter(|s| s.last.as_ref().is_some_and(|b| b.matches(solution)))
            .count(),
        versions_out_of_order: stats.iter().map(|s| s.out_of_order).sum(),
        load_tester_cpu_percent,
        server,
    }
}

/// Parses Prometheus text into (name with labels, value) pairs, skipping comments.
pub fn parse_metrics(text: &str) -> Vec<(String, f64)> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| {
            let (name, value) = l.rsplit_once(' ')?;
            Some((name.to_string(), value.parse().ok()?))
        })
        .collect()
}

/// Every server's `/metrics` (one that does not answer gives none); with several servers each
/// name is prefixed by the server's base URL, `http://host:port radcast_viewers`.
pub fn servers_metrics(bases: &[String]) -> Vec<(String, f64)> {
    bases
        .iter()
        .flat_map(|base| {
            let metrics = crate::fetch_metrics(base)
                .map(|text| parse_metrics(&text))
                .unwrap_or_default();
            let prefix = match bases.len() {
                1 => String::new(),
                _ => format!("{base} "),
            };
            metrics
                .into_iter()
                .map(move |(name, value)| (format!("{prefix}{name}"), value))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank() {
        let p = Percentiles::of((1..=100).map(|ms| ms * 1000).collect());
        assert_eq!((p.p50, p.p90, p.p99, p.max), (50.0, 90.0, 99.0, 100.0));
        assert_eq!(Percentiles::of(vec![]).max, 0.0);
    }

    #[test]
    fn edit_latency_is_the_slowest_viewers_first_frame_after_the_edit() {
        let viewer = |arrivals: Vec<(u64, u64)>| ViewerStats {
            connected: true,
            arrivals,
            ..Default::default()
        };
        let stats = [
            viewer(vec![(100, 150), (1000, 1010)]),
            viewer(vec![(100, 120), (1000, 1040), (2000, 2001)]),
        ];
        assert_eq!(edit_latencies(&stats, &[990]), [0.05]);
        // An edit the first viewer never saw a frame for is left out.
        assert!(edit_latencies(&stats, &[1500]).is_empty());
    }

    #[test]
    fn metrics_text_parses_with_labels() {
        let parsed = parse_metrics(
            "# HELP x y\nradcast_viewers 3\nradcast_viewers_dropped_total{reason=\"slow\"} 1\n",
        );
        assert_eq!(
            parsed,
            [
                ("radcast_viewers".to_string(), 3.0),
                (
                    "radcast_viewers_dropped_total{reason=\"slow\"}".to_string(),
                    1.0
                )
            ]
        );
    }
}
