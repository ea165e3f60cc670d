//! The browser viewer: its page and scripts, embedded in the binary so nothing is fetched from
//! anywhere else at run time.

use axum::Router;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;

/// Each embedded file: its route, content type and text.
const FILES: [(&str, &str, &str); 5] = [
    (
        "/",
        "text/html; charset=utf-8",
        include_str!("../../web/index.html"),
    ),
    (
        "/viewer.js",
        "text/javascript; charset=utf-8",
        include_str!("../../web/viewer.js"),
    ),
    (
        "/protocol.js",
        "text/javascript; charset=utf-8",
        include_str!("../../web/protocol.js"),
    ),
    (
        "/display.js",
        "text/javascript; charset=utf-8",
        include_str!("../../web/display.js"),
    ),
    (
        "/control.js",
        "text/javascript; charset=utf-8",
        include_str!("../../web/control.js"),
    ),
];

/// The routes of the page and its scripts.
pub fn routes<S: Clone + Send + Sync + 'static>() -> Router<S> {
    FILES
        .iter()
        .fold(Router::new(), |router, &(path, content_type, text)| {
            router.route(
                path,
                get(move || async move {
                    ([(header::CONTENT_TYPE, content_type)], text).into_response()
                }),
            )
        })
}
