//! Past one machine: the origin publishes each solution version to NATS once
//! ([`origin`]), and edges serve viewers from what it published ([`edge`]), byte for byte.
//!
//! Per scene `S` (a name, so several origins share one NATS):
//! - `radcast.S.frame` (core NATS): each version as viewers get it — the delta from the
//!   version before, or the full frame when there is none — with headers naming the version,
//!   the geometry version and the origin's run. An edge that misses one reads the snapshot.
//! - object store `radcast-snapshots` (JetStream), objects `S.geometry` and `S.full`: the
//!   newest geometry (stored before the frames that need it) and full frame (stored right
//!   after its frame is announced; before it when the frame is too big for one message), so an
//!   edge that starts late (or missed a message) is served at once without asking the origin;
//!   `S.texture.I`, the PNG of texture I of a textured scene (stored once per run, before the
//!   first geometry); and
//!   `S.record`, the [`SceneRecord`] (report, emissions, health), by which edges discover
//!   scenes (they watch the bucket). One object store, not a key-value bucket too: async-nats
//!   0.51 cannot create a bucket on nats-server 2.9 (it misreads the account info).
//! - `radcast.S.sum` (core NATS): for protocol-3 viewers, each light's response once a run
//!   (when it fits one message), then each version's sum frame after its frame, with the same
//!   headers. Objects `S.responses` (the responses the newest sum names, stored before any is
//!   announced) and `S.sum` (that sum) serve edges that start late or miss one.
//! - `radcast.S.record` (core NATS): the record again, sent before the frame it goes with,
//!   so an edge that shows a final frame already has its report (as the origin does).
//! - `radcast.S.alive` (core NATS): the origin's heartbeat, every [`ALIVE_INTERVAL`].
//! - `radcast.S.control` (request/reply): control-API requests an edge forwards; the origin
//!   checks the token and answers as it would over HTTP.

pub mod edge;
pub mod follow;
pub mod origin;

use crate::control::{Field, Reply};
use async_nats::jetstream;
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// Object store bucket with each scene's newest geometry, full frame and record.
pub const SNAPSHOTS_BUCKET: &str = "radcast-snapshots";
/// How often an origin says it is alive.
pub const ALIVE_INTERVAL: Duration = Duration::from_secs(1);
/// An origin unheard for this long is reported silent by its edges.
pub const SILENT_AFTER: Duration = Duration::from_secs(3);
/// How long an edge waits for the origin's answer to a control request.
pub const CONTROL_TIMEOUT: Duration = Duration::from_secs(5);

/// Header names on frame, snapshot and control messages.
pub mod headers {
    /// The solution version a frame carries.
    pub const VERSION: &str = "Radcast-Version";
    /// The geometry version a frame belongs to.
    pub const GEOMETRY: &str = "Radcast-Geometry";
    /// The origin's run: a random id per start, so an edge tells a restarted origin (whose
    /// versions start again at 1) from an old message.
    pub const RUN: &str = "Radcast-Run";
    /// The scene id (hex) the hello carries.
    pub const SCENE_ID: &str = "Radcast-Scene-Id";
    /// A control request's object name.
    pub const OBJECT: &str = "Radcast-Object";
    /// A control request's field (`emission`, `translate`).
    pub const FIELD: &str = "Radcast-Field";
    /// A control request's `Authorization` header, passed on as it came.
    pub const AUTHORIZATION: &str = "Authorization";
    /// A control reply's HTTP status.
    pub const STATUS: &str = "Radcast-Status";
}

/// Header `name` of `message`, parsed (as `String`: the text itself); `None` when it is absent
/// or does not parse.
pub(super) fn header<T: std::str::FromStr>(message: &async_nats::Message, name: &str) -> Option<T> {
    message.headers.as_ref()?.get(name)?.as_str().parse().ok()
}

/// The subject a scene's frames are published on.
pub fn frame_subject(scene: &str) -> String {
    format!("radcast.{scene}.frame")
}

/// The subject a scene's responses and sums are published on.
pub fn sum_subject(scene: &str) -> String {
    format!("radcast.{scene}.sum")
}

