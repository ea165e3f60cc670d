//! The headless radcast viewer: fetch geometry, follow the stream until the solution is final,
//! render it from any camera. It links the wire protocol only, never the solver.

pub mod load;
pub mod render;
pub mod session;
pub mod viewer;

use anyhow::{Context, bail};

/// The HTTP base (`http://host:port`) of a viewer URL like `ws://host:port/ws`.
pub fn http_base(ws_url: &str) -> anyhow::Result<String> {
    let rest = ws_url
        .strip_prefix("ws://")
        .with_context(|| format!("'{ws_url}' is not a ws:// URL (TLS is not supported)"))?;
    let authority = rest.split('/').next().unwrap_or_default();
    if authority.is_empty() {
        bail!("'{ws_url}' has no host");
    }
    Ok(format!("http://{authority}"))
}

/// GETs `url` (blocking) and returns the body, refusing bodies over `limit` bytes.
pub fn http_get(url: &str, limit: u64) -> anyhow::Result<Vec<u8>> {
    let mut response = ureq::get(url)
        .call()
        .with_context(|| format!("GET {url}"))?;
    response
        .body_mut()
        .with_config()
        .limit(limit)
        .read_to_vec()
        .with_context(|| format!("reading the body of {url}"))
}

/// The scene geometry from `/api/scene`.
pub fn fetch_geometry(base: &str) -> anyhow::Result<wire::Geometry> {
    let bytes = http_get(&format!("{base}/api/scene"), 1 << 30)?;
    wire::Geometry::decode(&bytes).with_context(|| format!("{base}/api/scene"))
}

/// The PNG of every texture `geometry`'s texture section names, from `/api/textures/{index}`,
/// decoded; none for an untextured scene.
pub fn fetch_textures(
    base: &str,
    geometry: &wire::Geometry,
) -> anyhow::Result<Vec<render::TextureImage>> {
    let count = geometry.textures.as_ref().map_or(0, |t| t.means.len());
    (0..count)
        .map(|index| {
            let url = format!("{base}/api/textures/{index}");
            render::TextureImage::from_png(&http_get(&url, 1 << 30)?).with_context(|| url)
        })
        .collect()
}

/// The geometry, its textures and which objects emit now: what a viewer draws on.
pub fn fetch_scene(base: &str) -> anyhow::Result<render::Model> {
    let geometry = fetch_geometry(base)?;
    let textures = fetch_textures(base, &geometry)?;
    let url = format!("{base}/api/objects");
    let objects: Vec<ObjectEmission> = serde_json::from_slice(&http_get(&url, 1 << 26)?)
        .with_context(|| format!("{url} is not a list of objects and emissions"))?;
    let emitting = geometry
        .objects
        .iter()
        .map(|name| {
            objects
                .iter()
                .any(|o| o.name == *name && o.emission.iter().any(|c| *c > 0.0))
        })
        .collect();
    Ok(render::Model {
        geometry,
        textures,
        emitting,
    })
}

/// One entry of `/api/objects`.
#[derive(serde::Deserialize)]
struct ObjectEmission {
    name: String,
    emission: [f64; 3],
}

/// `/metrics` as text.
pub fn fetch_metrics(base: &str) -> anyhow::Result<String> {
    String::from_utf8(http_get(&format!("{base}/metrics"), 1 << 20)?)
        .with_context(|| format!("{base}/metrics is not UTF-8"))
}

/// Raises this process's open-file limit to the hard limit (one descriptor per viewer).
pub fn raise_file_limit() -> u64 {
    rlimit::increase_nofile_limit(u64::MAX).unwrap_or(0)
}

/// `/api/solution`.
pub fn fetch_solution(base: &str) -> anyhow::Result<wire::SolutionSummary> {
    let bytes = http_get(&format!("{base}/api/solution"), 1 << 24)?;
    serde_json::from_slice(&bytes)
        .with_context(|| format!("{base}/api/solution is not a solution summary"))
}
