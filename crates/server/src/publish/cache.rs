//! The disk cache of finished solutions. An entry is served only when it proves that it belongs
//! to this scene and these settings (the full scene digest is stored in it) and that its bytes
//! are intact (a SHA-256 over the whole entry); anything else is a [`Rejected`] entry, solved
//! again.
//!
//! Layout of `<dir>/<first 8 digest bytes as hex>.radcast`:
//!
//! | bytes | what |
//! |---|---|
//! | 8 | magic `RCCACHE3` |
//! | 32 | scene digest ([`scene_digest`]) |
//! | 8 | payload length, u64 little-endian |
//! | n | payload: bincode (standard config) of the geometry, the patch and vertex values and the report |
//! | 32 | SHA-256 of everything before it |

use anyhow::Context;
use bincode::{Decode, Encode};
use sha2::{Digest, Sha256};
use solver::{Scene, SolveRequest};
use std::io::Write;
use std::path::{Path, PathBuf};
use wire::Geometry;

const MAGIC: &[u8; 8] = b"RCCACHE3";
const DIGEST_BYTES: usize = 32;
const HEADER_BYTES: usize = MAGIC.len() + DIGEST_BYTES + 8;

/// SHA-256 of what the solver sees — the loaded scene (every position, face and material, as
/// exact decimal text), the solve settings — and this program's version and
/// [`solver::SOLUTION_REVISION`] (a build that solves the same scene to other values does not
/// serve an earlier build's entries: the crate version alone did not change). Parsed content, not
/// file bytes, so two files that load the same scene share an entry and no file the loader
/// reads (an `mtllib` of any spelling) can change the answer without changing the digest.
pub fn scene_digest(scene: &Scene, request: &SolveRequest) -> [u8; DIGEST_BYTES] {
    digest_at_revision(scene, request, solver::SOLUTION_REVISION)
}

/// [`scene_digest`] as a build solving at `revision` computes it.
fn digest_at_revision(scene: &Scene, request: &SolveRequest, revision: u32) -> [u8; DIGEST_BYTES] {
    struct Hashing(Sha256);
    impl std::fmt::Write for Hashing {
        fn write_str(&mut self, text: &str) -> std::fmt::Result {
            self.0.update(text.as_bytes());
            Ok(())
        }
    }
    let mut hashing = Hashing(Sha256::new());
    // Debug prints every f64 with the shortest text that reads back exactly.
    std::fmt::write(
        &mut hashing,
        format_args!(
            "{scene:?}\n{request:?}\nradcast {} solution revision {revision}",
            env!("CARGO_PKG_VERSION"),
        ),
    )
    .expect("hashing never fails");
    hashing.0.finalize().into()
}

/// A finished solution as cached, with the geometry its values belong to (a hierarchy's
/// leaves are known only after refinement, which a cache hit skips).
#[derive(Clone, Debug, PartialEq, Encode, Decode)]
pub struct CachedSolution {
    /// The geometry viewers are served, as `/api/scene` sends it.
    pub geometry: Vec<u8>,
    /// Per patch: what a session adopts when the first edit arrives.
    pub radiosity: Vec<[f32; 3]>,
    /// Per vertex: what viewers are sent.
    pub vertex_radiosity: Vec<[f32; 3]>,
    /// The solve report as `/api/solution` gives it, JSON.
    pub report_json: String,
}

/// Why a cache entry was not served.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum Rejected {
    /// No entry for this scene.
    #[error("no cached solution")]
    Missing,
    /// The file could not be read.
    #[error("cannot read: {0}")]
    Unreadable(String),
    /// Not a radcast cache file of this format.
    #[error(
        "not a radcast cache file of format {}",
        String::from_utf8_lossy(MAGIC)
    )]
    WrongFormat,
    /// The digest inside names another scene or other settings.
    #[error("written for another scene or other settings")]
    OtherScene,
    /// Shorter or longer than its header says, or its checksum does not match.
    #[error("corrupt: {0}")]
    Corrupt(&'static str),
    /// Intact, but its values do not fit its geometry.
    #[error("does not fit its geometry: {0}")]
    Mismatch(String),
}

