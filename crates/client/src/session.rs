//! One viewer's WebSocket session: the socket side of a [`Viewer`].

use crate::viewer::{Step, Viewer};
use anyhow::{Context, anyhow, bail};
use futures_util::{SinkExt, StreamExt};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::{Bytes, Message};
use wire::{ClientMessage, ColourBuffer, Hello};

/// A viewer's WebSocket.
pub type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// What a viewer ended with.
#[derive(Debug)]
pub struct ViewerOutcome {
    /// The server's hello.
    pub hello: Hello,
    /// The colours at the end.
    pub buffer: ColourBuffer,
    /// Frames received (full, delta and sum).
    pub frames: u64,
    /// Bytes of frames (and responses) received.
    pub bytes: u64,
    /// Time from connecting to the first full frame.
    pub first_frame: Duration,
}

/// Opens a viewer's WebSocket to `url` asking for `protocol` (3: with the subprotocol
/// `radcast.3`; 2: with none), with tungstenite's buffers as `config` sets them. A server
/// that speaks only version 2 (it answers without a subprotocol) is connected to again
/// without one: the hello then says 2, and frames are all it sends.
pub async fn connect(
    url: &str,
    protocol: u16,
    config: Option<WebSocketConfig>,
) -> anyhow::Result<Socket> {
    use tokio_tungstenite::tungstenite::Error;
    use tokio_tungstenite::tungstenite::error::{ProtocolError, SubProtocolError};
    match open(url, protocol, config).await {
        Err(Error::Protocol(ProtocolError::SecWebSocketSubProtocolError(
            SubProtocolError::NoSubProtocol,
        ))) if protocol > wire::PLAIN_PROTOCOL_VERSION => {
            open(url, wire::PLAIN_PROTOCOL_VERSION, config).await
        }
        opened => opened,
    }
    .with_context(|| format!("connecting to {url}"))
}

/// One WebSocket handshake with `url`, asking for `protocol`.
async fn open(
    url: &str,
    protocol: u16,
    config: Option<WebSocketConfig>,
) -> Result<Socket, tokio_tungstenite::tungstenite::Error> {
    let mut request = url.into_client_request()?;
    if protocol > wire::PLAIN_PROTOCOL_VERSION {
        let name = wire::subprotocol(protocol);
        request.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            name.parse().expect("radcast.N is a header value"),
        );
    }
    let (socket, _) = tokio_tungstenite::connect_async_with_config(request, config, false).await?;
    Ok(socket)
}

/// Connects to `url` with `protocol` and applies frames until one is final, or fails after
/// `limit`.
pub async fn watch_until_final(
    url: &str,
    protocol: u16,
    limit: Duration,
) -> anyhow::Result<ViewerOutcome> {
    tokio::time::timeout(limit, run(url, protocol))
        .await
        .with_context(|| format!("{url}: no final frame within {limit:?}"))?
}

/// Like [`watch_until_final`] on `urls[first % n]`; a server that fails is left for the next
/// in turn, until each failed once.
pub async fn watch_until_final_on_any(
    urls: &[String],
    first: usize,
    protocol: u16,
    limit: Duration,
) -> anyhow::Result<ViewerOutcome> {
    let mut failures = Vec::new();
    for k in 0..urls.len() {
        let url = &urls[(first + k) % urls.len()];
        match watch_until_final(url, protocol, limit).await {
            Ok(outcome) => return Ok(outcome),
            Err(error) => failures.push(format!("{error:#}")),
        }
    }
    bail!("every server failed: {}", failures.join("; "))
}

/// The next binary message on `socket`: `None` when the connection ends; an error when it
/// fails or the server closes it.
pub async fn next_binary(socket: &mut Socket) -> Option<anyhow::Result<Bytes>> {
    while let Some(message) = socket.next().await {
        match message {
            Ok(Message::Binary(data)) => return Some(Ok(data)),
            Ok(Message::Close(frame)) => {
                return Some(Err(anyhow!("the server closed the connection: {frame:?}")));
            }
            Ok(_) => {}
            Err(error) => return Some(Err(anyhow!("connection failed: {error}"))),
        }
    }
    None
}

/// Asks the server for a full frame (after [`Step::NeedsFull`]).
pub async fn request_full(socket: &mut Socket) -> anyhow::Result<()> {
    socket
        .send(Message::Binary(ClientMessage::RequestFull.encode().into()))
        .await
        .context("asking for a full frame")
}

async fn run(url: &str, protocol: u16) -> anyhow::Result<ViewerOutcome> {
    let start = Instant::now();
    let mut socket = connect(url, protocol, None).await?;
    let mut viewer = Viewer::default();
    let (mut frames, mut bytes, mut first_frame) = (0u64, 0u64, None);
    while let Some(data) = next_binary(&mut socket).await {
        let data = data.with_context(|| url.to_string())?;
        match viewer.receive(&data).with_context(|| url.to_string())? {
            Step::Hello(_) | Step::GeometryChanged { .. } => {}
            Step::Response { .. } => bytes += data.len() as u64,
            Step::NeedsFull => request_full(&mut socket).await?,
            Step::Applied { info, .. } => {
                frames += 1;
                bytes += data.len() as u64;
                first_frame.get_or_insert_with(|| start.elapsed());
                if info.is_final {
                    let _ = socket.close(None).await;
                    return Ok(ViewerOutcome {
                        hello: viewer.hello().context("applied frames follow the hello")?,
                        buffer: viewer.into_buffer(),
                        frames,
                        bytes,
                        first_frame: first_frame.unwrap_or_default(),
                    });
                }
            }
        }
    }
    bail!("{url}: connection ended before a final frame")
}
