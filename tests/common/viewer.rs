//! A viewer over a real WebSocket that keeps its buffer current, for end-to-end tests.

use futures_util::StreamExt;
use std::net::SocketAddr;
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;
use wire::{ColourBuffer, ServerMessage};

/// Generous bound on a wait for a state; a hang fails instead of blocking CI.
const PATIENCE: Duration = Duration::from_secs(90);

/// A viewer that applies every frame it gets, and notes what came as deltas and geometry changes.
pub struct Viewer {
    socket: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    /// The colours held now.
    pub buffer: ColourBuffer,
    /// The number of changed vertices of every delta received.
    pub deltas: Vec<usize>,
    /// The number of full frames received.
    pub full_frames: usize,
    /// Every geometry version announced.
    pub geometry_versions: Vec<u64>,
    /// Protocol 3: the id of every response received.
    pub responses: Vec<u32>,
    /// Protocol 3: the size in bytes of every sum frame received.
    pub sums: Vec<usize>,
}

impl Viewer {
    /// Connects to `ws://ADDRESS/ws`, speaking protocol 2 (no subprotocol asked for).
    pub async fn connect(address: SocketAddr) -> Viewer {
        Viewer::connect_speaking(address, 2).await
    }

    /// Connects to `ws://ADDRESS/ws` asking for `protocol` with its WebSocket subprotocol.
    pub async fn connect_speaking(address: SocketAddr, protocol: u16) -> Viewer {
        use tokio_tungstenite::tungstenite::client::IntoClientRequest;
        let mut request = format!("ws://{address}/ws").into_client_request().unwrap();
        if protocol > 2 {
            let name = wire::subprotocol(protocol).parse().unwrap();
            request.headers_mut().insert("Sec-WebSocket-Protocol", name);
        }
        let (socket, _) = tokio_tungstenite::connect_async(request).await.unwrap();
        Viewer {
            socket,
            buffer: ColourBuffer::default(),
            deltas: Vec::new(),
            full_frames: 0,
            geometry_versions: Vec::new(),
            responses: Vec::new(),
            sums: Vec::new(),
        }
    }

    /// Reads until it holds a final frame that satisfies `done`; fails if the connection ends.
    pub async fn wait_for(&mut self, done: impl Fn(&ColourBuffer) -> bool) {
        tokio::time::timeout(PATIENCE, async {
            while !(self.buffer.info.is_some_and(|i| i.is_final) && done(&self.buffer)) {
                let bytes = match self.socket.next().await {
                    Some(Ok(Message::Binary(bytes))) => bytes,
                    Some(Ok(_)) => continue,
                    other => panic!("the viewer's connection ended: {other:?}"),
                };
                let message = ServerMessage::decode(&bytes).unwrap();
                match &message {
                    ServerMessage::Delta(delta) => self.deltas.push(delta.indices.len()),
                    ServerMessage::Full(_) => self.full_frames += 1,
                    ServerMessage::GeometryChanged { geometry_version } => {
                        self.geometry_versions.push(*geometry_version)
                    }
                    ServerMessage::Response(response) => self.responses.push(response.response_id),
                    ServerMessage::Sum(_) => self.sums.push(bytes.len()),
                    _ => {}
                }
                self.buffer
                    .apply(&message)
                    .expect("deltas apply to what the viewer holds");
            }
        })
        .await
        .expect("the expected state arrives");
    }

    /// Reads until it holds a final frame whose checksum is `checksum`.
    pub async fn ends_with(&mut self, checksum: u32) {
        self.wait_for(|buffer| wire::checksum(&buffer.colours) == checksum)
            .await
    }

    /// The solution version held (0 before the first frame).
    pub fn version(&self) -> u64 {
        self.buffer.info.map_or(0, |i| i.solution_version)
    }
}
