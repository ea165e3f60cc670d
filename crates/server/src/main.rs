//! `radcast-server`: solve a scene once, stream it to every viewer.

use anyhow::Context;
use clap::Parser;
use server::http::listen;
use server::publish::prepare::{prepare, shared_for};
use server::publish::solver_thread;
use server::{Limits, fanout};
use solver::args::SolveArgs;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

/// jemalloc gives freed pages back to the system: after a flood of 18,000 slow connections had
/// closed, glibc's per-thread arenas kept 185 of 398 MiB, jemalloc 55 of 329 (docs/RELIABILITY.md).
#[global_allocator]
static ALLOCATOR: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

/// Serves the radiosity of a scene over WebSocket (viewers: `radcast-client view`).
#[derive(Parser)]
#[command(version, about)]
struct Args {
    /// The scene to serve: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
    #[arg(long, env = "RADCAST_SCENE", default_value = "scenes/cornell-box.obj")]
    scene: PathBuf,
    /// Address to listen on.
    #[arg(long, env = "RADCAST_ADDR", default_value = "127.0.0.1:8080")]
    addr: String,
    #[command(flatten)]
    solve: SolveArgs,
    /// Folder for cached solutions (keyed by scene content and settings).
    #[arg(long, env = "RADCAST_CACHE_DIR", default_value = "cache")]
    cache_dir: PathBuf,
    /// Neither read nor write the cache.
    #[arg(long)]
    no_cache: bool,
    /// Most viewers at once; more get 503.
    #[arg(long, env = "RADCAST_MAX_VIEWERS", default_value_t = Limits::default().max_viewers)]
    max_viewers: usize,
    /// Most viewers at once from one IP address; more get 429.
    #[arg(long, env = "RADCAST_MAX_VIEWERS_PER_IP", default_value_t = Limits::default().max_viewers_per_ip)]
    max_viewers_per_ip: usize,
    /// Most TCP connections at once, viewers included; more are refused with 503 before any
    /// byte is read (lowered to fit the open-file limit).
    #[arg(long, env = "RADCAST_MAX_CONNECTIONS", default_value_t = Limits::default().max_connections)]
    max_connections: usize,
    /// Most TCP connections at once from one IP address; more get 429.
    #[arg(long, env = "RADCAST_MAX_CONNECTIONS_PER_IP", default_value_t = Limits::default().max_connections_per_ip)]
    max_connections_per_ip: usize,
    /// Seconds a connection may take to send a whole request head before it is closed.
    #[arg(long, default_value_t = Limits::default().header_timeout.as_secs_f64())]
    header_timeout: f64,
    /// Seconds a send may take before a viewer is dropped as stalled.
    #[arg(long, default_value_t = Limits::default().send_timeout.as_secs_f64())]
    send_timeout: f64,
    /// Seconds without any message (pongs included) before a viewer is dropped.
    #[arg(long, default_value_t = Limits::default().idle_timeout.as_secs_f64())]
    idle_timeout: f64,
    /// Bearer token for the control API; a random one is made and printed when absent.
    #[arg(long, env = "RADCAST_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// NATS server (`nats://host:4222`) to publish every solution version to, for edges
    /// (`--edge`); with `--edge`, the one to follow.
    #[arg(long, env = "RADCAST_NATS")]
    nats: Option<String>,
    /// Run as an edge: no solver, no scene file; serve every scene origins publish to
    /// `--nats`, the same bytes as the origin.
    #[arg(long, requires = "nats")]
    edge: bool,
    /// The scene's name on NATS (subjects, `/scenes/NAME/` on edges); default: the scene
    /// file's stem. On an edge: the scene served at the root (default: the only one).
    #[arg(long, env = "RADCAST_NAME")]
    name: Option<String>,
    /// Demo: the scene's lights flicker (emission changes once a second), so viewers see live updates.
    #[arg(long)]
    animate: bool,
}

