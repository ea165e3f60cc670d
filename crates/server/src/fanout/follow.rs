//! How an edge follows NATS: each scene starts from its stored snapshot (geometry, full frame,
//! record), then frames keep it current; a frame that does not follow what the edge holds, a
//! reconnect or a late start reads the snapshot again.

use super::edge::{Edge, Served, upstream};
use super::{
    RECORD_SUFFIX, SceneRecord, Tag, Upstream, full_object, geometry_object, header, headers,
    record_object, responses_object, sum_object, texture_object, unpack,
};
use crate::Shared;
use crate::publish::hub::{GeometryState, HeldResponse, Hub, Published, SumForm};
use async_nats::jetstream::object_store;
use bytes::Bytes;
use futures_util::StreamExt;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;
use tokio::io::AsyncReadExt;
use wire::{Geometry, ServerMessage};

/// A scene's newest state as its origin stored it.
struct Snapshot {
    tag: Tag,
    geometry: GeometryState,
    state: Published,
    record: SceneRecord,
    /// The stored sum of `state`'s version, when there is one.
    sum: Option<Bytes>,
}

/// How long reading one snapshot object may take: a read that races the object's replacement
/// (its chunks purged under it) would otherwise wait forever.
const READ_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);

async fn read_object(
    objects: &object_store::ObjectStore,
    name: &str,
) -> anyhow::Result<(Tag, Vec<u8>)> {
    let read = async {
        let mut object = objects
            .get(name)
            .await
            .map_err(|e| anyhow::anyhow!("cannot read {name}: {e}"))?;
        let tag = Tag::from_metadata(&object.info().metadata)
            .ok_or_else(|| anyhow::anyhow!("{name} carries no radcast tag"))?;
        let mut bytes = Vec::with_capacity(object.info().size);
        object.read_to_end(&mut bytes).await?;
        Ok((tag, bytes))
    };
    tokio::time::timeout(READ_TIMEOUT, read)
        .await
        .map_err(|_| {
            anyhow::anyhow!("reading {name} took over {READ_TIMEOUT:?} (replaced meanwhile?)")
        })?
}

async fn read_geometry(
    objects: &object_store::ObjectStore,
    scene: &str,
) -> anyhow::Result<(Tag, GeometryState)> {
    let (tag, bytes) = read_object(objects, &geometry_object(scene)).await?;
    let geometry = Geometry::decode(&bytes)?;
    let texture_count = geometry.textures.as_ref().map_or(0, |t| t.means.len());
    let mut textures = Vec::with_capacity(texture_count);
    for index in 0..texture_count {
        let (texture_tag, png) = read_object(objects, &texture_object(scene, index)).await?;
        if texture_tag.run != tag.run {
            anyhow::bail!("the textures of '{scene}' are being replaced");
        }
        textures.push(Bytes::from(png));
    }
    Ok((
        tag.clone(),
        GeometryState::new(tag.scene_id, tag.version, geometry, textures.into()),
    ))
}

async fn read_snapshot(
    objects: &object_store::ObjectStore,
    scene: &str,
) -> anyhow::Result<Snapshot> {
    let (geometry_tag, geometry) = read_geometry(objects, scene).await?;
    let (tag, bytes) = read_object(objects, &full_object(scene)).await?;
    if tag.run != geometry_tag.run || tag.geometry_version != geometry_tag.version {
        anyhow::bail!("the snapshot of '{scene}' is being replaced");
    }
    let ServerMessage::Full(frame) = ServerMessage::decode(&bytes)? else {
        anyhow::bail!("{} is not a full frame", full_object(scene));
    };
    let state = Published::new(frame.info, frame.colours, None, tag.geometry_version);
    let (_, record) = read_object(objects, &record_object(scene)).await?;
    let record: SceneRecord = serde_json::from_slice(&record)?;
    if record.run != tag.run {
        anyhow::bail!("the record of '{scene}' is being replaced");
    }
    // Without it, protocol-3 viewers get frames until the next sum.
    let sum = match read_object(objects, &sum_object(scene)).await {
        Ok((sum_tag, bytes)) if sum_tag.run == tag.run && sum_tag.version == tag.version => {
            Some(Bytes::from(bytes))
        }
        _ => None,
    };
    Ok(Snapshot {
        tag,
        geometry,
        state,
        record,
        sum,
    })
}

