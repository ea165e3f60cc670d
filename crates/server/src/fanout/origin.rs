//! The origin's side: each version the hub publishes goes to NATS once, whatever the number of
//! edges — the frame first (for latency), its snapshot stored right after (a new geometry
//! before it) — and control requests that edges forward are answered as the HTTP route would.

use super::{
    Nats, SceneRecord, Tag, alive_subject, control_subject, frame_subject, full_object,
    geometry_object, header, headers, record_object, record_subject, texture_object,
};
use crate::Shared;
use crate::control::{Field, Reply};
use crate::health::Fault;
use crate::publish::hub::Published;
use async_nats::jetstream::object_store;
use axum::http::StatusCode;
use bytes::Bytes;
use futures_util::StreamExt;
use std::sync::Arc;

/// What NATS holds of this origin's scene, as far as it knows.
struct Sent {
    version: u64,
    geometry_version: u64,
    record: SceneRecord,
}

/// Publishes `shared`'s scene as `scene` on `nats` and answers its control requests, until
/// shutdown. `run` tells this start of the origin from earlier ones.
pub async fn serve(shared: Arc<Shared>, nats: Nats, scene: String, run: String) {
    tokio::join!(
        publish(&shared, &nats, &scene, &run),
        answer_control(&shared, &nats, &scene)
    );
}

async fn publish(shared: &Shared, nats: &Nats, scene: &str, run: &str) {
    let mut updates = shared.hub.subscribe();
    let mut connects = nats.connects.clone();
    connects.mark_unchanged();
    let mut alive = tokio::time::interval(super::ALIVE_INTERVAL);
    let mut store = None;
    let mut sent = None;
    loop {
        tokio::select! {
            changed = updates.changed() => if changed.is_err() { return },
            _ = alive.tick() => {
                // Best effort: a lost heartbeat only makes edges wait for the next.
                let _ = nats.client.publish(alive_subject(scene), Bytes::from(run.to_string())).await;
            }
            // NATS may have restarted without its stores: send everything again.
            _ = connects.changed() => (store, sent) = (None, None),
            _ = shared.process.shutdown.cancelled() => return,
        }
        match publish_newest(shared, nats, scene, run, &mut store, &mut sent).await {
            Ok(()) => shared.health.recovered(Fault::Nats),
            Err(error) => {
                store = None;
                shared.health.fault(
                    Fault::Nats,
                    format!("publishing scene '{scene}' to NATS failed: {error:#} (retrying every second)"),
                );
            }
        }
    }
}

/// Sends what NATS lacks of the hub's newest state: the geometry snapshot when it changed,
/// the record when it changed, the frame (the delta when NATS holds its base), then the full
/// frame and record snapshots.
async fn publish_newest(
    shared: &Shared,
    nats: &Nats,
    scene: &str,
    run: &str,
    store: &mut Option<object_store::ObjectStore>,
    sent: &mut Option<Sent>,
) -> anyhow::Result<()> {
    let objects = match store {
        Some(store) => store,
        None => store.insert(nats.snapshots().await?),
    };
    let current = shared.hub.current();
    let geometry = shared.hub.geometry();
    if geometry.version != current.geometry_version {
        // A move in progress: the frame for the new geometry follows and is sent with it.
        return Ok(());
    }
    let tag = |version| Tag {
        run: run.to_string(),
        scene_id: geometry.scene_id,
        version,
        geometry_version: geometry.version,
    };
    let held = sent.as_ref().map(|s| (s.version, s.geometry_version));
    if held.is_none() {
        // Textures never change within a run: stored once, before any geometry naming them.
        for (index, png) in geometry.textures.iter().enumerate() {
            put(
                objects,
                &texture_object(scene, index),
                tag(geometry.version),
                png,
            )
            .await?;
        }
    }
    if held.map(|(_, g)| g) != Some(geometry.version) {
        put(
            objects,
            &geometry_object(scene),
            tag(geometry.version),
            &geometry.encoded,
        )
        .await?;
    }
    let record = SceneRecord {
        run: run.to_string(),
        report: shared.report.lock().expect("report lock").clone(),
        emissions: shared.emissions.lock().expect("emissions lock").clone(),
        health: shared.health.text(),
        sum_checksum: current
            .sum
            .as_ref()
            .map(|sum| (current.version, sum.checksum)),
    };
    let record_json = match sent.as_ref().map(|s| &s.record) != Some(&record) {
        true => Some(serde_json::to_vec(&record)?),
        false => None,
    };
    if let Some(json) = &record_json {
        // Before the frame, on the same connection: edges get the two in this order.
        let mut record_headers = async_nats::HeaderMap::new();
        record_headers.insert(headers::VERSION, current.version.to_string());
        nats.client
            .publish_with_headers(record_subject(scene), record_headers, json.clone().into())
            .await?;
    }
    let held_version = held.map(|(v, _)| v);
    if held_version != Some(current.version) {
        publish_frame(
            nats,
            objects,
            scene,
            &current,
            held_version,
            tag(current.version),
        )
        .await?;
    }
    if let Some(json) = &record_json {
        put(objects, &record_object(scene), tag(current.version), json).await?;
    }
    *sent = Some(Sent {
        version: current.version,
        geometry_version: geometry.version,
        record,
    });
    Ok(())
}

