//! The scene with its current colours as binary glTF 2.0 (`GET /api/scene.glb`), for Blender,
//! three.js and other viewers: one named mesh per object (a primitive per texture it shows),
//! tone-mapped vertex colours, textures embedded.
//!
//! Layout per the glTF 2.0 specification, section "GLB File Format Specification": a 12-byte
//! header, a JSON chunk padded with spaces and a BIN chunk padded with zeros, each to 4 bytes.

use crate::Geometry;
use crate::display::{corners, exposure, tone_map};
use crate::geometry::NO_TEXTURE;
use std::fmt::Write;

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const NEAREST: u32 = 9728;
const REPEAT: u32 = 10497;

/// JSON string literal for `text` (quotes and control characters escaped).
fn json_string(text: &str) -> String {
    let mut out = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Encodes `geometry` with per-vertex radiosity (W/m^2) as a GLB file; `textures` are the PNGs
/// its texture section names (`/api/textures/{index}`), embedded; `emitting[o]` whether object
/// `o` emits (left out of the exposure, [`crate::display`]).
///
/// Every primitive is unlit (`KHR_materials_unlit`): `COLOR_0` is the tone-mapped light. A
/// textured primitive's `COLOR_0` is the light divided by its texture's mean (what a white texel
/// would show), and its material's `baseColorTexture` multiplies it back: exact where the tone
/// map is linear, darker than the headless client's per-pixel tone map only near white.
pub fn encode_glb(
    geometry: &Geometry,
    textures: &[impl AsRef<[u8]>],
    emitting: &[bool],
    vertex_radiosity: &[[f32; 3]],
) -> Vec<u8> {
    let shading = Shading {
        geometry,
        vertex_radiosity,
        exposure: exposure(geometry, vertex_radiosity, emitting),
        textures: textures.len(),
    };
    let mut buffer = Buffer::default();
    let (mut meshes, mut nodes) = (Vec::new(), Vec::new());
    for (object, name) in geometry.objects.iter().enumerate() {
        let primitives: Vec<String> = shading
            .texture_groups(object)
            .into_iter()
            .map(|group| buffer.primitive(&shading.primitive(object, group), group))
            .collect();
        if primitives.is_empty() {
            continue;
        }
        meshes.push(format!(
            "{{\"name\":{},\"primitives\":[{}]}}",
            json_string(name),
            primitives.join(",")
        ));
        nodes.push(format!(
            "{{\"name\":{},\"mesh\":{}}}",
            json_string(name),
            meshes.len() - 1
        ));
    }
    let (materials, textures_json) = buffer.materials(textures);
    let node_ids: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
    let json = format!(
        "{{\"asset\":{{\"version\":\"2.0\",\"generator\":\"radcast\"}},\"extensionsUsed\":[\"KHR_materials_unlit\"],\"scene\":0,\"scenes\":[{{\"nodes\":[{}]}}],\"nodes\":[{}],\"meshes\":[{}],\"materials\":[{}],\"accessors\":[{}],\"bufferViews\":[{}],\"buffers\":[{{\"byteLength\":{}}}]{textures_json}}}",
        node_ids.join(","),
        nodes.join(","),
        meshes.join(","),
        materials.join(","),
        buffer.accessors.join(","),
        buffer.views.join(","),
        buffer.bin.len()
    );
    glb_container(json.into_bytes(), buffer.bin)
}

/// What colours a primitive's vertices.
struct Shading<'a> {
    geometry: &'a Geometry,
    vertex_radiosity: &'a [[f32; 3]],
    /// The tone map's exposure ([`crate::display::exposure`]).
    exposure: f32,
    /// Textures embedded.
    textures: usize,
}

/// One primitive's vertices (renumbered from zero) and triangles.
#[derive(Default)]
struct Primitive {
    positions: Vec<[f32; 3]>,
    colours: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    indices: Vec<u32>,
}

impl Shading<'_> {
    /// The texture `patch` shows, if one is embedded.
    fn texture_of(&self, patch: usize) -> Option<u32> {
        self.geometry
            .textures
            .as_ref()
            .map(|s| s.patch_textures[patch])
            .filter(|&t| t != NO_TEXTURE && (t as usize) < self.textures)
    }

    /// The textures `object`'s patches show, a primitive each (untextured first).
    fn texture_groups(&self, object: usize) -> Vec<Option<u32>> {
        let mut groups: Vec<Option<u32>> = Vec::new();
        for (patch, o) in self.geometry.patch_objects.iter().enumerate() {
            if *o as usize == object && !groups.contains(&self.texture_of(patch)) {
                groups.push(self.texture_of(patch));
            }
        }
        groups.sort();
        groups
    }

    /// The primitive of `object`'s patches that show `group`.
    fn primitive(&self, object: usize, group: Option<u32>) -> Primitive {
        let geometry = self.geometry;
        let surface = geometry.textures.as_ref();
        let mut local = vec![u32::MAX; geometry.positions.len()];
        let mut primitive = Primitive::default();
        let inverse_mean = group.map_or([1.0; 3], |t| {
            surface.map_or([1.0; 3], |s| s.modulation(t, [1.0; 3]))
        });
        for (patch, corner_ids) in geometry.patches.iter().enumerate() {
            if geometry.patch_objects[patch] as usize != object || self.texture_of(patch) != group {
                continue;
            }
            let ids: Vec<u32> = corners(corner_ids)
                .iter()
                .map(|&c| {
                    if local[c as usize] == u32::MAX {
                        local[c as usize] = primitive.positions.len() as u32;
                        primitive.positions.push(geometry.positions[c as usize]);
                        let light = self
                            .vertex_radiosity
                            .get(c as usize)
                            .copied()
                            .unwrap_or_default();
                        primitive.colours.push(tone_map(
                            std::array::from_fn(|i| light[i] * inverse_mean[i]),
                            self.exposure,
                        ));
                        if let Some(s) = surface {
                            primitive.uvs.push(s.uvs[c as usize]);
                        }
                    }
                    local[c as usize]
                })
                .collect();
            for t in 1..ids.len() - 1 {
                primitive.indices.extend([ids[0], ids[t], ids[t + 1]]);
            }
        }
        primitive
    }
}