/// The subject a scene's record is published on when it changes.
pub fn record_subject(scene: &str) -> String {
    format!("radcast.{scene}.record")
}

/// The subject a scene's origin says it is alive on.
pub fn alive_subject(scene: &str) -> String {
    format!("radcast.{scene}.alive")
}

/// The subject a scene's origin takes control requests on.
pub fn control_subject(scene: &str) -> String {
    format!("radcast.{scene}.control")
}

/// The object holding a scene's newest encoded geometry.
pub fn geometry_object(scene: &str) -> String {
    format!("{scene}.geometry")
}

/// The object holding the PNG of texture `index` of a scene.
pub fn texture_object(scene: &str, index: usize) -> String {
    format!("{scene}.texture.{index}")
}

/// The object holding a scene's newest encoded full frame.
pub fn full_object(scene: &str) -> String {
    format!("{scene}.full")
}

/// The object holding a scene's newest sum frame.
pub fn sum_object(scene: &str) -> String {
    format!("{scene}.sum")
}

/// The object holding the responses a scene's newest sum names, as [`pack`] joins them.
pub fn responses_object(scene: &str) -> String {
    format!("{scene}.responses")
}

/// Messages joined into one object: each one's length (u32, little-endian), then its bytes.
pub fn pack<'a>(messages: impl IntoIterator<Item = &'a [u8]>) -> Vec<u8> {
    let mut packed = Vec::new();
    for message in messages {
        packed.extend_from_slice(&(message.len() as u32).to_le_bytes());
        packed.extend_from_slice(message);
    }
    packed
}

/// The messages [`pack`] joined; `None` when `packed` is cut short.
pub fn unpack(mut packed: &[u8]) -> Option<Vec<&[u8]>> {
    let mut messages = Vec::new();
    while !packed.is_empty() {
        let (length, rest) = packed.split_first_chunk::<4>()?;
        let length = u32::from_le_bytes(*length) as usize;
        messages.push(rest.get(..length)?);
        packed = &rest[length..];
    }
    Some(messages)
}

/// Suffix of the object holding a scene's [`SceneRecord`].
pub const RECORD_SUFFIX: &str = ".record";

/// The object holding a scene's [`SceneRecord`] (JSON).
pub fn record_object(scene: &str) -> String {
    format!("{scene}{RECORD_SUFFIX}")
}

/// A scene name is one NATS subject token and one key: 1-64 of `A-Z a-z 0-9 _ -`.
pub fn check_scene_name(name: &str) -> Result<(), String> {
    let fits = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-';
    match name.len() {
        1..=64 if name.chars().all(fits) => Ok(()),
        _ => Err(format!(
            "scene name '{name}' must be 1-64 characters of A-Z, a-z, 0-9, '_' and '-'"
        )),
    }
}

/// The default scene name: the file's stem, with every other character made `-`.
pub fn scene_name_for(path: &std::path::Path) -> String {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
    let name: String = stem
        .chars()
        .take(64)
        .map(
            |c| match c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                true => c,
                false => '-',
            },
        )
        .collect();
    match name.is_empty() {
        true => "scene".into(),
        false => name,
    }
}

/// What an origin says about its scene besides the frames: everything `/api/solution`,
/// `/api/objects` and `/healthz` answer from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneRecord {
    /// The origin's run (see [`headers::RUN`]).
    pub run: String,
    /// The report of the last finished solve.
    pub report: Option<wire::summary::SolveReport>,
    /// Every object's emission (W/m^2), in scene order.
    pub emissions: Vec<(String, [f64; 3])>,
    /// The origin's `/healthz` text: `ok`, `degraded: …` or `down: …`.
    pub health: String,
    /// The `sum_checksum` of the origin's `/api/solution` and the version it is of (edges
    /// serve frames only, but the same `/api/solution`).
    #[serde(default)]
    pub sum_checksum: Option<(u64, u32)>,
    /// The record's place among its run's records, from 1. Several can go with one solution
    /// version (the sum's checksum follows its frame), and an edge reads the stored one while
    /// live ones queue: it takes none older than the one it holds.
    #[serde(default)]
    pub sequence: u64,
}

