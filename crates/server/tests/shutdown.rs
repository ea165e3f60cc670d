//! SIGTERM and Ctrl-C as `docker stop` and an operator send them: every viewer gets a close
//! frame (1001, going away) and the process exits within seconds, even in the middle of a solve.

mod common;

use futures_util::StreamExt;
use std::process::Command;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

/// Bound on waits that normally take milliseconds; a hang fails instead of blocking CI.
const PATIENCE: Duration = Duration::from_secs(60);

/// Viewers connected before the signal.
const VIEWERS: usize = 200;

/// Starts the server on a scene whose form factors take long on 2 cores, connects viewers
/// while it solves, sends `signal`, and checks every viewer's close frame and the exit.
async fn viewers_are_closed_and_the_server_exits_on(signal: &str) {
    // Only the first line is read, and stdout closed: the server must not mind.
    let (mut server, address) = common::start_server(&[
        "--no-cache",
        "--patches",
        "8000",
        "--scene",
        "scenes/cornell-box.obj",
        "--token",
        "t",
    ]);
    let mut viewers = Vec::new();
    for _ in 0..VIEWERS {
        let (mut socket, _) = tokio_tungstenite::connect_async(format!("ws://{address}/ws"))
            .await
            .expect("a viewer connects");
        // The hello: the viewer is being served.
        let first = tokio::time::timeout(PATIENCE, socket.next())
            .await
            .expect("hello in time");
        assert!(matches!(first, Some(Ok(Message::Binary(_)))), "{first:?}");
        viewers.push(socket);
    }
    let solution: serde_json::Value = serde_json::from_str(
        &ureq::get(format!("http://{address}/api/solution"))
            .call()
            .expect("answers")
            .into_body()
            .read_to_string()
            .expect("text"),
    )
    .expect("JSON");
    assert_eq!(
        solution["is_final"], false,
        "the signal lands during the solve"
    );

    let sent = Instant::now();
    let killed = Command::new("kill")
        .args([format!("-{signal}"), server.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let closes = futures_util::future::join_all(viewers.into_iter().map(|mut socket| async move {
        tokio::time::timeout(PATIENCE, async {
            while let Some(message) = socket.next().await {
                if let Ok(Message::Close(frame)) = message {
                    return frame.map(|f| f.code);
                }
            }
            None
        })
        .await
        .expect("the close frame in time")
    }))
    .await;
    let away = closes
        .iter()
        .filter(|c| **c == Some(CloseCode::Away))
        .count();
    assert_eq!(away, VIEWERS, "close codes: {closes:?}");
    let status = tokio::task::spawn_blocking(move || server.wait().expect("reaped"))
        .await
        .unwrap();
    let took = sent.elapsed();
    assert!(status.success(), "{status:?}");
    // The promise is "within a couple of seconds"; the bound leaves room for a loaded CI box.
    assert!(took < Duration::from_secs(10), "exit took {took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_closes_every_viewer_and_exits_mid_solve() {
    viewers_are_closed_and_the_server_exits_on("TERM").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ctrl_c_closes_every_viewer_and_exits_mid_solve() {
    viewers_are_closed_and_the_server_exits_on("INT").await;
}
