//! `radcast-client watch | head -1`: a reader that goes away ends the client quietly.

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// A server that says hello, then sends a new full frame every few milliseconds until the
/// viewer hangs up.
async fn chatty_server() -> std::net::SocketAddr {
    common::serve_one(|mut socket| async move {
        if !common::send_hello(&mut socket).await {
            return;
        }
        for version in 1.. {
            if !common::send_full(&mut socket, version, false).await {
                return;
            }
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_ends_quietly_when_its_reader_goes_away() {
    let address = chatty_server().await;
    let mut client = Command::new(env!("CARGO_BIN_EXE_radcast-client"))
        .args(["watch", "--url", &format!("ws://{address}/ws")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the client starts");
    let mut first = String::new();
    BufReader::new(client.stdout.take().expect("piped"))
        .read_line(&mut first)
        .expect("a first line");
    assert!(first.starts_with("hello: scene"), "{first}");
    // The reader is gone (dropped above); the next line the client writes meets a closed pipe.
    let output = tokio::task::spawn_blocking(move || client.wait_with_output())
        .await
        .unwrap()
        .expect("the client ends");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{:?}: {stderr}", output.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}
