//! One viewer's WebSocket session: hello, then frames applied to a [`PatchBuffer`].

use anyhow::{Context, bail};
use futures_util::{SinkExt, StreamExt};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;
use wire::{ApplyError, ClientMessage, Hello, PatchBuffer, ServerMessage};

/// A viewer's WebSocket.
pub type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// What a viewer ended with.
#[derive(Debug)]
pub struct ViewerOutcome {
    /// The server's hello.
    pub hello: Hello,
    /// The colours at the end.
    pub buffer: PatchBuffer,
    /// Frames received (full and delta).
    pub frames: u64,
    /// Bytes of frames received.
    pub bytes: u64,
    /// Time from connecting to the first full frame.
    pub first_frame: Duration,
}

/// Connects to `url` and applies frames until one is final, or fails after `limit`.
pub async fn watch_until_final(url: &str, limit: Duration) -> anyhow::Result<ViewerOutcome> {
    tokio::time::timeout(limit, run(url))
        .await
        .with_context(|| format!("{url}: no final frame within {limit:?}"))?
}

async fn run(url: &str) -> anyhow::Result<ViewerOutcome> {
    let start = Instant::now();
    let (mut socket, _) = tokio_tungstenite::connect_async(url)
        .await
        .with_context(|| format!("connecting to {url}"))?;
    let mut hello = None;
    let mut buffer = PatchBuffer::default();
    let (mut frames, mut bytes, mut first_frame) = (0u64, 0u64, None);
    while let Some(message) = socket.next().await {
        let data = match message.with_context(|| format!("{url}: connection failed"))? {
            Message::Binary(data) => data,
            Message::Close(frame) => bail!("{url}: server closed the connection: {frame:?}"),
            _ => continue,
        };
        let message = ServerMessage::decode(&data)
            .with_context(|| format!("{url}: bad message from the server"))?;
        match (&message, hello) {
            // Colours stay valid across a geometry change; a renderer refetches the geometry.
            (ServerMessage::GeometryChanged { .. }, _) => continue,
            (ServerMessage::Hello(h), None) => hello = Some(*h),
            (ServerMessage::Hello(_), Some(_)) => bail!("{url}: a second hello"),
            (_, None) => bail!("{url}: a frame before the hello"),
            (_, Some(h)) => {
                frames += 1;
                bytes += data.len() as u64;
                match buffer.apply(&message) {
                    Ok(()) => {}
                    Err(ApplyError::BaseMismatch { .. }) => {
                        socket
                            .send(Message::Binary(ClientMessage::RequestFull.encode().into()))
                            .await?;
                        continue;
                    }
                }
                if buffer.colours.len() != h.patch_count as usize {
                    bail!(
                        "{url}: frame has {} patches, hello said {}",
                        buffer.colours.len(),
                        h.patch_count
                    );
                }
                first_frame.get_or_insert_with(|| start.elapsed());
                if buffer.info.is_some_and(|i| i.is_final) {
                    let _ = socket.close(None).await;
                    return Ok(ViewerOutcome {
                        hello: h,
                        buffer,
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
