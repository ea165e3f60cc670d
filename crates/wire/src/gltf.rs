//! The scene with its current colours as binary glTF 2.0 (`GET /api/scene.glb`), for Blender,
//! three.js and other viewers: one named mesh per object, tone-mapped vertex colours.
//!
//! Layout per the glTF 2.0 specification, section "GLB File Format Specification": a 12-byte
//! header, a JSON chunk padded with spaces and a BIN chunk padded with zeros, each to 4 bytes.

use crate::Geometry;
use crate::display::{corners, exposure, tone_map};
use std::fmt::Write;

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

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

/// Encodes `geometry` with per-vertex radiosity (W/m^2) as a GLB file.
pub fn encode_glb(geometry: &Geometry, vertex_radiosity: &[[f32; 3]]) -> Vec<u8> {
    let k = exposure(geometry, vertex_radiosity);
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut nodes) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut view = |bin: &mut Vec<u8>, bytes: Vec<u8>, target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(&bytes);
        views.push(format!(
            "{{\"buffer\":0,\"byteOffset\":{offset},\"byteLength\":{},\"target\":{target}}}",
            bytes.len()
        ));
        views.len() - 1
    };
    for (object_index, name) in geometry.objects.iter().enumerate() {
        // This object's corners, renumbered from zero.
        let mut local = vec![u32::MAX; geometry.positions.len()];
        let (mut positions, mut colours, mut indices) = (Vec::new(), Vec::new(), Vec::<u32>::new());
        for (patch, _) in geometry
            .patches
            .iter()
            .zip(&geometry.patch_objects)
            .filter(|(_, o)| **o as usize == object_index)
        {
            let ids: Vec<u32> = corners(patch)
                .iter()
                .map(|&c| {
                    if local[c as usize] == u32::MAX {
                        local[c as usize] = positions.len() as u32;
                        positions.push(geometry.positions[c as usize]);
                        colours.push(tone_map(
                            vertex_radiosity
                                .get(c as usize)
                                .copied()
                                .unwrap_or_default(),
                            k,
                        ));
                    }
                    local[c as usize]
                })
                .collect();
            for t in 1..ids.len() - 1 {
                indices.extend([ids[0], ids[t], ids[t + 1]]);
            }
        }
        if indices.is_empty() {
            continue;
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
        let floats = |v: &[[f32; 3]]| {
            v.iter()
                .flatten()
                .flat_map(|f| f.to_le_bytes())
                .collect::<Vec<u8>>()
        };
        let position_view = view(&mut bin, floats(&positions), ARRAY_BUFFER);
        let colour_view = view(&mut bin, floats(&colours), ARRAY_BUFFER);
        let index_view = view(
            &mut bin,
            indices.iter().flat_map(|i| i.to_le_bytes()).collect(),
            ELEMENT_ARRAY_BUFFER,
        );
        let first = accessors.len();
        accessors.push(format!(
            "{{\"bufferView\":{position_view},\"componentType\":{FLOAT},\"count\":{},\"type\":\"VEC3\",\"min\":{lo:?},\"max\":{hi:?}}}",
            positions.len()
        ));
        accessors.push(format!("{{\"bufferView\":{colour_view},\"componentType\":{FLOAT},\"count\":{},\"type\":\"VEC3\"}}", colours.len()));
        accessors.push(format!("{{\"bufferView\":{index_view},\"componentType\":{UNSIGNED_INT},\"count\":{},\"type\":\"SCALAR\"}}", indices.len()));
        meshes.push(format!(
            "{{\"name\":{},\"primitives\":[{{\"attributes\":{{\"POSITION\":{first},\"COLOR_0\":{}}},\"indices\":{}}}]}}",
            json_string(name),
            first + 1,
            first + 2
        ));
        nodes.push(format!(
            "{{\"name\":{},\"mesh\":{}}}",
            json_string(name),
            meshes.len() - 1
        ));
    }
    let node_ids: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
    let mut json = format!(
        "{{\"asset\":{{\"version\":\"2.0\",\"generator\":\"radcast\"}},\"scene\":0,\"scenes\":[{{\"nodes\":[{}]}}],\"nodes\":[{}],\"meshes\":[{}],\"accessors\":[{}],\"bufferViews\":[{}],\"buffers\":[{{\"byteLength\":{}}}]}}",
        node_ids.join(","),
        nodes.join(","),
        meshes.join(","),
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
