//! One viewer's connection: hello, the current frame, then every newer version (as a delta
//! when the viewer holds its base), until the viewer leaves, misbehaves or stalls.

use crate::Shared;
use crate::metrics::{DropReason, Metrics};
use axum::extract::ws::{CloseFrame, Message, WebSocket, close_code};
use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use std::net::IpAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use tokio::time::{Instant, interval, timeout};
use wire::{ClientMessage, ServerMessage};

/// A claimed place under the viewer limits; released however the connection ends, including
/// an upgrade that never completes.
pub struct ViewerSlot(Arc<Shared>, IpAddr);

impl Drop for ViewerSlot {
    fn drop(&mut self) {
        self.0.metrics.viewers.fetch_sub(1, Ordering::Relaxed);
        let mut per_ip = self.0.viewers_per_ip.lock().expect("per-IP lock");
        if let Some(count) = per_ip.get_mut(&self.1) {
            *count -= 1;
            if *count == 0 {
                per_ip.remove(&self.1);
            }
        }
    }
}

/// Why a viewer was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// The server holds its maximum number of viewers.
    ServerFull,
    /// That address holds its maximum number of viewers.
    AddressFull,
}

/// Claims a viewer slot for a viewer from `ip`, or says which limit refused it (counted).
pub fn try_admit(shared: &Arc<Shared>, ip: IpAddr) -> Result<ViewerSlot, Refusal> {
    let metrics: &Metrics = &shared.metrics;
    let mut per_ip = shared.viewers_per_ip.lock().expect("per-IP lock");
    let from_ip = per_ip.entry(ip).or_insert(0);
    if *from_ip >= shared.limits.max_viewers_per_ip {
        metrics.refused_per_ip.fetch_add(1, Ordering::Relaxed);
        if *from_ip == 0 {
            per_ip.remove(&ip);
        }
        return Err(Refusal::AddressFull);
    }
    let limit = shared.limits.max_viewers as u64;
    if metrics
        .viewers
        .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
            (n < limit).then_some(n + 1)
        })
        .is_err()
    {
        metrics.refused.fetch_add(1, Ordering::Relaxed);
        if *from_ip == 0 {
            per_ip.remove(&ip);
        }
        return Err(Refusal::ServerFull);
    }
    *from_ip += 1;
    Ok(ViewerSlot(shared.clone(), ip))
}

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

/// Runs one admitted viewer to the end.
pub async fn serve_viewer(socket: WebSocket, slot: ViewerSlot) {
    let shared = slot.0.clone();
    let metrics = &shared.metrics;
    let (mut sink, mut stream) = socket.split();
    let limits = shared.limits;
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
                _ = shared.shutdown.cancelled() => break 'session End::Shutdown,
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
        End::Shutdown => Some(close(close_code::AWAY, "server shutting down")),
    };
    if let Some(message) = farewell {
        // Best effort: a stalled viewer may not take even this.
        let _ = timeout(limits.send_timeout, sink.send(message)).await;
    }
}
