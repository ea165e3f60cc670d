//! `radcast-client`: headless viewers for a radcast server.

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use client::render::{View, render};
use client::session::{ViewerOutcome, next_binary, request_full, watch_until_final_on_any};
use client::viewer::{Step, Viewer};
use client::{fetch_scene, fetch_solution, http_base};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Writes a line to stdout. A reader that went away (`radcast-client watch | head -1`) ends the
/// program quietly instead of with a panic; other write errors are returned.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(error) = writeln!(std::io::stdout(), $($arg)*) {
            if error.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            return Err(error.into());
        }
    }};
}

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
        /// The server's stream, e.g. ws://127.0.0.1:8080/ws; repeat (or separate with commas)
        /// for several servers showing the same scene (an origin and its edges): viewers
        /// are spread over them, and one that loses its server goes on with the next.
        #[arg(
            long = "url",
            default_value = "ws://127.0.0.1:8080/ws",
            value_delimiter = ','
        )]
        urls: Vec<String>,
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
    /// Stay connected and print every update (version, vertices changed, bytes, latency).
    Watch {
        /// The server's stream; with several (repeated or comma-separated), a lost connection
        /// goes on with the next, as a viewer of an edge that stopped would.
        #[arg(
            long = "url",
            default_value = "ws://127.0.0.1:8080/ws",
            value_delimiter = ','
        )]
        urls: Vec<String>,
        /// Render a PNG of every final update into this folder.
        #[arg(long)]
        out_dir: Option<PathBuf>,
        /// Stop after this many updates (default: run until interrupted).
        #[arg(long)]
        updates: Option<u64>,
    },
    /// Load test: open many viewers in this process, each decoding every frame, and report
    /// connection times, frame latency percentiles, traffic and the server's own figures.
    Load {
        /// The server's stream; with several (repeated or comma-separated), viewers are spread
        /// over them in turn (an origin and its edges).
        #[arg(
            long = "url",
            default_value = "ws://127.0.0.1:8080/ws",
            value_delimiter = ','
        )]
        urls: Vec<String>,
        /// Viewers to open.
        #[arg(long, default_value_t = 100)]
        clients: usize,
        /// Seconds over which to spread the connections.
        #[arg(long, default_value_t = 1.0)]
        ramp: f64,
        /// Seconds to keep every viewer connected after the ramp.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
        /// Also change this object's emission once a second (alternating half and full
        /// --edit-emission) and report how long each edit took to reach the last viewer.
        #[arg(long, requires = "token")]
        edit: Option<String>,
        /// Emission for --edit, `r,g,b`.
        #[arg(long, default_value = "17,12,4")]
        edit_emission: String,
        /// The server's control token, for --edit.
        #[arg(long, env = "RADCAST_TOKEN", hide_env_values = true)]
        token: Option<String>,
    },
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

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::View {
            urls,
            out,
            cameras,
            width,
            height,
            clients,
            timeout,
        } => view(urls, out, cameras, width, height, clients, timeout).await,
        Command::Watch {
            urls,
            out_dir,
            updates,
        } => watch(&urls, out_dir, updates).await,
        Command::Load {
            urls,
            clients,
            ramp,
            duration,
            json,
            edit,
            edit_emission,
            token,
        } => {
            let edits = match edit {
                // Edits go to the first server; an edge passes them to its origin.
                Some(object) => Some(Editor::new(
                    &urls[0],
                    object,
                    &edit_emission,
                    token.unwrap_or_default(),
                )?),
                None => None,
            };
            load(urls, clients, ramp, duration, json, edits).await
        }
    }
}

fn positive_seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value)
        .with_context(|| format!("--{flag} must be a non-negative number of seconds, got {value}"))
}

/// Emission edits issued during a load run.
struct Editor {
    url: String,
    token: String,
    emission: [f64; 3],
}

