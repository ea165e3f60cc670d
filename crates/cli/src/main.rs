//! `radcast`: offline radiosity solves and benchmarks from the command line.

mod bench;
mod fuzz;
mod generate;
mod reference;
mod solve;

use anyhow::Context;
use clap::{Parser, Subcommand};
use solver::{Progress, ProgressLine, ProgressThrottle};
use std::time::{Duration, Instant};

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
    /// The scene: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
    /// Print one JSON object on stdout instead of the table.
    /// Also measure the error against this reference file (adds `error` to the JSON).
    Solve(solve::SolveCommand),
    /// Estimate the continuous radiosity at probe points by path tracing: a reference that
    /// depends on no mesh.
    /// The scene: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
    /// Probe points, spread over the surfaces by area.
    /// Paths per probe.
    /// Seed of the random streams.
    /// Where to write the JSON.
    Reference(reference::ReferenceCommand),
    /// Write a generated scene (OBJ + MTL beside it) for scaling tests: a furnished room, or
    /// with --town a town of triangle soup under a sky.
    /// Pieces of furniture (tables, chairs, cabinets; about 14 faces each).
    /// A town of about this many triangles instead: buildings, domes and trees cut into
    /// small triangles under one large emitting sky quad.
    /// Seed: the same seed gives the same room.
    /// Where to write the OBJ; the MTL goes beside it with the same stem.
    Generate(generate::GenerateCommand),
    /// Seeded mutation fuzzing of the scene loader and solver (`scene`) or of every wire
    /// decoder (`wire`); saves each finding's input and exits 1 if there was any.
    /// What to fuzz.
    /// Stop after this many cases.
    /// Stop after this many seconds (with --cases: whichever comes first).
    /// Seed: the same seed and case number give the same input.
    /// Where findings' inputs are saved.
    /// Folders of scene files to mutate (`scene` target).
    Fuzz(fuzz::FuzzCommand),
    /// Time every stage at several patch counts and print a Markdown table of medians; with
    /// --error, sweep configurations against each scene's reference and write
    /// docs/speed-vs-error.md and .svg.
    /// The scenes, OBJ or glTF (several with --error).
    /// Measure speed against error (needs scenes/reference/<name>.json).
    /// Shadow rays per far pair to sweep with --error, comma-separated.
    /// Hierarchical error knobs to sweep with --error, comma-separated.
    /// Folder for the --error table and plot.
    /// Another system's measured rows to compare against at equal error (JSON, as
    /// docs/peers/cornell-box.json); repeatable.
    /// File stem of the --error table and plot (`<out-dir>/<name>.md` and `.svg`).
    /// Patch counts to run, comma-separated.
    /// Runs per count; the table shows medians.
    Bench(bench::BenchCommand),
}

/// Prints a progress line to stderr at most once a second, after the first second.
pub(crate) struct ProgressPrinter {
    start: Instant,
    throttle: ProgressThrottle,
}

impl ProgressPrinter {
    pub(crate) fn new() -> Self {
        ProgressPrinter {
            start: Instant::now(),
            throttle: ProgressThrottle::new(Duration::from_secs(1)),
        }
    }

    pub(crate) fn report(&self, progress: Progress) {
        match self.throttle.admit(progress) {
            Some(ProgressLine::Warning(line)) => eprintln!("warning: {line}"),
            Some(ProgressLine::Status(line)) => {
                eprintln!("[{:6.1}s] {line}", self.start.elapsed().as_secs_f64())
            }
            None => {}
        }
    }
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
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