/// Which snapshot an object is: its version, geometry version, run and scene id.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tag {
    /// The origin's run.
    pub run: String,
    /// The scene id (hello).
    pub scene_id: u64,
    /// The solution version (for the full frame) or geometry version (for the geometry).
    pub version: u64,
    /// The geometry version the full frame belongs to (the same as `version` for geometry).
    pub geometry_version: u64,
}

impl Tag {
    /// As object metadata.
    pub fn to_metadata(&self) -> HashMap<String, String> {
        HashMap::from([
            ("run".into(), self.run.clone()),
            ("scene_id".into(), format!("{:016x}", self.scene_id)),
            ("version".into(), self.version.to_string()),
            ("geometry_version".into(), self.geometry_version.to_string()),
        ])
    }

    /// From object metadata; `None` when a field is missing or malformed.
    pub fn from_metadata(metadata: &HashMap<String, String>) -> Option<Tag> {
        Some(Tag {
            run: metadata.get("run")?.clone(),
            scene_id: u64::from_str_radix(metadata.get("scene_id")?, 16).ok()?,
            version: metadata.get("version")?.parse().ok()?,
            geometry_version: metadata.get("geometry_version")?.parse().ok()?,
        })
    }
}

/// A NATS connection and whether it is up now.
#[derive(Clone)]
pub struct Nats {
    /// The client (it reconnects by itself, forever).
    pub client: async_nats::Client,
    /// Counts connections made: it changes on every reconnect, when state must be resent or
    /// read again.
    pub connects: watch::Receiver<u64>,
}

impl Nats {
    /// Connects to `url` as `name`; keeps trying while the server is down at start.
    pub async fn connect(url: &str, name: &str) -> anyhow::Result<Nats> {
        let (sender, connects) = watch::channel(0u64);
        let sender = Arc::new(sender);
        let url_shown = url.to_string();
        let client = async_nats::ConnectOptions::new()
            .name(name)
            .retry_on_initial_connect()
            .max_reconnects(None)
            .event_callback(move |event| {
                let sender = sender.clone();
                let url = url_shown.clone();
                async move {
                    match event {
                        async_nats::Event::Connected => {
                            tracing::info!("NATS {url}: connected");
                            sender.send_modify(|n| *n += 1);
                        }
                        async_nats::Event::Disconnected => {
                            tracing::warn!("NATS {url}: disconnected, reconnecting")
                        }
                        other => tracing::warn!("NATS {url}: {other}"),
                    }
                }
            })
            .connect(url)
            .await
            .map_err(|e| anyhow::anyhow!("cannot connect to NATS at {url}: {e}"))?;
        Ok(Nats { client, connects })
    }

    /// Whether the connection is up now.
    pub fn is_connected(&self) -> bool {
        self.client.connection_state() == async_nats::connection::State::Connected
    }

    /// The snapshot store, made when absent.
    pub async fn snapshots(&self) -> anyhow::Result<jetstream::object_store::ObjectStore> {
        let js = jetstream::new(self.client.clone());
        if let Ok(store) = js.get_object_store(SNAPSHOTS_BUCKET).await {
            return Ok(store);
        }
        js.create_object_store(jetstream::object_store::Config {
            bucket: SNAPSHOTS_BUCKET.into(),
            description: Some(
                "radcast: each scene's newest geometry, full frame and record".into(),
            ),
            ..Default::default()
        })
        .await
        .map_err(|e| anyhow::anyhow!("cannot open object store {SNAPSHOTS_BUCKET}: {e}"))
    }
}

/// An edge's link to one scene's origin: where control requests go, and when it was heard.
pub struct Upstream {
    /// The connection.
    pub nats: Nats,
    /// The scene's name.
    pub scene: String,
    /// The origin's run this copy follows.
    pub run: String,
    /// When the origin last said it was alive (or sent anything).
    pub last_heard: std::sync::Mutex<std::time::Instant>,
    /// The [`SceneRecord::sequence`] of the record in use: an older one (a live record that
    /// queued while the snapshot was read) is not taken.
    pub record_sequence: std::sync::atomic::AtomicU64,
    /// Set when a frame could not be applied (a gap, a newer geometry not yet stored): the
    /// snapshot is read again.
    pub stale: std::sync::atomic::AtomicBool,
    /// The origin's sum checksum and its version, from the record in use.
    pub sum_checksum: std::sync::Mutex<Option<(u64, u32)>>,
    /// A sum that came ahead of its frame, and its version.
    pub pending_sum: std::sync::Mutex<Option<(u64, bytes::Bytes)>>,
}

