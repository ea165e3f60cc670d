//! Round trips and hostile bytes for every message.

use proptest::prelude::*;
use wire::frame::{FLAG_COMPRESSED, MAX_VERTICES};
use wire::*;

fn info(version: u64, vertex_count: u32, is_final: bool) -> FrameInfo {
    FrameInfo {
        solution_version: version,
        sent_at_unix_micros: version.wrapping_add(1_700_000_000_000_000),
        scale: 0.5,
        vertex_count,
        is_final,
    }
}

fn full(colours: Vec<u32>) -> ServerMessage {
    ServerMessage::Full(FullFrame {
        info: info(7, colours.len() as u32, true),
        colours,
    })
}

#[test]
fn hello_round_trips_and_other_versions_are_refused() {
    let hello = Hello {
        protocol_version: PROTOCOL_VERSION,
        scene_id: 42,
        geometry_version: 3,
        vertex_count: 600,
    };
    let bytes = ServerMessage::Hello(hello).encode();
    assert_eq!(bytes.len(), 2 + 2 + 8 + 8 + 4);
    assert_eq!(
        ServerMessage::decode(&bytes),
        Ok(ServerMessage::Hello(hello))
    );
    let future = ServerMessage::Hello(Hello {
        protocol_version: 99,
        ..hello
    })
    .encode();
    assert_eq!(
        ServerMessage::decode(&future),
        Err(DecodeError::UnsupportedVersion {
            got: 99,
            supported: PROTOCOL_VERSION
        })
    );
}

