//! One viewer's connection: hello, the current frame, then every newer version (as a delta
//! when the viewer holds its base), until the viewer leaves, misbehaves or stalls.

use crate::Shared;
use crate::http::admission::Pass;
use crate::http::metrics::DropReason;
use axum::extract::ws::{CloseFrame, Message, WebSocket, close_code};
use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use tokio::time::{Instant, interval, timeout};
use wire::{ClientMessage, ServerMessage};

/// Why a read failed: `Some(reason)` when the viewer broke the protocol (an oversized or
/// malformed message), `None` when it just went away (reset, closed socket).
fn classify(error: axum::Error) -> Option<&'static str> {
    use tokio_tungstenite::tungstenite::Error;
    match error.into_inner().downcast::<Error>().map(|e| *e) {
        Ok(Error::Capacity(_)) => Some("message too large"),
        Ok(Error::Protocol(
            tokio_tungstenite::tungstenite::error::ProtocolError::ResetWithoutClosingHandshake,
        )) => None,
        Ok(Error::ConnectionClosed | Error::AlreadyClosed | Error::Io(_)) => None,
        Ok(_) => Some("malformed WebSocket message"),
        Err(_) => None,
    }
}

/// What ended a session.
enum End {
    Left,
    Dropped(DropReason, &'static str),
    Shutdown,
}

/// Runs one admitted viewer to the end; `_place` holds its place under the viewer caps.
pub async fn serve_viewer(socket: WebSocket, shared: Arc<Shared>, _place: Pass) {
    let metrics = &shared.metrics;
    let (mut sink, mut stream) = socket.split();
    let limits = shared.process.limits;
    let mut updates = shared.hub.subscribe();
    let sent = |bytes: &Bytes| metrics.sent(bytes.len());

    let end = 'session: {
        let first = updates.borrow_and_update().clone();
        let geometry = shared.hub.geometry();
        let mut held_geometry = geometry.version;
        for bytes in [geometry.hello.clone(), first.full.clone()] {
            sent(&bytes);
            if !matches!(
                timeout(limits.send_timeout, sink.send(Message::Binary(bytes))).await,
                Ok(Ok(()))
            ) {
                break 'session End::Dropped(DropReason::Slow, "send timed out");
            }
        }
        let mut held = first.version;
        let mut last_heard = Instant::now();
        let mut ping = interval(limits.ping_interval);
        ping.tick().await;
        loop {
            let outgoing = tokio::select! {
                changed = updates.changed() => {
                    if changed.is_err() {
                        break 'session End::Shutdown;
                    }
                    let newest = updates.borrow_and_update().clone();
                    if newest.geometry_version != held_geometry {
                        // Tell the viewer to refetch the geometry before the colours that go with it.
                        held_geometry = newest.geometry_version;
                        let notice = Bytes::from(ServerMessage::GeometryChanged { geometry_version: held_geometry }.encode());
                        sent(&notice);
                        if !matches!(timeout(limits.send_timeout, sink.send(Message::Binary(notice))).await, Ok(Ok(()))) {
                            break 'session End::Dropped(DropReason::Slow, "send timed out");
                        }
                    }
                    let bytes = match &newest.delta {
                        Some((base, delta)) if *base == held => delta.clone(),
                        _ => {
                            metrics.versions_skipped.fetch_add(newest.version.saturating_sub(held + 1), Ordering::Relaxed);
                            metrics.full_resyncs.fetch_add(1, Ordering::Relaxed);
                            newest.full.clone()
                        }
                    };
                    held = newest.version;
                    Message::Binary(bytes)
                }
                incoming = stream.next() => {
                    last_heard = Instant::now();
                    match incoming {
                        Some(Ok(Message::Binary(bytes))) => match ClientMessage::decode(&bytes) {
                            Ok(ClientMessage::RequestFull) => {
                                let newest = updates.borrow_and_update().clone();
                                held = newest.version;
                                metrics.full_resyncs.fetch_add(1, Ordering::Relaxed);
                                Message::Binary(newest.full.clone())
                            }
                            Err(_) => break 'session End::Dropped(DropReason::BadMessage, "not a radcast message"),
                        },
                        Some(Ok(Message::Text(_))) => break 'session End::Dropped(DropReason::BadMessage, "text messages are not part of the protocol"),
                        Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                        Some(Ok(Message::Close(_))) | None => break 'session End::Left,
                        Some(Err(error)) => match classify(error) {
                            Some(text) => break 'session End::Dropped(DropReason::BadMessage, text),
                            None => break 'session End::Left,
                        },
                    }
                }
                _ = ping.tick() => {
                    if last_heard.elapsed() > limits.idle_timeout {
                        break 'session End::Dropped(DropReason::Idle, "idle timeout");
                    }
                    Message::Ping(Bytes::new())
                }
                _ = shared.retired.cancelled() => break 'session End::Shutdown,
            };
            if let Message::Binary(bytes) = &outgoing {
                sent(bytes);
            }
            if !matches!(
                timeout(limits.send_timeout, sink.send(outgoing)).await,
                Ok(Ok(()))
            ) {
                break 'session End::Dropped(DropReason::Slow, "send timed out");
            }
        }
    };
    let close = |code, reason: &str| {
        Message::Close(Some(CloseFrame {
            code,
            reason: reason.into(),
        }))
    };
    let farewell = match end {
        End::Left => None,
        End::Dropped(reason, text) => {
            metrics.dropped(reason);
            let code = if reason == DropReason::BadMessage {
                close_code::POLICY
            } else {
                close_code::AWAY
            };
            Some(close(code, text))
        }
        End::Shutdown => Some(close(
            close_code::AWAY,
            match shared.process.shutdown.is_cancelled() {
                true => "server shutting down",
                false => "the scene's origin restarted: reconnect",
            },
        )),
    };
    if let Some(message) = farewell {
        // Best effort: a stalled viewer may not take even this, and shutdown does not wait.
        let patience = match shared.process.shutdown.is_cancelled() {
            true => limits.send_timeout.min(crate::SHUTDOWN_GRACE),
            false => limits.send_timeout,
        };
        let _ = timeout(patience, sink.send(message)).await;
    }
}
