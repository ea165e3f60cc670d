//! `radcast bench --error`: speed against error over a sweep of configurations, with the
//! Pareto front marked, as a Markdown table and a log-log SVG plot.

use anyhow::{Context, bail};
use plotters::prelude::*;
use solver::accuracy::{SolutionError, check_probes_match, evaluate};
use solver::reference::Reference;
use solver::{
    FormFactorSettings, HierarchySettings, Method, PatchTarget, Scene, SolveRequest,
    SolverSettings, solve_scene,
};
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One configuration's measurements.
struct Row {
    scene: String,
    patches: usize,
    /// The solver, or `hierarchical E=...`.
    method: String,
    rays: u32,
    /// Links (hierarchical) or non-zero-capable entries n^2 (dense).
    links: u64,
    peak_bytes: usize,
    seconds: [f64; 4], // load + mesh, form factors, solve, total
    error: SolutionError,
    pareto: bool,
}

/// Where the reference of `scene` lives: `reference/<stem>.json` beside it.
pub fn reference_path(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene");
    scene
        .parent()
        .unwrap_or(Path::new("."))
        .join("reference")
        .join(format!("{stem}.json"))
}

/// Probes and paths of a reference the sweep makes for a scene that has none: 4,096 paths keep
/// it to seconds on a 125k-triangle model, and its noise is in the table beside the errors.
const MADE_REFERENCE: (usize, u32) = (1000, 4096);

/// The reference of `scene` ([`reference_path`]); path-traced and written there first when
/// there is none, so that any scene can be swept.
pub fn load_reference(scene: &Path) -> anyhow::Result<Reference> {
    let path = reference_path(scene);
    if !path.exists() {
        let (probes, samples) = MADE_REFERENCE;
        eprintln!(
            "{}: no reference: path-tracing one ({probes} probes x {samples} paths)",
            path.display()
        );
        return crate::reference::write_reference(scene, probes, samples, 1, &path);
    }
    crate::reference::read_reference(&path)
}

/// The configurations a sweep runs.
pub struct Sweep<'a> {
    /// Dense patch counts.
    pub counts: &'a [usize],
    /// Shadow rays per far pair for the dense runs.
    pub rays: &'a [u32],
    /// Hierarchical error knobs.
    pub errors: &'a [f64],
    /// Runs per configuration (the table shows medians).
    pub repeat: usize,
}

/// Runs the sweep and writes `<out_dir>/<name>.{md,svg}`: dense GMRES at each count and ray
/// setting, the other solvers at the middle count, and the hierarchical path at each knob.
pub fn run(
    scenes: &[PathBuf],
    sweep: &Sweep,
    (out_dir, name): (&Path, &str),
    command: &str,
    peer_files: &[PathBuf],
) -> anyhow::Result<()> {
    if scenes.is_empty() {
        bail!("name at least one scene");
    }
    let peers = peer_files
        .iter()
        .map(|path| Peers::load(path))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut rows = Vec::new();
    for scene_path in scenes {
        let reference = load_reference(scene_path)?;
        let start = Instant::now();
        let scene = solver::load_scene(scene_path)?;
        let load = start.elapsed().as_secs_f64();
        check_probes_match(&scene, &reference.probes)
            .map_err(|e| anyhow::anyhow!("{}: {e}", reference_path(scene_path).display()))?;
        for request in configurations(sweep) {
            let row = measure(scene_path, &scene, load, &request, sweep.repeat, &reference)?;
            rows.push(row);
        }
    }
    // Pareto front per scene: nothing else is both faster and more accurate to the eye.
    for i in 0..rows.len() {
        let dominated = rows
            .iter()
            .any(|o| o.scene == rows[i].scene && dominates(o, &rows[i], smooth_rms));
        rows[i].pareto = !dominated;
    }
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("{}: cannot create", out_dir.display()))?;
    let mut table = markdown(&rows, command, scenes, name)?;
    for p in &peers {
        table.push_str(&p.comparison(&rows)?);
    }
    print!("{table}");
    let table_path = out_dir.join(format!("{name}.md"));
    std::fs::write(&table_path, &table)
        .with_context(|| format!("{}: cannot write", table_path.display()))?;
    plot(&rows, &peers, &out_dir.join(format!("{name}.svg")))?;
    Ok(())
}

