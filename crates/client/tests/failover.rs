//! `radcast-client watch` with several servers (an origin's edges): when its server goes, it
//! goes on with the next.

mod common;

use std::process::Command;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_goes_on_with_the_next_server_when_one_goes_away() {
    // The first server sends version 1 and closes; the second sends version 2 and stays.
    let going = common::serve_one(|mut socket| async move {
        if common::send_hello(&mut socket).await {
            common::send_full(&mut socket, 1, false).await;
        }
        let _ = socket.close(None).await;
    })
    .await;
    let staying = common::serve_one(|mut socket| async move {
        if common::send_hello(&mut socket).await && common::send_full(&mut socket, 2, true).await {
            // Until the viewer hangs up.
            use futures_util::StreamExt;
            while socket.next().await.is_some_and(|m| m.is_ok()) {}
        }
    })
    .await;
    let urls = format!("ws://{going}/ws,ws://{staying}/ws");
    let output = tokio::task::spawn_blocking(move || {
        Command::new(env!("CARGO_BIN_EXE_radcast-client"))
            .args(["watch", "--url", &urls, "--updates", "2"])
            .output()
            .expect("the client runs")
    })
    .await
    .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(
        lines[0].starts_with("hello: scene")
            && lines[0].ends_with(&format!("from ws://{going}/ws")),
        "{stdout}"
    );
    assert!(lines[1].starts_with("version 1: full"), "{stdout}");
    assert!(
        lines[2].starts_with(&format!("ws://{going}/ws: "))
            && lines[2].ends_with("going on with the next server"),
        "{stdout}"
    );
    assert!(
        lines[3].ends_with(&format!("from ws://{staying}/ws")),
        "{stdout}"
    );
    assert!(
        lines[4].starts_with("version 2: full") && lines[4].ends_with(", final"),
        "{stdout}"
    );
    assert_eq!(lines.len(), 5, "{stdout}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_stops_with_an_error_once_every_server_refused_in_a_row() {
    // Two ports nobody listens on.
    let closed: Vec<String> = (0..2)
        .map(|_| {
            let port = std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port();
            format!("ws://127.0.0.1:{port}/ws")
        })
        .collect();
    let urls = closed.join(",");
    let output = tokio::task::spawn_blocking(move || {
        Command::new(env!("CARGO_BIN_EXE_radcast-client"))
            .args(["watch", "--url", &urls])
            .output()
            .expect("the client runs")
    })
    .await
    .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains(&format!("connecting to {}", closed[1])),
        "{stderr}"
    );
}
