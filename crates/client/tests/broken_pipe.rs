//! `radcast-client watch | head -1`: a reader that goes away ends the client quietly.

use futures_util::SinkExt;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use tokio_tungstenite::tungstenite::Message;
use wire::{FrameInfo, FullFrame, Hello, ServerMessage};

/// A server that says hello, then sends a new full frame every few milliseconds until the
/// viewer hangs up.
async fn chatty_server() -> std::net::SocketAddr {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(async move {
        let (stream, _) = listener.accept().await.unwrap();
        let mut socket = tokio_tungstenite::accept_async(stream).await.unwrap();
        let hello = Hello {
            protocol_version: wire::PROTOCOL_VERSION,
            scene_id: 1,
            geometry_version: 1,
            vertex_count: 1,
        };
        let send = |m: ServerMessage| Message::Binary(m.encode().into());
        if socket
            .send(send(ServerMessage::Hello(hello)))
            .await
            .is_err()
        {
            return;
        }
        for version in 1.. {
            let frame = FullFrame {
                info: FrameInfo {
                    solution_version: version,
                    sent_at_unix_micros: wire::unix_micros_now(),
                    scale: 1.0,
                    vertex_count: 1,
                    is_final: false,
                },
                colours: vec![wire::encode_colour([version as f32, 0.0, 0.0], 1.0)],
            };
            if socket.send(send(ServerMessage::Full(frame))).await.is_err() {
                return;
            }
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
    });
    address
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
