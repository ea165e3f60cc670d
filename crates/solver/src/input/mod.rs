//! Scene files in: OBJ + MTL ([`obj`]) and glTF 2.0 ([`gltf`]), with their texture images
//! ([`image`]), read into a [`Scene`], then the steps every loader ends with ([`finish`]):
//! degenerate faces dropped, faces cut along contact lines ([`contact`]) and along the faces
//! running across them ([`section`]).

pub(crate) mod contact;
mod gltf;
mod image;
mod lines;
mod obj;
mod section;

use crate::scene::Scene;
use std::path::{Path, PathBuf};

pub use self::gltf::load_gltf;
pub use obj::load_obj;

/// Why a scene could not be loaded. Every variant names the file and, where one exists, the line.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The OBJ or MTL file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The OBJ parser rejected the file.
    #[error("{path}: {reason}")]
    Parse {
        /// The OBJ file.
        path: PathBuf,
        /// The parser's reason.
        reason: String,
    },
    /// A line of the OBJ file is wrong: a bad number, an index out of range, an unknown material.
    #[error("{path}:{line}: {reason}")]
    Line {
        /// The OBJ file.
        path: PathBuf,
        /// One-based line number.
        line: usize,
        /// What is wrong on that line.
        reason: String,
    },
    /// A material has a value outside its physical range.
    #[error("{path}: material '{material}': {reason}")]
    Material {
        /// The file that defines the material.
        path: PathBuf,
        /// The material's name.
        material: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Faces were given without any `usemtl`.
    #[error("{path}: object '{object}' has faces but no material (add `usemtl NAME`)")]
    NoMaterial {
        /// The OBJ file.
        path: PathBuf,
        /// The object's name.
        object: String,
    },
    /// An emitter has a face too small next to the scene to be solved: dropping it would
    /// silently darken the scene.
    #[error(
        "{path}: object '{object}' emits light from a face below 1e-14 of the scene's squared diagonal: too small next to the rest of the scene to solve"
    )]
    EmitterTooSmall {
        /// The OBJ file.
        path: PathBuf,
        /// The emitting object.
        object: String,
    },
    /// Nothing with a non-zero area is left to light.
    #[error("{path}: the scene has no faces with non-zero area")]
    Empty {
        /// The OBJ file.
        path: PathBuf,
    },
}

/// Loads an OBJ (with its MTL) or a glTF 2.0 file (`.gltf`, `.glb`), by extension.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("gltf" | "glb") => self::gltf::load_gltf(path),
        _ => obj::load_obj(path),
    }
}

/// What every loader ends with: degenerate faces dropped (an emitter among them is an
/// error), a scene left with nothing to light refused, and faces cut along the contact
/// lines of what stands on them ([`contact`]) and the faces running across them
/// ([`section`]).
pub(crate) fn finish(mut scene: Scene, path: &Path) -> Result<Scene, SceneError> {
    if let Some(object) = scene.drop_degenerate_faces() {
        return Err(SceneError::EmitterTooSmall {
            path: path.into(),
            object,
        });
    }
    if scene.faces.is_empty() {
        return Err(SceneError::Empty { path: path.into() });
    }
    contact::split_at_contacts(&mut scene);
    Ok(scene)
}

/// The largest scene or material file read: far past any real model, short of what a
/// mistaken path (a device, a disk image) would make the loader swallow.
pub const MAX_SCENE_FILE_BYTES: u64 = 4 << 30;

/// Reads a scene or material file as text: a regular file of at most
/// [`MAX_SCENE_FILE_BYTES`].
pub fn read_scene_file(path: &Path) -> Result<String, SceneError> {
    check_scene_file(path)?;
    std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.into(),
        source,
    })
}

/// Checks, without reading it, that `path` is a regular file of at most
/// [`MAX_SCENE_FILE_BYTES`]: not a device that never ends, not a disk image.
pub fn check_scene_file(path: &Path) -> Result<(), SceneError> {
    let io = |source| SceneError::Io {
        path: path.into(),
        source,
    };
    let metadata = std::fs::metadata(path).map_err(io)?;
    let refuse = |reason: String| SceneError::Parse {
        path: path.into(),
        reason,
    };
    if !metadata.is_file() {
        return Err(refuse("not a regular file".into()));
    }
    if metadata.len() > MAX_SCENE_FILE_BYTES {
        return Err(refuse(format!(
            "{} bytes is more than a scene file may have ({MAX_SCENE_FILE_BYTES})",
            metadata.len()
        )));
    }
    Ok(())
}
