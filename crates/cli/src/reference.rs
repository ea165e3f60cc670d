//! `radcast reference`: path-traced probes, a reference that depends on no mesh.

use crate::{ProgressPrinter, create_parent};
use anyhow::Context;
use solver::reference::{Reference, place_probes, trace_probes};
use solver::visibility::Occluders;
use std::path::{Path, PathBuf};

/// The arguments of `radcast reference`.
#[derive(clap::Args)]
pub struct ReferenceCommand {
    /// The scene: OBJ (with its MTL) or glTF 2.0 (`.gltf`, `.glb`).
    pub scene: PathBuf,
    /// Probe points, spread over the surfaces by area.
    #[arg(long, default_value_t = 1000)]
    pub probes: usize,
    /// Paths per probe.
    #[arg(long, default_value_t = 16384)]
    pub samples: u32,
    /// Seed of the random streams.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where to write the JSON.
    #[arg(long)]
    pub out: PathBuf,
}

impl ReferenceCommand {
    /// Runs the command.
    pub fn run(self) -> anyhow::Result<()> {
        let ReferenceCommand {
            scene: path,
            probes,
            samples,
            seed,
            out,
        } = self;
        anyhow::ensure!(
            probes > 0 && samples > 1,
            "--probes must be at least 1 and --samples at least 2"
        );
        write_reference(&path, probes, samples, seed, &out).map(|_| ())
    }
}

/// The reference file at `path`, its errors naming it.
pub fn read_reference(path: &Path) -> anyhow::Result<Reference> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: not a radcast reference", path.display()))
}

/// Path-traces `probes` probes of the scene at `path`, `samples` paths each, and writes the
/// reference to `out` (its folder made first); returns it.
pub fn write_reference(
    path: &Path,
    probes: usize,
    samples: u32,
    seed: u64,
    out: &Path,
) -> anyhow::Result<Reference> {
    let scene = solver::load_scene(path)?;
    // Before minutes of tracing, not after.
    create_parent(out)?;
    let occluders = Occluders::new(&scene);
    let printer = ProgressPrinter::new();
    let placed = place_probes(&scene, probes, seed);
    let traced = trace_probes(&scene, &occluders, &placed, samples, seed, &|p| {
        printer.report(p)
    });
    drop(printer);
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
    std::fs::write(out, serde_json::to_string_pretty(&reference)?)
        .with_context(|| format!("{}: cannot write", out.display()))?;
    eprintln!(
        "wrote {} ({} probes x {samples} paths)",
        out.display(),
        probes
    );
    Ok(reference)
}
