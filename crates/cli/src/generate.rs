//! `radcast generate`: a furnished room or a town of triangle soup, written as OBJ + MTL.

use crate::create_parent;
use anyhow::Context;
use std::path::PathBuf;

/// The arguments of `radcast generate`.
#[derive(clap::Args)]
pub struct GenerateCommand {
    /// Pieces of furniture (tables, chairs, cabinets; about 14 faces each).
    #[arg(long, default_value_t = 1000, conflicts_with = "town")]
    pub pieces: usize,
    /// A town of about this many triangles instead: buildings, domes and trees cut into
    /// small triangles under one large emitting sky quad.
    #[arg(long)]
    pub town: Option<usize>,
    /// Seed: the same seed gives the same room.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where to write the OBJ; the MTL goes beside it with the same stem.
    #[arg(long)]
    pub out: PathBuf,
}

impl GenerateCommand {
    /// Runs the command.
    pub fn run(self) -> anyhow::Result<()> {
        let GenerateCommand {
            pieces,
            town,
            seed,
            out,
        } = self;
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
        Ok(())
    }
}
