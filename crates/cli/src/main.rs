//! `radcast`: offline radiosity solves and benchmarks from the command line.

mod bench;
mod fuzz;
mod generate;
mod progress;
mod reference;
mod solve;

use anyhow::Context;
use clap::{Parser, Subcommand};
pub(crate) use progress::ProgressPrinter;

/// Counts heap bytes, so that reports can give their peak.
#[global_allocator]
pub(crate) static HEAP: peak_alloc::PeakAlloc = peak_alloc::PeakAlloc;

/// Radiosity for Wavefront OBJ + MTL scenes (Kd = reflectance, Ke = emitted radiosity).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Solve a scene and print a summary (or JSON).
    Solve(solve::SolveCommand),
    /// Estimate the continuous radiosity at probe points by path tracing: a reference that
    /// depends on no mesh.
    Reference(reference::ReferenceCommand),
    /// Write a generated scene (OBJ + MTL beside it) for scaling tests: a furnished room, or
    /// with --town a town of triangle soup under a sky.
    Generate(generate::GenerateCommand),
    /// Seeded mutation fuzzing of the scene loader and solver (`scene`) or of every wire
    /// decoder (`wire`); saves each finding's input and exits 1 if there was any.
    Fuzz(fuzz::FuzzCommand),
    /// Time every stage at several patch counts and print a Markdown table of medians; with
    /// --error, sweep configurations against each scene's reference and write
    /// docs/speed-vs-error.md and .svg.
    Bench(bench::BenchCommand),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    // The main thread is one of rayon's workers: a parallel loop started from it runs there
    // and is stolen from, instead of waking a pool thread and sleeping until the loop ends
    // (docs/BENCHMARKS.md, "The main thread in the pool").
    rayon::ThreadPoolBuilder::new()
        .use_current_thread()
        .build_global()?;
    match cli.command {
        Command::Solve(command) => command.run(),
        Command::Reference(command) => command.run(),
        Command::Generate(command) => command.run(),
        Command::Fuzz(command) => command.run(),
        Command::Bench(command) => command.run(),
    }
}

/// Creates the folder `path` is to be written in, if it names one.
pub(crate) fn create_parent(path: &std::path::Path) -> anyhow::Result<()> {
    if let Some(folder) = path.parent().filter(|f| !f.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder)
            .with_context(|| format!("{}: cannot create", folder.display()))?;
    }
    Ok(())
}
