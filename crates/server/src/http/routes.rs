//! HTTP routes; each handler is a thin wrapper over plain data in [`Shared`].

use crate::Shared;
use crate::control::Field;
use crate::health::Status;
use crate::http::admission::Refusal;
use crate::http::viewer::serve_viewer;
use axum::Router;
use axum::extract::ConnectInfo;
use axum::extract::Path;
use axum::extract::State;
use axum::extract::ws::WebSocketUpgrade;
use axum::http::HeaderMap;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, put};
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::net::TcpListener;
use wire::SolutionSummary;

/// The router: the browser viewer at `/`, `/healthz`, `/api/scene`, `/api/scene.glb`,
/// `/api/textures/{index}`, `/api/solution`, `/api/objects`, `/ws`, `/metrics`,
/// and the control API `PUT /api/objects/{name}/emission` and `.../transform` (bearer token).
pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/healthz", get(health))
        .route("/api/scene", get(scene))
        .route("/api/scene.glb", get(scene_glb))
        .route("/api/textures/{index}", get(texture))
        .route("/api/solution", get(solution))
        .route("/api/objects", get(objects))
        .route("/ws", get(websocket))
        .route("/metrics", get(metrics))
        .route("/api/objects/{name}/emission", put(set_emission))
        .route("/api/objects/{name}/transform", put(set_transform))
        .merge(crate::http::page::routes())
        .with_state(shared)
}

/// The header of `/api/scene` that names the geometry version of its body.
pub const GEOMETRY_VERSION_HEADER: &str = "x-radcast-geometry-version";

async fn scene(State(shared): State<Arc<Shared>>) -> Response {
    let geometry = shared.hub.geometry();
    (
        [
            (
                header::CONTENT_TYPE,
                "application/vnd.radcast.geometry".to_string(),
            ),
            (
                header::HeaderName::from_static(GEOMETRY_VERSION_HEADER),
                geometry.version.to_string(),
            ),
        ],
        geometry.encoded.clone(),
    )
        .into_response()
}

/// Texture `index` of the geometry's texture section, as PNG. Its bytes never change while the
/// server runs, so a viewer may keep it for the whole connection.
async fn texture(State(shared): State<Arc<Shared>>, Path(index): Path<String>) -> Response {
    let textures = shared.hub.geometry().textures.clone();
    match index.parse::<usize>().ok().and_then(|i| textures.get(i)) {
        Some(png) => ([(header::CONTENT_TYPE, "image/png")], png.clone()).into_response(),
        None => {
            let held = match textures.len() {
                0 => "this scene has no textures".to_string(),
                n => format!("this scene's are 0 to {}", n - 1),
            };
            (
                StatusCode::NOT_FOUND,
                format!("no texture '{index}': {held}\n"),
            )
                .into_response()
        }
    }
}

/// The current state as binary glTF, decoded from the same codes viewers hold.
async fn scene_glb(State(shared): State<Arc<Shared>>) -> Response {
    let current = shared.hub.current();
    let served = shared.hub.geometry();
    let emitting = emitting_objects(&shared);
    let glb = tokio::task::spawn_blocking(move || {
        let radiosity: Vec<[f32; 3]> = current
            .colours
            .iter()
            .map(|&c| wire::decode_colour(c, current.scale))
            .collect();
        wire::gltf::encode_glb(&served.model, &served.textures, &emitting, &radiosity)
    })
    .await;
    match glb {
        Ok(bytes) => ([(header::CONTENT_TYPE, "model/gltf-binary")], bytes).into_response(),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "glTF export failed\n").into_response(),
    }
}

/// Per object in scene order, whether it emits now (what `/api/objects` reports).
fn emitting_objects(shared: &Shared) -> Vec<bool> {
    let emissions = shared.emissions.lock().expect("emissions lock");
    emissions
        .iter()
        .map(|(_, e)| e.iter().any(|c| *c > 0.0))
        .collect()
}