impl Editor {
    fn new(ws_url: &str, object: String, emission: &str, token: String) -> anyhow::Result<Editor> {
        let values: Vec<f64> = emission
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("--edit-emission '{emission}' is not r,g,b"))?;
        let [r, g, b] = values[..] else {
            bail!("--edit-emission '{emission}' needs three numbers")
        };
        Ok(Editor {
            url: format!("{}/api/objects/{object}/emission", http_base(ws_url)?),
            token,
            emission: [r, g, b],
        })
    }

    /// Sends edit number `k` (half the emission when even, full when odd, so the first edit
    /// changes a scene that starts at full); returns its time, µs.
    fn send(&self, k: u64) -> anyhow::Result<u64> {
        let factor = if k % 2 == 0 { 0.5 } else { 1.0 };
        let body = serde_json::json!({ "emission": self.emission.map(|c| c * factor) }).to_string();
        let at = wire::unix_micros_now();
        ureq::put(&self.url)
            .header("Authorization", &format!("Bearer {}", self.token))
            .header("Content-Type", "application/json")
            .send(body.as_bytes())
            .with_context(|| format!("PUT {}", self.url))?;
        Ok(at)
    }
}

async fn load(
    urls: Vec<String>,
    clients: usize,
    ramp: f64,
    duration: f64,
    json: bool,
    editor: Option<Editor>,
) -> anyhow::Result<()> {
    if clients == 0 {
        bail!("--clients must be at least 1");
    }
    let (ramp, duration) = (
        positive_seconds(ramp, "ramp")?,
        positive_seconds(duration, "duration")?,
    );
    let bases = urls
        .iter()
        .map(|url| http_base(url))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let limit = client::raise_file_limit();
    if (limit as usize) < clients + 64 {
        eprintln!("warning: the open-file limit is {limit}; {clients} viewers may fail to connect");
    }
    let (started, cpu_at_start) = (
        std::time::Instant::now(),
        client::load::process_cpu_seconds(),
    );
    let deadline = started + ramp + duration;
    let viewers: Vec<_> = (0..clients)
        .map(|k| {
            tokio::spawn(client::load::run_viewer(
                urls[k % urls.len()].clone(),
                ramp.mul_f64(k as f64 / clients as f64),
                deadline,
            ))
        })
        .collect();
    // Edits start once every viewer is connected and stop a second before the end.
    let edits = editor.map(|editor| {
        tokio::task::spawn_blocking(move || -> anyhow::Result<Vec<u64>> {
            std::thread::sleep(ramp + Duration::from_millis(500)); // wait out the ramp: pacing, not synchronisation
            let mut times = Vec::new();
            for k in 0.. {
                if std::time::Instant::now() + Duration::from_secs(1) >= deadline {
                    break;
                }
                times.push(editor.send(k)?);
                std::thread::sleep(Duration::from_secs(1)); // one edit a second
            }
            Ok(times)
        })
    });
    let mut stats = Vec::with_capacity(clients);
    for viewer in viewers {
        stats.push(viewer.await?);
    }
    let edit_times = match edits {
        Some(task) => task.await??,
        None => Vec::new(),
    };
    let metrics =
        tokio::task::spawn_blocking(move || client::load::servers_metrics(&bases)).await?;
    let cpu = cpu_at_start
        .zip(client::load::process_cpu_seconds())
        .map(|(a, b)| 100.0 * (b - a) / started.elapsed().as_secs_f64());
    let report = client::load::summarize(stats, metrics, cpu, &edit_times);
    if json {
        say!("{}", serde_json::to_string(&report)?);
    } else {
        let l = report.latency_ms;
        say!(
            "viewers   {} asked, {} connected, {} failed {:?}",
            report.clients,
            report.connected,
            report.failed,
            report.failures
        );
        say!(
            "connect   p50 {:.1} ms, p99 {:.1} ms; first frame p50 {:.1} ms, p99 {:.1} ms",
            report.connect_ms.p50,
            report.connect_ms.p99,
            report.first_frame_ms.p50,
            report.first_frame_ms.p99
        );
        say!(
            "latency   p50 {:.1} ms, p90 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
            l.p50,
            l.p90,
            l.p99,
            l.max
        );
        say!(
            "traffic   {} frames, {} bytes; per viewer {}..{} frames; {} resyncs",
            report.frames,
            report.bytes,
            report.frames_per_viewer[0],
            report.frames_per_viewer[1],
            report.resyncs
        );
        if !report.edit_to_last_viewer_ms.is_empty() {
            let e = &report.edit_to_last_viewer_ms;
            let mut sorted = e.clone();
            sorted.sort_by(f64::total_cmp);
            say!(
                "edits     {} edits, PUT to last viewer: median {:.1} ms, max {:.1} ms",
                e.len(),
                sorted[sorted.len() / 2],
                sorted[sorted.len() - 1]
            );
        }
        if let Some(cpu) = report.load_tester_cpu_percent {
            say!("tester    {cpu:.0}% CPU (of one core) in this process");
        }
        for (name, value) in report
            .server
            .iter()
            .filter(|(n, _)| !n.contains("radcast_solve"))
        {
            say!("server    {name} {value}");
        }
    }
    Ok(())
}