/// 128 random bits as hex, from the operating system.
fn random_token() -> anyhow::Result<String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes)
        .map_err(|e| anyhow::anyhow!("no randomness for the control token: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

fn seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value)
        .ok()
        .filter(|d| !d.is_zero())
        .with_context(|| format!("--{flag} must be a positive number of seconds, got {value}"))
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .init();
    let args = Args::parse();
    let request = args.solve.request().map_err(anyhow::Error::msg)?;
    let limits = Limits {
        max_viewers: args.max_viewers,
        max_viewers_per_ip: args.max_viewers_per_ip,
        max_connections: connection_cap(args.max_connections),
        max_connections_per_ip: args.max_connections_per_ip,
        header_timeout: seconds(args.header_timeout, "header-timeout")?,
        send_timeout: seconds(args.send_timeout, "send-timeout")?,
        idle_timeout: seconds(args.idle_timeout, "idle-timeout")?,
        ..Limits::default()
    };
    match args.edge {
        true => run_edge(args, server::Process::new(limits)).await,
        false => run_origin(args, request, limits).await,
    }
}

/// Solves the scene and serves it (and publishes it to NATS with `--nats`).
async fn run_origin(
    args: Args,
    request: solver::SolveRequest,
    limits: Limits,
) -> anyhow::Result<()> {
    let mut prepared = prepare(&args.scene, request)?;
    prepared.check = args.solve.checked();
    if !prepared.scene.has_emitter() {
        tracing::warn!(
            "{}: no material emits light (no positive Ke): every value is 0 until an emission edit",
            args.scene.display()
        );
    }
    // A token the operator chose is theirs to know: only a made-up one is shown.
    let (token, shown) = match args.token {
        Some(token) if !token.is_empty() => (token, "$RADCAST_TOKEN".to_string()),
        Some(_) => anyhow::bail!("--token must not be empty"),
        None => {
            let token = random_token()?;
            (token.clone(), token)
        }
    };
    let shared = shared_for(&prepared, limits, token.clone());
    let (listener, address) = bind(&args.addr).await?;
    // A closed stdout (`radcast-server | head -1`) must not stop the server: errors ignored.
    let _ = writeln!(
        std::io::stdout(),
        "radcast-server: {} ({}) on http://{address}\n  viewers: radcast-client view --url ws://{address}/ws --out view.png\n  control: curl -X PUT -H \"Authorization: Bearer {shown}\" -d '{{\"emission\": [17, 12, 4]}}' http://{address}/api/objects/NAME/emission",
        args.scene.display(),
        match prepared.request.hierarchy {
            Some(_) => format!(
                "{} faces; hierarchical, leaves follow refinement",
                prepared.scene.faces.len()
            ),
            None => format!("{} patches", prepared.mesh.patches.len()),
        }
    );
    if args.animate {
        let emitters = shared
            .emissions
            .lock()
            .expect("emissions lock")
            .iter()
            .filter(|(_, e)| e.iter().any(|c| *c > 0.0))
            .cloned()
            .collect();
        tokio::spawn(animate(shared.clone(), emitters));
    }

    let cache_dir = (!args.no_cache).then_some(args.cache_dir);
    // A plain thread: the process exits on a signal without waiting for a long solve.
    solver_thread::start(prepared, shared.clone(), cache_dir);
    if let Some(url) = &args.nats {
        let name = args
            .name
            .clone()
            .unwrap_or_else(|| fanout::scene_name_for(&args.scene));
        fanout::check_scene_name(&name).map_err(anyhow::Error::msg)?;
        let nats = fanout::Nats::connect(url, &format!("radcast origin {name}")).await?;
        let run = random_token()?;
        tracing::info!("publishing scene '{name}' to NATS at {url}");
        tokio::spawn(fanout::origin::serve(shared.clone(), nats, name, run));
    }
    let router = server::http::routes::router(shared.clone());
    let served = serve_until_signal(listener, router, &shared.process).await;
    shared.edits.close();
    served
}

