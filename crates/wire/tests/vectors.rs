//! Cross-language conformance: every message kind, compressed and not, and hostile variants,
//! written by this crate into `tests/vectors/` with what each decodes to
//! (`tests/vectors/expected.json`). This test holds the Rust encoder and decoder to the
//! checked-in files; `crates/server/web/protocol.test.mjs` holds the JavaScript decoder to the
//! same files. After a deliberate protocol change: `RADCAST_WRITE_VECTORS=1 cargo test -p
//! radcast-wire --test vectors`, then review the diff.

use serde_json::{Value, json};
use std::path::PathBuf;
use wire::*;

fn folder() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../tests/vectors"))
}

fn info(version: u64, vertex_count: u32, scale: f32, is_final: bool) -> FrameInfo {
    FrameInfo {
        solution_version: version,
        sent_at_unix_micros: 1_764_000_000_000_000 + version,
        scale,
        vertex_count,
        is_final,
    }
}

/// What a decoded message is, as the JavaScript test reads it (u64s as decimal strings).
fn describe(message: &ServerMessage) -> Value {
    let frame = |info: &FrameInfo| {
        json!({
            "solution_version": info.solution_version.to_string(),
            "sent_at": info.sent_at_unix_micros.to_string(),
            "scale": info.scale,
            "vertex_count": info.vertex_count,
            "is_final": info.is_final,
        })
    };
    match message {
        ServerMessage::Hello(h) => json!({
            "kind": "hello",
            "protocol_version": h.protocol_version,
            "scene_id": h.scene_id.to_string(),
            "geometry_version": h.geometry_version.to_string(),
            "vertex_count": h.vertex_count,
        }),
        ServerMessage::Full(f) => json!({
            "kind": "full",
            "info": frame(&f.info),
            "colours": f.colours,
            "checksum": checksum(&f.colours),
            "radiosity_of_first": decode_colour(f.colours[0], f.info.scale),
        }),
        ServerMessage::Delta(d) => json!({
            "kind": "delta",
            "base_version": d.base_version.to_string(),
            "info": frame(&d.info),
            "indices": d.indices,
            "colours": d.colours,
        }),
        ServerMessage::GeometryChanged { geometry_version } => json!({
            "kind": "geometry-changed",
            "geometry_version": geometry_version.to_string(),
        }),
        ServerMessage::Response(r) => json!({
            "kind": "response",
            "response_id": r.response_id,
            "scale": r.scale,
            "vertex_count": r.codes.len(),
            "codes": r.codes,
        }),
        ServerMessage::Sum(sum) => json!({
            "kind": "sum",
            "info": frame(&sum.info),
            "terms": sum.terms.iter().map(|t| json!({
                "response_id": t.response_id,
                "weight": t.weight,
            })).collect::<Vec<_>>(),
        }),
    }
}

/// Two responses of 600 vertices and the sum of them that `sum-final` carries: what a viewer
/// must compute from the three files, value for value and checksum.
fn response_values(id: u32) -> Vec<[f32; 3]> {
    (0..600)
        .map(|i| {
            let x = i as f32 / 600.0;
            match id {
                1 => [0.9 * x, 0.5 * x * x, 0.05],
                _ => [1e-6 * (1.0 + x), 0.3 - 0.2 * x, 1.7 * (1.0 - x)],
            }
        })
        .collect()
}

fn sum_terms() -> Vec<responses::Term> {
    vec![
        responses::Term {
            response_id: 1,
            weight: [17.0, 12.0, 4.0],
        },
        responses::Term {
            response_id: 2,
            weight: [0.0, 3.5, 1e-3],
        },
    ]
}

fn describe_geometry(g: &Geometry) -> Value {
    json!({
        "positions": g.positions,
        "patches": g.patches,
        "patch_objects": g.patch_objects,
        "objects": g.objects,
        "camera": g.camera.map(|c| json!({
            "eye": c.eye, "target": c.target, "up": c.up,
            "vertical_fov_degrees": c.vertical_fov_degrees,
        })),
        "textures": g.textures.as_ref().map(|t| json!({
            "means": t.means, "patch_textures": t.patch_textures, "uvs": t.uvs,
        })),
    })
}