#[test]
fn geometry_changes_round_trip() {
    let message = ServerMessage::GeometryChanged {
        geometry_version: 7,
    };
    let bytes = message.encode();
    assert_eq!(bytes, [4, 0, 7, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(ServerMessage::decode(&bytes), Ok(message));
    assert!(ServerMessage::decode(&bytes[..9]).is_err());
}

#[test]
fn uniform_frames_compress_and_noisy_ones_do_not() {
    let uniform = full(vec![0x1234_5678; 10_000]).encode();
    assert_ne!(uniform[1] & FLAG_COMPRESSED, 0);
    assert!(uniform.len() < 1_000, "{} bytes", uniform.len());
    let noisy: Vec<u32> = (0..10_000u32)
        .map(|i| i.wrapping_mul(2_654_435_761))
        .collect();
    let bytes = full(noisy.clone()).encode();
    assert_eq!(bytes[1] & FLAG_COMPRESSED, 0);
    assert_eq!(bytes.len(), 2 + 24 + 40_000);
    assert_eq!(ServerMessage::decode(&bytes), Ok(full(noisy)));
}

#[test]
fn truncation_anywhere_is_an_error_not_a_panic() {
    let delta = ServerMessage::Delta(DeltaFrame {
        base_version: 1,
        info: info(2, 1000, false),
        indices: vec![0, 5, 999],
        colours: vec![1, 2, 3],
    });
    for message in [full((0..100).collect()), delta] {
        let bytes = message.encode();
        for cut in 0..bytes.len() {
            assert!(
                ServerMessage::decode(&bytes[..cut]).is_err(),
                "cut at {cut}"
            );
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(ServerMessage::decode(&longer).is_err());
    }
}

#[test]
fn hostile_sizes_and_indices_are_refused() {
    // A full frame claiming 2^26 + 1 vertices.
    let mut bytes = full(vec![0; 4]).encode();
    bytes[2 + 20..2 + 24].copy_from_slice(&(MAX_VERTICES + 1).to_le_bytes());
    assert_eq!(
        ServerMessage::decode(&bytes),
        Err(DecodeError::TooLarge {
            what: "vertex count",
            size: MAX_VERTICES as u64 + 1,
            limit: MAX_VERTICES as u64
        })
    );
    // A delta whose index is past the end.
    let delta = DeltaFrame {
        base_version: 1,
        info: info(2, 10, false),
        indices: vec![3, 12],
        colours: vec![1, 2],
    };
    let bytes = ServerMessage::Delta(delta).encode();
    assert_eq!(
        ServerMessage::decode(&bytes),
        Err(DecodeError::IndexOutOfRange {
            index: 12,
            vertex_count: 10
        })
    );
    // A compressed payload that claims to inflate past what the header allows.
    let mut bytes = full(vec![7; 1000]).encode();
    assert_ne!(bytes[1] & FLAG_COMPRESSED, 0);
    bytes[26..30].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        ServerMessage::decode(&bytes),
        Err(DecodeError::TooLarge {
            what: "uncompressed payload",
            ..
        })
    ));
    assert_eq!(
        ServerMessage::decode(&[9, 0]),
        Err(DecodeError::UnknownKind(9))
    );
    assert_eq!(
        ServerMessage::decode(&[2, 0x80]),
        Err(DecodeError::UnknownFlags(0x80))
    );
    assert_eq!(
        ClientMessage::decode(b"hello"),
        Err(DecodeError::UnknownKind(b'h'))
    );
}

#[test]
fn buffers_follow_full_and_delta_frames_and_refuse_foreign_bases() {
    let old: Vec<u32> = (0..50).collect();
    let mut new = old.clone();
    new[3] = 99;
    new[49] = 7;
    let (indices, colours) = changes(&old, &new);
    assert_eq!(indices, [3, 49]);
    let mut buffer = ColourBuffer::default();
    let delta = ServerMessage::Delta(DeltaFrame {
        base_version: 7,
        info: info(8, 50, true),
        indices,
        colours,
    });
    assert_eq!(
        buffer.apply(&delta),
        Err(ApplyError::BaseMismatch {
            base: 7,
            held: None
        })
    );
    buffer.apply(&full(old)).unwrap();
    buffer.apply(&delta).unwrap();
    assert_eq!(buffer.colours, new);
    assert_eq!(checksum(&buffer.colours), checksum(&new));
    assert_ne!(
        checksum(&buffer.colours),
        checksum(&(0..50).collect::<Vec<_>>())
    );
}

#[test]
fn checksum_is_zlib_crc32_of_little_endian_codes() {
    // crc32(b"\x01\x00\x00\x00\x02\x00\x00\x00") from zlib.
    assert_eq!(checksum(&[1, 2]), 0x0381_177C);
}

#[test]
fn scaled_colours_keep_hdr_range_and_the_relative_bound() {
    let brightest = 1e6f32;
    let scale = scale_for(brightest);
    assert!(brightest / scale <= rgb9e5::MAX_VALUE && brightest / scale > rgb9e5::MAX_VALUE / 2.0);
    for rgb in [[1e6, 5e5, 1.0], [1e-3, 2e-3, 0.0], [17.0, 12.0, 4.0]] {
        let back = decode_colour(encode_colour(rgb, scale), scale);
        let max = rgb.iter().cloned().fold(0.0, f32::max);
        for (a, b) in rgb.iter().zip(back) {
            assert!(
                (a - b).abs() <= rgb9e5::RELATIVE_ERROR_BOUND * max,
                "{rgb:?} -> {back:?}"
            );
        }
    }
    assert_eq!(scale_for(0.0), 1.0);
    assert_eq!(scale_for(f32::NAN), 1.0);
}

#[test]
fn geometry_round_trips_and_bad_geometry_is_refused() {
    let geometry = Geometry {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        patches: vec![[0, 1, 2, 3], [0, 1, 2, geometry::NO_CORNER]],
        patch_objects: vec![0, 1],
        objects: vec!["floor".into(), "wall".into()],
        camera: Some(Camera {
            eye: [0.0, 0.0, 5.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            vertical_fov_degrees: 40.0,
        }),
        textures: None,
    };
    let bytes = geometry.encode();
    assert_eq!(Geometry::decode(&bytes), Ok(geometry.clone()));
    assert_eq!(Geometry::decode(b"GARBAGE"), Err(DecodeError::BadMagic));
    for cut in 0..bytes.len() {
        assert!(Geometry::decode(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    let bad = Geometry {
        patches: vec![[0, 1, 9, 3], [0, 1, 2, geometry::NO_CORNER]],
        ..geometry.clone()
    };
    assert_eq!(
        Geometry::decode(&bad.encode()),
        Err(DecodeError::Invalid(
            "patch 0 refers to vertex 9 of 4".into()
        ))
    );
    let nan = Geometry {
        positions: vec![[f32::NAN, 0.0, 0.0]; 4],
        ..geometry
    };
    assert_eq!(
        Geometry::decode(&nan.encode()),
        Err(DecodeError::Invalid("position 0 is not finite".into()))
    );
}

proptest! {
    #[test]
    fn frames_round_trip(colours in prop::collection::vec(any::<u32>(), 0..300), picks in prop::collection::vec(any::<bool>(), 300), version in any::<u64>()) {
        let message = ServerMessage::Full(FullFrame { info: info(version, colours.len() as u32, false), colours: colours.clone() });
        prop_assert_eq!(ServerMessage::decode(&message.encode()), Ok(message));
        let (indices, changed): (Vec<u32>, Vec<u32>) = colours.iter().enumerate().filter(|(i, _)| picks[*i]).map(|(i, c)| (i as u32, c.wrapping_add(1))).unzip();
        let delta = ServerMessage::Delta(DeltaFrame { base_version: version.wrapping_sub(1), info: info(version, colours.len() as u32, true), indices, colours: changed });
        prop_assert_eq!(ServerMessage::decode(&delta.encode()), Ok(delta));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let _ = ServerMessage::decode(&bytes);
        let _ = ClientMessage::decode(&bytes);
        let _ = Geometry::decode(&bytes);
        let mut prefixed = geometry::MAGIC.to_vec();
        prefixed.extend_from_slice(&bytes);
        let _ = Geometry::decode(&prefixed);
    }
}