/// Follows every scene published to `--nats` and serves it.
async fn run_edge(args: Args, process: std::sync::Arc<server::Process>) -> anyhow::Result<()> {
    let url = args.nats.as_deref().context("--edge needs --nats URL")?;
    if let Some(name) = &args.name {
        fanout::check_scene_name(name).map_err(anyhow::Error::msg)?;
    }
    let nats = fanout::Nats::connect(url, "radcast edge").await?;
    let edge = fanout::edge::Edge::new(process.clone(), nats, args.name.clone());
    let (listener, address) = bind(&args.addr).await?;
    let _ = writeln!(
        std::io::stdout(),
        "radcast-server: edge of NATS {url} on http://{address}\n  viewers: radcast-client view --url ws://{address}/ws --out view.png\n  scenes:  curl http://{address}/scenes"
    );
    tokio::spawn(fanout::follow::follow(edge.clone()));
    serve_until_signal(listener, fanout::edge::router(edge), &process).await
}

/// Serves `router` until SIGTERM or SIGINT, then closes every viewer (1001) and waits for
/// their close frames, at most [`SHUTDOWN_DEADLINE`].
async fn serve_until_signal(
    listener: tokio::net::TcpListener,
    router: axum::Router,
    process: &std::sync::Arc<server::Process>,
) -> anyhow::Result<()> {
    let shutdown = process.shutdown.clone();
    let signals = shutdown_signals()?;
    tokio::spawn(async move {
        let signal = signals.await;
        tracing::info!("{signal}: shutting down, closing viewers");
        shutdown.cancel();
    });
    listen::serve_router(listener, router, process.clone()).await?;
    process.tasks.close();
    if tokio::time::timeout(SHUTDOWN_DEADLINE, process.tasks.wait())
        .await
        .is_err()
    {
        tracing::warn!(
            viewers = process.viewers.open(),
            "exiting with connections still open"
        );
    }
    Ok(())
}

/// A listener on `addr` and the address it got (the port, when `addr` asks for any).
async fn bind(addr: &str) -> anyhow::Result<(tokio::net::TcpListener, std::net::SocketAddr)> {
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot listen on {addr}"))?;
    let address = listener.local_addr()?;
    Ok((listener, address))
}

/// From the shutdown signal to exit, at most.
const SHUTDOWN_DEADLINE: Duration = Duration::from_secs(2);

/// File descriptors kept for everything but client connections (the listener, the cache,
/// logs, the runtime).
const RESERVED_DESCRIPTORS: u64 = 64;

/// `asked`, lowered to what the open-file limit allows (raised to its hard limit first: one
/// descriptor per connection), so the cap refuses connections before accept starts failing.
fn connection_cap(asked: usize) -> usize {
    let Ok(files) = rlimit::increase_nofile_limit(u64::MAX) else {
        return asked;
    };
    let fits = files.saturating_sub(RESERVED_DESCRIPTORS) as usize;
    if asked > fits {
        // Only a cap the operator chose is worth a warning; the default just fits itself.
        let line =
            format!("--max-connections {asked} lowered to {fits}: the open-file limit is {files}");
        match asked == Limits::default().max_connections {
            true => tracing::info!("{line}"),
            false => tracing::warn!("{line}"),
        }
    }
    asked.min(fits)
}

/// Handles Ctrl-C (SIGINT) and SIGTERM (what `docker stop` sends) from now on; the future
/// ends with the name of the first that arrives.
fn shutdown_signals() -> anyhow::Result<impl Future<Output = &'static str>> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut terminate = signal(SignalKind::terminate()).context("cannot handle SIGTERM")?;
    let mut interrupt = signal(SignalKind::interrupt()).context("cannot handle SIGINT")?;
    Ok(async move {
        tokio::select! {
            _ = terminate.recv() => "SIGTERM",
            _ = interrupt.recv() => "SIGINT",
        }
    })
}

/// Flickers every emitter between 40% and 100% of its emission, one change a second.
async fn animate(shared: std::sync::Arc<server::Shared>, emitters: Vec<(String, [f64; 3])>) {
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    for step in 0u64.. {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shared.process.shutdown.cancelled() => return,
        }
        let level = 0.7 + 0.3 * (step as f64 * 0.9).sin();
        for (name, emission) in &emitters {
            shared.edits.set_emission(name, emission.map(|c| c * level));
        }
    }
}
