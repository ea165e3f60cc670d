//! `radcast bench --error`: speed against error over a sweep of configurations, with the
//! Pareto front marked, as a Markdown table and a log-log SVG plot.

use anyhow::{Context, bail};
use plotters::prelude::*;
use solver::accuracy::{SolutionError, evaluate};
use solver::reference::Reference;
use solver::{FormFactorSettings, Method, PatchTarget, Scene, SolveRequest, SolverSettings, solve_scene};
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One configuration's measurements.
struct Row {
    scene: String,
    patches: usize,
    method: Method,
    rays: u32,
    seconds: [f64; 4], // load + mesh, form factors, solve, total
    error: SolutionError,
    pareto: bool,
}

/// Where the reference of `scene` lives: `reference/<stem>.json` beside it.
pub fn reference_path(scene: &Path) -> PathBuf {
    let stem = scene.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
    scene.parent().unwrap_or(Path::new(".")).join("reference").join(format!("{stem}.json"))
}

pub fn load_reference(scene: &Path) -> anyhow::Result<Reference> {
    let path = reference_path(scene);
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!("{}: no reference; make one with `radcast reference {} --probes 1000 --samples 16384 --out {}`", path.display(), scene.display(), path.display())
    })?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a radcast reference", path.display()))
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// Runs the sweep and writes `<out_dir>/speed-vs-error.{md,svg}`.
pub fn run(scenes: &[PathBuf], counts: &[usize], rays: &[u32], repeat: usize, out_dir: &Path, command: &str) -> anyhow::Result<()> {
    if scenes.is_empty() {
        bail!("name at least one scene");
    }
    let mut rows = Vec::new();
    for scene_path in scenes {
        let reference = load_reference(scene_path)?;
        let start = Instant::now();
        let scene = Scene::load_obj(scene_path)?;
        let load = start.elapsed().as_secs_f64();
        let middle = counts[counts.len() / 2];
        // Mesh size and ray count decide the error; the method only the solve time.
        let mut configurations: Vec<(usize, Method, u32)> = counts.iter().flat_map(|&n| rays.iter().map(move |&r| (n, Method::Gmres, r))).collect();
        configurations.extend([Method::Jacobi, Method::GaussSeidel, Method::Progressive].map(|m| (middle, m, FormFactorSettings::default().rays_per_pair)));
        for (count, method, ray_count) in configurations {
            let request = SolveRequest {
                patches: PatchTarget::Count(count),
                form_factors: FormFactorSettings { rays_per_pair: ray_count },
                solver: SolverSettings { method, ..SolverSettings::default() },
                ..SolveRequest::default()
            };
            let mut runs = Vec::new();
            for _ in 0..repeat {
                runs.push(solve_scene(scene.clone(), &request, &solver::no_progress)?);
            }
            let stage = |f: fn(&solver::SolveReport) -> f64| median(runs.iter().map(|r| f(&r.report)).collect());
            let (mesh, ff, solve) = (stage(|r| r.seconds.mesh), stage(|r| r.seconds.form_factors), stage(|r| r.seconds.solve));
            let last = runs.last().context("one run")?;
            let error = evaluate(&last.scene, &last.mesh, &last.radiosity, &reference.probes);
            eprintln!("{}: {} patches, {method}, {ray_count} rays: {:.3} s, smooth RMS {:.4}", scene_path.display(), last.report.patches, load + mesh + ff + solve, error.smooth.rms);
            rows.push(Row {
                scene: scene_path.display().to_string(),
                patches: last.report.patches,
                method,
                rays: ray_count,
                seconds: [load + mesh, ff, solve, load + mesh + ff + solve],
                error,
                pareto: false,
            });
        }
    }
    // Pareto front per scene: nothing else is both faster and more accurate.
    for i in 0..rows.len() {
        let dominated = rows.iter().any(|o| {
            o.scene == rows[i].scene
                && o.seconds[3] <= rows[i].seconds[3]
                && o.error.smooth.rms <= rows[i].error.smooth.rms
                && (o.seconds[3] < rows[i].seconds[3] || o.error.smooth.rms < rows[i].error.smooth.rms)
        });
        rows[i].pareto = !dominated;
    }
    std::fs::create_dir_all(out_dir).with_context(|| format!("{}: cannot create", out_dir.display()))?;
    let table = markdown(&rows, command, scenes)?;
    print!("{table}");
    std::fs::write(out_dir.join("speed-vs-error.md"), &table)?;
    plot(&rows, &out_dir.join("speed-vs-error.svg"))?;
    Ok(())
}