/// What the sweep solves on each scene: dense GMRES at each count and ray setting, the other
/// solvers at the middle count, and the hierarchical path at each knob.
fn configurations(sweep: &Sweep) -> Vec<SolveRequest> {
    let Sweep {
        counts,
        rays,
        errors,
        ..
    } = *sweep;
    let middle = counts[counts.len() / 2];
    let dense = |count: usize, method: Method, rays_per_pair: u32| SolveRequest {
        patches: PatchTarget::Count(count),
        form_factors: FormFactorSettings { rays_per_pair },
        solver: SolverSettings {
            method,
            ..SolverSettings::default()
        },
        ..SolveRequest::default()
    };
    // Mesh size and ray count decide the error; the method only the solve time.
    let mut configurations: Vec<SolveRequest> = counts
        .iter()
        .flat_map(|&n| rays.iter().map(move |&r| dense(n, Method::Gmres, r)))
        .collect();
    configurations.extend(
        [Method::Jacobi, Method::GaussSeidel, Method::Progressive]
            .map(|m| dense(middle, m, FormFactorSettings::default().rays_per_pair)),
    );
    configurations.extend(errors.iter().map(|&error| SolveRequest {
        hierarchy: Some(HierarchySettings {
            error,
            ..HierarchySettings::default()
        }),
        ..SolveRequest::default()
    }));
    configurations
}

/// `request` solved `repeat` times on `scene` (loaded from `scene_path` in `load` seconds):
/// the median stage times, the peak heap and the error against `reference`.
fn measure(
    scene_path: &Path,
    scene: &Scene,
    load: f64,
    request: &SolveRequest,
    repeat: usize,
    reference: &Reference,
) -> anyhow::Result<Row> {
    let mut runs = Vec::new();
    let mut peak_bytes = 0;
    let printer = crate::ProgressPrinter::new();
    for _ in 0..repeat {
        crate::HEAP.reset_peak_usage();
        runs.push(solve_scene(scene.clone(), request, &|p| printer.report(p))?);
        peak_bytes = peak_bytes.max(crate::HEAP.peak_usage());
    }
    drop(printer);
    let stage = |f: fn(&solver::SolveReport) -> f64| {
        super::median(runs.iter().map(|r| f(&r.report)).collect())
    };
    let (mesh, ff, solve) = (
        stage(|r| r.seconds.mesh),
        stage(|r| r.seconds.form_factors),
        stage(|r| r.seconds.solve),
    );
    let last = runs.last().context("one run")?;
    let error = evaluate(
        &last.scene,
        &last.mesh,
        &last.radiosity,
        &last.vertex_radiosity,
        &reference.probes,
    );
    let (method, links) = match (&request.hierarchy, &last.report.hierarchy) {
        (Some(settings), Some(stats)) => (
            format!("hierarchical E={}", settings.error),
            stats.links as u64,
        ),
        _ => (
            request.solver.method.to_string(),
            (last.report.patches as u64).pow(2),
        ),
    };
    eprintln!(
        "{}: {} patches, {method}, {} rays: {:.3} s, smooth RMS {:.4}",
        scene_path.display(),
        last.report.patches,
        request.form_factors.rays_per_pair,
        load + mesh + ff + solve,
        error.smooth.rms
    );
    Ok(Row {
        scene: scene_path.display().to_string(),
        patches: last.report.patches,
        method,
        rays: request.form_factors.rays_per_pair,
        links,
        peak_bytes,
        seconds: [load + mesh, ff, solve, load + mesh + ff + solve],
        error,
        pareto: false,
    })
}

/// Another system's rows on one scene, measured elsewhere (a file under docs/peers/).
#[derive(serde::Deserialize)]
struct Peers {
    scene: String,
    /// How and where they were measured.
    source: String,
    rows: Vec<PeerRow>,
}