/// The current summary, for `/api/solution` and tests: every field read from one published
/// version, so the vertex count, geometry version and checksum always agree.
pub fn solution_summary(shared: &Shared) -> SolutionSummary {
    let current = shared.hub.current();
    SolutionSummary {
        scene_id: format!("{:016x}", shared.hub.scene_id),
        vertex_count: current.colours.len() as u32,
        geometry_version: current.geometry_version,
        solution_version: current.version,
        is_final: current.is_final,
        checksum: current.checksum,
        scale: current.scale,
        // An edge serves frames only, and the origin's checksum of the version's sum.
        sum_checksum: match &shared.upstream {
            None => current.sum.as_ref().map(|sum| sum.checksum),
            Some(upstream) => upstream
                .sum_checksum
                .lock()
                .expect("sum lock")
                .filter(|(version, _)| *version == current.version)
                .map(|(_, checksum)| checksum),
        },
        report: shared.report.lock().ok().and_then(|r| r.clone()),
    }
}

/// Every object and its current emission: `[{"name": …, "emission": [r, g, b]}]`.
async fn objects(State(shared): State<Arc<Shared>>) -> Response {
    let emissions = shared.emissions.lock().expect("emissions lock").clone();
    let list: Vec<serde_json::Value> = emissions
        .into_iter()
        .map(|(name, emission)| serde_json::json!({ "name": name, "emission": emission }))
        .collect();
    axum::Json(list).into_response()
}

async fn solution(State(shared): State<Arc<Shared>>) -> Response {
    axum::Json(solution_summary(&shared)).into_response()
}

async fn metrics(State(shared): State<Arc<Shared>>) -> Response {
    let text = crate::http::metrics::render(&shared);
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text).into_response()
}

/// `ok`; `degraded: WHAT` (still 200: viewers are served the last good solution); or
/// `down: WHY` with 503 once the solver stopped and edits can no longer be applied.
async fn health(State(shared): State<Arc<Shared>>) -> Response {
    let text = format!("{}\n", shared.health.text());
    match shared.health.status() {
        Status::Down(_) => (StatusCode::SERVICE_UNAVAILABLE, text).into_response(),
        _ => text.into_response(),
    }
}

/// Whether `key` is what RFC 6455 (4.2.1) asks of `Sec-WebSocket-Key`: 16 bytes in base64,
/// which is 22 characters of the alphabet (the last carrying 2 bits, so one of `AQgw`) and `==`.
pub fn is_websocket_key(key: &[u8]) -> bool {
    let alphabet = |c: &u8| c.is_ascii_alphanumeric() || *c == b'+' || *c == b'/';
    key.len() == 24
        && key[..22].iter().all(alphabet)
        && b"AQgw".contains(&key[21])
        && &key[22..] == b"=="
}

/// The protocol version a viewer asked for with `Sec-WebSocket-Protocol` (RFC 6455, 4.1): the
/// newest `radcast.N` it offers that this server speaks, or version 2 when it offers none at
/// all; a refusal naming what it offered when none of them is spoken here.
fn negotiate(offered: Option<&axum::http::HeaderValue>) -> Result<u16, String> {
    let Some(offered) = offered else {
        return Ok(wire::PLAIN_PROTOCOL_VERSION);
    };
    let text = offered.to_str().unwrap_or("");
    text.split(',')
        .map(str::trim)
        .filter_map(|name| name.strip_prefix("radcast.")?.parse::<u16>().ok())
        .filter(|v| (wire::PLAIN_PROTOCOL_VERSION..=wire::PROTOCOL_VERSION).contains(v))
        .max()
        .ok_or_else(|| {
            let spoken: Vec<String> = (wire::PLAIN_PROTOCOL_VERSION..=wire::PROTOCOL_VERSION)
                .map(wire::subprotocol)
                .collect();
            format!(
                "radcast-server: none of the WebSocket subprotocols offered ({}) is spoken here: {} (or offer none for radcast.2)\n",
                text.escape_debug(),
                spoken.join(", ")
            )
        })
}