/// The scene id viewers see (hello, `/api/solution`): the digest's first 8 bytes.
pub fn scene_id(digest: &[u8; DIGEST_BYTES]) -> u64 {
    u64::from_le_bytes(digest[..8].try_into().expect("8 bytes"))
}

/// Where the entry for `digest` lives in `dir`: named by the scene id, as viewers see it.
pub fn entry_path(dir: &Path, digest: &[u8; DIGEST_BYTES]) -> PathBuf {
    dir.join(format!("{:016x}.radcast", scene_id(digest)))
}

/// Reads the entry for `digest` from `dir`: its geometry and values, once proven.
pub fn read(
    dir: &Path,
    digest: &[u8; DIGEST_BYTES],
) -> Result<(CachedSolution, Geometry), Rejected> {
    let bytes = match std::fs::read(entry_path(dir, digest)) {
        Ok(bytes) => bytes,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => {
            return Err(Rejected::Missing);
        }
        Err(error) => return Err(Rejected::Unreadable(error.to_string())),
    };
    let cached = decode(&bytes, digest)?;
    let geometry = Geometry::decode(&cached.geometry)
        .map_err(|e| Rejected::Mismatch(format!("its geometry does not decode: {e}")))?;
    let counts_fit = cached.radiosity.len() == geometry.patches.len()
        && cached.vertex_radiosity.len() == geometry.positions.len();
    if !counts_fit {
        return Err(Rejected::Mismatch(format!(
            "{} patch and {} vertex values for {} patches and {} vertices",
            cached.radiosity.len(),
            cached.vertex_radiosity.len(),
            geometry.patches.len(),
            geometry.positions.len()
        )));
    }
    Ok((cached, geometry))
}

/// The entry's payload, once its format, digest, length and checksum are proven.
fn decode(bytes: &[u8], digest: &[u8; DIGEST_BYTES]) -> Result<CachedSolution, Rejected> {
    if bytes.len() < HEADER_BYTES || &bytes[..MAGIC.len()] != MAGIC {
        return Err(Rejected::WrongFormat);
    }
    if &bytes[MAGIC.len()..MAGIC.len() + DIGEST_BYTES] != digest {
        return Err(Rejected::OtherScene);
    }
    let length = u64::from_le_bytes(
        bytes[HEADER_BYTES - 8..HEADER_BYTES]
            .try_into()
            .expect("8 bytes"),
    );
    let body_end = usize::try_from(length)
        .ok()
        .and_then(|n| n.checked_add(HEADER_BYTES))
        .filter(|&end| end.checked_add(DIGEST_BYTES) == Some(bytes.len()))
        .ok_or(Rejected::Corrupt("its length is not what its header says"))?;
    if Sha256::digest(&bytes[..body_end]).as_slice() != &bytes[body_end..] {
        return Err(Rejected::Corrupt("checksum mismatch"));
    }
    let (cached, read): (CachedSolution, usize) =
        bincode::decode_from_slice(&bytes[HEADER_BYTES..body_end], bincode::config::standard())
            .map_err(|_| Rejected::Corrupt("payload does not decode"))?;
    if read != body_end - HEADER_BYTES {
        return Err(Rejected::Corrupt("payload has trailing bytes"));
    }
    let physical = cached
        .radiosity
        .iter()
        .chain(&cached.vertex_radiosity)
        .flatten()
        .all(|c| c.is_finite() && *c >= 0.0);
    if !physical {
        return Err(Rejected::Corrupt("a value is negative or not finite"));
    }
    Ok(cached)
}

