//! An origin and an edge as an operator starts them (`--nats`, `--edge`), and the origin
//! killed outright (SIGKILL: no goodbye on NATS): the edge keeps serving its last solution
//! and says why. Uses the NATS at 127.0.0.1:4222 (`scripts/nats.sh`); skips, saying so,
//! when none answers there.

mod common;

use std::net::SocketAddr;
use std::process::Child;
use std::time::{Duration, Instant};

const NATS: &str = "nats://127.0.0.1:4222";
/// Generous bound on each wait; a hang fails instead of blocking CI.
const PATIENCE: Duration = Duration::from_secs(90);

/// A server process, killed when dropped.
struct Server {
    child: Child,
    address: SocketAddr,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `radcast-server ARGS`, killed when dropped.
fn start(args: &[&str]) -> Server {
    let (child, address) = common::start_server(args);
    Server { child, address }
}

fn get(address: SocketAddr, path: &str) -> (u16, String) {
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let mut response = agent
        .get(&format!("http://{address}{path}"))
        .call()
        .expect("the server answers");
    let status = response.status().as_u16();
    (status, response.body_mut().read_to_string().expect("text"))
}

/// Polls `path` until `done` holds for its body (the edge checks its origin once a second).
fn until(address: SocketAddr, path: &str, done: impl Fn(&str) -> bool) -> String {
    let start = Instant::now();
    loop {
        let (_, body) = get(address, path);
        if done(&body) {
            return body;
        }
        assert!(
            start.elapsed() < PATIENCE,
            "{path} never became as expected: {body}"
        );
        std::thread::sleep(Duration::from_millis(100)); // polling interval, not synchronisation
    }
}

#[test]
fn an_edge_outlives_its_killed_origin_and_says_so() {
    if std::net::TcpStream::connect_timeout(
        &"127.0.0.1:4222".parse().unwrap(),
        Duration::from_secs(1),
    )
    .is_err()
    {
        eprintln!(
            "skipped: no NATS at 127.0.0.1:4222 (scripts/nats.sh starts one; .ci/run runs it)"
        );
        return;
    }
    let name = "test-process-origin";
    let mut origin = start(&[
        "--scene",
        "scenes/shadow-slab.obj",
        "--no-cache",
        "--nats",
        NATS,
        "--name",
        name,
    ]);
    let edge = start(&["--edge", "--nats", NATS, "--name", name]);
    let solution = until(origin.address, "/api/solution", |s| {
        s.contains("\"is_final\":true")
    });
    // The edge serves the origin's final solution, healthy (a copy left by an earlier run of
    // this test, whose origin is gone, is replaced once this origin's record arrives).
    until(edge.address, "/api/solution", |s| s == solution);
    until(edge.address, "/healthz", |h| h == "ok\n");

    origin.child.kill().expect("SIGKILL");
    let health = until(edge.address, "/healthz", |h| h.starts_with("degraded: "));
    assert!(
        health.contains(&format!("the origin of '{name}' is silent")),
        "{health}"
    );
    assert_eq!(get(edge.address, "/api/solution"), (200, solution));
    let (_, metrics) = get(edge.address, "/metrics");
    assert!(metrics.contains("radcast_edge_origin_up 0"), "{metrics}");
    assert!(
        metrics.contains("radcast_edge_nats_connected 1"),
        "{metrics}"
    );
}
