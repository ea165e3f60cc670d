//! `radcast`: offline radiosity solves and benchmarks from the command line.

mod error_sweep;
mod fuzz;

use anyhow::Context;
use clap::{Parser, Subcommand};
use solver::HierarchySettings;
use solver::accuracy::evaluate;
use solver::args::{SolveArgs, SolverArgs, budget_warnings};
use solver::reference::{Reference, place_probes, trace_probes};
use solver::visibility::Occluders;
use solver::{Progress, ProgressLine, ProgressThrottle, SolveReport, solve_file};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Counts heap bytes, so that reports can give their peak.
#[global_allocator]
static HEAP: peak_alloc::PeakAlloc = peak_alloc::PeakAlloc;

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
    Solve {
        /// The scene: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
        scene: PathBuf,
        #[command(flatten)]
        settings: SolveArgs,
        /// Print one JSON object on stdout instead of the table.
        #[arg(long)]
        json: bool,
        /// Also measure the error against this reference file (adds `error` to the JSON).
        #[arg(long)]
        reference: Option<PathBuf>,
    },
    /// Estimate the continuous radiosity at probe points by path tracing: a reference that
    /// depends on no mesh.
    Reference {
        /// The scene: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
        scene: PathBuf,
        /// Probe points, spread over the surfaces by area.
        #[arg(long, default_value_t = 1000)]
        probes: usize,
        /// Paths per probe.
        #[arg(long, default_value_t = 16384)]
        samples: u32,
        /// Seed of the random streams.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Where to write the JSON.
        #[arg(long)]
        out: PathBuf,
    },
    /// Write a generated scene (OBJ + MTL beside it) for scaling tests: a furnished room, or
    /// with --town a town of triangle soup under a sky.
    Generate {
        /// Pieces of furniture (tables, chairs, cabinets; about 14 faces each).
        #[arg(long, default_value_t = 1000, conflicts_with = "town")]
        pieces: usize,
        /// A town of about this many triangles instead: buildings, domes and trees cut into
        /// small triangles under one large emitting sky quad.
        #[arg(long)]
        town: Option<usize>,
        /// Seed: the same seed gives the same room.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Where to write the OBJ; the MTL goes beside it with the same stem.
        #[arg(long)]
        out: PathBuf,
    },
    /// Seeded mutation fuzzing of the scene loader and solver (`scene`) or of every wire
    /// decoder (`wire`); saves each finding's input and exits 1 if there was any.
    Fuzz {
        /// What to fuzz.
        #[arg(value_enum)]
        target: FuzzTarget,
        /// Stop after this many cases.
        #[arg(long)]
        cases: Option<u64>,
        /// Stop after this many seconds (with --cases: whichever comes first).
        #[arg(long)]
        seconds: Option<f64>,
        /// Seed: the same seed and case number give the same input.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Where findings' inputs are saved.
        #[arg(long, default_value = "fuzz-findings")]
        findings: PathBuf,
        /// Folders of scene files to mutate (`scene` target).
        #[arg(long, default_values = ["scenes", "tests/fuzz/scenes"])]
        corpus: Vec<PathBuf>,
    },
    /// Time every stage at several patch counts and print a Markdown table of medians; with
    /// --error, sweep configurations against each scene's reference and write
    /// docs/speed-vs-error.md and .svg.
    Bench {
        /// The scenes, OBJ or glTF (several with --error).
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
        /// Measure speed against error (needs scenes/reference/<name>.json).
        #[arg(long)]
        error: bool,
        /// Shadow rays per far pair to sweep with --error, comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "1,2,4")]
        sweep_rays: Vec<u32>,
        /// Hierarchical error knobs to sweep with --error, comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "0.1,0.05,0.02")]
        sweep_error: Vec<f64>,
        /// Folder for the --error table and plot.
        #[arg(long, default_value = "docs")]
        out_dir: PathBuf,
        /// Another system's measured rows to compare against at equal error (JSON, as
        /// docs/peers/cornell-box.json); repeatable.
        #[arg(long)]
        peers: Vec<PathBuf>,
        /// File stem of the --error table and plot (`<out-dir>/<name>.md` and `.svg`).
        #[arg(long, default_value = "speed-vs-error")]
        name: String,
        /// Patch counts to run, comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "150,600,2500,10000")]
        counts: Vec<usize>,
        /// Runs per count; the table shows medians.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        #[command(flatten)]
        settings: SolverArgs,
    },
}

