//! `radcast-client`: headless viewers for a radcast server.

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use client::render::{View, render};
use client::session::{ViewerOutcome, watch_until_final};
use client::{fetch_geometry, fetch_solution, http_base};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Headless viewers for radcast-server.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Connect, wait for the final solution and render PNGs.
    View {
        /// The server's stream, e.g. ws://127.0.0.1:8080/ws.
        #[arg(long, default_value = "ws://127.0.0.1:8080/ws")]
        url: String,
        /// Output PNG; with several viewers or cameras, `-v{viewer}` and `-c{camera}` are added.
        #[arg(long, default_value = "view.png")]
        out: PathBuf,
        /// Camera `ex,ey,ez,tx,ty,tz,ux,uy,uz,fov` (repeatable); default: the scene's own view.
        #[arg(long = "camera", value_parser = View::parse)]
        cameras: Vec<View>,
        /// Image width in pixels.
        #[arg(long, default_value_t = 512)]
        width: u32,
        /// Image height in pixels.
        #[arg(long, default_value_t = 512)]
        height: u32,
        /// Viewers to open at once; all must end with the server's checksum.
        #[arg(long, default_value_t = 1)]
        clients: usize,
        /// Seconds to wait for the final solution.
        #[arg(long, default_value_t = 600.0)]
        timeout: f64,
    },
}

fn output_path(out: &Path, viewer: usize, viewers: usize, camera: usize, cameras: usize) -> PathBuf {
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

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let Command::View { url, out, cameras, width, height, clients, timeout } = Cli::parse().command;
    if clients == 0 || width == 0 || height == 0 {
        bail!("--clients, --width and --height must be at least 1");
    }
    let limit = Duration::try_from_secs_f64(timeout).context("--timeout must be a positive number of seconds")?;
    let base = http_base(&url)?;
    let geometry = {
        let base = base.clone();
        tokio::task::spawn_blocking(move || fetch_geometry(&base)).await??
    };
    let viewers: Vec<_> = (0..clients).map(|_| tokio::spawn({
        let url = url.clone();
        async move { watch_until_final(&url, limit).await }
    })).collect();
    let mut outcomes: Vec<ViewerOutcome> = Vec::with_capacity(clients);
    for viewer in viewers {
        outcomes.push(viewer.await??);
    }
    let solution = {
        let base = base.clone();
        tokio::task::spawn_blocking(move || fetch_solution(&base)).await??
    };
    let expected = solution["checksum"].as_u64().context("/api/solution has no checksum")? as u32;
    let cameras = if cameras.is_empty() { vec![View::for_scene(&geometry)] } else { cameras };
    let mut mismatched = 0;
    for (v, outcome) in outcomes.iter().enumerate() {
        if outcome.buffer.colours.len() != geometry.patches.len() {
            bail!("viewer {v}: {} patches, but the geometry has {}", outcome.buffer.colours.len(), geometry.patches.len());
        }
        let checksum = wire::checksum(&outcome.buffer.colours);
        let version = outcome.buffer.info.map_or(0, |i| i.solution_version);
        let status = if checksum == expected { "ok" } else { "MISMATCH" };
        mismatched += usize::from(checksum != expected);
        println!(
            "viewer {v}: version {version}, {} frames, {} bytes, first frame after {:.1} ms, checksum {checksum:08x} {status}",
            outcome.frames,
            outcome.bytes,
            outcome.first_frame.as_secs_f64() * 1e3
        );
        for (c, view) in cameras.iter().enumerate() {
            let path = output_path(&out, v, clients, c, cameras.len());
            render(&geometry, &outcome.buffer, view, width, height).write_png(&path)?;
            println!("  wrote {}", path.display());
        }
    }
    if mismatched > 0 {
        bail!("{mismatched} of {clients} viewers do not match the server's checksum {expected:08x}");
    }
    Ok(())
}