impl Upstream {
    /// A link to `run` of `scene`'s origin, heard now, with no record taken yet.
    pub fn new(nats: Nats, scene: &str, run: &str) -> Upstream {
        Upstream {
            nats,
            scene: scene.to_string(),
            run: run.to_string(),
            last_heard: std::time::Instant::now().into(),
            record_sequence: 0.into(),
            stale: false.into(),
            sum_checksum: None.into(),
            pending_sum: None.into(),
        }
    }

    /// Seconds since the origin was last heard.
    pub fn silent_for(&self) -> Duration {
        self.last_heard.lock().expect("heard lock").elapsed()
    }

    /// Sends a control request to the origin and gives back its answer, or 503 when no origin
    /// answers.
    pub async fn control(
        &self,
        name: &str,
        field: Field,
        authorization: Option<&str>,
        body: &[u8],
    ) -> Reply {
        let mut request_headers = async_nats::HeaderMap::new();
        request_headers.insert(headers::OBJECT, name);
        request_headers.insert(headers::FIELD, field.key());
        if let Some(authorization) = authorization {
            request_headers.insert(headers::AUTHORIZATION, authorization);
        }
        let request = async_nats::Request::new()
            .headers(request_headers)
            .payload(bytes::Bytes::copy_from_slice(body))
            .timeout(Some(CONTROL_TIMEOUT));
        let unreachable = |why: String| {
            Reply::refusal(
                StatusCode::SERVICE_UNAVAILABLE,
                format!(
                    "this is an edge; the origin of scene '{}' did not answer over NATS ({why}): send control requests to the origin",
                    self.scene
                ),
            )
        };
        let answer = match self
            .nats
            .client
            .send_request(control_subject(&self.scene), request)
            .await
        {
            Ok(answer) => answer,
            Err(error) => return unreachable(error.to_string()),
        };
        let status =
            header::<u16>(&answer, headers::STATUS).and_then(|s| StatusCode::from_u16(s).ok());
        match (status, serde_json::from_slice(&answer.payload)) {
            (Some(status), Ok(body)) => Reply { status, body },
            _ => unreachable("its answer was malformed".into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_names_are_one_subject_token() {
        assert_eq!(
            scene_name_for("scenes/cornell-box.obj".as_ref()),
            "cornell-box"
        );
        assert_eq!(scene_name_for("my scene.v2.gltf".as_ref()), "my-scene-v2");
        assert!(check_scene_name("cornell-box").is_ok());
        for bad in ["", "a.b", "a*", "a>", "a b", &"x".repeat(65)] {
            assert!(check_scene_name(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn packed_messages_come_back_and_a_cut_pack_is_refused() {
        let messages: [&[u8]; 3] = [b"response one", b"", b"two"];
        let packed = pack(messages);
        assert_eq!(unpack(&packed), Some(messages.to_vec()));
        assert_eq!(unpack(&[]), Some(vec![]));
        for cut in 1..packed.len() {
            let unpacked = unpack(&packed[..cut]);
            assert!(
                unpacked.is_none() || cut == 16 || cut == 20,
                "{cut}: {unpacked:?}"
            );
        }
    }

    #[test]
    fn a_tag_survives_object_metadata_and_a_damaged_one_is_none() {
        let tag = Tag {
            run: "r1".into(),
            scene_id: u64::MAX - 7,
            version: 12,
            geometry_version: 3,
        };
        let mut metadata = tag.to_metadata();
        assert_eq!(Tag::from_metadata(&metadata), Some(tag));
        metadata.insert("version".into(), "twelve".into());
        assert_eq!(Tag::from_metadata(&metadata), None);
    }
}