/// `state` with its sum from `encoded`, when there is one and it can be made (see
/// [`sum_of`]).
async fn with_sum_of(
    objects: &object_store::ObjectStore,
    shared: &Shared,
    state: Published,
    encoded: Option<Bytes>,
) -> Published {
    let Some(encoded) = encoded else {
        return state;
    };
    match sum_of(objects, shared, &state, encoded).await {
        Some(sum) => state.with_sum(sum),
        None => state,
    }
}

/// The responses the newest sum of `scene` names, as stored by origin run `run`.
async fn read_responses(
    objects: &object_store::ObjectStore,
    scene: &str,
    run: &str,
) -> anyhow::Result<Vec<HeldResponse>> {
    let (tag, packed) = read_object(objects, &responses_object(scene)).await?;
    if tag.run != run {
        anyhow::bail!("the responses of '{scene}' are of another run");
    }
    let messages = unpack(&packed).ok_or_else(|| anyhow::anyhow!("cut short"))?;
    messages
        .into_iter()
        .map(|message| match ServerMessage::decode(message)? {
            ServerMessage::Response(response) => Ok(HeldResponse {
                response,
                message: Bytes::copy_from_slice(message),
            }),
            _ => anyhow::bail!("not a response"),
        })
        .collect()
}

/// `state`'s sum from `encoded`, an origin's sum frame of it, with the stored responses read
/// when `shared`'s hub lacks one; `None`, logged, when it cannot be made (the version then
/// travels as frames to every viewer).
async fn sum_of(
    objects: &object_store::ObjectStore,
    shared: &Shared,
    state: &Published,
    encoded: Bytes,
) -> Option<Arc<SumForm>> {
    let hub = &shared.hub;
    let lacking = match hub.sum_for(state, encoded.clone()) {
        Ok(sum) => return Some(sum),
        Err(why) => why,
    };
    let link = upstream(shared);
    let made = match read_responses(objects, &link.scene, &link.run).await {
        Ok(responses) => {
            responses.into_iter().for_each(|r| hub.hold_response(r));
            hub.sum_for(state, encoded)
                .map_err(|why| anyhow::anyhow!(why))
        }
        Err(error) => Err(error),
    };
    made.inspect_err(|error| {
        tracing::debug!(
            scene = link.scene,
            version = state.version,
            "edge: frames only ({lacking}; then {error:#})"
        )
    })
    .ok()
}

/// Follows NATS until shutdown: scene records (new scenes, summaries, health), frames,
/// heartbeats; reads snapshots where frames cannot be applied and after every reconnect.
pub async fn follow(edge: Arc<Edge>) {
    // One subscription for frames, records and heartbeats: NATS keeps one publisher's
    // messages in order on it, so a record is taken before the frame it goes with.
    let mut messages = match edge.nats.client.subscribe("radcast.*.*").await {
        Ok(messages) => messages,
        Err(error) => {
            tracing::error!("cannot subscribe on NATS: {error}");
            return;
        }
    };
    tokio::spawn(watch_health(edge.clone()));
    let mut connects = edge.nats.connects.clone();
    connects.mark_unchanged();
    let mut tick = tokio::time::interval(super::ALIVE_INTERVAL);
    loop {
        let objects = match edge.nats.snapshots().await {
            Ok(objects) => Some(objects),
            Err(error) => {
                tracing::warn!("edge: {error:#}");
                None
            }
        };
        let watch = match &objects {
            Some(objects) => objects.watch_with_history().await.ok(),
            None => None,
        };
        let (Some(objects), Some(mut watch)) = (objects, watch) else {
            tokio::select! {
                _ = tick.tick() => continue,
                _ = edge.process.shutdown.cancelled() => return,
            }
        };
        loop {
            tokio::select! {
                change = watch.next() => match change {
                    Some(Ok(info)) => {
                        let tag = Tag::from_metadata(&info.metadata);
                        if let Some(scene) = info.name.strip_suffix(RECORD_SUFFIX).filter(|_| !info.deleted) {
                            // A known run's records come ahead of its frames; only a new scene
                            // or a new run needs the stored one.
                            let known = edge.scene(scene).is_some_and(|s| tag.is_some_and(|t| t.run == upstream(&s).run));
                            if !known {
                                edge.serve_or_retry(&objects, scene).await;
                            }
                        }
                    }
                    // The watch ends with its connection: make it again.
                    _ => break,
                },
                Some(message) = messages.next() => match message.subject.rsplit('.').next() {
                    Some("frame") => edge.take_frame(&objects, message).await,
                    Some("sum") => edge.take_sum(&objects, message).await,
                    Some("record") => edge.take_record_message(&message),
                    Some("alive") => edge.heard(&message),
                    _ => {}
                },
                _ = tick.tick() => {
                    let pending = std::mem::take(&mut *edge.pending.lock().expect("pending lock"));
                    for scene in pending {
                        edge.serve_or_retry(&objects, &scene).await;
                    }
                    edge.resync_stale(&objects).await;
                }
                _ = connects.changed() => {
                    // Frames sent while disconnected are lost: read every snapshot again.
                    for name in edge.scene_names() {
                        if let Some(shared) = edge.scene(&name) {
                            upstream(&shared).stale.store(true, Ordering::Relaxed);
                        }
                    }
                    break;
                }
                _ = edge.process.shutdown.cancelled() => return,
            }
        }
    }
}

