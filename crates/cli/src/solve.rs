//! `radcast solve`: one solve, its summary (or JSON) and its error against a reference.

use crate::reference::read_reference;
use crate::{HEAP, ProgressPrinter};
use anyhow::Context;
use solver::accuracy::{SolutionError, check_probes_match, evaluate};
use solver::args::{SolveArgs, budget_warnings};
use solver::check::{CheckSettings, Estimate, ReadingEstimate, self_check};
use solver::reference::Reference;
use solver::visibility::Occluders;
use solver::{SolveReport, solve_file};
use std::path::PathBuf;

/// The worst probes the summary prints (the JSON lists all of `SolutionError::worst`), each by
/// its largest channel.
const WORST_SHOWN: usize = 3;

/// The arguments of `radcast solve`.
#[derive(clap::Args)]
pub struct SolveCommand {
    /// The scene: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
    pub scene: PathBuf,
    #[command(flatten)]
    pub settings: SolveArgs,
    /// Print one JSON object on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also measure the error against this reference file (adds `error` to the JSON).
    #[arg(long)]
    pub reference: Option<PathBuf>,
}

impl SolveCommand {
    /// Runs the command.
    pub fn run(self) -> anyhow::Result<()> {
        let SolveCommand {
            scene,
            settings,
            json,
            reference,
        } = self;
        let request = settings.request().map_err(anyhow::Error::msg)?;
        let printer = ProgressPrinter::new();
        let reference = reference
            .map(|path| -> anyhow::Result<(PathBuf, Reference)> {
                let parsed = read_reference(&path)?;
                Ok((path, parsed))
            })
            .transpose()?;
        let mut solved = solve_file(&scene, &request, &|p| printer.report(p))?;
        let measured = reference
            .map(|(path, r)| {
                check_probes_match(&solved.scene, &r.probes)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
                Ok::<_, anyhow::Error>(evaluate(
                    &solved.scene,
                    &solved.mesh,
                    &solved.radiosity,
                    &solved.vertex_radiosity,
                    &r.probes,
                ))
            })
            .transpose()?;
        // A solve to a target has checked its last step already.
        if settings.checked() && solved.report.estimate.is_none() {
            solved.report.estimate = Some(self_check(
                &solved.scene,
                &Occluders::new(&solved.scene),
                &solved.mesh,
                (&solved.radiosity, &solved.vertex_radiosity),
                &CheckSettings::after_solve(solved.report.seconds.total),
                &|p| printer.report(p),
            ));
        }
        // The bar goes before the summary is printed.
        drop(printer);
        let report = &solved.report;
        print_warnings((&scene, &solved.scene), &request, report);
        if json {
            let mut value = serde_json::to_value(report).context("serialising the report")?;
            value["peak_memory_bytes"] = HEAP.peak_usage().into();
            if let Some(measured) = measured {
                value["error"] = serde_json::to_value(measured)?;
            }
            println!("{value}");
        } else {
            print_summary(&scene, report);
            if let Some(t) = &report.target {
                println!(
                    "target      {:.1}% smooth RMS {} after {} steps ({})",
                    100.0 * t.error,
                    if t.reached { "reached" } else { "not reached" },
                    t.steps.len(),
                    t.stopped
                );
            }
            if let Some(e) = &measured {
                print_error(e);
            }
        }
        Ok(())
    }
}

/// The error against a reference, as the summary prints it: the whole, at the probes a viewer
/// can see, by object, and the worst probes.
fn print_error(e: &SolutionError) {
    println!(
        "error       smooth RMS {:.4}, max {:.3}, energy {:+.4}; flat RMS {:.4}  ({} probes, reference noise {:.4})",
        e.smooth.rms, e.smooth.max, e.smooth.energy, e.flat.rms, e.probes, e.reference_noise
    );
    if e.buried_probes > 0 {
        println!(
            "            smooth RMS {:.4}, energy {:+.4} at the {} probes a viewer can see ({} lie inside solids)",
            e.visible_smooth.rms,
            e.visible_smooth.energy,
            e.probes - e.buried_probes,
            e.buried_probes
        );
    }
    for o in &e.objects {
        println!(
            "  {:<20} smooth RMS {:.4}, energy {:+.4}; flat RMS {:.4}  ({} probes, {:.0}% of the squared error)",
            o.name,
            o.smooth.rms,
            o.smooth.energy,
            o.flat.rms,
            o.probes,
            100.0 * o.smooth_share
        );
    }
    // The few places that hold most of the error on a real model, to look at.
    for w in e.worst.iter().take(WORST_SHOWN) {
        let [x, y, z] = w.position;
        println!(
            "  worst at ({x:.3}, {y:.3}, {z:.3}), face {} of {}: shown {:.4}, reference {:.4}  ({:.0}% of the squared error)",
            w.face,
            w.object,
            w.smooth.into_iter().fold(0.0, f64::max),
            w.reference.into_iter().fold(0.0, f64::max),
            100.0 * w.smooth_share
        );
    }
}

/// What the user must know about this answer, on stderr: a bad self-check, a target not
/// reached, what loading changed, a coarser knob than asked, no convergence.
fn print_warnings(
    (path, scene): (&std::path::Path, &solver::Scene),
    request: &solver::SolveRequest,
    report: &SolveReport,
) {
    let target = report.target.as_ref();
    if let Some(warning) = report.estimate.as_ref().and_then(Estimate::warning) {
        eprintln!("warning: {warning}");
    }
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
    if let Some(t) = target.filter(|t| !t.reached) {
        let high = t.steps.last().map_or(f64::NAN, |s| s.high);
        eprintln!(
            "warning: --target-error {} not reached: stopped at the {} with the estimate up to {:.1}%",
            t.error,
            t.stopped,
            100.0 * high
        );
    }
    if report.skipped_faces > 0 {
        eprintln!(
            "warning: {}: skipped {} zero-area faces",
            path.display(),
            report.skipped_faces
        );
    }
    // Toward a target, the knob asked of the last step is that step's.
    let last_knob = target.and_then(|t| t.steps.last()?.knob);
    let asked = request.hierarchy.map(|h| solver::HierarchySettings {
        error: last_knob.unwrap_or(h.error),
        ..h.fitted_to(scene)
    });
    if let (Some(asked), Some(stats)) = (&asked, &report.hierarchy) {
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
}

fn print_summary(scene: &std::path::Path, r: &SolveReport) {
    let s = &r.seconds;
    println!(
        "scene       {} ({} objects, {} triangles)",
        scene.display(),
        r.objects.len(),
        r.triangles
    );
    println!(
        "patches     {}  ({} shadow rays, {})",
        r.patches, r.rays, r.ray_backend
    );
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
    if let Some(e) = &r.estimate {
        let percent = |r: &ReadingEstimate| {
            format!(
                "{:.1}% ({:.1}-{:.1}%), energy {:+.1}%",
                100.0 * r.rms,
                100.0 * r.low,
                100.0 * r.high,
                100.0 * r.energy
            )
        };
        println!(
            "estimate    smooth RMS {}; flat RMS {}  (self-check: {} probes, noise {:.1}%, {:.2} s)",
            percent(&e.smooth),
            percent(&e.flat),
            e.probes,
            100.0 * e.noise,
            e.seconds
        );
    }
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
