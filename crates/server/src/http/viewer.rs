//! One viewer's connection: hello, the current frame, then every newer version (as a delta
//! when the viewer holds its base), until the viewer leaves, misbehaves or stalls.

use crate::Shared;
use crate::http::admission::Pass;
use crate::http::metrics::DropReason;
use crate::publish::hub::{HeldResponse, Published};
use axum::extract::ws::{CloseFrame, Message, WebSocket, close_code};
use bytes::Bytes;
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use std::collections::HashSet;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use tokio::sync::watch;
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

/// Runs one admitted viewer speaking `protocol` (2 or 3) to the end; `_place` holds its place
/// under the viewer caps.
pub async fn serve_viewer(socket: WebSocket, shared: Arc<Shared>, _place: Pass, protocol: u16) {
    let (sink, stream) = socket.split();
    let updates = shared.hub.subscribe();
    let mut viewer = Viewer {
        shared: &shared,
        sink,
        stream,
        updates,
        protocol,
        held: 0,
        held_sum: false,
        held_responses: HashSet::new(),
        held_geometry: 0,
        last_heard: Instant::now(),
    };
    let Err(end) = viewer.run().await;
    viewer.say_farewell(end).await;
}

/// One viewer's connection and what it holds.
struct Viewer<'a> {
    shared: &'a Shared,
    sink: SplitSink<WebSocket, Message>,
    stream: SplitStream<WebSocket>,
    updates: watch::Receiver<Arc<Published>>,
    /// The protocol version it speaks: 3 takes sums of responses.
    protocol: u16,
    /// The solution version the viewer holds (a delta's base must be this).
    held: u64,
    /// Whether it holds that version as a sum (then a delta cannot apply to it).
    held_sum: bool,
    /// The responses it was sent for the geometry it holds.
    held_responses: HashSet<u32>,
    /// The geometry version the viewer holds.
    held_geometry: u64,
    last_heard: Instant,
}