/// Every vector: (file stem, bytes, what it must decode to — or `"refused"`).
fn vectors() -> Vec<(&'static str, Vec<u8>, Value)> {
    let smooth: Vec<u32> = (0..600)
        .map(|i| encode_colour([1.0 + (i / 100) as f32, 0.5, 0.25], 1.0))
        .collect();
    let noisy: Vec<u32> = (0..64u32)
        .map(|i| i.wrapping_mul(2_654_435_761) ^ 0x5bd1_e995)
        .collect();
    let messages = [
        (
            "hello",
            ServerMessage::Hello(Hello {
                protocol_version: PLAIN_PROTOCOL_VERSION,
                scene_id: 0xfedc_ba98_7654_3210,
                geometry_version: 3,
                vertex_count: 600,
            }),
        ),
        (
            "hello-3",
            ServerMessage::Hello(Hello {
                protocol_version: PROTOCOL_VERSION,
                scene_id: 0xfedc_ba98_7654_3210,
                geometry_version: 3,
                vertex_count: 600,
            }),
        ),
        (
            "response-lz4",
            ServerMessage::Response(responses::Response::quantise(1, &response_values(1))),
        ),
        (
            "response-raw",
            ServerMessage::Response(responses::Response {
                response_id: 9,
                scale: 2.0f32.powi(-20),
                codes: noisy.clone(),
            }),
        ),
        (
            "response-2",
            ServerMessage::Response(responses::Response::quantise(2, &response_values(2))),
        ),
        (
            "sum-final",
            ServerMessage::Sum(responses::SumFrame {
                info: info(9, 600, 1.0, true),
                terms: sum_terms(),
            }),
        ),
        (
            "sum-empty",
            ServerMessage::Sum(responses::SumFrame {
                info: info(10, 600, 1.0, false),
                terms: vec![],
            }),
        ),
        (
            "full-lz4",
            ServerMessage::Full(FullFrame {
                info: info(5, 600, 0.25, true),
                colours: smooth.clone(),
            }),
        ),
        (
            "full-raw",
            ServerMessage::Full(FullFrame {
                info: info(6, 64, 2.0f32.powi(-20), false),
                colours: noisy,
            }),
        ),
        (
            "delta-raw",
            ServerMessage::Delta(DeltaFrame {
                base_version: 5,
                info: info(6, 600, 0.25, false),
                indices: vec![0, 1, 200, 599],
                colours: vec![7, 0x7fff_ffff, 9, 0],
            }),
        ),
        (
            "delta-lz4",
            ServerMessage::Delta(DeltaFrame {
                base_version: 6,
                info: info(7, 600, 0.25, true),
                indices: (100..400).collect(),
                colours: vec![smooth[0]; 300],
            }),
        ),
        (
            "delta-empty-final",
            ServerMessage::Delta(DeltaFrame {
                base_version: 7,
                info: info(8, 600, 0.25, true),
                indices: vec![],
                colours: vec![],
            }),
        ),
        (
            "geometry-changed",
            ServerMessage::GeometryChanged {
                geometry_version: 4,
            },
        ),
    ];
    let mut out: Vec<(&'static str, Vec<u8>, Value)> = messages
        .iter()
        .map(|(name, m)| (*name, m.encode(), describe(m)))
        .collect();
    let geometry = Geometry {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.5],
        ],
        patches: vec![[0, 1, 2, 3], [0, 2, 3, geometry::NO_CORNER]],
        patch_objects: vec![0, 1],
        objects: vec!["floor".into(), "lämp".into()],
        camera: Some(Camera {
            eye: [0.5, 0.5, -2.0],
            target: [0.5, 0.5, 0.0],
            up: [0.0, 1.0, 0.0],
            vertical_fov_degrees: 39.3,
        }),
        textures: None,
    };
    out.push(("geometry", geometry.encode(), describe_geometry(&geometry)));
    let bare = Geometry {
        camera: None,
        ..geometry.clone()
    };
    out.push((
        "geometry-no-camera",
        bare.encode(),
        describe_geometry(&bare),
    ));
    let textured = Geometry {
        textures: Some(geometry::SurfaceTextures {
            means: vec![[0.25, 0.5, 0.125]],
            patch_textures: vec![0, geometry::NO_TEXTURE],
            uvs: vec![[0.0, 1.0], [2.0, 1.0], [2.0, -1.0], [0.0, -1.0]],
        }),
        ..bare.clone()
    };
    out.push((
        "geometry-textured",
        textured.encode(),
        describe_geometry(&textured),
    ));
    // A section this version does not know (tag 99) is skipped.
    let mut unknown = textured.encode();
    unknown.extend(99u32.to_le_bytes());
    unknown.extend(3u64.to_le_bytes());
    unknown.extend([1, 2, 3]);
    out.push((
        "geometry-unknown-section",
        unknown,
        describe_geometry(&textured),
    ));
    // What a viewer holding responses 1 and 2 shows for `sum-final`: not a file of its own.
    let mut held = responses::Responses::default();
    for id in [1, 2] {
        held.insert(&responses::Response::quantise(id, &response_values(id)));
    }
    let sum = responses::SumFrame {
        info: info(9, 600, 1.0, true),
        terms: sum_terms(),
    };
    let shown = held.evaluate(&sum).expect("both responses held");
    out.push((
        "evaluation",
        vec![],
        json!({
            "responses": ["response-lz4", "response-2"],
            "sum": "sum-final",
            "values": shown,
            "sum_checksum": responses::sum_checksum(&shown),
        }),
    ));
    out.push((
        "request-full",
        ClientMessage::RequestFull.encode(),
        json!({"kind": "request-full"}),
    ));
    // Hostile variants of the above: each must be refused by every decoder.
    let bytes = |name: &str| out.iter().find(|v| v.0 == name).unwrap().1.clone();
    let mut refused = vec![];
    let mut old_version = bytes("hello");
    old_version[2] = 1;
    refused.push(("refused-hello-version-1", old_version));
    let mut new_version = bytes("hello-3");
    new_version[2] = 4;
    refused.push(("refused-hello-version-4", new_version));
    let sum = bytes("sum-final");
    refused.push(("refused-sum-truncated", sum[..sum.len() - 1].to_vec()));
    let mut nan_weight = sum.clone();
    let weight = sum.len() - 4; // the last term's blue weight
    nan_weight[weight..].copy_from_slice(&f32::NAN.to_le_bytes());
    refused.push(("refused-sum-weight-nan", nan_weight));
    let mut negative_weight = sum.clone();
    negative_weight[weight..].copy_from_slice(&(-1f32).to_le_bytes());
    refused.push(("refused-sum-weight-negative", negative_weight));
    let mut too_many = bytes("sum-empty");
    too_many[22..26].copy_from_slice(&65u32.to_le_bytes()); // term_count past the limit
    refused.push(("refused-sum-too-many-terms", too_many));
    let mut final_response = bytes("response-raw");
    final_response[1] |= 2; // a response has no final flag
    refused.push(("refused-response-final-flag", final_response));
    let mut response_scale = bytes("response-raw");
    response_scale[6..10].copy_from_slice(&0f32.to_le_bytes());
    refused.push(("refused-response-scale-zero", response_scale));
    let full = bytes("full-raw");
    refused.push(("refused-full-truncated", full[..full.len() - 1].to_vec()));
    let mut zero_scale = full.clone();
    zero_scale[18..22].copy_from_slice(&0f32.to_le_bytes());
    refused.push(("refused-full-scale-zero", zero_scale));
    let mut huge_scale = full.clone();
    huge_scale[18..22].copy_from_slice(&1e34f32.to_le_bytes());
    refused.push(("refused-full-scale-overflows", huge_scale));
    let mut flags = full;
    flags[1] |= 0x80;
    refused.push(("refused-unknown-flags", flags));
    let mut past_end = bytes("delta-raw");
    past_end[30..34].copy_from_slice(&599u32.to_le_bytes()); // vertex_count 599: index 599 is out
    refused.push(("refused-delta-index-out-of-range", past_end));
    let lz4 = bytes("full-lz4");
    refused.push(("refused-lz4-truncated", lz4[..lz4.len() - 3].to_vec()));
    refused.push(("refused-unknown-kind", vec![9, 0]));
    let mut geometry_bad = bytes("geometry");
    let last = geometry_bad.len() - 1 - 40; // the camera tag
    geometry_bad[last] = 7;
    refused.push(("refused-geometry-camera-tag", geometry_bad));
    let textured = bytes("geometry-textured");
    refused.push((
        "refused-geometry-section-truncated",
        textured[..textured.len() - 1].to_vec(),
    ));
    let mut foreign_texture = textured.clone();
    // The first patch's texture index: before the uvs (u64 count, 4 × 8 bytes) and patch 1's.
    let patch_texture = textured.len() - 4 * 8 - 8 - 4 - 4;
    foreign_texture[patch_texture..patch_texture + 4].copy_from_slice(&1u32.to_le_bytes());
    refused.push(("refused-geometry-texture-out-of-range", foreign_texture));
    out.extend(
        refused
            .into_iter()
            .map(|(name, b)| (name, b, Value::from("refused"))),
    );
    out
}

