//! Origins and edges through a real NATS: the one at 127.0.0.1:4222 (`scripts/nats.sh`, run by
//! `.ci/run`, starts it), or where none answers there a `nats-server` of the test's own on a
//! free port, as for the restart test. Without either, the tests say so and skip.
//! Origins and edges run in this process; "killing" one shuts it down: its listener, viewers,
//! heartbeat and publishing stop, as they do when the process dies.

mod common;

use common::http::{edit_and_wait, get, get_text, put};
use common::viewer::Viewer;
use futures_util::StreamExt;
use server::fanout::{self, Nats, edge::Edge};
use server::publish::prepare::{prepare, shared_for};
use server::publish::solver_thread;
use server::{Limits, Process, Shared};
use solver::{PatchTarget, SolveRequest};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

const TOKEN: &str = "fan-out-token";
/// Generous bound on waits that take milliseconds to seconds; a hang fails instead of blocking.
const PATIENCE: Duration = Duration::from_secs(90);
const SHARED_NATS: &str = "nats://127.0.0.1:4222";

/// The shared NATS when it answers, else one of this test's own (kept alive by the second
/// value); `None` when there is neither.
fn test_nats() -> Option<(String, Option<NatsProcess>)> {
    let shared = "127.0.0.1:4222".parse().unwrap();
    match std::net::TcpStream::connect_timeout(&shared, Duration::from_secs(1)) {
        Ok(_) => Some((SHARED_NATS.to_string(), None)),
        Err(_) => NatsProcess::start().map(|own| (own.url(), Some(own))),
    }
}

/// Connects to NATS at `url`, failing with what to do when nothing answers.
async fn connect(url: &str, name: &str) -> Nats {
    let nats = Nats::connect(url, name).await.expect("the client starts");
    tokio::time::timeout(Duration::from_secs(10), nats.client.flush())
        .await
        .unwrap_or_else(|_| panic!("no NATS at {url}: `.ci/run` starts one (scripts/nats.sh)"))
        .expect("NATS answers");
    nats
}

/// An origin serving the Cornell box as scene `name` and publishing it to NATS.
struct Origin {
    address: SocketAddr,
    shared: Arc<Shared>,
    run: String,
}

impl Drop for Origin {
    fn drop(&mut self) {
        // Ends the solver thread's edit loop and everything the process runs.
        self.shared.edits.close();
        self.shared.process.shutdown.cancel();
    }
}

async fn origin(url: &str, name: &str) -> Origin {
    origin_of(url, name, "scenes/cornell-box.obj").await
}

/// An origin serving `scene` as `name`.
async fn origin_of(url: &str, name: &str, scene: &str) -> Origin {
    let request = SolveRequest {
        patches: PatchTarget::Count(300),
        ..SolveRequest::default()
    };
    let prepared = prepare(scene.as_ref(), request).expect("scene loads");
    let shared = shared_for(&prepared, Limits::default(), TOKEN.into());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(server::http::routes::serve(listener, shared.clone()));
    solver_thread::start(prepared, shared.clone(), None);
    let run = format!("run-{name}-{}", wire::unix_micros_now());
    let nats = connect(url, "test origin").await;
    tokio::spawn(fanout::origin::serve(
        shared.clone(),
        nats,
        name.into(),
        run.clone(),
    ));
    Origin {
        address,
        shared,
        run,
    }
}

/// An edge following NATS at `url`, serving `root` at its root (without, its only scene).
struct EdgeServer {
    address: SocketAddr,
    edge: Arc<Edge>,
    process: Arc<Process>,
}

impl Drop for EdgeServer {
    fn drop(&mut self) {
        self.process.shutdown.cancel();
    }
}

async fn edge(url: &str, root: impl Into<Option<&str>>) -> EdgeServer {
    let process = Process::new(Limits::default());
    let edge = Edge::new(
        process.clone(),
        connect(url, "test edge").await,
        root.into().map(str::to_string),
    );
    tokio::spawn(fanout::follow::follow(edge.clone()));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(server::http::listen::serve_router(
        listener,
        fanout::edge::router(edge.clone()),
        process.clone(),
    ));
    EdgeServer {
        address,
        edge,
        process,
    }
}