impl Viewer<'_> {
    /// Hello and the current frame, then every newer version and a ping each interval, until
    /// the session ends (never `Ok`).
    async fn run(&mut self) -> Result<std::convert::Infallible, End> {
        let limits = self.shared.process.limits;
        let geometry = self.shared.hub.geometry();
        self.held_geometry = geometry.version;
        self.send(Message::Binary(geometry.hello(self.protocol)))
            .await?;
        self.catch_up().await?;
        let mut ping = interval(limits.ping_interval);
        ping.tick().await;
        loop {
            let outgoing = tokio::select! {
                changed = self.updates.changed() => match changed {
                    Ok(()) => {
                        self.catch_up().await?;
                        continue;
                    }
                    Err(_) => return Err(End::Shutdown),
                },
                incoming = self.stream.next() => match self.answer(incoming)? {
                    Some(message) => message,
                    None => continue,
                },
                _ = ping.tick() => {
                    if self.last_heard.elapsed() > limits.idle_timeout {
                        return Err(End::Dropped(DropReason::Idle, "idle timeout"));
                    }
                    Message::Ping(Bytes::new())
                }
                _ = self.shared.retired.cancelled() => return Err(End::Shutdown),
            };
            self.send(outgoing).await?;
        }
    }

    /// Sends `message` within the send timeout, or ends the session: a viewer that does not
    /// take it has stopped reading.
    async fn send(&mut self, message: Message) -> Result<(), End> {
        if let Message::Binary(bytes) = &message {
            self.shared.metrics.sent(bytes.len());
        }
        let send_timeout = self.shared.process.limits.send_timeout;
        match timeout(send_timeout, self.sink.send(message)).await {
            Ok(Ok(())) => Ok(()),
            _ => Err(End::Dropped(DropReason::Slow, "send timed out")),
        }
    }

    /// Brings the viewer to the newest version: its responses (those not sent yet) and its sum
    /// for a protocol-3 viewer when the version has one, else a delta from the version it
    /// holds, or the full frame; nothing when it holds the newest already. A new geometry is
    /// announced first, so the viewer refetches it before the colours that go with it.
    async fn catch_up(&mut self) -> Result<(), End> {
        let newest = self.updates.borrow_and_update().clone();
        if newest.geometry_version != self.held_geometry && self.held != 0 {
            self.held_geometry = newest.geometry_version;
            self.held_responses.clear();
            let notice = ServerMessage::GeometryChanged {
                geometry_version: self.held_geometry,
            };
            self.send(Message::Binary(Bytes::from(notice.encode())))
                .await?;
        }
        if let Some(sum) = newest.sum.as_ref().filter(|_| self.protocol >= 3) {
            if self.held == newest.version && self.held_sum {
                return Ok(());
            }
            if let Some(responses) = self.responses_to_send(&sum.response_ids) {
                for response in responses {
                    self.send(Message::Binary(response.message.clone())).await?;
                    self.held_responses.insert(response.response.response_id);
                }
                self.send(Message::Binary(sum.frame.clone())).await?;
                self.hold(&newest, true);
                return Ok(());
            }
            // A response already replaced by a newer set: this version travels as frames.
        }
        if self.held == newest.version && !self.held_sum {
            return Ok(());
        }
        let bytes = match &newest.delta {
            Some((base, delta)) if *base == self.held && !self.held_sum => delta.clone(),
            _ => newest.full.clone(),
        };
        self.send(Message::Binary(bytes)).await?;
        self.hold(&newest, false);
        Ok(())
    }

    /// The responses of `ids` this viewer lacks, or `None` if the hub no longer has one.
    fn responses_to_send(&self, ids: &[u32]) -> Option<Vec<Arc<HeldResponse>>> {
        ids.iter()
            .filter(|id| !self.held_responses.contains(id))
            .map(|id| self.shared.hub.response(*id))
            .collect()
    }

    /// Records that the viewer now holds `published` (as its sum or as codes), counting the
    /// versions it skipped and the full frames it took.
    fn hold(&mut self, published: &Published, as_sum: bool) {
        let metrics = &self.shared.metrics;
        let skipped = published.version.saturating_sub(self.held + 1);
        if self.held != 0 && skipped > 0 {
            metrics
                .versions_skipped
                .fetch_add(skipped, Ordering::Relaxed);
        }
        let was_delta = !as_sum
            && !self.held_sum
            && published
                .delta
                .as_ref()
                .is_some_and(|(base, _)| *base == self.held);
        if !as_sum && !was_delta && self.held != 0 {
            metrics.full_resyncs.fetch_add(1, Ordering::Relaxed);
        }
        self.held = published.version;
        self.held_sum = as_sum;
    }

    /// What to send for what the viewer sent (`None`: nothing), or why the session ends.
    fn answer(
        &mut self,
        incoming: Option<Result<Message, axum::Error>>,
    ) -> Result<Option<Message>, End> {
        self.last_heard = Instant::now();
        let bad = |text| Err(End::Dropped(DropReason::BadMessage, text));
        match incoming {
            Some(Ok(Message::Binary(bytes))) => match ClientMessage::decode(&bytes) {
                Ok(ClientMessage::RequestFull) => {
                    let newest = self.updates.borrow_and_update().clone();
                    (self.held, self.held_sum) = (newest.version, false);
                    let metrics = &self.shared.metrics;
                    metrics.full_resyncs.fetch_add(1, Ordering::Relaxed);
                    Ok(Some(Message::Binary(newest.full.clone())))
                }
                Err(_) => bad("not a radcast message"),
            },
            Some(Ok(Message::Text(_))) => bad("text messages are not part of the protocol"),
            Some(Ok(Message::Ping(_) | Message::Pong(_))) => Ok(None),
            Some(Ok(Message::Close(_))) | None => Err(End::Left),
            Some(Err(error)) => match classify(error) {
                Some(text) => bad(text),
                None => Err(End::Left),
            },
        }
    }

    /// The close frame that says why the session ended, sent best effort: a stalled viewer may
    /// not take even this, and shutdown does not wait for it.
    async fn say_farewell(mut self, end: End) {
        let close = |code, reason: &str| {
            Message::Close(Some(CloseFrame {
                code,
                reason: reason.into(),
            }))
        };
        let shutting_down = self.shared.process.shutdown.is_cancelled();
        let message = match end {
            End::Left => return,
            End::Dropped(reason, text) => {
                self.shared.metrics.dropped(reason);
                let code = match reason {
                    DropReason::BadMessage => close_code::POLICY,
                    _ => close_code::AWAY,
                };
                close(code, text)
            }
            End::Shutdown => close(
                close_code::AWAY,
                match shutting_down {
                    true => "server shutting down",
                    false => "the scene's origin restarted: reconnect",
                },
            ),
        };
        let limits = self.shared.process.limits;
        let patience = match shutting_down {
            true => limits.send_timeout.min(crate::SHUTDOWN_GRACE),
            false => limits.send_timeout,
        };
        let _ = timeout(patience, self.sink.send(message)).await;
    }
}
