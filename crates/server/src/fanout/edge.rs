//! An edge: runs no solver and reads no scene file. It serves every scene it follows on NATS
//! ([`super::follow`]) with the same routes as an origin, byte for byte: the root serves the
//! default scene, `/scenes/NAME/…` any.

use super::{Nats, Upstream};
use crate::{Process, Shared};
use axum::Router;
use axum::extract::{Request, State};
use axum::http::{StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use std::collections::BTreeMap;
use std::sync::Arc;
use tokio::sync::watch;
use tower::ServiceExt;

/// One scene as this edge serves it.
pub(super) struct Served {
    pub(super) shared: Arc<Shared>,
    pub(super) router: Router,
}

/// Every scene this edge follows.
pub struct Edge {
    pub(super) process: Arc<Process>,
    pub(super) nats: Nats,
    pub(super) scenes: watch::Sender<BTreeMap<String, Arc<Served>>>,
    default_scene: Option<String>,
    /// Scenes whose record was seen but whose snapshot could not be read yet.
    pub(super) pending: std::sync::Mutex<std::collections::BTreeSet<String>>,
}

impl Edge {
    /// An edge on `nats` in `process`; `default_scene` is served at the root (without it, the
    /// only scene is, when there is one).
    pub fn new(process: Arc<Process>, nats: Nats, default_scene: Option<String>) -> Arc<Edge> {
        Arc::new(Edge {
            process,
            nats,
            scenes: Default::default(),
            default_scene,
            pending: Default::default(),
        })
    }

    /// The names of the scenes served now.
    pub fn scene_names(&self) -> Vec<String> {
        self.scenes.borrow().keys().cloned().collect()
    }

    /// The shared state of scene `name`, if it is served.
    pub fn scene(&self, name: &str) -> Option<Arc<Shared>> {
        self.served(name).map(|s| s.shared.clone())
    }

    /// Waits until scene `name` is served as published by the origin run `run`, and returns it.
    pub async fn serving(&self, name: &str, run: &str) -> Arc<Shared> {
        let mut scenes = self.scenes.subscribe();
        let served = scenes
            .wait_for(|scenes| {
                scenes
                    .get(name)
                    .is_some_and(|s| upstream(&s.shared).run == run)
            })
            .await
            .expect("the edge lives as long as its sender");
        served[name].shared.clone()
    }

    pub(super) fn served(&self, name: &str) -> Option<Arc<Served>> {
        self.scenes.borrow().get(name).cloned()
    }

    /// The scene the root serves: the one named at start, or the only one.
    fn root_scene(&self) -> Result<Arc<Served>, String> {
        let scenes = self.scenes.borrow();
        match (&self.default_scene, scenes.len()) {
            (Some(name), _) => scenes.get(name).cloned().ok_or_else(|| {
                format!("down: scene '{name}' has not been published to NATS (yet)")
            }),
            (None, 1) => Ok(scenes.values().next().expect("one scene").clone()),
            (None, 0) => Err("down: no origin has published a scene to NATS (yet)".into()),
            (None, _) => Err(format!(
                "down: this edge serves several scenes: use /scenes/NAME/... with NAME one of {}",
                scenes.keys().cloned().collect::<Vec<_>>().join(", ")
            )),
        }
    }
}

/// The edge's routes: `/scenes` lists the scene names, `/scenes/NAME/...` serves scene NAME
/// and every other path the root scene, with an origin's routes.
pub fn router(edge: Arc<Edge>) -> Router {
    Router::new()
        .route("/scenes", axum::routing::get(list))
        .fallback(dispatch)
        .with_state(edge)
}

async fn list(State(edge): State<Arc<Edge>>) -> Response {
    axum::Json(edge.scene_names()).into_response()
}

async fn dispatch(State(edge): State<Arc<Edge>>, mut request: Request) -> Response {
    let path = request.uri().path().to_string();
    let (served, rest) = match path.strip_prefix("/scenes/") {
        Some(tail) => {
            let Some((name, rest)) = tail.find('/').map(|slash| tail.split_at(slash)) else {
                // The page's links are relative: it must be served under a trailing slash.
                let query = request
                    .uri()
                    .query()
                    .map(|q| format!("?{q}"))
                    .unwrap_or_default();
                return axum::response::Redirect::permanent(&format!("/scenes/{tail}/{query}"))
                    .into_response();
            };
            match edge.served(name) {
                Some(served) => (served, rest.to_string()),
                None => {
                    return (
                        StatusCode::NOT_FOUND,
                        format!("no scene named '{name}' on this edge\n"),
                    )
                        .into_response();
                }
            }
        }
        None => match edge.root_scene() {
            Ok(served) => (served, path),
            Err(why) => {
                return (StatusCode::SERVICE_UNAVAILABLE, format!("{why}\n")).into_response();
            }
        },
    };
    let query = request
        .uri()
        .query()
        .map(|q| format!("?{q}"))
        .unwrap_or_default();
    let uri = format!("{rest}{query}");
    match uri.parse::<Uri>() {
        Ok(uri) => *request.uri_mut() = uri,
        Err(_) => return (StatusCode::BAD_REQUEST, "malformed path\n").into_response(),
    }
    match served.router.clone().oneshot(request).await {
        Ok(response) => response,
        Err(never) => match never {},
    }
}

/// The link to its origin that every scene an edge serves has.
pub(super) fn upstream(shared: &Shared) -> &Upstream {
    shared
        .upstream
        .as_ref()
        .expect("an edge's scenes have an upstream")
}
