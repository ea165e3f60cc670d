//! The origin's side: each version the hub publishes goes to NATS once, whatever the number of
//! edges — the frame first (for latency), its snapshot stored right after (a new geometry
//! before it) — and control requests that edges forward are answered as the HTTP route would.

use super::{
    Nats, SceneRecord, Tag, alive_subject, control_subject, frame_subject, full_object,
    geometry_object, header, headers, pack, record_object, record_subject, responses_object,
    sum_object, sum_subject, texture_object,
};
use crate::Shared;
use crate::control::{Field, Reply};
use crate::health::Fault;
use crate::publish::hub::{GeometryState, Hub, Published, SumForm};
use async_nats::jetstream::object_store;
use axum::http::StatusCode;
use bytes::Bytes;
use futures_util::StreamExt;
use std::collections::BTreeSet;
use std::sync::Arc;

/// What NATS holds of this origin's scene, as far as it knows.
struct Sent {
    version: u64,
    geometry_version: u64,
    record: SceneRecord,
    /// The version whose sum was sent last.
    sum_version: Option<u64>,
    /// The responses sent this run.
    responses: BTreeSet<u32>,
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
    // Records sent this run; counted across reconnects, as edges keep the last they took.
    let mut records = 0;
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
        let sending = (&mut store, &mut sent, &mut records);
        match publish_newest(shared, nats, scene, run, sending).await {
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
/// the record when it changed (numbered after the `records` sent before it), the frame (the
/// delta when NATS holds its base), then the full frame and record snapshots.
async fn publish_newest(
    shared: &Shared,
    nats: &Nats,
    scene: &str,
    run: &str,
    (store, sent, records): (
        &mut Option<object_store::ObjectStore>,
        &mut Option<Sent>,
        &mut u64,
    ),
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
    if held.map(|(_, g)| g) != Some(geometry.version) {
        store_geometry(
            objects,
            scene,
            &geometry,
            held.is_none(),
            tag(geometry.version),
        )
        .await?;
    }
    let record = record_of(shared, run, &current);
    let record_json = match sent.as_ref().map(|s| &s.record) != Some(&record) {
        true => Some(announce_record(nats, scene, &record, records).await?),
        false => None,
    };
    let (mut sum_version, mut responses) = sent
        .as_ref()
        .map(|s| (s.sum_version, s.responses.clone()))
        .unwrap_or_default();
    let sum = current
        .sum
        .as_ref()
        .filter(|_| sum_version != Some(current.version));
    if let Some(sum) = sum {
        // Ahead of its frame, so an edge installs the two at once.
        let sum_tag = tag(current.version);
        publish_sum(
            nats,
            objects,
            scene,
            &shared.hub,
            sum,
            &mut responses,
            sum_tag,
        )
        .await?;
        sum_version = Some(current.version);
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
    if let Some(sum) = sum {
        put(
            objects,
            &sum_object(scene),
            tag(current.version),
            &sum.frame,
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
        sum_version,
        responses,
    });
    Ok(())
}

/// Stores `geometry` as the scene's geometry snapshot, with its textures first when
/// `with_textures` (the first time in a run: they never change within one).
async fn store_geometry(
    objects: &object_store::ObjectStore,
    scene: &str,
    geometry: &GeometryState,
    with_textures: bool,
    tag: Tag,
) -> anyhow::Result<()> {
    if with_textures {
        for (index, png) in geometry.textures.iter().enumerate() {
            put(objects, &texture_object(scene, index), tag.clone(), png).await?;
        }
    }
    put(objects, &geometry_object(scene), tag, &geometry.encoded).await
}

/// Publishes `record`, numbered after the `records` sent before it, and gives back its JSON to
/// store. Sent before the frame, on the same connection: edges get the two in this order.
async fn announce_record(
    nats: &Nats,
    scene: &str,
    record: &SceneRecord,
    records: &mut u64,
) -> anyhow::Result<Vec<u8>> {
    *records += 1;
    let json = serde_json::to_vec(&SceneRecord {
        sequence: *records,
        ..record.clone()
    })?;
    nats.client
        .publish(record_subject(scene), json.clone().into())
        .await?;
    Ok(json)
}

/// What `/api/solution`, `/api/objects` and `/healthz` answer now, as edges are told it
/// (numbered when it is sent).
fn record_of(shared: &Shared, run: &str, current: &Published) -> SceneRecord {
    SceneRecord {
        run: run.to_string(),
        report: shared.report.lock().expect("report lock").clone(),
        emissions: shared.emissions.lock().expect("emissions lock").clone(),
        health: shared.health.text(),
        sum_checksum: current
            .sum
            .as_ref()
            .map(|sum| (current.version, sum.checksum)),
        sequence: 0,
    }
}

/// Publishes the responses `sum` names that were not sent this run (`sent`; each one stored
/// first with the others it names, in case it is too big for a message or an edge misses it),
/// then the sum frame itself, on the sum subject with `tag`'s headers. A sum naming a
/// response the hub just replaced is not sent: the next version will be.
async fn publish_sum(
    nats: &Nats,
    objects: &object_store::ObjectStore,
    scene: &str,
    hub: &Hub,
    sum: &SumForm,
    sent: &mut BTreeSet<u32>,
    tag: Tag,
) -> anyhow::Result<()> {
    let Some(held) = sum
        .response_ids
        .iter()
        .map(|id| hub.response(*id))
        .collect::<Option<Vec<_>>>()
    else {
        return Ok(());
    };
    let subject = sum_subject(scene);
    let sum_headers = message_headers(&tag);
    if held.iter().any(|r| !sent.contains(&r.response.response_id)) {
        let packed = pack(held.iter().map(|r| &r.message[..]));
        put(objects, &responses_object(scene), tag, &packed).await?;
        for response in held
            .iter()
            .filter(|r| !sent.contains(&r.response.response_id))
        {
            if response.message.len() <= nats.client.server_info().max_payload {
                nats.client
                    .publish_with_headers(
                        subject.clone(),
                        sum_headers.clone(),
                        response.message.clone(),
                    )
                    .await?;
            }
        }
        *sent = held.iter().map(|r| r.response.response_id).collect();
    }
    nats.client
        .publish_with_headers(subject, sum_headers, sum.frame.clone())
        .await?;
    Ok(())
}

/// The headers naming `tag`'s version, geometry version and run on a frame or sum message.
fn message_headers(tag: &Tag) -> async_nats::HeaderMap {
    let mut message_headers = async_nats::HeaderMap::new();
    message_headers.insert(headers::VERSION, tag.version.to_string());
    message_headers.insert(headers::GEOMETRY, tag.geometry_version.to_string());
    message_headers.insert(headers::RUN, tag.run.as_str());
    message_headers
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
    let frame_headers = message_headers(&full_tag);
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