/// Publishes `current`'s frame (its delta when NATS holds its base, `held_version`) and stores
/// its full frame as the snapshot, tagged `full_tag`.
async fn publish_frame(
    nats: &Nats,
    objects: &object_store::ObjectStore,
    scene: &str,
    current: &Published,
    held_version: Option<u64>,
    full_tag: Tag,
) -> anyhow::Result<()> {
    let payload = match &current.delta {
        Some((base, delta)) if held_version == Some(*base) => delta.clone(),
        _ => current.full.clone(),
    };
    let mut frame_headers = async_nats::HeaderMap::new();
    frame_headers.insert(headers::VERSION, current.version.to_string());
    frame_headers.insert(headers::GEOMETRY, full_tag.geometry_version.to_string());
    frame_headers.insert(headers::RUN, full_tag.run.as_str());
    let subject = frame_subject(scene);
    let full_name = full_object(scene);
    let full = |objects| put(objects, &full_name, full_tag, &current.full);
    if payload.len() <= nats.client.server_info().max_payload {
        // The frame first, for latency; the snapshot right after, for edges that missed it
        // (one that asks in between retries a second later).
        nats.client
            .publish_with_headers(subject, frame_headers, payload)
            .await?;
        full(objects).await?;
    } else {
        // Too big for one message: an empty announcement after the snapshot is stored.
        full(objects).await?;
        nats.client
            .publish_with_headers(subject, frame_headers, Bytes::new())
            .await?;
    }
    Ok(())
}

async fn put(
    objects: &object_store::ObjectStore,
    name: &str,
    tag: Tag,
    bytes: &[u8],
) -> anyhow::Result<()> {
    let metadata = object_store::ObjectMetadata {
        name: name.to_string(),
        metadata: tag.to_metadata(),
        ..Default::default()
    };
    objects
        .put(metadata, &mut &bytes[..])
        .await
        .map_err(|e| anyhow::anyhow!("cannot store {name}: {e}"))?;
    Ok(())
}

/// Answers control requests edges forward, with the token checked here as on HTTP.
async fn answer_control(shared: &Shared, nats: &Nats, scene: &str) {
    let mut requests = match nats.client.subscribe(control_subject(scene)).await {
        Ok(requests) => requests,
        Err(error) => {
            shared.health.fault(
                Fault::Nats,
                format!("cannot take control requests for '{scene}' over NATS: {error}"),
            );
            return;
        }
    };
    loop {
        let request = tokio::select! {
            request = requests.next() => match request {
                Some(request) => request,
                None => return,
            },
            _ = shared.process.shutdown.cancelled() => return,
        };
        let Some(reply_to) = request.reply.clone() else {
            continue;
        };
        let text = |name| header::<String>(&request, name);
        let answer = match (
            text(headers::OBJECT),
            text(headers::FIELD).as_deref().and_then(Field::from_key),
        ) {
            (Some(object), Some(field)) => crate::control::apply(
                shared,
                &object,
                field,
                text(headers::AUTHORIZATION).as_deref(),
                &request.payload,
            ),
            _ => Reply::refusal(
                StatusCode::BAD_REQUEST,
                "a control request over NATS needs the headers Radcast-Object and Radcast-Field",
            ),
        };
        let mut reply_headers = async_nats::HeaderMap::new();
        reply_headers.insert(headers::STATUS, answer.status.as_u16().to_string());
        let body = serde_json::to_vec(&answer.body).unwrap_or_default();
        // An edge that gave up waiting gets nothing; it already answered 503.
        let _ = nats
            .client
            .publish_with_headers(reply_to, reply_headers, body.into())
            .await;
    }
}
