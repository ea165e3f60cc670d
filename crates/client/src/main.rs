//! `radcast-client`: headless viewers for a radcast server, a command a file (`commands/`).

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

mod commands;

use clap::{Parser, Subcommand};
use commands::{load, view, watch};

/// Headless viewers for radcast-server.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// The protocol version viewers ask for: 3 takes each light's response once and then
    /// only emissions (docs/PROTOCOL.md); 2 takes frames only.
    #[arg(long, global = true, default_value_t = wire::PROTOCOL_VERSION,
          value_parser = clap::value_parser!(u16).range(2..=3))]
    protocol: u16,
}

#[derive(Subcommand)]
enum Command {
    /// Connect, wait for the final solution and render PNGs.
    View(view::ViewCommand),
    /// Stay connected and print every update (version, vertices changed, bytes, latency).
    Watch(watch::WatchCommand),
    /// Load test: open many viewers in this process, each decoding every frame, and report
    /// connection times, frame latency percentiles, traffic and the server's own figures.
    Load(load::LoadCommand),
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::View(command) => command.run(cli.protocol).await,
        Command::Watch(command) => command.run(cli.protocol).await,
        Command::Load(command) => command.run(cli.protocol).await,
    }
}