async fn watch(
    urls: &[String],
    out_dir: Option<PathBuf>,
    updates: Option<u64>,
) -> anyhow::Result<()> {
    let fetch = |url: &str| {
        let base = http_base(url);
        tokio::task::spawn_blocking(move || fetch_scene(&base?))
    };
    let mut geometry = match &out_dir {
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create", dir.display()))?;
            Some(fetch(&urls[0]).await??)
        }
        None => None,
    };
    let mut seen = 0u64;
    let mut failed_in_a_row = 0;
    for url in urls.iter().cycle() {
        let ended = match tokio_tungstenite::connect_async(url.as_str()).await {
            Ok((mut socket, _)) => {
                failed_in_a_row = 0;
                let mut viewer = Viewer::default();
                loop {
                    let data = match next_binary(&mut socket).await {
                        Some(Ok(data)) => data,
                        Some(Err(error)) => break Err(error),
                        None => break Ok(()),
                    };
                    let (full, changed, info) = match viewer.receive(&data)? {
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
                            if geometry.is_some() {
                                geometry = Some(fetch(url).await??);
                            }
                            continue;
                        }
                        Step::NeedsFull => {
                            request_full(&mut socket).await?;
                            continue;
                        }
                        Step::Applied {
                            full,
                            changed,
                            info,
                        } => (full, changed, info),
                    };
                    let latency_ms =
                        wire::unix_micros_now().saturating_sub(info.sent_at_unix_micros) as f64
                            / 1e3;
                    say!(
                        "version {}: {}, {changed} vertices changed, {} bytes, latency {latency_ms:.1} ms{}",
                        info.solution_version,
                        if full { "full" } else { "delta" },
                        data.len(),
                        if info.is_final { ", final" } else { "" }
                    );
                    if let (Some(dir), Some(model), true) = (&out_dir, &geometry, info.is_final) {
                        let path = dir.join(format!("version-{:06}.png", info.solution_version));
                        render(
                            model,
                            viewer.buffer(),
                            &View::for_scene(&model.geometry),
                            512,
                            512,
                        )
                        .write_png(&path)?;
                    }
                    seen += 1;
                    if updates.is_some_and(|n| seen >= n) {
                        socket.close(None).await?;
                        return Ok(());
                    }
                }
            }
            Err(error) => {
                failed_in_a_row += 1;
                Err(anyhow::Error::new(error).context(format!("connecting to {url}")))
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

async fn view(
    urls: Vec<String>,
    out: PathBuf,
    cameras: Vec<View>,
    width: u32,
    height: u32,
    clients: usize,
    timeout: f64,
) -> anyhow::Result<()> {
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
            tokio::spawn(async move { watch_until_final_on_any(&urls, k, limit).await })
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
    let expected = solution.checksum;
    let cameras = if cameras.is_empty() {
        vec![View::for_scene(&model.geometry)]
    } else {
        cameras
    };
    let mut mismatched = 0;
    for (v, outcome) in outcomes.iter().enumerate() {
        if outcome.buffer.colours.len() != model.geometry.positions.len() {
            bail!(
                "viewer {v}: {} colours, but the geometry has {} vertices",
                outcome.buffer.colours.len(),
                model.geometry.positions.len()
            );
        }
        let checksum = wire::checksum(&outcome.buffer.colours);
        let version = outcome.buffer.info.map_or(0, |i| i.solution_version);
        let status = if checksum == expected {
            "ok"
        } else {
            "MISMATCH"
        };
        mismatched += usize::from(checksum != expected);
        say!(
            "viewer {v}: version {version}, {} frames, {} bytes, first frame after {:.1} ms, checksum {checksum:08x} {status}",
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
            "{mismatched} of {clients} viewers do not match the server's checksum {expected:08x}"
        );
    }
    Ok(())
}