fn markdown(rows: &[Row], command: &str, scenes: &[PathBuf]) -> anyhow::Result<String> {
    let mut out = String::new();
    writeln!(out, "# Speed against error\n")?;
    writeln!(out, "Made by `{command}` on this project's 2-core machine (timings: medians; errors are deterministic).")?;
    writeln!(out, "Plot: [speed-vs-error.svg](speed-vs-error.svg). Error is measured at the reference's probes on")?;
    writeln!(out, "non-emitting surfaces: *smooth* is what viewers show (corner-interpolated), *flat* the patch value;")?;
    writeln!(out, "RMS relative to the reference's RMS, max relative to the reference's RMS probe value, energy =")?;
    writeln!(out, "Σ B / Σ B_ref − 1. ★ marks the Pareto front (nothing else is both faster and more accurate).\n")?;
    for scene in scenes {
        let reference = load_reference(scene)?;
        let noise = rows.iter().find(|r| r.scene == scene.display().to_string()).map_or(0.0, |r| r.error.reference_noise);
        writeln!(out, "Reference for `{}`: {} probes × {} paths (`{}`), relative noise {:.4}.\n", scene.display(), reference.probes.len(), reference.samples, reference.command, noise)?;
    }
    writeln!(out, "| scene | patches | method | rays | load+mesh s | form factors s | solve s | total s | smooth RMS | flat RMS | max | energy | front |")?;
    writeln!(out, "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|:-:|")?;
    for r in rows {
        writeln!(
            out,
            "| {} | {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.3} | {:+.4} | {} |",
            r.scene, r.patches, r.method, r.rays, r.seconds[0], r.seconds[1], r.seconds[2], r.seconds[3],
            r.error.smooth.rms, r.error.flat.rms, r.error.smooth.max, r.error.smooth.energy,
            if r.pareto { "★" } else { "" }
        )?;
    }
    Ok(out)
}

fn plot(rows: &[Row], path: &Path) -> anyhow::Result<()> {
    let bounds = |f: fn(&Row) -> f64| rows.iter().map(f).fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let (t_lo, t_hi) = bounds(|r| r.seconds[3]);
    let (e_lo, e_hi) = bounds(|r| r.error.smooth.rms.max(1e-6));
    let root = SVGBackend::new(path, (960, 640)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption("radcast: total seconds vs smooth RMS error (log-log)", ("sans-serif", 22))
        .margin(20)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((t_lo * 0.7..t_hi * 1.4).log_scale(), (e_lo * 0.7..e_hi * 1.4).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("total seconds (load + mesh + form factors + solve)")
        .y_desc("smooth RMS error vs reference")
        .x_label_formatter(&|x| format!("{x:.3}"))
        .y_label_formatter(&|y| format!("{y:.3}"))
        .draw()?;
    let colours = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
    let mut groups: Vec<(String, u32)> = rows.iter().map(|r| (r.method.to_string(), r.rays)).collect();
    groups.sort();
    groups.dedup();
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    let point = |r: &Row| (r.seconds[3], r.error.smooth.rms.max(1e-6));
    for (k, (method, rays)) in groups.iter().enumerate() {
        let colour = colours[k % colours.len()];
        let in_group = |r: &&Row| r.method.to_string() == *method && r.rays == *rays;
        // Circles for the first scene, triangles for the second, squares after.
        for (s, scene) in scenes.iter().enumerate() {
            let points: Vec<(f64, f64)> = rows.iter().filter(in_group).filter(|r| r.scene == *scene).map(point).collect();
            let style = colour.filled();
            match s {
                0 => chart.draw_series(points.iter().map(|p| Circle::new(*p, 5, style)))?,
                1 => chart.draw_series(points.iter().map(|p| TriangleMarker::new(*p, 6, style)))?,
                _ => chart.draw_series(points.iter().map(|p| Rectangle::new([*p, *p], style)))?,
            };
        }
        chart.draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?.label(format!("{method}, {rays} rays/pair")).legend(move |(x, y)| Circle::new((x, y), 5, colour.filled()));
    }
    for (s, scene) in scenes.iter().enumerate() {
        let mut front: Vec<(f64, f64)> = rows.iter().filter(|r| r.pareto && r.scene == *scene).map(point).collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        let marker = if s == 0 { "circles" } else if s == 1 { "triangles" } else { "squares" };
        chart.draw_series(LineSeries::new(front, BLACK.stroke_width(1)))?.label(format!("Pareto front, {scene} ({marker})")).legend(|(x, y)| PathElement::new([(x - 8, y), (x + 8, y)], BLACK));
    }
    chart.configure_series_labels().position(SeriesLabelPosition::LowerLeft).background_style(WHITE.mix(0.9)).border_style(BLACK).draw()?;
    root.present()?;
    Ok(())
}
