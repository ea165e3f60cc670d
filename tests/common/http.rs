//! Plain HTTP against a test server, and the control API's edit-then-wait.

use std::net::SocketAddr;
use std::time::Duration;

/// Generous bound on a batch of edits; a hang fails instead of blocking CI.
const PATIENCE: Duration = Duration::from_secs(90);

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into()
}

/// GET `path`: the status and the body's bytes.
pub async fn get(address: SocketAddr, path: &str) -> (u16, Vec<u8>) {
    let url = format!("http://{address}{path}");
    tokio::task::spawn_blocking(move || {
        let mut response = agent().get(&url).call().unwrap();
        let status = response.status().as_u16();
        (status, response.body_mut().read_to_vec().unwrap())
    })
    .await
    .unwrap()
}

/// GET `path`: the status and the body as text.
pub async fn get_text(address: SocketAddr, path: &str) -> (u16, String) {
    let (status, body) = get(address, path).await;
    (status, String::from_utf8(body).unwrap())
}

/// PUT `body` with an optional bearer token; the status and the body as text.
pub async fn put(
    address: SocketAddr,
    path: &str,
    token: Option<&str>,
    body: &str,
) -> (u16, String) {
    let (url, body, token) = (
        format!("http://{address}{path}"),
        body.to_string(),
        token.map(str::to_string),
    );
    tokio::task::spawn_blocking(move || {
        let mut request = agent().put(&url).header("Content-Type", "application/json");
        if let Some(token) = token {
            request = request.header("Authorization", &format!("Bearer {token}"));
        }
        let mut response = request.send(body.as_bytes()).unwrap();
        (
            response.status().as_u16(),
            response.body_mut().read_to_string().unwrap(),
        )
    })
    .await
    .unwrap()
}

/// PUTs an edit with `token` to `address` (a server, or an edge that forwards it), expects it
/// queued, and waits until the solver behind `finished` has finished the batch it went into.
/// One at a time: edits sent together may share a batch.
pub async fn edit_and_wait(
    address: SocketAddr,
    finished: &mut tokio::sync::watch::Receiver<u64>,
    token: &str,
    path: &str,
    body: &str,
) {
    let done = *finished.borrow_and_update() + 1;
    let (status, reply) = put(address, path, Some(token), body).await;
    assert_eq!(status, 202, "{reply}");
    tokio::time::timeout(PATIENCE, finished.wait_for(|n| *n >= done))
        .await
        .expect("the batch is finished")
        .unwrap();
}