/// Once a second, whatever the feed is doing: reports silent origins and a lost NATS.
async fn watch_health(edge: Arc<Edge>) {
    let mut tick = tokio::time::interval(super::ALIVE_INTERVAL);
    loop {
        tokio::select! {
            _ = tick.tick() => edge.check_silence(),
            _ = edge.process.shutdown.cancelled() => return,
        }
    }
}

/// The report, emissions and origin health of `record` (none older than the one in use), for
/// `/api/solution`, `/api/objects` and `/healthz`.
fn take_record(shared: &Shared, scene: &str, record: SceneRecord) {
    if upstream(shared)
        .record_sequence
        .fetch_max(record.sequence, Ordering::Relaxed)
        > record.sequence
    {
        return;
    }
    *shared.report.lock().expect("report lock") = record.report;
    *shared.emissions.lock().expect("emissions lock") = record.emissions;
    *upstream(shared).sum_checksum.lock().expect("sum lock") = record.sum_checksum;
    match record.health.as_str() {
        "ok" => shared.health.recovered(crate::health::Fault::Origin),
        other => shared.health.fault(
            crate::health::Fault::Origin,
            format!("the origin of '{scene}' reports {other}"),
        ),
    }
}

/// The scene a subject `radcast.SCENE.KIND` is about.
fn scene_of(subject: &str) -> Option<&str> {
    subject.strip_prefix("radcast.")?.split('.').next()
}

impl Edge {
    /// Serves `scene` from its snapshot, or notes it to try again a second later.
    async fn serve_or_retry(&self, objects: &object_store::ObjectStore, scene: &str) {
        if self.start_serving(objects, scene).await.is_none() {
            let mut pending = self.pending.lock().expect("pending lock");
            pending.insert(scene.to_string());
        }
    }

    /// A record sent ahead of a frame, for a scene served now.
    fn take_record_message(&self, message: &async_nats::Message) {
        let Some((scene, shared)) =
            scene_of(&message.subject).and_then(|s| Some((s, self.scene(s)?)))
        else {
            return;
        };
        match serde_json::from_slice::<SceneRecord>(&message.payload) {
            Ok(record) if record.run == upstream(&shared).run => {
                take_record(&shared, scene, record)
            }
            Ok(_) => {}
            Err(error) => tracing::warn!("edge: a record of '{scene}' is unreadable: {error}"),
        }
    }

    /// Serves `scene` from its snapshot and record, replacing (and closing the viewers of) an
    /// earlier run's copy.
    async fn start_serving(
        &self,
        objects: &object_store::ObjectStore,
        scene: &str,
    ) -> Option<Arc<Shared>> {
        let snapshot = match read_snapshot(objects, scene).await {
            Ok(snapshot) => snapshot,
            Err(error) => {
                tracing::warn!("edge: cannot serve '{scene}' yet: {error:#}; trying again");
                return None;
            }
        };
        let upstream = Upstream::new(self.nats.clone(), scene, &snapshot.tag.run);
        let hub = Hub::restore(snapshot.geometry, snapshot.state);
        let shared = Shared::in_process(self.process.clone(), hub, String::new(), Some(upstream));
        if let Some(encoded) = snapshot.sum {
            let state = shared.hub.current();
            if let Some(sum) = sum_of(objects, &shared, &state, encoded).await {
                shared.hub.install(state.with_sum(sum));
            }
        }
        // Before anyone can ask: /api/solution must not answer without the report.
        take_record(&shared, scene, snapshot.record);
        let served = Arc::new(Served {
            router: crate::http::routes::router(shared.clone()),
            shared: shared.clone(),
        });
        let mut previous = None;
        self.scenes
            .send_modify(|scenes| previous = scenes.insert(scene.to_string(), served));
        match previous {
            Some(previous) => {
                tracing::info!("edge: the origin of '{scene}' restarted; its viewers reconnect");
                previous.shared.retired.cancel();
            }
            None => tracing::info!("edge: serving scene '{scene}'"),
        }
        Some(shared)
    }

