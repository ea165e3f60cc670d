//! `radcast bench`: medians of every stage at several patch counts, or with `--error` the
//! speed-against-error sweep ([`error_sweep`]).

mod error_sweep;

use anyhow::Context;
use solver::args::SolverArgs;
use solver::{HierarchySettings, MethodChoice, SolveReport, solve_file};
use std::path::PathBuf;

/// The arguments of `radcast bench`.
#[derive(clap::Args)]
pub struct BenchCommand {
    /// The scenes, OBJ or glTF (several with --error).
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Measure speed against error (needs scenes/reference/<name>.json).
    #[arg(long)]
    pub error: bool,
    /// Shadow rays per far pair to sweep with --error, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4")]
    pub sweep_rays: Vec<u32>,
    /// Hierarchical error knobs to sweep with --error, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0.1,0.05,0.02")]
    pub sweep_error: Vec<f64>,
    /// Folder for the --error table and plot.
    #[arg(long, default_value = "docs")]
    pub out_dir: PathBuf,
    /// Another system's measured rows to compare against at equal error (JSON, as
    /// docs/peers/cornell-box.json); repeatable.
    #[arg(long)]
    pub peers: Vec<PathBuf>,
    /// File stem of the --error table and plot (`<out-dir>/<name>.md` and `.svg`).
    #[arg(long, default_value = "speed-vs-error")]
    pub name: String,
    /// Patch counts to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "150,600,2500,10000")]
    pub counts: Vec<usize>,
    /// Runs per count; the table shows medians.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    #[command(flatten)]
    pub settings: SolverArgs,
}

impl BenchCommand {
    /// Runs the command.
    pub fn run(self) -> anyhow::Result<()> {
        match self.error {
            true => self.error_sweep(),
            false => {
                let BenchCommand {
                    scenes,
                    counts,
                    repeat,
                    settings,
                    ..
                } = self;
                for scene in &scenes {
                    bench(scene, &counts, repeat.max(1), &settings)?;
                }
                Ok(())
            }
        }
    }

    /// `--error`: the sweep against each scene's reference, written as a table and a plot.
    fn error_sweep(self) -> anyhow::Result<()> {
        let BenchCommand {
            scenes,
            counts,
            repeat,
            sweep_rays,
            sweep_error,
            out_dir,
            name,
            peers,
            ..
        } = self;
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
        Ok(())
    }
}

/// The median of repeated timings (the upper one of an even count): these machines are
/// noisy, so tables report medians.
pub(crate) fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn bench(
    scene: &std::path::Path,
    counts: &[usize],
    repeat: usize,
    settings: &SolverArgs,
) -> anyhow::Result<()> {
    // A sweep of patch counts measures the dense path: auto means its default, gmres.
    let method = match settings.method {
        MethodChoice::Auto => MethodChoice::Dense(solver::Method::Gmres),
        chosen => chosen,
    };
    println!(
        "`radcast bench {} --counts {} --repeat {repeat} --method {method}` ({} threads), medians of {repeat} runs:\n",
        scene.display(),
        counts
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(","),
        rayon::current_num_threads()
    );
    println!(
        "| patches | load s | mesh s | form factors s | solve s | total s | iterations | rays |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    for &count in counts {
        let request = SolverArgs {
            patches: Some(count),
            patch_size: None,
            method,
            ..settings.clone()
        }
        .request(HierarchySettings::default())
        .map_err(anyhow::Error::msg)?;
        let mut runs = Vec::new();
        let printer = crate::ProgressPrinter::new();
        for _ in 0..repeat {
            runs.push(solve_file(scene, &request, &|p| printer.report(p))?.report);
        }
        drop(printer);
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