/// Waits until `shared` holds a final state with `checksum` (and at least `version`).
async fn final_state(shared: &Shared, version: u64, checksum: u32) {
    let mut updates = shared.hub.subscribe();
    // The borrowed state is dropped at once: held, it would block the edge's next install.
    let arrived = tokio::time::timeout(
        PATIENCE,
        updates.wait_for(|p| p.is_final && p.version >= version && p.checksum == checksum),
    )
    .await
    .map(|held| held.map(|_| ()).expect("the hub lives"));
    if arrived.is_err() {
        let held = shared.hub.current();
        panic!(
            "version {version} (final, checksum {checksum:08x}) never arrived: the hub holds \
             version {} (final {}, checksum {:08x}, geometry {})",
            held.version, held.is_final, held.checksum, held.geometry_version
        );
    }
    // The origin's record of the version's sum of responses follows the frame.
    tokio::time::timeout(PATIENCE, async {
        while server::http::routes::solution_summary(shared)
            .sum_checksum
            .is_none()
        {
            tokio::time::sleep(Duration::from_millis(10)).await; // polling interval, not synchronisation
        }
    })
    .await
    .expect("the record of the sum arrives");
}

/// Waits until the origin's solve is final, and summed from its lights' responses for
/// protocol-3 viewers, and returns its version and checksum.
async fn origin_final(origin: &Origin) -> (u64, u32) {
    let mut updates = origin.shared.hub.subscribe();
    let state = tokio::time::timeout(
        PATIENCE,
        updates.wait_for(|p| p.is_final && p.sum.is_some()),
    )
    .await
    .expect("the solve ends")
    .expect("the hub lives")
    .clone();
    (state.version, state.checksum)
}

/// What `address` answers at `/api/solution`.
async fn summary(address: SocketAddr) -> wire::summary::SolutionSummary {
    let (status, body) = get(address, "/api/solution").await;
    assert_eq!(status, 200);
    serde_json::from_slice(&body).expect("a solution summary")
}

/// Polls `/healthz` until its text starts with `prefix` (the edge checks once a second).
async fn health_becomes(address: SocketAddr, prefix: &str) -> String {
    tokio::time::timeout(PATIENCE, async {
        loop {
            let (_, text) = get_text(address, "/healthz").await;
            if text.starts_with(prefix) {
                return text;
            }
            tokio::time::sleep(Duration::from_millis(100)).await; // polling interval, not synchronisation
        }
    })
    .await
    .unwrap_or_else(|_| panic!("/healthz never said '{prefix}…'"))
}

/// The first two messages a new viewer gets (hello and full frame), as bytes.
async fn first_messages(address: SocketAddr) -> Vec<Vec<u8>> {
    let (mut socket, _) = tokio_tungstenite::connect_async(format!("ws://{address}/ws"))
        .await
        .unwrap();
    let mut messages = Vec::new();
    while messages.len() < 2 {
        if let Some(Ok(Message::Binary(bytes))) = socket.next().await {
            messages.push(bytes.to_vec());
        }
    }
    messages
}

/// Everything a viewer or a client can ask of a server, which must be equal on origin and edge:
/// each body by what it answers (the two first WebSocket messages as `ws hello`, `ws frame`).
async fn served_bytes(address: SocketAddr) -> Vec<(&'static str, Vec<u8>)> {
    let mut all = Vec::new();
    for path in [
        "/api/solution",
        "/api/scene",
        "/api/objects",
        "/api/scene.glb",
    ] {
        let (status, body) = get(address, path).await;
        assert_eq!(status, 200, "{path}");
        all.push((path, body));
    }
    all.extend(
        ["ws hello", "ws frame"]
            .into_iter()
            .zip(first_messages(address).await),
    );
    all
}