/// The BIN chunk as it grows, with the buffer views and accessors into it.
#[derive(Default)]
struct Buffer {
    bin: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl Buffer {
    /// Appends `bytes` as a buffer view; returns its index.
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        // Each view starts 4-byte aligned, as accessors of floats need.
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let target = target.map_or(String::new(), |t| format!(",\"target\":{t}"));
        self.views.push(format!(
            "{{\"buffer\":0,\"byteOffset\":{offset},\"byteLength\":{}{target}}}",
            bytes.len()
        ));
        self.views.len() - 1
    }

    /// Appends `values` as a view and an accessor of `count` elements of `kind`; returns the
    /// accessor's index.
    fn floats(&mut self, values: &[f32], count: usize, kind: &str, bounds: &str) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|f| f.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ARRAY_BUFFER));
        self.accessors.push(format!(
            "{{\"bufferView\":{view},\"componentType\":{FLOAT},\"count\":{count},\"type\":\"{kind}\"{bounds}}}"
        ));
        self.accessors.len() - 1
    }

    /// Appends `primitive`'s attributes and indices; returns its JSON (material 0 untextured,
    /// `1 + t` for texture `t`).
    fn primitive(&mut self, primitive: &Primitive, group: Option<u32>) -> String {
        let (lo, hi) = primitive.positions.iter().fold(
            ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
            |(lo, hi), p| {
                (
                    std::array::from_fn(|i| lo[i].min(p[i])),
                    std::array::from_fn(|i| hi[i].max(p[i])),
                )
            },
        );
        let bounds = format!(",\"min\":{lo:?},\"max\":{hi:?}");
        let count = primitive.positions.len();
        let position = self.floats(primitive.positions.as_flattened(), count, "VEC3", &bounds);
        let colour = self.floats(primitive.colours.as_flattened(), count, "VEC3", "");
        let index_bytes: Vec<u8> = primitive
            .indices
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let index_view = self.view(&index_bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(format!(
            "{{\"bufferView\":{index_view},\"componentType\":{UNSIGNED_INT},\"count\":{},\"type\":\"SCALAR\"}}",
            primitive.indices.len()
        ));
        let indices = self.accessors.len() - 1;
        let (texcoord, material) = match group {
            Some(texture) => {
                let uvs = primitive.uvs.as_flattened();
                let uv = self.floats(uvs, primitive.uvs.len(), "VEC2", "");
                (format!(",\"TEXCOORD_0\":{uv}"), texture as usize + 1)
            }
            None => (String::new(), 0),
        };
        format!(
            "{{\"attributes\":{{\"POSITION\":{position},\"COLOR_0\":{colour}{texcoord}}},\"indices\":{indices},\"material\":{material}}}"
        )
    }

    /// The materials (0 untextured, `1 + t` showing texture `t`, an embedded PNG) and the
    /// images, textures and sampler JSON that follows the buffers (empty without textures).
    fn materials(&mut self, textures: &[impl AsRef<[u8]>]) -> (Vec<String>, String) {
        let unlit = "\"extensions\":{\"KHR_materials_unlit\":{}}";
        let mut materials = vec![format!(
            "{{\"pbrMetallicRoughness\":{{\"metallicFactor\":0}},{unlit}}}"
        )];
        let mut images = Vec::new();
        for (t, png) in textures.iter().enumerate() {
            let image_view = self.view(png.as_ref(), None);
            images.push(format!(
                "{{\"bufferView\":{image_view},\"mimeType\":\"image/png\"}}"
            ));
            materials.push(format!(
                "{{\"pbrMetallicRoughness\":{{\"baseColorTexture\":{{\"index\":{t}}},\"metallicFactor\":0}},{unlit}}}"
            ));
        }
        let texture_list: Vec<String> = (0..textures.len())
            .map(|t| format!("{{\"source\":{t},\"sampler\":0}}"))
            .collect();
        // Nearest texels, repeating: what the headless client and the browser show.
        let json = match textures.is_empty() {
            true => String::new(),
            false => format!(
                ",\"images\":[{}],\"textures\":[{}],\"samplers\":[{{\"magFilter\":{NEAREST},\"minFilter\":{NEAREST},\"wrapS\":{REPEAT},\"wrapT\":{REPEAT}}}]",
                images.join(","),
                texture_list.join(",")
            ),
        };
        (materials, json)
    }
}

/// The GLB file: the 12-byte header, then the JSON chunk padded with spaces and the BIN chunk
/// padded with zeros, each to 4 bytes.
fn glb_container(mut json: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    json.resize(json.len().next_multiple_of(4), b' ');
    bin.resize(bin.len().next_multiple_of(4), 0);
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    for word in [GLB_MAGIC, 2, total as u32, json.len() as u32, CHUNK_JSON] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    out.extend_from_slice(&bin);
    out
}
