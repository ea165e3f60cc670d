//! The GLB export parses back as glTF 2.0 with consistent chunks, views and accessors.

use wire::Geometry;
use wire::geometry::NO_CORNER;

fn word(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

#[test]
fn glb_structure_matches_the_specification() {
    let geometry = Geometry {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [0.0, 1.0, 1.0],
        ],
        patches: vec![[0, 1, 2, 3], [4, 5, 6, NO_CORNER]],
        patch_objects: vec![0, 1],
        objects: vec!["floor".into(), "a \"quoted\" lamp".into()],
        camera: None,
        textures: None,
    };
    // One radiosity per vertex: the floor's four, then the lamp's three.
    let mut radiosity = vec![[0.5, 0.4, 0.3]; 4];
    radiosity.extend([[20.0, 20.0, 20.0]; 3]);
    let glb = wire::gltf::encode_glb(&geometry, &[] as &[&[u8]], &[false, true], &radiosity);
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(word(&glb, 4), 2);
    assert_eq!(word(&glb, 8) as usize, glb.len());
    let json_length = word(&glb, 12) as usize;
    assert_eq!(word(&glb, 16), 0x4E4F_534A);
    assert_eq!(json_length % 4, 0);
    let json: serde_json::Value =
        serde_json::from_slice(&glb[20..20 + json_length]).expect("the JSON chunk parses");
    let bin_at = 20 + json_length;
    let bin_length = word(&glb, bin_at) as usize;
    assert_eq!(word(&glb, bin_at + 4), 0x004E_4942);
    assert_eq!(bin_at + 8 + bin_length, glb.len());
    assert!(json["buffers"][0]["byteLength"].as_u64().unwrap() as usize <= bin_length);

    let names: Vec<_> = json["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["floor", "a \"quoted\" lamp"]);
    let count = |accessor: usize| json["accessors"][accessor]["count"].as_u64().unwrap();
    // Quad: 4 corners, 2 triangles; triangle: 3 corners, 1 triangle.
    assert_eq!((count(0), count(1), count(2)), (4, 4, 6));
    assert_eq!((count(3), count(4), count(5)), (3, 3, 3));
    for (i, view) in json["bufferViews"].as_array().unwrap().iter().enumerate() {
        let end = view["byteOffset"].as_u64().unwrap() + view["byteLength"].as_u64().unwrap();
        assert!(end as usize <= bin_length, "view {i} runs past the buffer");
    }
    // Colours are tone-mapped into [0, 1).
    let colours_view =
        &json["bufferViews"][json["accessors"][1]["bufferView"].as_u64().unwrap() as usize];
    let start = bin_at + 8 + colours_view["byteOffset"].as_u64().unwrap() as usize;
    let floats: Vec<f32> = glb
        [start..start + colours_view["byteLength"].as_u64().unwrap() as usize]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert!(
        floats.iter().all(|c| (0.0..1.0).contains(c) && *c > 0.0),
        "{floats:?}"
    );
}