async fn websocket(
    State(shared): State<Arc<Shared>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    let key = headers.get(header::SEC_WEBSOCKET_KEY).map(|k| k.as_bytes());
    if !key.is_some_and(is_websocket_key) {
        return (
            StatusCode::BAD_REQUEST,
            "radcast-server: Sec-WebSocket-Key must be 16 bytes in base64 (RFC 6455, 4.2.1)\n",
        )
            .into_response();
    }
    let protocol = match negotiate(headers.get(header::SEC_WEBSOCKET_PROTOCOL)) {
        Ok(protocol) => protocol,
        Err(refusal) => return (StatusCode::BAD_REQUEST, refusal).into_response(),
    };
    let place = match shared.process.viewers.admit(peer.ip()) {
        Ok(place) => place,
        Err(Refusal::ServerFull) => {
            return (
                StatusCode::SERVICE_UNAVAILABLE,
                "radcast-server: viewer limit reached\n",
            )
                .into_response();
        }
        Err(Refusal::AddressFull) => {
            return (
                StatusCode::TOO_MANY_REQUESTS,
                format!("radcast-server: too many viewers from {}\n", peer.ip()),
            )
                .into_response();
        }
    };
    let limits = shared.process.limits;
    // Viewers send only tiny control messages and every frame is flushed as it is sent, so
    // small buffers do: tungstenite's 128 KiB defaults made each idle viewer cost 144 KB.
    // A viewer that offered subprotocols must get the chosen one named back (RFC 6455, 4.1).
    let upgrade = match headers.contains_key(header::SEC_WEBSOCKET_PROTOCOL) {
        true => upgrade.protocols([wire::subprotocol(protocol)]),
        false => upgrade,
    };
    upgrade
        .read_buffer_size(4096)
        .write_buffer_size(0)
        .max_message_size(limits.max_message_bytes)
        .max_frame_size(limits.max_message_bytes)
        .on_upgrade(move |socket| {
            shared
                .process
                .tasks
                .track_future(serve_viewer(socket, shared.clone(), place, protocol))
        })
}

/// The control API: the origin applies the edit ([`crate::control`]); an edge forwards it to
/// the origin over NATS and answers with the origin's reply.
async fn edit(
    shared: &Shared,
    name: &str,
    headers: &HeaderMap,
    body: &[u8],
    field: Field,
) -> Response {
    let authorization = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok());
    let reply = match &shared.upstream {
        Some(upstream) => upstream.control(name, field, authorization, body).await,
        None => crate::control::apply(shared, name, field, authorization, body),
    };
    reply.into_response()
}

async fn set_emission(
    State(shared): State<Arc<Shared>>,
    Path(name): Path<String>,
    headers: HeaderMap,
    body: axum::body::Bytes,
) -> Response {
    edit(&shared, &name, &headers, &body, Field::Emission).await
}

async fn set_transform(
    State(shared): State<Arc<Shared>>,
    Path(name): Path<String>,
    headers: HeaderMap,
    body: axum::body::Bytes,
) -> Response {
    edit(&shared, &name, &headers, &body, Field::Move).await
}

/// Serves one scene's routes on `listener` until its process shuts down.
pub async fn serve(listener: TcpListener, shared: Arc<Shared>) -> std::io::Result<()> {
    let router = router(shared.clone());
    super::listen::serve_router(listener, router, shared.process.clone()).await
}

#[cfg(test)]
mod tests {
    use super::{is_websocket_key, negotiate};
    use axum::http::HeaderValue;

    #[test]
    fn a_viewer_gets_the_newest_protocol_it_offers_and_version_two_when_it_offers_none() {
        let offer = |text: &'static str| negotiate(Some(&HeaderValue::from_static(text)));
        assert_eq!(negotiate(None), Ok(2));
        assert_eq!(offer("radcast.3"), Ok(3));
        assert_eq!(offer("radcast.2, radcast.3"), Ok(3));
        assert_eq!(offer("chat, radcast.2"), Ok(2));
        assert_eq!(offer("radcast.9,radcast.3"), Ok(3));
        let refused = offer("radcast.4, chat").unwrap_err();
        assert!(
            refused.contains("(radcast.4, chat)") && refused.contains("radcast.2, radcast.3"),
            "{refused}"
        );
    }

    #[test]
    fn a_websocket_key_is_sixteen_bytes_in_base64() {
        // RFC 6455's own example, then what is not 16 bytes or not canonical base64.
        assert!(is_websocket_key(b"dGhlIHNhbXBsZSBub25jZQ=="));
        for bad in [
            &b"dGhlIHNhbXBsZSBub25jZQ"[..],
            b"dGhlIHNhbXBsZSBub25jZR==",
            b"dGhlIHNhbXBsZSBub25j*Q==",
            b"dGhlIHNhbXBsZSBub25jZQ=",
            b"x",
            b"",
        ] {
            assert!(!is_websocket_key(bad), "{}", String::from_utf8_lossy(bad));
        }
    }
}