/// Asserts that `address` serves what the origin at `origin` does, naming the first body that
/// differs (as text where it is text).
async fn serves_as_origin(address: SocketAddr, origin: SocketAddr) {
    let (served, expected) = (served_bytes(address).await, served_bytes(origin).await);
    for ((what, body), (_, origin_body)) in served.iter().zip(&expected) {
        assert!(
            body == origin_body,
            "{address} serves {what} unlike the origin {origin}: {} bytes against {}:\n{}\n{}",
            body.len(),
            origin_body.len(),
            String::from_utf8_lossy(&body[..body.len().min(600)]),
            String::from_utf8_lossy(&origin_body[..origin_body.len().min(600)]),
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn origin_and_edges_serve_the_same_bytes_through_edits_moves_and_a_late_start() {
    let Some((nats, _own)) = test_nats() else {
        return;
    };
    let name = "test-same-bytes";
    let (edge_a, edge_b) = (edge(&nats, name).await, edge(&nats, name).await);
    let origin = origin(&nats, name).await;
    let (version, checksum) = origin_final(&origin).await;
    let on_edges = [
        edge_a.edge.serving(name, &origin.run).await,
        edge_b.edge.serving(name, &origin.run).await,
    ];
    for on_edge in &on_edges {
        final_state(on_edge, version, checksum).await;
    }
    let servers = [origin.address, edge_a.address, edge_b.address];
    let mut viewers = Vec::new();
    for address in servers {
        viewers.push(Viewer::connect(address).await);
    }
    for (viewer, address) in viewers.iter_mut().zip(servers) {
        viewer.ends_with(checksum).await;
        serves_as_origin(address, origin.address).await;
    }
    let before = checksum;
    // Protocol 3 on an edge: the light's response once, then sums, as on the origin.
    let mut summing = Viewer::connect_speaking(edge_a.address, 3).await;
    let solution = summary(origin.address).await;
    summing.wait_for(|b| b.matches(&solution)).await;
    assert!(summing.buffer.sum.is_some(), "the edge serves the sum");
    assert_eq!(summing.responses.len(), 1, "the Cornell box has one light");
    let frames_before = (summing.full_frames, summing.deltas.len());

    // An edit sent to the edge reaches the origin, which answers as it would itself.
    let path = "/api/objects/light/emission";
    let refused = put(
        edge_a.address,
        path,
        Some("wrong"),
        r#"{"emission": [1, 2, 3]}"#,
    )
    .await;
    assert_eq!(
        refused,
        put(
            origin.address,
            path,
            Some("wrong"),
            r#"{"emission": [1, 2, 3]}"#
        )
        .await
    );
    assert_eq!(refused.0, 401, "{}", refused.1);
    let mut finished = origin.shared.edits.finished();
    edit_and_wait(
        edge_a.address,
        &mut finished,
        TOKEN,
        path,
        r#"{"emission": [30, 20, 10]}"#,
    )
    .await;
    let solution = summary(origin.address).await;
    summing.wait_for(|b| b.matches(&solution)).await;
    assert_eq!(
        (summing.sums.len(), *summing.sums.last().unwrap()),
        (2, 42),
        "the emission edit reached the edge's protocol-3 viewer as one 42-byte sum"
    );
    assert_eq!((summing.full_frames, summing.deltas.len()), frames_before);
    // A move, sent to the origin: new geometry travels too.
    let (address, path) = (origin.address, "/api/objects/tall_block/transform");
    edit_and_wait(
        address,
        &mut finished,
        TOKEN,
        path,
        r#"{"translate": [20, 0, -15]}"#,
    )
    .await;
    let (version, checksum) = origin_final(&origin).await;
    assert_ne!(checksum, before, "the edits changed the solution");
    // Viewers on the origin and on both edges end on it; everything served is the origin's.
    for on_edge in &on_edges {
        final_state(on_edge, version, checksum).await;
        assert_eq!(
            on_edge.hub.geometry().version,
            2,
            "the move's geometry reached the edge"
        );
    }
    // The move's version goes out as frames, then as a sum once the light's response is
    // solved again.
    let solution = summary(origin.address).await;
    summing
        .wait_for(|b| b.sum.is_some() && b.matches(&solution))
        .await;
    assert_eq!(summing.geometry_versions, [2]);
    for (viewer, address) in viewers.iter_mut().zip(servers) {
        viewer.ends_with(checksum).await;
        assert_eq!(
            viewer.geometry_versions,
            [2],
            "{address}: told of the move once"
        );
        serves_as_origin(address, origin.address).await;
    }

    // An edge started now is served from the snapshots at once, without the origin's help.
    let edge_c = edge(&nats, name).await;
    let on_c = edge_c.edge.serving(name, &origin.run).await;
    assert_eq!(
        (on_c.hub.current().version, on_c.hub.current().checksum),
        (version, checksum)
    );
    let mut late = Viewer::connect_speaking(edge_c.address, 3).await;
    late.wait_for(|b| b.matches(&solution)).await;
    assert!(
        late.buffer.sum.is_some(),
        "a late edge serves the sum from the stored responses"
    );
    serves_as_origin(edge_c.address, origin.address).await;
    let (status, scenes) = get_text(edge_c.address, "/scenes").await;
    assert_eq!(status, 200);
    assert!(scenes.contains(&format!("\"{name}\"")), "{scenes}");
    // The same scene under its name, as an edge serving several would.
    let (status, solution) = get(edge_c.address, &format!("/scenes/{name}/api/solution")).await;
    assert_eq!(
        (status, solution),
        get(origin.address, "/api/solution").await
    );
    // The browser page too, its links relative (`/scenes/NAME` redirects to `/scenes/NAME/`).
    let page = get(edge_c.address, &format!("/scenes/{name}")).await;
    assert_eq!(page, get(origin.address, "/").await);
    assert!(String::from_utf8_lossy(&page.1).contains("src=\"viewer.js\""));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn edges_keep_serving_a_dead_origin_and_viewers_move_on_from_a_dead_edge() {
    let Some((nats, _own)) = test_nats() else {
        return;
    };
    let name = "test-dead-origin";
    let origin = origin(&nats, name).await;
    let (edge_a, edge_b) = (edge(&nats, name).await, edge(&nats, name).await);
    let (version, checksum) = origin_final(&origin).await;
    for edge in [&edge_a, &edge_b] {
        let on_edge = edge.edge.serving(name, &origin.run).await;
        final_state(&on_edge, version, checksum).await;
    }
    let (_, solution) = get(edge_a.address, "/api/solution").await;
    assert_eq!(
        get_text(edge_a.address, "/healthz").await,
        (200, "ok\n".into())
    );

    drop(origin);
    let health = health_becomes(edge_a.address, "degraded: ").await;
    assert!(
        health.contains(&format!("the origin of '{name}' is silent")),
        "{health}"
    );
    assert!(health.contains(&format!("(version {version})")), "{health}");
    let (_, metrics) = get_text(edge_a.address, "/metrics").await;
    assert!(metrics.contains("radcast_edge_origin_up 0"), "{metrics}");
    assert!(
        metrics.contains("radcast_faults_total{kind=\"origin_silent\"} 1"),
        "{metrics}"
    );
    // Still serving the last solution, to viewers old and new.
    assert_eq!(get(edge_a.address, "/api/solution").await, (200, solution));
    Viewer::connect(edge_a.address)
        .await
        .ends_with(checksum)
        .await;
    // Control has nowhere to go: refused with a pointer to the origin.
    let (status, reply) = put(
        edge_a.address,
        "/api/objects/light/emission",
        Some(TOKEN),
        r#"{"emission": [1, 1, 1]}"#,
    )
    .await;
    assert_eq!(status, 503, "{reply}");
    assert!(
        reply.contains("send control requests to the origin"),
        "{reply}"
    );

    // Edge A goes away; a client given both edges goes on with B, which serves it the
    // origin's sum of responses (protocol 3) and the codes (protocol 2).
    let solution = summary(edge_b.address).await;
    let urls = [edge_a.address, edge_b.address].map(|a| format!("ws://{a}/ws"));
    drop(edge_a);
    for protocol in [wire::PROTOCOL_VERSION, wire::PLAIN_PROTOCOL_VERSION] {
        let outcome = client::session::watch_until_final_on_any(&urls, 0, protocol, PATIENCE)
            .await
            .expect("edge B serves");
        assert!(outcome.buffer.matches(&solution), "protocol {protocol}");
        assert_eq!(outcome.buffer.sum.is_some(), protocol == 3);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_edge_serves_every_scene_published_each_under_its_name() {
    let Some((nats, _own)) = test_nats() else {
        return;
    };
    let names = ["test-several-a", "test-several-b"];
    let edge = edge(&nats, None).await;
    // The second has textures: the edge serves them from the object store, byte for byte.
    let origins = [
        origin(&nats, names[0]).await,
        origin_of(&nats, names[1], "scenes/tiled-cornell-box.obj").await,
    ];
    for (origin, name) in origins.iter().zip(names) {
        let (version, checksum) = origin_final(origin).await;
        let served = edge.edge.serving(name, &origin.run).await;
        final_state(&served, version, checksum).await;
        for path in [
            "/api/solution",
            "/api/scene",
            "/api/scene.glb",
            "/api/textures/0",
            "/api/textures/1",
        ] {
            let on_edge = get(edge.address, &format!("/scenes/{name}{path}")).await;
            assert_eq!(on_edge, get(origin.address, path).await, "{name}{path}");
        }
    }
    let (status, scenes) = get_text(edge.address, "/scenes").await;
    assert_eq!(status, 200);
    for name in names {
        assert!(scenes.contains(&format!("\"{name}\"")), "{scenes}");
    }
    // With several scenes and none named at start, the root says how to choose.
    let (status, text) = get_text(edge.address, "/healthz").await;
    assert_eq!(status, 503, "{text}");
    assert!(text.contains("use /scenes/NAME/"), "{text}");
    let (status, text) = get_text(edge.address, "/scenes/no-such-scene/api/solution").await;
    assert_eq!(
        (status, text.trim()),
        (404, "no scene named 'no-such-scene' on this edge")
    );
}

/// A `nats-server` of this test's own (JetStream on, stored in a temporary folder), so it can
/// be stopped and started again on the same port with the same store.
struct NatsProcess {
    port: u16,
    store: tempfile::TempDir,
    child: Option<std::process::Child>,
}

const NATS_SERVER: &str = "nats-server";

impl NatsProcess {
    fn start() -> Option<NatsProcess> {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let mut nats = NatsProcess {
            port,
            store: tempfile::tempdir().unwrap(),
            child: None,
        };
        nats.restart().then_some(nats)
    }

    fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    /// Starts the server (again); false when there is no `nats-server` to start.
    fn restart(&mut self) -> bool {
        let spawned = std::process::Command::new(NATS_SERVER)
            .args([
                "-a",
                "127.0.0.1",
                "-p",
                &self.port.to_string(),
                "-js",
                "-sd",
            ])
            .arg(self.store.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn();
        match spawned {
            Ok(child) => {
                self.child = Some(child);
                true
            }
            Err(error) => {
                eprintln!(
                    "skipped: cannot start `{NATS_SERVER}` ({error}); Debian: apt-get install nats-server (.ci/run installs it)"
                );
                false
            }
        }
    }

    fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Drop for NatsProcess {
    fn drop(&mut self) {
        self.stop();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn after_nats_restarts_edges_resync_and_viewers_end_on_the_final_state() {
    let Some(mut nats) = NatsProcess::start() else {
        return;
    };
    let name = "test-restart";
    let origin = origin(&nats.url(), name).await;
    let edge = edge(&nats.url(), name).await;
    let (version, checksum) = origin_final(&origin).await;
    let on_edge = edge.edge.serving(name, &origin.run).await;
    final_state(&on_edge, version, checksum).await;
    let mut viewer = Viewer::connect(edge.address).await;
    viewer.ends_with(checksum).await;

    nats.stop();
    let health = health_becomes(edge.address, "degraded: ").await;
    assert!(health.contains("NATS is unreachable"), "{health}");
    // An edit while NATS is down: the origin applies it; edges cannot hear of it yet.
    let mut finished = origin.shared.edits.finished();
    let (path, body) = (
        "/api/objects/light/emission",
        r#"{"emission": [40, 40, 40]}"#,
    );
    edit_and_wait(origin.address, &mut finished, TOKEN, path, body).await;
    let (version, checksum) = origin_final(&origin).await;

    assert!(nats.restart());
    final_state(&on_edge, version, checksum).await;
    viewer.ends_with(checksum).await;
    health_becomes(edge.address, "ok").await;
}
