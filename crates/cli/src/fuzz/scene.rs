//! The scene target: a mutated OBJ and MTL go through the loader, and a scene that loads goes
//! on through meshing and a small solve (dense or hierarchical, case by case), where scaled
//! or degenerate input has broken the solver before. Checked: an error names the file it is
//! about, and every radiosity value of a solve is finite and non-negative.

use super::mutate::{Choices, mutate_text};
use super::{Input, Outcome, Target};
use anyhow::Context;
use solver::{FormFactorSettings, HierarchySettings, PatchTarget, SolveRequest};
use std::path::Path;

/// Scene files to start from: each OBJ and the MTL it names.
pub struct SceneTarget {
    corpus: Vec<Input>,
}

/// The name of the mutated OBJ in a case.
const OBJ_NAME: &str = "case.obj";

impl SceneTarget {
    /// Reads every `.obj` in `folders` and the first MTL library each names.
    pub fn from_folders(folders: &[&Path]) -> anyhow::Result<SceneTarget> {
        let mut corpus = Vec::new();
        for folder in folders.iter().filter(|f| f.is_dir()) {
            let mut paths: Vec<_> = std::fs::read_dir(folder)
                .with_context(|| format!("{}: cannot list", folder.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "obj"))
                .collect();
            paths.sort();
            for path in paths {
                let obj = std::fs::read(&path)
                    .with_context(|| format!("{}: cannot read", path.display()))?;
                let mut input = vec![(OBJ_NAME.to_string(), obj.clone())];
                let library = String::from_utf8_lossy(&obj).lines().find_map(|l| {
                    l.trim()
                        .strip_prefix("mtllib ")
                        .map(|n| n.trim().to_string())
                });
                // Through the loader's own reader: a library may be /dev/zero.
                if let Some(name) = library
                    && let Ok(mtl) = solver::read_scene_file(&folder.join(&name))
                {
                    input.push((name, mtl.into_bytes()));
                }
                corpus.push(input);
            }
        }
        anyhow::ensure!(!corpus.is_empty(), "no .obj files in {folders:?}");
        Ok(SceneTarget { corpus })
    }
}

impl Target for SceneTarget {
    fn name(&self) -> &'static str {
        "scene"
    }

    fn input(&self, choices: &mut Choices) -> Input {
        let mut input = choices.pick(&self.corpus).clone();
        for _ in 0..1 + choices.below(4) {
            // Mostly the OBJ; the MTL (when there is one) a quarter of the time.
            let file = match input.len() > 1 && choices.below(4) == 0 {
                true => 1,
                false => 0,
            };
            input[file].1 = mutate_text(&input[file].1, choices);
        }
        input
    }

    fn run(&self, input: &Input, scratch: &Path) -> Result<Outcome, String> {
        for (name, bytes) in input {
            std::fs::write(scratch.join(name), bytes).map_err(|e| format!("scratch: {e}"))?;
        }
        let scene = match solver::load_obj(&scratch.join(OBJ_NAME)) {
            Ok(scene) => scene,
            Err(error) => return names_a_file(&error.to_string(), input, scratch),
        };
        // Dense and hierarchical in turn, kept small: the point is what the input does to
        // them, not their accuracy.
        let hierarchical = input[0].1.len() % 2 == 1;
        let request = SolveRequest {
            patches: PatchTarget::Count(48),
            form_factors: FormFactorSettings { rays_per_pair: 1 },
            hierarchy: hierarchical.then_some(HierarchySettings {
                error: 0.5,
                max_leaves: 4_000,
                ..HierarchySettings::default()
            }),
            ..SolveRequest::default()
        };
        let solved = match solver::solve_scene(scene, &request, &solver::no_progress) {
            Ok(solved) => solved,
            Err(error) if !error.to_string().is_empty() => return Ok(Outcome::Rejected),
            Err(_) => return Err("a solve error with no message".into()),
        };
        let physical = solved
            .radiosity
            .iter()
            .chain(&solved.vertex_radiosity)
            .flat_map(|b| b.to_array())
            .all(|c| c.is_finite() && c >= 0.0);
        match physical {
            true => Ok(Outcome::Accepted),
            false => Err("radiosity that is negative or not finite".into()),
        }
    }
}

/// `Rejected` if `message` names one of the case's files, or a file the case names (a missing
/// MTL library); a finding otherwise.
fn names_a_file(message: &str, input: &Input, scratch: &Path) -> Result<Outcome, String> {
    let obj = String::from_utf8_lossy(&input[0].1);
    let libraries = obj
        .lines()
        .filter_map(|l| l.trim().strip_prefix("mtllib "))
        .flat_map(str::split_whitespace);
    let named = message.contains(scratch.to_string_lossy().as_ref())
        || input
            .iter()
            .any(|(name, _)| message.contains(name.as_str()))
        || libraries.into_iter().any(|name| message.contains(name));
    match named {
        true => Ok(Outcome::Rejected),
        false => Err(format!("an error that names no file: {message}")),
    }
}
