//! Scene geometry as viewers fetch it once (`GET /api/scene`): patch corners, topology and
//! object names, in a versioned binary form (docs/PROTOCOL.md).

use crate::DecodeError;
use crate::frame::{MAX_VERTICES, config};
use bincode::{Decode, Encode};

/// Leading bytes of an encoded [`Geometry`].
pub const MAGIC: &[u8; 6] = b"RCGEO1";

/// Marks the unused fourth corner of a triangular patch.
pub const NO_CORNER: u32 = u32::MAX;

/// A suggested viewpoint that a scene file may carry.
#[derive(Clone, Copy, Debug, PartialEq, Encode, Decode)]
pub struct Camera {
    /// Eye position, scene units.
    pub eye: [f32; 3],
    /// Point looked at.
    pub target: [f32; 3],
    /// Up direction.
    pub up: [f32; 3],
    /// Vertical field of view, degrees.
    pub vertical_fov_degrees: f32,
}

/// What a viewer needs to rebuild the scene: positions and, per patch, its corners and object.
#[derive(Clone, Debug, PartialEq, Encode, Decode)]
pub struct Geometry {
    /// Corner positions, scene units.
    pub positions: Vec<[f32; 3]>,
    /// Per patch: indices into `positions`, counter-clockwise from the front; a triangle's
    /// fourth is [`NO_CORNER`]. Corners are shared only within one input face, so smooth
    /// shading never blends across a crease.
    pub patches: Vec<[u32; 4]>,
    /// Per patch: index into `objects`.
    pub patch_objects: Vec<u32>,
    /// Object names from the scene file.
    pub objects: Vec<String>,
    /// The scene's suggested view, if it has one.
    pub camera: Option<Camera>,
}

impl Geometry {
    /// The bytes served at `/api/scene`.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        bincode::encode_into_std_write(self, &mut out, config())
            .expect("writing to a Vec cannot fail");
        out
    }

    /// Parses and checks geometry; never panics, whatever the bytes.
    pub fn decode(bytes: &[u8]) -> Result<Geometry, DecodeError> {
        let body = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or(DecodeError::BadMagic)?;
        // A byte limit stops hostile length prefixes from allocating more than the input could hold.
        let limited = config().with_limit::<{ 1 << 30 }>();
        let (geometry, used): (Geometry, usize) = bincode::decode_from_slice(body, limited)
            .map_err(|e| DecodeError::Header(e.to_string()))?;
        if used != body.len() {
            return Err(DecodeError::TrailingBytes(body.len() - used));
        }
        geometry.validate()?;
        Ok(geometry)
    }

    fn validate(&self) -> Result<(), DecodeError> {
        let patch_count = self.patches.len();
        if patch_count > MAX_VERTICES as usize {
            return Err(DecodeError::TooLarge {
                what: "patch count",
                size: patch_count as u64,
                limit: MAX_VERTICES as u64,
            });
        }
        if self.patch_objects.len() != patch_count {
            return Err(DecodeError::Length {
                what: "patch objects",
                expected: patch_count,
                got: self.patch_objects.len(),
            });
        }
        if let Some(p) = self
            .positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(DecodeError::Invalid(format!("position {p} is not finite")));
        }
        for (i, corners) in self.patches.iter().enumerate() {
            let used = if corners[3] == NO_CORNER {
                &corners[..3]
            } else {
                &corners[..]
            };
            if let Some(&bad) = used.iter().find(|&&c| c as usize >= self.positions.len()) {
                return Err(DecodeError::Invalid(format!(
                    "patch {i} refers to vertex {bad} of {}",
                    self.positions.len()
                )));
            }
        }
        if let Some(i) = self
            .patch_objects
            .iter()
            .position(|&o| o as usize >= self.objects.len())
        {
            return Err(DecodeError::Invalid(format!(
                "patch {i} refers to object {} of {}",
                self.patch_objects[i],
                self.objects.len()
            )));
        }
        Ok(())
    }
}
