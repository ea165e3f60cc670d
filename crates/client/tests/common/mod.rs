//! A stand-in server for the client's own tests: it speaks the protocol over a real socket.
#![allow(dead_code)] // each test binary uses its own subset

use futures_util::SinkExt;
use tokio_tungstenite::tungstenite::Message;
use wire::{FrameInfo, FullFrame, Hello, ServerMessage};

/// A viewer's socket on the server side.
pub type Socket = tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>;

/// Accepts one viewer on an ephemeral port and hands its socket to `serve`; returns the port's
/// address at once. It is a protocol-2 server, as servers were before subprotocols: it answers
/// a viewer that asks for `radcast.3` without one (which such a viewer must refuse, then
/// connect again asking for none) and serves the first that asks for none.
pub async fn serve_one<F, Fut>(serve: F) -> std::net::SocketAddr
where
    F: FnOnce(Socket) -> Fut + Send + 'static,
    Fut: Future<Output = ()> + Send,
{
    use tokio_tungstenite::tungstenite::handshake::server::{Request, Response};
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(async move {
        loop {
            let (stream, _) = listener.accept().await.unwrap();
            let mut asked = false;
            // The signature is tungstenite's handshake callback, its error type theirs.
            #[allow(clippy::result_large_err)]
            let note = |request: &Request, response: Response| {
                asked = request.headers().contains_key("Sec-WebSocket-Protocol");
                Ok(response)
            };
            let Ok(socket) = tokio_tungstenite::accept_hdr_async(stream, note).await else {
                continue;
            };
            if !asked {
                serve(socket).await;
                return;
            }
        }
    });
    address
}

/// Sends the hello of a one-vertex scene; false when the viewer is gone.
pub async fn send_hello(socket: &mut Socket) -> bool {
    let hello = Hello {
        protocol_version: wire::PLAIN_PROTOCOL_VERSION,
        scene_id: 1,
        geometry_version: 1,
        vertex_count: 1,
    };
    send(socket, ServerMessage::Hello(hello)).await
}

/// Sends a full frame of `version` (its one vertex's red is the version); false when the
/// viewer is gone.
pub async fn send_full(socket: &mut Socket, version: u64, is_final: bool) -> bool {
    let frame = FullFrame {
        info: FrameInfo {
            solution_version: version,
            sent_at_unix_micros: wire::unix_micros_now(),
            scale: 1.0,
            vertex_count: 1,
            is_final,
        },
        colours: vec![wire::encode_colour([version as f32, 0.0, 0.0], 1.0)],
    };
    send(socket, ServerMessage::Full(frame)).await
}

async fn send(socket: &mut Socket, message: ServerMessage) -> bool {
    socket
        .send(Message::Binary(message.encode().into()))
        .await
        .is_ok()
}
