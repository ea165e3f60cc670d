//! `radcast-server`: solve a scene once, stream it to every viewer.

use anyhow::Context;
use clap::Parser;
use server::solving::{prepare, shared_for, solve_and_publish};
use server::{Limits, routes};
use solver::{FormFactorSettings, Method, PatchTarget, SolveRequest, SolverSettings};
use std::path::PathBuf;
use std::time::Duration;

/// Serves the radiosity of a scene over WebSocket (viewers: `radcast-client view`).
#[derive(Parser)]
#[command(version, about)]
struct Args {
    /// The OBJ scene to serve.
    #[arg(long, env = "RADCAST_SCENE", default_value = "scenes/cornell-box.obj")]
    scene: PathBuf,
    /// Address to listen on.
    #[arg(long, env = "RADCAST_ADDR", default_value = "127.0.0.1:8080")]
    addr: String,
    /// Target number of patches.
    #[arg(long, env = "RADCAST_PATCHES", default_value_t = 1000)]
    patches: usize,
    /// Solver: jacobi, gauss-seidel, progressive or gmres.
    #[arg(long, env = "RADCAST_METHOD", default_value = "gmres")]
    method: Method,
    /// Relative residual to stop at.
    #[arg(long, env = "RADCAST_TOLERANCE", default_value_t = 1e-6)]
    tolerance: f64,
    /// Folder for cached solutions (keyed by scene content and settings).
    #[arg(long, env = "RADCAST_CACHE_DIR", default_value = "cache")]
    cache_dir: PathBuf,
    /// Neither read nor write the cache.
    #[arg(long)]
    no_cache: bool,
    /// Most viewers at once; more get 503.
    #[arg(long, env = "RADCAST_MAX_VIEWERS", default_value_t = Limits::default().max_viewers)]
    max_viewers: usize,
    /// Seconds a send may take before a viewer is dropped as stalled.
    #[arg(long, default_value_t = Limits::default().send_timeout.as_secs_f64())]
    send_timeout: f64,
    /// Seconds without any message (pongs included) before a viewer is dropped.
    #[arg(long, default_value_t = Limits::default().idle_timeout.as_secs_f64())]
    idle_timeout: f64,
}

fn seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value).ok().filter(|d| !d.is_zero()).with_context(|| format!("--{flag} must be a positive number of seconds, got {value}"))
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt().with_writer(std::io::stderr).with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into())).init();
    let args = Args::parse();
    anyhow::ensure!(args.patches > 0, "--patches must be at least 1");
    anyhow::ensure!(args.tolerance > 0.0 && args.tolerance < 1.0, "--tolerance must be in (0, 1), got {}", args.tolerance);
    let request = SolveRequest {
        patches: PatchTarget::Count(args.patches),
        form_factors: FormFactorSettings::default(),
        solver: SolverSettings { method: args.method, tolerance: args.tolerance, ..SolverSettings::default() },
        ..SolveRequest::default()
    };
    let limits = Limits {
        max_viewers: args.max_viewers,
        send_timeout: seconds(args.send_timeout, "send-timeout")?,
        idle_timeout: seconds(args.idle_timeout, "idle-timeout")?,
        ..Limits::default()
    };
    let prepared = prepare(&args.scene, request)?;
    let shared = shared_for(&prepared, limits);
    let listener = tokio::net::TcpListener::bind(&args.addr).await.with_context(|| format!("cannot listen on {}", args.addr))?;
    let address = listener.local_addr()?;
    println!(
        "radcast-server: {} ({} patches) on http://{address}\n  viewers: radcast-client view --url ws://{address}/ws --out view.png",
        args.scene.display(),
        prepared.mesh.patches.len()
    );

    let cache_dir = (!args.no_cache).then_some(args.cache_dir);
    let solving = {
        let shared = shared.clone();
        tokio::task::spawn_blocking(move || {
            if let Err(error) = solve_and_publish(&prepared, &shared, cache_dir.as_deref()) {
                tracing::error!("solve failed: {error:#}");
            }
        })
    };
    let shutdown = shared.shutdown.clone();
    tokio::spawn(async move {
        let _ = tokio::signal::ctrl_c().await;
        tracing::info!("shutting down: closing viewers");
        shutdown.cancel();
    });
    let stopped = shared.shutdown.clone();
    axum::serve(listener, routes::router(shared)).with_graceful_shutdown(async move { stopped.cancelled().await }).await?;
    solving.abort();
    Ok(())
}