/// One setting of another system.
#[derive(serde::Deserialize)]
struct PeerRow {
    system: String,
    setting: String,
    leaves: u64,
    links: u64,
    seconds: f64,
    flat_rms: f64,
    smooth_rms: f64,
    energy: f64,
}

impl Peers {
    fn load(path: &Path) -> anyhow::Result<Peers> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        serde_json::from_str(&text)
            .with_context(|| format!("{}: not a peers file (scene, source, rows)", path.display()))
    }

    /// The peer's rows, and radcast's seconds at each row's smooth and flat RMS: log-log
    /// between the two rows of radcast's front for that reading that bracket it, as a user who
    /// wants that error would choose; once on the front of every method, once on the
    /// hierarchy's alone (the path that scales, which a peer's hierarchy is measured against).
    fn comparison(&self, rows: &[Row]) -> anyhow::Result<String> {
        let mut out = String::new();
        writeln!(
            out,
            "\n## Against {} on `{}`\n",
            self.rows.first().map_or("peers", |r| r.system.as_str()),
            self.scene
        )?;
        writeln!(out, "Peer rows: {}.\n", self.source)?;
        writeln!(
            out,
            "radcast's seconds at the peer's error, interpolated log-log between the rows that bracket it on radcast's front for that reading (smooth: the rows nothing beats on time and smooth RMS, the ★ rows above where every method counts; flat: the same by flat RMS) (≤: the front's fastest row is already more accurate); a ratio above 1 means radcast is faster."
        )?;
        let of_scene: Vec<&Row> = rows.iter().filter(|r| r.scene == self.scene).collect();
        let hierarchical: Vec<&Row> = (of_scene.iter().copied())
            .filter(|r| r.method.starts_with("hierarchical"))
            .collect();
        for (methods, ours) in [
            ("Any method", &of_scene),
            ("The hierarchy alone", &hierarchical),
        ] {
            writeln!(out, "\n{methods}:\n")?;
            self.table(&mut out, ours)?;
        }
        Ok(out)
    }

    /// One table of [`Peers::comparison`], met on the fronts of `ours`.
    fn table(&self, out: &mut String, ours: &[&Row]) -> anyhow::Result<()> {
        let fronts = (front(ours, smooth_rms), front(ours, flat_rms));
        writeln!(
            out,
            "| system | setting | leaves | links | seconds | smooth RMS | flat RMS | energy | radcast s at that smooth RMS | ratio | radcast s at that flat RMS | ratio |"
        )?;
        writeln!(
            out,
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        )?;
        for p in &self.rows {
            let at = |target: f64, reading: fn(&Row) -> f64, ours: &[&Row]| {
                // Coarser than radcast's fastest row: that row already does better, so its
                // seconds bound radcast's from above.
                if let Some(fastest) = ours.first().filter(|r| reading(r) <= target) {
                    let seconds = fastest.seconds[3];
                    return format!("≤ {seconds:.3} | ≥ {:.1}×", p.seconds / seconds);
                }
                match seconds_at(ours, target, reading) {
                    Some((seconds, false)) => format!("{seconds:.3} | {:.1}×", p.seconds / seconds),
                    _ => "outside the rows above | –".into(),
                }
            };
            writeln!(
                out,
                "| {} | {} | {} | {} | {:.3} | {:.4} | {:.4} | {:+.4} | {} | {} |",
                p.system,
                p.setting,
                p.leaves,
                p.links,
                p.seconds,
                p.smooth_rms,
                p.flat_rms,
                p.energy,
                at(p.smooth_rms, smooth_rms, &fronts.0),
                at(p.flat_rms, flat_rms, &fronts.1),
            )?;
        }
        Ok(())
    }
}

