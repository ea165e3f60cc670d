//! `radcast-client watch`: one viewer that prints every update, going on with the next server
//! when its own ends.

use anyhow::Context;
use client::render::{Model, View, render};
use client::session::{next_binary, request_full};
use client::viewer::{Frame, Step, Viewer};
use client::{fetch_scene, http_base};
use std::path::PathBuf;

/// The arguments of `radcast-client watch`.
#[derive(clap::Args)]
pub struct WatchCommand {
    /// The server's stream; with several (repeated or comma-separated), a lost connection
    /// goes on with the next, as a viewer of an edge that stopped would.
    #[arg(
        long = "url",
        default_value = "ws://127.0.0.1:8080/ws",
        value_delimiter = ','
    )]
    pub urls: Vec<String>,
    /// Render a PNG of every final update into this folder.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Stop after this many updates (default: run until interrupted).
    #[arg(long)]
    pub updates: Option<u64>,
}

impl WatchCommand {
    /// Runs the command, speaking `protocol`.
    pub async fn run(self, protocol: u16) -> anyhow::Result<()> {
        let WatchCommand {
            urls,
            out_dir,
            updates,
        } = self;
        let geometry = match &out_dir {
            Some(dir) => {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("{}: cannot create", dir.display()))?;
                Some(fetch(&urls[0]).await?)
            }
            None => None,
        };
        let mut watcher = Watcher {
            out_dir,
            geometry,
            seen: 0,
            updates,
        };
        let mut failed_in_a_row = 0;
        for url in urls.iter().cycle() {
            let ended = match client::session::connect(url, protocol, None).await {
                Ok(socket) => {
                    failed_in_a_row = 0;
                    match watcher.follow(url, socket).await? {
                        Followed::Enough => return Ok(()),
                        Followed::Ended(ended) => ended,
                    }
                }
                Err(error) => {
                    failed_in_a_row += 1;
                    Err(error)
                }
            };
            // One server: its end is the end. Several: go on with the next, until every one
            // refused in a row.
            if urls.len() == 1 || failed_in_a_row == urls.len() {
                return ended;
            }
            let why = match &ended {
                Ok(()) => "connection ended".to_string(),
                Err(error) => format!("{error:#}"),
            };
            say!("{url}: {why}; going on with the next server");
        }
        unreachable!("urls is never empty: clap gives a default")
    }
}

/// The geometry served at the stream `url`'s server.
async fn fetch(url: &str) -> anyhow::Result<Model> {
    let base = http_base(url);
    tokio::task::spawn_blocking(move || fetch_scene(&base?)).await?
}

/// What a watch has seen, across the servers it goes through.
struct Watcher {
    out_dir: Option<PathBuf>,
    /// The geometry, when final updates are rendered.
    geometry: Option<Model>,
    /// Updates printed so far.
    seen: u64,
    /// Stop after this many.
    updates: Option<u64>,
}

/// How following one server ended.
enum Followed {
    /// The connection ended, cleanly or with this error (the next server may do better).
    Ended(anyhow::Result<()>),
    /// As many updates as asked for were seen.
    Enough,
}

impl Watcher {
    /// Prints every update `socket` brings until it ends or enough were seen; an error is one
    /// no other server would mend (a malformed frame, a PNG not written).
    async fn follow(
        &mut self,
        url: &str,
        mut socket: client::session::Socket,
    ) -> anyhow::Result<Followed> {
        let mut viewer = Viewer::default();
        loop {
            let data = match next_binary(&mut socket).await {
                Some(Ok(data)) => data,
                Some(Err(error)) => return Ok(Followed::Ended(Err(error))),
                None => return Ok(Followed::Ended(Ok(()))),
            };
            let (frame, changed, info) = match viewer.receive(&data)? {
                Step::Hello(hello) => {
                    say!(
                        "hello: scene {:016x}, {} vertices, protocol {}, from {url}",
                        hello.scene_id,
                        hello.vertex_count,
                        hello.protocol_version
                    );
                    continue;
                }
                Step::GeometryChanged { geometry_version } => {
                    say!("geometry changed: version {geometry_version}");
                    if self.geometry.is_some() {
                        self.geometry = Some(fetch(url).await?);
                    }
                    continue;
                }
                Step::NeedsFull => {
                    request_full(&mut socket).await?;
                    continue;
                }
                Step::Response { response_id } => {
                    say!("response {response_id}: {} bytes", data.len());
                    continue;
                }
                Step::Applied {
                    frame,
                    changed,
                    info,
                } => (frame, changed, info),
            };
            let latency_ms =
                wire::unix_micros_now().saturating_sub(info.sent_at_unix_micros) as f64 / 1e3;
            let what = match frame {
                Frame::Full => format!("full, {changed} vertices changed"),
                Frame::Delta => format!("delta, {changed} vertices changed"),
                Frame::Sum => format!("sum of {changed} responses"),
            };
            say!(
                "version {}: {what}, {} bytes, latency {latency_ms:.1} ms{}",
                info.solution_version,
                data.len(),
                if info.is_final { ", final" } else { "" }
            );
            if let (Some(dir), Some(model), true) = (&self.out_dir, &self.geometry, info.is_final) {
                let path = dir.join(format!("version-{:06}.png", info.solution_version));
                let view = View::for_scene(&model.geometry);
                render(model, viewer.buffer(), &view, 512, 512).write_png(&path)?;
            }
            self.seen += 1;
            if self.updates.is_some_and(|n| self.seen >= n) {
                socket.close(None).await?;
                return Ok(Followed::Enough);
            }
        }
    }
}