/// Vectors decoded as `/api/scene` geometry rather than as WebSocket messages.
fn is_geometry(name: &str) -> bool {
    name.starts_with("geometry") && name != "geometry-changed"
}

#[test]
fn the_checked_in_vectors_are_what_this_crate_writes_and_reads() {
    let vectors = vectors();
    let expected: serde_json::Map<String, Value> = vectors
        .iter()
        .map(|(name, _, value)| (name.to_string(), value.clone()))
        .collect();
    if std::env::var_os("RADCAST_WRITE_VECTORS").is_some() {
        std::fs::create_dir_all(folder()).unwrap();
        for (name, bytes, _) in vectors.iter().filter(|v| v.0 != "evaluation") {
            std::fs::write(folder().join(format!("{name}.bin")), bytes).unwrap();
        }
        let text = serde_json::to_string_pretty(&Value::Object(expected.clone())).unwrap();
        std::fs::write(folder().join("expected.json"), text + "\n").unwrap();
    }
    let checked_in: Value = serde_json::from_str(
        &std::fs::read_to_string(folder().join("expected.json"))
            .expect("tests/vectors/expected.json"),
    )
    .unwrap();
    assert_eq!(
        checked_in,
        Value::Object(expected),
        "expected.json is stale"
    );
    for (name, bytes, value) in vectors.iter().filter(|v| v.0 != "evaluation") {
        let file = std::fs::read(folder().join(format!("{name}.bin"))).expect(name);
        assert_eq!(&file, bytes, "{name}.bin is not what the encoder writes");
        // And the Rust decoders read the files to the same values.
        let decoded = if is_geometry(name) {
            Geometry::decode(&file).map(|g| describe_geometry(&g)).ok()
        } else if *name == "request-full" {
            ClientMessage::decode(&file)
                .ok()
                .map(|_| json!({"kind": "request-full"}))
        } else {
            ServerMessage::decode(&file).map(|m| describe(&m)).ok()
        };
        let refused = name.starts_with("refused");
        let refused_everywhere = ServerMessage::decode(&file).is_err()
            && Geometry::decode(&file).is_err()
            && ClientMessage::decode(&file).is_err();
        match refused {
            true => assert!(refused_everywhere, "{name} decodes"),
            false => assert_eq!(decoded.as_ref(), Some(value), "{name}"),
        }
    }
}

#[test]
fn the_sum_a_viewer_makes_of_the_checked_in_responses_is_the_expected_one() {
    let expected: Value = serde_json::from_str(
        &std::fs::read_to_string(folder().join("expected.json")).expect("expected.json"),
    )
    .unwrap();
    let evaluation = &expected["evaluation"];
    let read = |name: &Value| {
        let file = folder().join(format!("{}.bin", name.as_str().unwrap()));
        ServerMessage::decode(&std::fs::read(file).unwrap()).unwrap()
    };
    let mut buffer = ColourBuffer::default();
    for name in evaluation["responses"].as_array().unwrap() {
        buffer.apply(&read(name)).unwrap();
    }
    buffer.apply(&read(&evaluation["sum"])).unwrap();
    let shown = buffer.radiosity();
    assert_eq!(serde_json::to_value(&shown).unwrap(), evaluation["values"]);
    assert_eq!(
        Value::from(responses::sum_checksum(&shown)),
        evaluation["sum_checksum"]
    );
}