/// What `radcast fuzz` aims at.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum FuzzTarget {
    /// OBJ and MTL files through the loader, meshing and a small solve.
    Scene,
    /// Every wire decoder and the viewer's colour buffer.
    Wire,
}

/// Prints a progress line to stderr at most once a second, after the first second.
struct ProgressPrinter {
    start: Instant,
    throttle: ProgressThrottle,
}

impl ProgressPrinter {
    fn new() -> Self {
        ProgressPrinter {
            start: Instant::now(),
            throttle: ProgressThrottle::new(Duration::from_secs(1)),
        }
    }

    fn report(&self, progress: Progress) {
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
        Command::Solve {
            scene,
            settings,
            json,
            reference,
        } => {
            let request = settings.request().map_err(anyhow::Error::msg)?;
            let printer = ProgressPrinter::new();
            let reference = reference
                .map(|path| -> anyhow::Result<Reference> {
                    let text = std::fs::read_to_string(&path)
                        .with_context(|| format!("{}: cannot read", path.display()))?;
                    serde_json::from_str(&text)
                        .with_context(|| format!("{}: not a radcast reference", path.display()))
                })
                .transpose()?;
            let solved = solve_file(&scene, &request, &|p| printer.report(p))?;
            let measured = reference.map(|r| {
                evaluate(
                    &solved.scene,
                    &solved.mesh,
                    &solved.radiosity,
                    &solved.vertex_radiosity,
                    &r.probes,
                )
            });
            let report = &solved.report;
            if report.skipped_faces > 0 {
                eprintln!(
                    "warning: {}: skipped {} zero-area faces",
                    scene.display(),
                    report.skipped_faces
                );
            }
            if let (Some(asked), Some(stats)) = (&request.hierarchy, &report.hierarchy) {
                budget_warnings(asked, stats)
                    .iter()
                    .for_each(|warning| eprintln!("warning: {warning}"));
            }
            if !report.converged {
                eprintln!(
                    "warning: not converged after {} iterations (residual {:.3e} > tolerance {:.1e})",
                    report.iterations, report.residual, report.tolerance
                );
            }
            if json {
                let mut value = serde_json::to_value(report).context("serialising the report")?;
                value["peak_memory_bytes"] = HEAP.peak_usage().into();
                if let Some(measured) = measured {
                    value["error"] = serde_json::to_value(measured)?;
                }
                println!("{value}");
            } else {
                print_summary(&scene, report);
                if let Some(e) = measured {
                    println!(
                        "error       smooth RMS {:.4}, max {:.3}, energy {:+.4}; flat RMS {:.4}  ({} probes, reference noise {:.4})",
                        e.smooth.rms,
                        e.smooth.max,
                        e.smooth.energy,
                        e.flat.rms,
                        e.probes,
                        e.reference_noise
                    );
                }
            }
        }
        Command::Reference {
            scene: path,
            probes,
            samples,
            seed,
            out,
        } => {
            anyhow::ensure!(
                probes > 0 && samples > 1,
                "--probes must be at least 1 and --samples at least 2"
            );
            let scene = solver::load_scene(&path)?;
            // Before minutes of tracing, not after.
            create_parent(&out)?;
            let occluders = Occluders::new(&scene);
            let printer = ProgressPrinter::new();
            let placed = place_probes(&scene, probes, seed);
            let traced = trace_probes(&scene, &occluders, &placed, samples, seed, &|p| {
                printer.report(p)
            });
            let command = format!(
                "radcast reference {} --probes {probes} --samples {samples} --seed {seed} --out {}",
                path.display(),
                out.display()
            );
            let reference = Reference {
                command,
                seed,
                samples,
                probes: traced,
            };
            std::fs::write(&out, serde_json::to_string_pretty(&reference)?)
                .with_context(|| format!("{}: cannot write", out.display()))?;
            eprintln!(
                "wrote {} ({} probes x {samples} paths)",
                out.display(),
                probes
            );
        }
        Command::Fuzz {
            target,
            cases,
            seconds,
            seed,
            findings,
            corpus,
        } => {
            anyhow::ensure!(
                cases.is_some() || seconds.is_some(),
                "give --cases N, --seconds T or both"
            );
            let time = seconds
                .map(|s| Duration::try_from_secs_f64(s).context("--seconds must be >= 0"))
                .transpose()?;
            let target: Box<dyn fuzz::Target> = match target {
                FuzzTarget::Scene => Box::new(fuzz::scene::SceneTarget::from_folders(
                    &corpus.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
                )?),
                FuzzTarget::Wire => Box::new(fuzz::wire::WireTarget::default()),
            };
            let budget = fuzz::Budget { cases, time };
            let report = fuzz::run(target.as_ref(), seed, budget, &findings)?;
            println!(
                "{}: {} cases in {:.1} s (seed {seed}): {} accepted, {} rejected with an error, {} findings; slowest case {} took {:.3} s",
                target.name(),
                report.cases,
                report.seconds,
                report.accepted,
                report.rejected,
                report.findings.len(),
                report.slowest.0,
                report.slowest.1
            );
            for finding in &report.findings {
                println!(
                    "  case {}: {} (input in {})",
                    finding.case,
                    finding.what,
                    finding.saved.display()
                );
            }
            if !report.findings.is_empty() {
                std::process::exit(1);
            }
        }
        Command::Generate {
            pieces,
            town,
            seed,
            out,
        } => {
            let mtl_path = out.with_extension("mtl");
            let mtl_name = mtl_path
                .file_name()
                .and_then(|n| n.to_str())
                .context("--out needs a file name")?;
            let scene = match town {
                Some(triangles) => solver::generate::town(triangles, seed, mtl_name),
                None => solver::generate::furnished_room(pieces, seed, mtl_name),
            };
            create_parent(&out)?;
            std::fs::write(&out, &scene.obj)
                .with_context(|| format!("{}: cannot write", out.display()))?;
            std::fs::write(&mtl_path, &scene.mtl)
                .with_context(|| format!("{}: cannot write", mtl_path.display()))?;
            let loaded = solver::load_obj(&out)?;
            eprintln!(
                "wrote {} and {}: {} objects, {} faces ({} triangles)",
                out.display(),
                mtl_path.display(),
                loaded.objects.len(),
                loaded.faces.len(),
                loaded.triangle_count()
            );
        }
        Command::Bench {
            scenes,
            error: true,
            counts,
            repeat,
            sweep_rays,
            sweep_error,
            out_dir,
            name,
            peers,
            ..
        } => {
            let list = |values: &[String]| values.join(",");
            let named = if name == "speed-vs-error" {
                String::new()
            } else {
                format!(" --name {name}")
            };
            let named = peers
                .iter()
                .fold(named, |text, p| format!("{text} --peers {}", p.display()));
            let command = format!(
                "radcast bench --error {} --counts {} --sweep-rays {} --sweep-error {} --repeat {repeat}{named}",
                scenes
                    .iter()
                    .map(|s| s.display().to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
                list(&counts.iter().map(ToString::to_string).collect::<Vec<_>>()),
                list(
                    &sweep_rays
                        .iter()
                        .map(ToString::to_string)
                        .collect::<Vec<_>>()
                ),
                list(
                    &sweep_error
                        .iter()
                        .map(ToString::to_string)
                        .collect::<Vec<_>>()
                )
            );
            anyhow::ensure!(
                sweep_error.iter().all(|e| *e > 0.0 && *e < 1.0),
                "--sweep-error values must be in (0, 1)"
            );
            error_sweep::run(
                &scenes,
                &error_sweep::Sweep {
                    counts: &counts,
                    rays: &sweep_rays,
                    errors: &sweep_error,
                    repeat: repeat.max(1),
                },
                (&out_dir, &name),
                &command,
                &peers,
            )?;
        }
        Command::Bench {
            scenes,
            counts,
            repeat,
            settings,
            ..
        } => {
            for scene in &scenes {
                bench(scene, &counts, repeat.max(1), &settings)?;
            }
        }
    }
    Ok(())
}

fn print_summary(scene: &std::path::Path, r: &SolveReport) {
    let s = &r.seconds;
    println!(
        "scene       {} ({} objects, {} triangles)",
        scene.display(),
        r.objects.len(),
        r.triangles
    );
    println!("patches     {}  ({} shadow rays)", r.patches, r.rays);
    if let Some(h) = &r.hierarchy {
        println!(
            "hierarchy   {} links ({:.1} per leaf), {} clusters, {} rounds, {} links decided by the shaft alone",
            h.links,
            h.links as f64 / h.elements.max(1) as f64,
            h.clusters,
            h.rounds,
            h.shaft_decided
        );
    }
    println!("peak heap   {:.1} MB", HEAP.peak_usage() as f64 / 1e6);
    println!(
        "solver      {}: {} iterations, residual {:.2e}{}",
        r.method,
        r.iterations,
        r.residual,
        if r.converged { "" } else { " (NOT converged)" }
    );
    println!(
        "seconds     load {:.3}  mesh {:.3}  form factors {:.3}  solve {:.3}  total {:.3}",
        s.load, s.mesh, s.form_factors, s.solve, s.total
    );
    println!(
        "{:<16} {:>14}  mean radiosity W/m^2 (r, g, b)",
        "object", "area"
    );
    for o in &r.objects {
        let [red, green, blue] = o.radiosity;
        println!(
            "{:<16} {:>14.6e}  {red:10.4} {green:10.4} {blue:10.4}",
            o.name, o.area
        );
    }
}

/// The median of repeated timings (the upper one of an even count): these machines are
/// noisy, so tables report medians.
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn bench(
    scene: &std::path::Path,
    counts: &[usize],
    repeat: usize,
    settings: &SolverArgs,
) -> anyhow::Result<()> {
    println!(
        "`radcast bench {} --counts {} --repeat {repeat} --method {}` ({} threads), medians of {repeat} runs:\n",
        scene.display(),
        counts
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(","),
        settings.method,
        rayon::current_num_threads()
    );
    println!(
        "| patches | load s | mesh s | form factors s | solve s | total s | iterations | rays |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    for &count in counts {
        let request = SolverArgs {
            patches: count,
            patch_size: None,
            ..settings.clone()
        }
        .request(HierarchySettings::default())
        .map_err(anyhow::Error::msg)?;
        let mut runs = Vec::new();
        for _ in 0..repeat {
            runs.push(solve_file(scene, &request, &solver::no_progress)?.report);
        }
        let stage = |f: fn(&SolveReport) -> f64| median(runs.iter().map(f).collect());
        let (load, mesh, ff, solve, total) = (
            stage(|r| r.seconds.load),
            stage(|r| r.seconds.mesh),
            stage(|r| r.seconds.form_factors),
            stage(|r| r.seconds.solve),
            stage(|r| r.seconds.total),
        );
        let last = runs.last().context("at least one run")?;
        println!(
            "| {} | {load:.4} | {mesh:.4} | {ff:.4} | {solve:.4} | {total:.4} | {} | {} |",
            last.patches, last.iterations, last.rays
        );
    }
    Ok(())
}

/// Creates the folder `path` is to be written in, if it names one.
fn create_parent(path: &std::path::Path) -> anyhow::Result<()> {
    if let Some(folder) = path.parent().filter(|f| !f.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder)
            .with_context(|| format!("{}: cannot create", folder.display()))?;
    }
    Ok(())
}