    /// A frame: applied when it follows what this edge holds, else the snapshot is read.
    async fn take_frame(&self, objects: &object_store::ObjectStore, message: async_nats::Message) {
        let Some(shared) = scene_of(&message.subject).and_then(|s| self.scene(s)) else {
            return;
        };
        let link = upstream(&shared);
        *link.last_heard.lock().expect("heard lock") = Instant::now();
        let version = header::<u64>(&message, headers::VERSION);
        let geometry_version = header::<u64>(&message, headers::GEOMETRY);
        let (Some(version), Some(geometry_version)) = (version, geometry_version) else {
            return;
        };
        if header::<String>(&message, headers::RUN).as_deref() != Some(link.run.as_str()) {
            // A restarted origin: its record brings the new run.
            return;
        }
        let held = shared.hub.current();
        if version <= held.version {
            return;
        }
        if geometry_version != shared.hub.geometry().version {
            match read_geometry(objects, &link.scene).await {
                Ok((tag, geometry)) if tag.version == geometry_version && tag.run == link.run => {
                    shared.hub.install_geometry(geometry)
                }
                // The geometry moved on again: the snapshot has the newest.
                _ => return self.resync(objects, &link.scene, &shared, version).await,
            }
        }
        let next = match ServerMessage::decode(&message.payload) {
            Ok(ServerMessage::Full(frame)) => Some(Published::new(
                frame.info,
                frame.colours,
                None,
                geometry_version,
            )),
            Ok(ServerMessage::Delta(delta))
                if delta.base_version == held.version
                    && delta.info.vertex_count as usize == held.colours.len() =>
            {
                // Decoding checked every index against the vertex count.
                let mut colours = held.colours.to_vec();
                for (&index, &colour) in delta.indices.iter().zip(&delta.colours) {
                    colours[index as usize] = colour;
                }
                Some(Published::new(
                    delta.info,
                    colours,
                    Some((delta.base_version, message.payload.clone())),
                    geometry_version,
                ))
            }
            // Too big for a message, or a gap: the snapshot has it.
            _ => None,
        };
        let pending_sum = link.pending_sum.lock().expect("sum lock").take();
        match next {
            Some(state) if state.version == version => {
                let sum = pending_sum.filter(|(v, _)| *v == version).map(|(_, s)| s);
                let state = with_sum_of(objects, &shared, state, sum).await;
                shared.hub.install(state)
            }
            _ => self.resync(objects, &link.scene, &shared, version).await,
        }
    }

    /// A response, held for sums; or a sum, kept for its frame (which follows it) or given to
    /// the version served now when it is of that one (its responses were solved after it).
    async fn take_sum(&self, objects: &object_store::ObjectStore, message: async_nats::Message) {
        let Some(shared) = scene_of(&message.subject).and_then(|s| self.scene(s)) else {
            return;
        };
        let link = upstream(&shared);
        let version = header::<u64>(&message, headers::VERSION);
        let run = header::<String>(&message, headers::RUN);
        let (Some(version), true) = (version, run.as_deref() == Some(link.run.as_str())) else {
            return;
        };
        let current = shared.hub.current();
        match ServerMessage::decode(&message.payload) {
            Ok(ServerMessage::Response(response)) => shared.hub.hold_response(HeldResponse {
                response,
                message: message.payload,
            }),
            Ok(ServerMessage::Sum(_)) if version == current.version => {
                if let Some(sum) = sum_of(objects, &shared, &current, message.payload).await {
                    shared.hub.install(current.with_sum(sum));
                }
            }
            Ok(ServerMessage::Sum(_)) if version > current.version => {
                *link.pending_sum.lock().expect("sum lock") = Some((version, message.payload));
            }
            Ok(_) => {}
            Err(error) => tracing::warn!("edge: a sum of '{}' is unreadable: {error}", link.scene),
        }
    }

    fn heard(&self, message: &async_nats::Message) {
        if let Some(shared) = scene_of(&message.subject).and_then(|s| self.scene(s)) {
            *upstream(&shared).last_heard.lock().expect("heard lock") = Instant::now();
        }
    }