/// The section that reads, for each hierarchical row, the dense seconds at its smooth RMS.
fn hierarchy_against_dense(out: &mut String, rows: &[Row]) -> anyhow::Result<()> {
    writeln!(out, "\n## Hierarchical against dense at equal error\n")?;
    writeln!(
        out,
        "Dense GMRES seconds at the hierarchical row's smooth RMS, interpolated log-log between the two dense rows (2 rays per pair) that bracket it; beyond the dense rows, extrapolated from the last two (marked ~).\n"
    )?;
    writeln!(
        out,
        "| scene | hierarchical | leaves | seconds | smooth RMS | dense seconds at that RMS | dense patches at that RMS | speed-up |"
    )?;
    writeln!(out, "|---|---|---:|---:|---:|---:|---:|---:|")?;
    for h in rows.iter().filter(|r| r.method.starts_with("hierarchical")) {
        let mut dense: Vec<&Row> = rows
            .iter()
            .filter(|r| {
                r.scene == h.scene
                    && r.method == "gmres"
                    && r.rays == FormFactorSettings::default().rays_per_pair
            })
            .collect();
        dense.sort_by_key(|r| r.patches);
        let smooth = |r: &Row| r.error.smooth.rms;
        let (Some((seconds, extrapolated)), Some((patches, _))) = (
            seconds_at(&dense, h.error.smooth.rms, smooth),
            interpolate_at(&dense, h.error.smooth.rms, smooth, |r| r.patches as f64),
        ) else {
            continue;
        };
        writeln!(
            out,
            "| {} | {} | {} | {:.3} | {:.4} | {}{:.2} | {}{:.0} | {}{:.1}× |",
            h.scene,
            h.method,
            h.patches,
            h.seconds[3],
            h.error.smooth.rms,
            if extrapolated { "~" } else { "" },
            seconds,
            if extrapolated { "~" } else { "" },
            patches,
            if extrapolated { "~" } else { "" },
            seconds / h.seconds[3]
        )?;
    }
    Ok(())
}

fn markdown(rows: &[Row], command: &str, scenes: &[PathBuf], name: &str) -> anyhow::Result<String> {
    let mut out = String::new();
    writeln!(out, "# Speed against error\n")?;
    writeln!(
        out,
        "Made by `{command}` on this project's 2-core machine, {} solver thread(s) (`RAYON_NUM_THREADS`; timings: medians; errors are deterministic).",
        rayon::current_num_threads()
    )?;
    writeln!(
        out,
        "Plot: [{name}.svg]({name}.svg). Error is measured at the reference's probes on"
    )?;
    writeln!(
        out,
        "non-emitting surfaces: *smooth* is what viewers show (the vertex values interpolated), *flat* the patch value;"
    )?;
    writeln!(
        out,
        "RMS relative to the reference's RMS, max relative to the reference's RMS probe value, energy ="
    )?;
    writeln!(
        out,
        "Σ B / Σ B_ref − 1. ★ marks the Pareto front (nothing else is both faster and more accurate).\n"
    )?;
    for scene in scenes {
        let reference = load_reference(scene)?;
        let noise = rows
            .iter()
            .find(|r| r.scene == scene.display().to_string())
            .map_or(0.0, |r| r.error.reference_noise);
        writeln!(
            out,
            "Reference for `{}`: {} probes × {} paths (`{}`), relative noise {:.4}.\n",
            scene.display(),
            reference.probes.len(),
            reference.samples,
            reference.command,
            noise
        )?;
    }
    writeln!(
        out,
        "*links* are the dense matrix's n² entries or the hierarchy's links; *peak MB* is the largest heap in use during the run.\n"
    )?;
    writeln!(
        out,
        "| scene | patches | method | rays | links | links/patch | peak MB | load+mesh s | form factors s | solve s | total s | smooth RMS | flat RMS | max | energy | front |"
    )?;
    writeln!(
        out,
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|:-:|"
    )?;
    for r in rows {
        writeln!(
            out,
            "| {} | {} | {} | {} | {} | {:.1} | {:.0} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.3} | {:+.4} | {} |",
            r.scene,
            r.patches,
            r.method,
            r.rays,
            r.links,
            r.links as f64 / r.patches.max(1) as f64,
            r.peak_bytes as f64 / 1e6,
            r.seconds[0],
            r.seconds[1],
            r.seconds[2],
            r.seconds[3],
            r.error.smooth.rms,
            r.error.flat.rms,
            r.error.smooth.max,
            r.error.smooth.energy,
            if r.pareto { "★" } else { "" }
        )?;
    }
    hierarchy_against_dense(&mut out, rows)?;
    Ok(out)
}

