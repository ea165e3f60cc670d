//! `radcast-client view`: viewers that follow the stream to the final solution, check the
//! server's checksum and render PNGs.

use anyhow::{Context, bail};
use client::render::{View, render};
use client::session::{ViewerOutcome, watch_until_final_on_any};
use client::{fetch_scene, fetch_solution, http_base};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The arguments of `radcast-client view`.
#[derive(clap::Args)]
pub struct ViewCommand {
    /// The server's stream, e.g. ws://127.0.0.1:8080/ws; repeat (or separate with commas)
    /// for several servers showing the same scene (an origin and its edges): viewers
    /// are spread over them, and one that loses its server goes on with the next.
    #[arg(
        long = "url",
        default_value = "ws://127.0.0.1:8080/ws",
        value_delimiter = ','
    )]
    pub urls: Vec<String>,
    /// Output PNG; with several viewers or cameras, `-v{viewer}` and `-c{camera}` are added.
    #[arg(long, default_value = "view.png")]
    pub out: PathBuf,
    /// Camera `ex,ey,ez,tx,ty,tz,ux,uy,uz,fov` (repeatable); default: the scene's own view.
    #[arg(long = "camera", value_parser = View::parse)]
    pub cameras: Vec<View>,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Viewers to open at once; all must end with the server's checksum.
    #[arg(long, default_value_t = 1)]
    pub clients: usize,
    /// Seconds to wait for the final solution.
    #[arg(long, default_value_t = 600.0)]
    pub timeout: f64,
}

impl ViewCommand {
    /// Runs the command, its viewers speaking `protocol`.
    pub async fn run(self, protocol: u16) -> anyhow::Result<()> {
        let ViewCommand {
            urls,
            out,
            cameras,
            width,
            height,
            clients,
            timeout,
        } = self;
        if clients == 0 || width == 0 || height == 0 {
            bail!("--clients, --width and --height must be at least 1");
        }
        let limit = Duration::try_from_secs_f64(timeout)
            .context("--timeout must be a positive number of seconds")?;
        let base = http_base(&urls[0])?;
        let model = {
            let base = base.clone();
            tokio::task::spawn_blocking(move || fetch_scene(&base)).await??
        };
        let viewers: Vec<_> = (0..clients)
            .map(|k| {
                let urls = urls.clone();
                tokio::spawn(
                    async move { watch_until_final_on_any(&urls, k, protocol, limit).await },
                )
            })
            .collect();
        let mut outcomes: Vec<ViewerOutcome> = Vec::with_capacity(clients);
        for viewer in viewers {
            outcomes.push(viewer.await??);
        }
        let solution = {
            let base = base.clone();
            tokio::task::spawn_blocking(move || fetch_solution(&base)).await??
        };
        let cameras = if cameras.is_empty() {
            vec![View::for_scene(&model.geometry)]
        } else {
            cameras
        };
        let mut mismatched = 0;
        for (v, outcome) in outcomes.iter().enumerate() {
            let values = outcome.buffer.radiosity().len();
            if values != model.geometry.positions.len() {
                bail!(
                    "viewer {v}: {values} colours, but the geometry has {} vertices",
                    model.geometry.positions.len()
                );
            }
            let version = outcome.buffer.info.map_or(0, |i| i.solution_version);
            let (held, checksum) = match &outcome.buffer.sum {
                Some(values) => ("sum", wire::responses::sum_checksum(values)),
                None => ("codes", wire::checksum(&outcome.buffer.colours)),
            };
            let matches = outcome.buffer.matches(&solution);
            let status = if matches { "ok" } else { "MISMATCH" };
            mismatched += usize::from(!matches);
            say!(
                "viewer {v}: version {version} as {held}, {} frames, {} bytes, first frame after {:.1} ms, checksum {checksum:08x} {status}",
                outcome.frames,
                outcome.bytes,
                outcome.first_frame.as_secs_f64() * 1e3
            );
            for (c, view) in cameras.iter().enumerate() {
                let path = output_path(&out, v, clients, c, cameras.len());
                render(&model, &outcome.buffer, view, width, height).write_png(&path)?;
                say!("  wrote {}", path.display());
            }
        }
        if mismatched > 0 {
            bail!(
                "{mismatched} of {clients} viewers do not match the server's version {} (checksum {:08x}, sum checksum {:?})",
                solution.solution_version,
                solution.checksum,
                solution.sum_checksum
            );
        }
        Ok(())
    }
}

fn output_path(
    out: &Path,
    viewer: usize,
    viewers: usize,
    camera: usize,
    cameras: usize,
) -> PathBuf {
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("view");
    let mut name = stem.to_string();
    if viewers > 1 {
        name += &format!("-v{viewer}");
    }
    if cameras > 1 {
        name += &format!("-c{camera}");
    }
    out.with_file_name(format!("{name}.png"))
}
