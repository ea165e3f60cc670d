//! The accept loop: every TCP connection is counted against the connection caps before any
//! byte is read, must finish its request headers within the header timeout, and may buffer
//! only [`MAX_REQUEST_HEAD_BYTES`]; so sockets that trickle partial headers are closed on time,
//! can neither take every file descriptor nor hold memory, and one address cannot take the
//! server. On shutdown the loop stops accepting and open requests get a short grace.

use crate::Process;
use crate::http::admission::{Pass, Refusal};
use axum::extract::ConnectInfo;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tower::ServiceExt;

/// Largest request head (request line and headers) a connection may buffer, bytes. A browser's
/// WebSocket upgrade is about 1 KB; hyper's default (~400 KB) let 20,000 trickling sockets hold
/// 431 MB.
pub const MAX_REQUEST_HEAD_BYTES: usize = 16 * 1024;

/// A connection refused before reading anything is told so in one short write, at most this slow.
const REFUSAL_WRITE_TIMEOUT: Duration = Duration::from_secs(1);

/// A socket that holds its place under the connection caps for as long as it lives, through
/// an upgrade to WebSocket too.
struct Counted {
    stream: TcpStream,
    _pass: Pass,
}

impl AsyncRead for Counted {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for Counted {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

/// The response written to a connection refused at a cap (no request is read from it).
pub fn refusal_response(refusal: Refusal, peer: SocketAddr) -> String {
    let (status, body) = match refusal {
        Refusal::ServerFull => (
            "503 Service Unavailable",
            "radcast-server: connection limit reached\n".to_string(),
        ),
        Refusal::AddressFull => (
            "429 Too Many Requests",
            format!("radcast-server: too many connections from {}\n", peer.ip()),
        ),
    };
    format!(
        "HTTP/1.1 {status}\r\ncontent-type: text/plain\r\ncontent-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n{body}",
        body.len()
    )
}

/// Serves `router` on `listener` until `process.shutdown` is cancelled. Each connection (and
/// each viewer it becomes) is tracked in `process.tasks`, so a caller can wait for their ends.
pub async fn serve_router(
    listener: TcpListener,
    router: axum::Router,
    process: Arc<Process>,
) -> std::io::Result<()> {
    loop {
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(error) => {
                    // Out of descriptors (or a connection reset before accept): wait for
                    // some to close rather than spin.
                    tracing::warn!("accept failed: {error}");
                    tokio::select! {
                        _ = tokio::time::sleep(Duration::from_millis(50)) => continue,
                        _ = process.shutdown.cancelled() => return Ok(()),
                    }
                }
            },
            _ = process.shutdown.cancelled() => return Ok(()),
        };
        match process.connections.admit(peer.ip()) {
            Ok(pass) => {
                let io = TokioIo::new(Counted {
                    stream,
                    _pass: pass,
                });
                process
                    .tasks
                    .spawn(connection(io, peer, router.clone(), process.clone()));
            }
            Err(refusal) => {
                process.tasks.spawn(async move {
                    let mut stream = stream;
                    let text = refusal_response(refusal, peer);
                    let _ = tokio::time::timeout(
                        REFUSAL_WRITE_TIMEOUT,
                        stream.write_all(text.as_bytes()),
                    )
                    .await;
                });
            }
        }
    }
}

/// One HTTP/1.1 connection, upgrades included, until it ends or shutdown's grace runs out.
async fn connection(
    io: TokioIo<Counted>,
    peer: SocketAddr,
    router: axum::Router,
    process: Arc<Process>,
) {
    let service = hyper::service::service_fn(move |mut request: hyper::Request<_>| {
        // Routes read the peer address for the per-address viewer cap.
        request.extensions_mut().insert(ConnectInfo(peer));
        router.clone().oneshot(request)
    });
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(process.limits.header_timeout)
        .max_buf_size(MAX_REQUEST_HEAD_BYTES);
    let connection = http.serve_connection(io, service).with_upgrades();
    tokio::pin!(connection);
    tokio::select! {
        _ = connection.as_mut() => {}
        _ = process.shutdown.cancelled() => {
            connection.as_mut().graceful_shutdown();
            let _ = tokio::time::timeout(crate::SHUTDOWN_GRACE, connection).await;
        }
    }
}