/// Total seconds of `rows` (sorted by patches, error falling) where `reading` is `target`
/// ([`interpolate_at`]).
/// What viewers see, interpolated.
fn smooth_rms(row: &Row) -> f64 {
    row.error.smooth.rms
}

/// The patch values.
fn flat_rms(row: &Row) -> f64 {
    row.error.flat.rms
}

/// Whether `a` is at least as fast and as accurate by `reading` as `b`, and better in one.
fn dominates(a: &Row, b: &Row, reading: fn(&Row) -> f64) -> bool {
    let (ta, tb) = (a.seconds[3], b.seconds[3]);
    ta <= tb && reading(a) <= reading(b) && (ta < tb || reading(a) < reading(b))
}

/// The rows of `rows` that no other dominates by `reading`, fastest first (along a front,
/// error falls as time grows).
fn front<'a>(rows: &[&'a Row], reading: fn(&Row) -> f64) -> Vec<&'a Row> {
    let mut front: Vec<&Row> = (rows.iter().copied())
        .filter(|r| !rows.iter().any(|o| dominates(o, r, reading)))
        .collect();
    front.sort_by(|a, b| a.seconds[3].total_cmp(&b.seconds[3]));
    front
}

fn seconds_at(rows: &[&Row], target: f64, reading: fn(&Row) -> f64) -> Option<(f64, bool)> {
    interpolate_at(rows, target, reading, |r| r.seconds[3])
}

/// `value` of `rows` (sorted so that error falls) where `reading` is `target`: log-log
/// interpolation between the bracketing rows, or extrapolation from the nearest two; and
/// whether it was extrapolated.
fn interpolate_at(
    rows: &[&Row],
    target: f64,
    reading: fn(&Row) -> f64,
    value: fn(&Row) -> f64,
) -> Option<(f64, bool)> {
    if rows.len() < 2 {
        return None;
    }
    let pair = rows
        .windows(2)
        .find(|w| reading(w[0]) >= target && target >= reading(w[1]));
    let (a, b, extrapolated) = match pair {
        Some(w) => (w[0], w[1], false),
        // Past the coarse end: the first two; past the fine end: the last two.
        None if target > reading(rows[0]) => (rows[0], rows[1], true),
        None => (rows[rows.len() - 2], rows[rows.len() - 1], true),
    };
    let (ea, eb) = (reading(a).ln(), reading(b).ln());
    if ea == eb {
        return None;
    }
    let t = (target.ln() - ea) / (eb - ea);
    Some((
        (value(a).ln() + t * (value(b).ln() - value(a).ln())).exp(),
        extrapolated,
    ))
}

/// A peer system's name and its (seconds, smooth RMS) points, per peer file.
type PeerPoints<'a> = Vec<(&'a str, Vec<(f64, f64)>)>;

fn peer_points(peers: &[Peers]) -> PeerPoints<'_> {
    peers
        .iter()
        .map(|p| {
            let system = p.rows.first().map_or("peer", |r| r.system.as_str());
            (
                system,
                p.rows.iter().map(|r| (r.seconds, r.smooth_rms)).collect(),
            )
        })
        .collect()
}

/// The (seconds, smooth RMS) ranges the plot must show: every row and every peer point.
fn plot_ranges(rows: &[Row], peer_points: &PeerPoints) -> ((f64, f64), (f64, f64)) {
    let bounds = |f: fn(&Row) -> f64| {
        rows.iter()
            .map(f)
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    };
    let widen = |(lo, hi): (f64, f64), values: &mut dyn Iterator<Item = f64>| {
        values.fold((lo, hi), |(lo, hi), v| (lo.min(v), hi.max(v)))
    };
    let all_peers = || {
        peer_points
            .iter()
            .flat_map(|(_, points)| points.iter().copied())
    };
    let (t_lo, t_hi) = widen(bounds(|r| r.seconds[3]), &mut all_peers().map(|p| p.0));
    let (e_lo, e_hi) = widen(
        bounds(|r| r.error.smooth.rms.max(1e-6)),
        &mut all_peers().map(|p| p.1),
    );
    ((t_lo, t_hi), (e_lo, e_hi))
}

