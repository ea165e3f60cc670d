//! `radcast-client load`: many viewers in one process, optionally with emission edits, and
//! what they measured.

use super::positive_seconds;
use anyhow::{Context, bail};
use client::http_base;
use client::load::LoadReport;
use std::time::Duration;

/// The arguments of `radcast-client load`.
#[derive(clap::Args)]
pub struct LoadCommand {
    /// The server's stream; with several (repeated or comma-separated), viewers are spread
    /// over them in turn (an origin and its edges).
    #[arg(
        long = "url",
        default_value = "ws://127.0.0.1:8080/ws",
        value_delimiter = ','
    )]
    pub urls: Vec<String>,
    /// Viewers to open.
    #[arg(long, default_value_t = 100)]
    pub clients: usize,
    /// Seconds over which to spread the connections.
    #[arg(long, default_value_t = 1.0)]
    pub ramp: f64,
    /// Seconds to keep every viewer connected after the ramp.
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also change this object's emission once a second (alternating half and full
    /// --edit-emission) and report how long each edit took to reach the last viewer.
    #[arg(long, requires = "token")]
    pub edit: Option<String>,
    /// Emission for --edit, `r,g,b`.
    #[arg(long, default_value = "17,12,4")]
    pub edit_emission: String,
    /// Seconds between edits (with --edit).
    #[arg(long, default_value_t = 1.0)]
    pub edit_every: f64,
    /// With --edit, make every other edit a move of this object, 10 units along x and back.
    #[arg(long = "move", requires = "edit")]
    pub move_object: Option<String>,
    /// The server's control token, for --edit.
    #[arg(long, env = "RADCAST_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

impl LoadCommand {
    /// Runs the command, its viewers speaking `protocol`.
    pub async fn run(self, protocol: u16) -> anyhow::Result<()> {
        let LoadCommand {
            urls,
            clients,
            ramp,
            duration,
            json,
            edit,
            edit_emission,
            edit_every,
            move_object,
            token,
        } = self;
        let every = positive_seconds(edit_every, "edit-every")?;
        let editor = match edit {
            // Edits go to the first server; an edge passes them to its origin.
            Some(object) => Some(Editor::new(
                &urls[0],
                (object, move_object),
                &edit_emission,
                (token.unwrap_or_default(), every),
            )?),
            None => None,
        };
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
            eprintln!(
                "warning: the open-file limit is {limit}; {clients} viewers may fail to connect"
            );
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
                    protocol,
                    ramp.mul_f64(k as f64 / clients as f64),
                    deadline,
                ))
            })
            .collect();
        let edits = editor.map(|editor| editor.spawn(ramp, deadline));
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
        let solution = {
            let base = http_base(&urls[0])?;
            tokio::task::spawn_blocking(move || client::fetch_solution(&base)).await?
        }?;
        let report = client::load::summarize(stats, metrics, cpu, &edit_times, &solution);
        match json {
            true => say!("{}", serde_json::to_string(&report)?),
            false => print_report(&report)?,
        }
        Ok(())
    }
}

/// Edits issued during a load run: emissions, and moves when asked for.
struct Editor {
    emission_url: String,
    move_url: Option<String>,
    token: String,
    emission: [f64; 3],
    every: Duration,
}

/// The seconds the last edit leaves before the run ends, for the server to solve it and every
/// viewer to get it: the run's end then checks what each viewer holds.
const SETTLE: Duration = Duration::from_secs(3);

impl Editor {
    fn new(
        ws_url: &str,
        (object, move_object): (String, Option<String>),
        emission: &str,
        (token, every): (String, Duration),
    ) -> anyhow::Result<Editor> {
        let values: Vec<f64> = emission
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("--edit-emission '{emission}' is not r,g,b"))?;
        let [r, g, b] = values[..] else {
            bail!("--edit-emission '{emission}' needs three numbers")
        };
        let base = http_base(ws_url)?;
        Ok(Editor {
            emission_url: format!("{base}/api/objects/{object}/emission"),
            move_url: move_object.map(|o| format!("{base}/api/objects/{o}/transform")),
            token,
            emission: [r, g, b],
            every,
        })
    }

    /// Edits every `every` from when every viewer is connected (after `ramp`) to [`SETTLE`]
    /// before `deadline`, on a thread of its own; the task gives each edit's time, µs.
    fn spawn(
        self,
        ramp: Duration,
        deadline: std::time::Instant,
    ) -> tokio::task::JoinHandle<anyhow::Result<Vec<u64>>> {
        tokio::task::spawn_blocking(move || {
            std::thread::sleep(ramp + Duration::from_millis(500)); // wait out the ramp: pacing, not synchronisation
            let mut times = Vec::new();
            for k in 0.. {
                if std::time::Instant::now() + SETTLE >= deadline {
                    break;
                }
                times.push(self.send(k)?);
                std::thread::sleep(self.every); // the edit rate asked for: pacing
            }
            Ok(times)
        })
    }

    /// Sends edit number `k`: with a move object, odd edits move it 10 units along +x or back
    /// (in turn); the others set half the emission or all of it (in turn, so the first edit
    /// changes a scene that starts at full). Returns its time, µs.
    fn send(&self, k: u64) -> anyhow::Result<u64> {
        let (url, body) = match (&self.move_url, k % 2) {
            (Some(url), 1) => {
                let x = if k % 4 == 1 { 10.0 } else { -10.0 };
                (url, serde_json::json!({ "translate": [x, 0.0, 0.0] }))
            }
            _ => {
                let emissions = if self.move_url.is_some() { k / 2 } else { k };
                let factor = if emissions % 2 == 0 { 0.5 } else { 1.0 };
                let emission = self.emission.map(|c| c * factor);
                (
                    &self.emission_url,
                    serde_json::json!({ "emission": emission }),
                )
            }
        };
        let at = wire::unix_micros_now();
        ureq::put(url)
            .header("Authorization", &format!("Bearer {}", self.token))
            .header("Content-Type", "application/json")
            .send(body.to_string().as_bytes())
            .with_context(|| format!("PUT {url}"))?;
        Ok(at)
    }
}

/// The load report as text.
fn print_report(report: &LoadReport) -> anyhow::Result<()> {
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
            "edits     {} edits, PUT to last viewer: median {:.1} ms, max {:.1} ms; {:.0} bytes per viewer per edit",
            e.len(),
            sorted[sorted.len() / 2],
            sorted[sorted.len() - 1],
            report.bytes_per_viewer_per_edit.unwrap_or(0.0)
        );
    }
    say!(
        "end       {} of {} connected viewers hold the server's final version {} ({} out-of-order versions seen)",
        report.viewers_on_final_version,
        report.connected,
        report.final_version,
        report.versions_out_of_order
    );
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
    Ok(())
}