/// The bytes of an entry for `digest`.
fn encode(digest: &[u8; DIGEST_BYTES], cached: &CachedSolution) -> anyhow::Result<Vec<u8>> {
    let payload = bincode::encode_to_vec(cached, bincode::config::standard())?;
    let mut bytes = Vec::with_capacity(HEADER_BYTES + payload.len() + DIGEST_BYTES);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(digest);
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&payload);
    let checksum = Sha256::digest(&bytes);
    bytes.extend_from_slice(&checksum);
    Ok(bytes)
}

/// Writes the entry atomically (a temporary file in `dir`, synced, renamed over the target), so
/// a crash leaves the old entry or the new one, never half of one. Returns its path.
pub fn write(
    dir: &Path,
    digest: &[u8; DIGEST_BYTES],
    cached: &CachedSolution,
) -> anyhow::Result<PathBuf> {
    let path = entry_path(dir, digest);
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut file = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("{}: cannot create a file in it", dir.display()))?;
    file.write_all(&encode(digest, cached)?)
        .and_then(|()| file.as_file().sync_all())
        .with_context(|| format!("{}: cannot write", file.path().display()))?;
    file.persist(&path)
        .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> CachedSolution {
        CachedSolution {
            geometry: vec![1, 2, 3],
            radiosity: vec![[0.5, 1.0, 2.0], [3.0, 0.0, 0.25]],
            vertex_radiosity: vec![[1.5, 1.0, 0.125]; 3],
            report_json: "{}".into(),
        }
    }

    #[test]
    fn every_single_bit_flip_is_rejected() {
        let digest = [7u8; DIGEST_BYTES];
        let bytes = encode(&digest, &sample()).unwrap();
        assert_eq!(decode(&bytes, &digest), Ok(sample()));
        for bit in 0..bytes.len() * 8 {
            let mut flipped = bytes.clone();
            flipped[bit / 8] ^= 1 << (bit % 8);
            assert!(decode(&flipped, &digest).is_err(), "bit {bit} flipped");
        }
    }

    #[test]
    fn another_scenes_entry_and_truncations_are_rejected_with_the_reason() {
        let digest = [7u8; DIGEST_BYTES];
        let bytes = encode(&digest, &sample()).unwrap();
        assert_eq!(
            decode(&bytes, &[8u8; DIGEST_BYTES]),
            Err(Rejected::OtherScene)
        );
        for length in [0, 7, HEADER_BYTES - 1, HEADER_BYTES, bytes.len() - 1] {
            let reason = decode(&bytes[..length], &digest).unwrap_err().to_string();
            assert!(
                reason.starts_with("not a radcast cache") || reason.starts_with("corrupt"),
                "{length} bytes: {reason}"
            );
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(
            decode(&longer, &digest),
            Err(Rejected::Corrupt("its length is not what its header says"))
        );
    }

    #[test]
    fn the_digest_follows_content_and_settings() {
        let scene = |reflectance: f64| Scene {
            objects: vec![solver::SceneObject {
                name: "wall".into(),
            }],
            faces: vec![solver::Face {
                polygon: solver::Polygon::triangle(
                    glam::DVec3::ZERO,
                    glam::DVec3::X,
                    glam::DVec3::Y,
                ),
                object: 0,
                reflectance: solver::Rgb::splat(reflectance),
                emission: solver::Rgb::ZERO,
                source: 0,
                texture: None,
            }],
            ..Scene::default()
        };
        let request = SolveRequest::default();
        let base = scene_digest(&scene(0.5), &request);
        assert_eq!(base, scene_digest(&scene(0.5), &request));
        // One ulp of one reflectance, or another setting, is another scene.
        assert_ne!(base, scene_digest(&scene(0.5f64.next_up()), &request));
        let mut finer = request;
        finer.form_factors.rays_per_pair += 1;
        assert_ne!(base, scene_digest(&scene(0.5), &finer));
        // A build whose numerics solve the same scene to other values is another entry.
        let revision = solver::SOLUTION_REVISION;
        assert_eq!(base, digest_at_revision(&scene(0.5), &request, revision));
        assert_ne!(
            base,
            digest_at_revision(&scene(0.5), &request, revision - 1)
        );
    }
}