type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>;

/// Each scene's Pareto front as a line, and each peer's rows as crosses on a line.
fn draw_fronts_and_peers(
    chart: &mut Chart,
    rows: &[Row],
    scenes: &[&str],
    peer_points: &PeerPoints,
) -> anyhow::Result<()> {
    let point = |r: &Row| (r.seconds[3], r.error.smooth.rms.max(1e-6));
    for (s, scene) in scenes.iter().enumerate() {
        let mut front: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.pareto && r.scene == *scene)
            .map(point)
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        let marker = if s == 0 {
            "circles"
        } else if s == 1 {
            "triangles"
        } else {
            "squares"
        };
        chart
            .draw_series(LineSeries::new(front, BLACK.stroke_width(1)))?
            .label(format!("Pareto front, {scene} ({marker})"))
            .legend(|(x, y)| PathElement::new([(x - 8, y), (x + 8, y)], BLACK));
    }
    for (system, points) in peer_points {
        chart
            .draw_series(LineSeries::new(points.clone(), BLACK.stroke_width(2)))?
            .label(format!("{system} (peer, 1 thread; crosses)"))
            .legend(|(x, y)| Cross::new((x, y), 5, BLACK.stroke_width(2)));
        chart.draw_series(
            points
                .iter()
                .map(|p| Cross::new(*p, 6, BLACK.stroke_width(2))),
        )?;
    }
    Ok(())
}