    /// Reports origins not heard for [`super::SILENT_AFTER`] and a NATS connection that is down.
    fn check_silence(&self) {
        let connected = self.nats.is_connected();
        for name in self.scene_names() {
            let Some(shared) = self.scene(&name) else {
                continue;
            };
            let version = shared.hub.current().version;
            match connected {
                true => shared.health.recovered(crate::health::Fault::Nats),
                false => shared.health.fault(
                    crate::health::Fault::Nats,
                    format!("NATS is unreachable: serving the last solution of '{name}' (version {version})"),
                ),
            }
            match upstream(&shared).silent_for() > super::SILENT_AFTER {
                true => shared.health.fault(
                    crate::health::Fault::OriginSilent,
                    format!("the origin of '{name}' is silent: serving its last solution (version {version})"),
                ),
                false => shared.health.recovered(crate::health::Fault::OriginSilent),
            }
        }
    }

    /// Reads the snapshot of every scene marked stale (a reconnect, or a read that failed).
    async fn resync_stale(&self, objects: &object_store::ObjectStore) {
        for name in self.scene_names() {
            if let Some(shared) = self.scene(&name) {
                if upstream(&shared).stale.swap(false, Ordering::Relaxed) {
                    self.resync(objects, &name, &shared, 0).await;
                }
            }
        }
    }

    /// Serves the stored snapshot of `name` (a new run's from scratch); when it cannot be read,
    /// or is older than version `at_least`, the scene is marked stale: read again a second later.
    async fn resync(
        &self,
        objects: &object_store::ObjectStore,
        name: &str,
        shared: &Shared,
        at_least: u64,
    ) {
        let link = upstream(shared);
        tracing::debug!(scene = name, at_least, "reading the snapshot");
        match read_snapshot(objects, name).await {
            Ok(snapshot) if snapshot.tag.run != link.run => {
                self.start_serving(objects, name).await;
            }
            Ok(snapshot) => {
                if snapshot.geometry.version != shared.hub.geometry().version {
                    shared.hub.install_geometry(snapshot.geometry);
                }
                if snapshot.state.version < at_least {
                    link.stale.store(true, Ordering::Relaxed);
                }
                let held = shared.hub.current();
                let gains_sum = snapshot.state.version == held.version
                    && held.sum.is_none()
                    && snapshot.sum.is_some();
                if snapshot.state.version > held.version || gains_sum {
                    let state = with_sum_of(objects, shared, snapshot.state, snapshot.sum).await;
                    shared.hub.install(state);
                }
                take_record(shared, name, snapshot.record);
            }
            Err(error) => {
                tracing::warn!("edge: cannot read the snapshot of '{name}': {error:#}");
                link.stale.store(true, Ordering::Relaxed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fanout::Nats;
    use crate::{Limits, Process};

    #[tokio::test]
    async fn a_record_older_than_the_one_held_is_not_taken() {
        // Nothing answers on this port: the client connects lazily, and records need no NATS.
        let nats = Nats::connect("nats://127.0.0.1:9", "test edge")
            .await
            .unwrap();
        let geometry = Geometry {
            positions: vec![[0.0; 3]; 3],
            patches: vec![[0, 1, 2, wire::geometry::NO_CORNER]],
            patch_objects: vec![0],
            objects: vec!["thing".into()],
            camera: None,
            textures: None,
        };
        let hub = Hub::new(1, &geometry, Arc::from([]), &[[1.0; 3]; 3]);
        let upstream = Upstream::new(nats, "scene", "run-1");
        let shared = Shared::in_process(
            Process::new(Limits::default()),
            hub,
            String::new(),
            Some(upstream),
        );
        let record = |sequence, sum_checksum, health: &str| SceneRecord {
            run: "run-1".into(),
            report: None,
            emissions: Vec::new(),
            health: health.into(),
            sum_checksum,
            sequence,
        };
        let served = || {
            let summary = crate::http::routes::solution_summary(&shared);
            (summary.sum_checksum, shared.health.text())
        };
        // The stored record, read while two live ones of the same version queued behind it:
        // the first of those came before the sum's checksum and must not take it away.
        take_record(&shared, "scene", record(2, Some((1, 7)), "ok"));
        take_record(&shared, "scene", record(1, None, "degraded: solving"));
        assert_eq!(served(), (Some(7), "ok".to_string()));
        take_record(&shared, "scene", record(2, Some((1, 7)), "ok"));
        assert_eq!(served(), (Some(7), "ok".to_string()));
        // A newer one is taken, whatever it says.
        take_record(&shared, "scene", record(3, None, "ok"));
        assert_eq!(served(), (None, "ok".to_string()));
    }
}
