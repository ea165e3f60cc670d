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
    let k = exposure(geometry, vertex_radiosity, emitting);
    let surface = geometry.textures.as_ref();
    let texture_of = |patch: usize| {
        surface
            .map(|s| s.patch_textures[patch])
            .filter(|&t| t != NO_TEXTURE && (t as usize) < textures.len())
    };
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut nodes) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| {
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        // Each view starts 4-byte aligned, as accessors of floats need.
        bin.resize(bin.len().next_multiple_of(4), 0);
        let target = target.map_or(String::new(), |t| format!(",\"target\":{t}"));
        views.push(format!(
            "{{\"buffer\":0,\"byteOffset\":{offset},\"byteLength\":{}{target}}}",
            bytes.len()
        ));
        views.len() - 1
    };
    let floats = |v: &[f32]| v.iter().flat_map(|f| f.to_le_bytes()).collect::<Vec<u8>>();
    for (object_index, name) in geometry.objects.iter().enumerate() {
        // One primitive per texture the object's patches show (untextured first).
        let mut groups: Vec<Option<u32>> = Vec::new();
        for (patch, object) in geometry.patch_objects.iter().enumerate() {
            if *object as usize == object_index && !groups.contains(&texture_of(patch)) {
                groups.push(texture_of(patch));
            }
        }
        groups.sort();
        let mut primitives = Vec::new();
        for group in groups {
            // This primitive's corners, renumbered from zero.
            let mut local = vec![u32::MAX; geometry.positions.len()];
            let (mut positions, mut colours, mut uvs, mut indices) =
                (Vec::new(), Vec::new(), Vec::new(), Vec::<u32>::new());
            let inverse_mean = group.map_or([1.0; 3], |t| {
                surface.map_or([1.0; 3], |s| s.modulation(t, [1.0; 3]))
            });
            for (patch, corner_ids) in geometry.patches.iter().enumerate() {
                if geometry.patch_objects[patch] as usize != object_index
                    || texture_of(patch) != group
                {
                    continue;
                }
                let ids: Vec<u32> = corners(corner_ids)
                    .iter()
                    .map(|&c| {
                        if local[c as usize] == u32::MAX {
                            local[c as usize] = positions.len() as u32;
                            positions.push(geometry.positions[c as usize]);
                            let light = vertex_radiosity
                                .get(c as usize)
                                .copied()
                                .unwrap_or_default();
                            colours.push(tone_map(
                                std::array::from_fn(|i| light[i] * inverse_mean[i]),
                                k,
                            ));
                            if let Some(s) = surface {
                                uvs.push(s.uvs[c as usize]);
                            }
                        }
                        local[c as usize]
                    })
                    .collect();
                for t in 1..ids.len() - 1 {
                    indices.extend([ids[0], ids[t], ids[t + 1]]);
                }
            }
            let (lo, hi) = positions.iter().fold(
                ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
                |(lo, hi), p| {
                    (
                        std::array::from_fn(|i| lo[i].min(p[i])),
                        std::array::from_fn(|i| hi[i].max(p[i])),
                    )
                },
            );
            let position_view = view(
                &mut bin,
                &floats(positions.as_flattened()),
                Some(ARRAY_BUFFER),
            );
            let colour_view = view(
                &mut bin,
                &floats(colours.as_flattened()),
                Some(ARRAY_BUFFER),
            );
            let index_bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
            let index_view = view(&mut bin, &index_bytes, Some(ELEMENT_ARRAY_BUFFER));
            let first = accessors.len();
            accessors.push(format!(
                "{{\"bufferView\":{position_view},\"componentType\":{FLOAT},\"count\":{},\"type\":\"VEC3\",\"min\":{lo:?},\"max\":{hi:?}}}",
                positions.len()
            ));
            accessors.push(format!("{{\"bufferView\":{colour_view},\"componentType\":{FLOAT},\"count\":{},\"type\":\"VEC3\"}}", colours.len()));
            accessors.push(format!("{{\"bufferView\":{index_view},\"componentType\":{UNSIGNED_INT},\"count\":{},\"type\":\"SCALAR\"}}", indices.len()));
            let (texcoord, material) = match group {
                Some(texture) => {
                    let uv_view = view(&mut bin, &floats(uvs.as_flattened()), Some(ARRAY_BUFFER));
                    accessors.push(format!("{{\"bufferView\":{uv_view},\"componentType\":{FLOAT},\"count\":{},\"type\":\"VEC2\"}}", uvs.len()));
                    (
                        format!(",\"TEXCOORD_0\":{}", first + 3),
                        texture as usize + 1,
                    )
                }
                None => (String::new(), 0),
            };
            primitives.push(format!(
                "{{\"attributes\":{{\"POSITION\":{first},\"COLOR_0\":{}{texcoord}}},\"indices\":{},\"material\":{material}}}",
                first + 1,
                first + 2
            ));
        }
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
    // Material 0 is untextured; material 1 + t shows texture t, an embedded PNG.
    let unlit = "\"extensions\":{\"KHR_materials_unlit\":{}}";
    let mut materials = vec![format!(
        "{{\"pbrMetallicRoughness\":{{\"metallicFactor\":0}},{unlit}}}"
    )];
    let mut images = Vec::new();
    for (t, png) in textures.iter().enumerate() {
        let image_view = view(&mut bin, png.as_ref(), None);
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
    let textures_json = match textures.is_empty() {
        true => String::new(),
        false => format!(
            ",\"images\":[{}],\"textures\":[{}],\"samplers\":[{{\"magFilter\":{NEAREST},\"minFilter\":{NEAREST},\"wrapS\":{REPEAT},\"wrapT\":{REPEAT}}}]",
            images.join(","),
            texture_list.join(",")
        ),
    };
    let node_ids: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
    let mut json = format!(
        "{{\"asset\":{{\"version\":\"2.0\",\"generator\":\"radcast\"}},\"extensionsUsed\":[\"KHR_materials_unlit\"],\"scene\":0,\"scenes\":[{{\"nodes\":[{}]}}],\"nodes\":[{}],\"meshes\":[{}],\"materials\":[{}],\"accessors\":[{}],\"bufferViews\":[{}],\"buffers\":[{{\"byteLength\":{}}}]{textures_json}}}",
        node_ids.join(","),
        nodes.join(","),
        meshes.join(","),
        materials.join(","),
        accessors.join(","),
        views.join(","),
        bin.len()
    )
    .into_bytes();
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