fn plot(rows: &[Row], peers: &[Peers], path: &Path) -> anyhow::Result<()> {
    let peer_points = peer_points(peers);
    let ((t_lo, t_hi), (e_lo, e_hi)) = plot_ranges(rows, &peer_points);
    let root = SVGBackend::new(path, (960, 640)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "radcast: total seconds vs smooth RMS error (log-log)",
            ("sans-serif", 22),
        )
        .margin(20)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (t_lo * 0.7..t_hi * 1.4).log_scale(),
            (e_lo * 0.7..e_hi * 1.4).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("total seconds (load + mesh + form factors + solve)")
        .y_desc("smooth RMS error vs reference")
        .x_label_formatter(&|x| format!("{x:.3}"))
        .y_label_formatter(&|y| format!("{y:.3}"))
        .draw()?;
    let colours = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
    // Hierarchical rows form one group whatever their knob.
    let group = |r: &Row| {
        if r.method.starts_with("hierarchical") {
            ("hierarchical".to_string(), 0)
        } else {
            (r.method.clone(), r.rays)
        }
    };
    let mut groups: Vec<(String, u32)> = rows.iter().map(group).collect();
    groups.sort();
    groups.dedup();
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    let point = |r: &Row| (r.seconds[3], r.error.smooth.rms.max(1e-6));
    for (k, (method, rays)) in groups.iter().enumerate() {
        let colour = colours[k % colours.len()];
        let in_group = |r: &&Row| group(r) == (method.clone(), *rays);
        // Circles for the first scene, triangles for the second, squares after.
        for (s, scene) in scenes.iter().enumerate() {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter(in_group)
                .filter(|r| r.scene == *scene)
                .map(point)
                .collect();
            let style = colour.filled();
            match s {
                0 => chart.draw_series(points.iter().map(|p| Circle::new(*p, 5, style)))?,
                1 => chart.draw_series(points.iter().map(|p| TriangleMarker::new(*p, 6, style)))?,
                _ => chart.draw_series(points.iter().map(|p| Rectangle::new([*p, *p], style)))?,
            };
        }
        let label = if *rays == 0 {
            format!("{method} (E sweep)")
        } else {
            format!("{method}, {rays} rays/pair")
        };
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label(label)
            .legend(move |(x, y)| Circle::new((x, y), 5, colour.filled()));
    }
    draw_fronts_and_peers(&mut chart, rows, &scenes, &peer_points)?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{PeerRow, Peers, Row};
    use solver::accuracy::{ErrorStats, SolutionError};

    fn ours(seconds: f64, smooth_rms: f64) -> Row {
        ours_reading(seconds, smooth_rms, 2.0 * smooth_rms)
    }

    fn ours_reading(seconds: f64, smooth_rms: f64, flat_rms: f64) -> Row {
        let stats = |rms| ErrorStats {
            rms,
            ..ErrorStats::default()
        };
        Row {
            scene: "box".into(),
            patches: 100,
            method: "gmres".into(),
            rays: 1,
            links: 0,
            peak_bytes: 0,
            seconds: [0.0, 0.0, 0.0, seconds],
            error: SolutionError {
                smooth: stats(smooth_rms),
                flat: stats(flat_rms),
                ..SolutionError::default()
            },
            pareto: true,
        }
    }

    fn peer(seconds: f64, smooth_rms: f64) -> PeerRow {
        PeerRow {
            system: "Peer".into(),
            setting: "T".into(),
            leaves: 1,
            links: 1,
            seconds,
            flat_rms: smooth_rms,
            smooth_rms,
            energy: 0.0,
        }
    }

    #[test]
    fn peers_are_met_between_our_rows_and_bounded_past_our_coarsest() {
        let peers = Peers {
            scene: "box".into(),
            source: "here".into(),
            // Between our rows (log-log halfway: 0.2 s), and coarser than our fastest row.
            rows: vec![peer(2.0, 0.2), peer(1.0, 0.5)],
        };
        let table = peers
            .comparison(&[ours(0.1, 0.4), ours(0.4, 0.1)])
            .expect("a table");
        let lines: Vec<&str> = table.lines().filter(|l| l.starts_with("| Peer")).collect();
        assert!(lines[0].contains("| 0.200 | 10.0× |"), "{}", lines[0]);
        assert!(lines[1].contains("| ≤ 0.100 | ≥ 10.0× |"), "{}", lines[1]);
    }

    #[test]
    fn the_hierarchy_alone_is_met_on_its_own_rows_after_every_method() {
        // Dense rows twice as fast as the hierarchical ones at each error: every method meets
        // the peer on the dense rows, the hierarchy alone on its own.
        let hierarchical = |seconds, smooth_rms| Row {
            method: "hierarchical E=0.3".into(),
            ..ours(seconds, smooth_rms)
        };
        let rows = [
            ours(0.1, 0.4),
            ours(0.4, 0.1),
            hierarchical(0.2, 0.4),
            hierarchical(0.8, 0.1),
        ];
        let peers = Peers {
            scene: "box".into(),
            source: "here".into(),
            rows: vec![peer(2.0, 0.2)],
        };
        let table = peers.comparison(&rows).expect("a table");
        let lines: Vec<&str> = table.lines().filter(|l| l.starts_with("| Peer")).collect();
        assert_eq!(lines.len(), 2, "{table}");
        assert!(lines[0].contains("| 0.200 | 10.0× |"), "{}", lines[0]);
        assert!(lines[1].contains("| 0.400 | 5.0× |"), "{}", lines[1]);
        let alone = table.find("The hierarchy alone").expect("its heading");
        assert!(table.find(lines[1]).expect("its row") > alone);
    }

    #[test]
    fn each_reading_is_met_on_its_own_front() {
        // The middle row is off the smooth front (slower and worse to the eye than the first)
        // but on the flat one: a peer's flat error is met there, not between the other two.
        let rows = [
            ours_reading(0.1, 0.4, 0.8),
            ours_reading(0.15, 0.5, 0.3),
            ours_reading(0.4, 0.1, 0.2),
        ];
        let peers = Peers {
            scene: "box".into(),
            source: "here".into(),
            rows: vec![PeerRow {
                flat_rms: 0.3,
                ..peer(1.5, 0.2)
            }],
        };
        let table = peers.comparison(&rows).expect("a table");
        let line = table
            .lines()
            .find(|l| l.starts_with("| Peer"))
            .expect("a row");
        // Smooth 0.2 between the first and last rows (log-log: 0.2 s); flat 0.3 at 0.15 s.
        assert!(line.ends_with("| 0.200 | 7.5× | 0.150 | 10.0× |"), "{line}");
    }
}
