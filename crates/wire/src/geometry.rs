//! Scene geometry as viewers fetch it once (`GET /api/scene`): patch corners, topology and
//! object names, in a versioned binary form (docs/PROTOCOL.md), followed by optional
//! sections (today: [`SurfaceTextures`], present only for a scene with textures).

use crate::DecodeError;
use crate::frame::{MAX_VERTICES, config};
use bincode::{Decode, Encode};

/// Leading bytes of an encoded [`Geometry`].
pub const MAGIC: &[u8; 6] = b"RCGEO1";

/// Marks the unused fourth corner of a triangular patch.
pub const NO_CORNER: u32 = u32::MAX;

/// Marks a patch without a texture in [`SurfaceTextures::patch_textures`].
pub const NO_TEXTURE: u32 = u32::MAX;

/// Tag of the section holding [`SurfaceTextures`].
pub const TEXTURES_SECTION: u32 = 1;

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

/// How viewers show textured surfaces. The solution holds one value per vertex computed with
/// each texture's mean reflectance; a viewer multiplies it by `texel / mean` per channel
/// (linear colour), so the texture shows the detail and the light stays what was solved.
/// Textures are served once, as PNG, at `/api/textures/{index}`.
#[derive(Clone, Debug, Default, PartialEq, Encode, Decode)]
pub struct SurfaceTextures {
    /// Per texture: the mean of its texels in linear RGB (sRGB bytes decoded), which the
    /// solver used as the surface's reflectance factor.
    pub means: Vec<[f32; 3]>,
    /// Per patch: index into `means`, or [`NO_TEXTURE`].
    pub patch_textures: Vec<u32>,
    /// Per position: texture coordinates `(u, v)`, glTF's convention (`(0, 0)` the image's
    /// top-left corner, `v` down), repeating outside [0, 1]; `(0, 0)` on untextured patches.
    pub uvs: Vec<[f32; 2]>,
}

/// The fields every geometry has, in their encoded order.
#[derive(Encode, Decode)]
struct Core {
    positions: Vec<[f32; 3]>,
    patches: Vec<[u32; 4]>,
    patch_objects: Vec<u32>,
    objects: Vec<String>,
    camera: Option<Camera>,
}

/// What a viewer needs to rebuild the scene: positions and, per patch, its corners and object.
#[derive(Clone, Debug, PartialEq)]
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
    /// Textures and their coordinates, for a scene that has any.
    pub textures: Option<SurfaceTextures>,
}

impl Geometry {
    /// The bytes served at `/api/scene`: the core fields, then each section present as
    /// `u32 tag, u64 byte length, body`.
    pub fn encode(&self) -> Vec<u8> {
        let core = Core {
            positions: self.positions.clone(),
            patches: self.patches.clone(),
            patch_objects: self.patch_objects.clone(),
            objects: self.objects.clone(),
            camera: self.camera,
        };
        let mut out = MAGIC.to_vec();
        bincode::encode_into_std_write(core, &mut out, config())
            .expect("writing to a Vec cannot fail");
        if let Some(textures) = &self.textures {
            let body =
                bincode::encode_to_vec(textures, config()).expect("encoding to a Vec cannot fail");
            out.extend_from_slice(&TEXTURES_SECTION.to_le_bytes());
            out.extend_from_slice(&(body.len() as u64).to_le_bytes());
            out.extend_from_slice(&body);
        }
        out
    }

    /// Parses and checks geometry; never panics, whatever the bytes.
    pub fn decode(bytes: &[u8]) -> Result<Geometry, DecodeError> {
        let body = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or(DecodeError::BadMagic)?;
        // A byte limit stops hostile length prefixes from allocating more than the input could hold.
        let limited = config().with_limit::<{ 1 << 30 }>();
        let (core, used): (Core, usize) = bincode::decode_from_slice(body, limited)
            .map_err(|e| DecodeError::Header(e.to_string()))?;
        let mut geometry = Geometry {
            positions: core.positions,
            patches: core.patches,
            patch_objects: core.patch_objects,
            objects: core.objects,
            camera: core.camera,
            textures: None,
        };
        let mut rest = &body[used..];
        while !rest.is_empty() {
            let (tag, section, after) = split_section(rest)?;
            // Sections a viewer does not know are skipped: that is how geometry grows.
            if tag == TEXTURES_SECTION {
                if geometry.textures.is_some() {
                    return Err(DecodeError::Invalid("two texture sections".into()));
                }
                let (textures, used) = bincode::decode_from_slice(section, limited)
                    .map_err(|e| DecodeError::Header(format!("texture section: {e}")))?;
                if used != section.len() {
                    return Err(DecodeError::TrailingBytes(section.len() - used));
                }
                geometry.textures = Some(textures);
            }
            rest = after;
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
        match &self.textures {
            Some(textures) => textures.validate(patch_count, self.positions.len()),
            None => Ok(()),
        }
    }
}

impl SurfaceTextures {
    /// The factor a viewer multiplies a patch's light by at texel `texel` (linear RGB) of
    /// texture `texture`: `texel / mean` per channel, 0 where the mean is 0 (a black
    /// texture's texels are all 0).
    pub fn modulation(&self, texture: u32, texel: [f32; 3]) -> [f32; 3] {
        let mean = self.means[texture as usize];
        std::array::from_fn(|k| match mean[k] > 0.0 {
            true => texel[k] / mean[k],
            false => 0.0,
        })
    }

    fn validate(&self, patch_count: usize, position_count: usize) -> Result<(), DecodeError> {
        let counts = [
            ("patch textures", patch_count, self.patch_textures.len()),
            ("texture coordinates", position_count, self.uvs.len()),
        ];
        for (what, expected, got) in counts {
            if expected != got {
                return Err(DecodeError::Length {
                    what,
                    expected,
                    got,
                });
            }
        }
        if let Some(t) = self
            .means
            .iter()
            .position(|m| !m.iter().all(|c| c.is_finite() && *c >= 0.0))
        {
            return Err(DecodeError::Invalid(format!(
                "texture {t}'s mean {:?} is not finite and >= 0",
                self.means[t]
            )));
        }
        if let Some(p) = self
            .patch_textures
            .iter()
            .position(|&t| t != NO_TEXTURE && t as usize >= self.means.len())
        {
            return Err(DecodeError::Invalid(format!(
                "patch {p} refers to texture {} of {}",
                self.patch_textures[p],
                self.means.len()
            )));
        }
        if let Some(v) = self
            .uvs
            .iter()
            .position(|uv| !uv.iter().all(|c| c.is_finite()))
        {
            return Err(DecodeError::Invalid(format!(
                "texture coordinates of position {v} are not finite"
            )));
        }
        Ok(())
    }
}

/// Splits `bytes` into one section's tag and body and what follows it.
fn split_section(bytes: &[u8]) -> Result<(u32, &[u8], &[u8]), DecodeError> {
    let truncated = |needed: usize| DecodeError::Truncated {
        what: "geometry section",
        needed,
        got: bytes.len(),
    };
    let header: &[u8; 12] = bytes
        .get(..12)
        .and_then(|h| h.try_into().ok())
        .ok_or(truncated(12))?;
    let tag = u32::from_le_bytes(header[..4].try_into().expect("4 bytes"));
    let length = u64::from_le_bytes(header[4..].try_into().expect("8 bytes"));
    let end = usize::try_from(length)
        .ok()
        .and_then(|l| l.checked_add(12))
        .filter(|&end| end <= bytes.len())
        .ok_or(truncated(12usize.saturating_add(length as usize)))?;
    Ok((tag, &bytes[12..end], &bytes[end..]))
}
