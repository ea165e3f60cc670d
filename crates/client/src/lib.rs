//! The headless radcast viewer: fetch geometry, follow the stream until the solution is final,
//! render it from any camera. It links the wire protocol only, never the solver.

pub mod render;
pub mod session;

use anyhow::{Context, bail};

/// The HTTP base (`http://host:port`) of a viewer URL like `ws://host:port/ws`.
pub fn http_base(ws_url: &str) -> anyhow::Result<String> {
    let rest = ws_url.strip_prefix("ws://").with_context(|| format!("'{ws_url}' is not a ws:// URL (TLS is not supported)"))?;
    let authority = rest.split('/').next().unwrap_or_default();
    if authority.is_empty() {
        bail!("'{ws_url}' has no host");
    }
    Ok(format!("http://{authority}"))
}

/// GETs `url` (blocking) and returns the body, refusing bodies over `limit` bytes.
pub fn http_get(url: &str, limit: u64) -> anyhow::Result<Vec<u8>> {
    let mut response = ureq::get(url).call().with_context(|| format!("GET {url}"))?;
    response.body_mut().with_config().limit(limit).read_to_vec().with_context(|| format!("reading the body of {url}"))
}

/// The scene geometry from `/api/scene`.
pub fn fetch_geometry(base: &str) -> anyhow::Result<wire::Geometry> {
    let bytes = http_get(&format!("{base}/api/scene"), 1 << 30)?;
    wire::Geometry::decode(&bytes).with_context(|| format!("{base}/api/scene"))
}

/// `/api/solution` as JSON.
pub fn fetch_solution(base: &str) -> anyhow::Result<serde_json::Value> {
    let bytes = http_get(&format!("{base}/api/solution"), 1 << 24)?;
    serde_json::from_slice(&bytes).with_context(|| format!("{base}/api/solution is not JSON"))
}
