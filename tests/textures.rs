//! Textures end to end on the shipped example (scenes/tiled-cornell-box.obj): the geometry's
//! texture section, each texture served once as PNG whose linear mean is the one the solver
//! used, the glTF export embedding them, and the headless client drawing them.

mod common;

use common::http::{get, get_text};
use server::Limits;
use server::publish::prepare::{prepare, shared_for};
use server::publish::solver_thread;
use solver::{PatchTarget, SolveRequest};
use std::time::Duration;
use wire::geometry::NO_TEXTURE;

const SCENE: &str = "scenes/tiled-cornell-box.obj";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn textures_travel_with_the_geometry_and_are_served_once_as_png() {
    let request = SolveRequest {
        patches: PatchTarget::Count(300),
        ..SolveRequest::default()
    };
    let prepared = prepare(SCENE.as_ref(), request).unwrap();
    let scene = prepared.scene.clone();
    let shared = shared_for(&prepared, Limits::default(), "t".into());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(server::http::routes::serve(listener, shared.clone()));
    solver_thread::start(prepared, shared.clone(), None);
    let mut published = shared.hub.subscribe();
    tokio::time::timeout(Duration::from_secs(60), published.wait_for(|p| p.is_final))
        .await
        .expect("the solve ends")
        .unwrap();

    let base = format!("http://{address}");
    let client::render::Model {
        geometry, textures, ..
    } = tokio::task::spawn_blocking(move || client::fetch_scene(&base))
        .await
        .unwrap()
        .unwrap();
    let section = geometry
        .textures
        .as_ref()
        .expect("a textured scene has a texture section");
    assert_eq!(section.means.len(), 2);
    assert_eq!(textures.len(), 2);
    // Each texture's PNG decodes to texels whose linear mean is the mean the solver used
    // (its reflectance is Kd 1 times it), to f32 precision.
    for (t, image) in textures.iter().enumerate() {
        let sum: glam::DVec3 = image.texels.iter().map(|t| t.as_dvec3()).sum();
        let mean = sum / image.texels.len() as f64;
        let solver_mean = scene.textures[t].mean;
        assert!(
            (mean - solver_mean).abs().max_element() < 1e-6,
            "texture {t}: {mean} {solver_mean}"
        );
        assert_eq!(glam::Vec3::from(section.means[t]), solver_mean.as_vec3());
    }
    // Patches of the floor and the back wall show their textures; the rest none.
    let object = |name: &str| geometry.objects.iter().position(|o| o == name).unwrap() as u32;
    let shown = |name: &str| {
        let mut textures: Vec<u32> = (0..geometry.patches.len())
            .filter(|&p| geometry.patch_objects[p] == object(name))
            .map(|p| section.patch_textures[p])
            .collect();
        textures.dedup();
        textures
    };
    assert_eq!(shown("floor"), [0]);
    assert_eq!(shown("back_wall"), [1]);
    assert_eq!(shown("ceiling"), [NO_TEXTURE]);
    // The floor repeats its tiles twice across: u = x / 276.4, v = 1 - z / 279.6 (OBJ's v up).
    for (p, corners) in geometry.patches.iter().enumerate() {
        if geometry.patch_objects[p] != object("floor") {
            continue;
        }
        for &c in wire::display::corners(corners) {
            let [x, _, z] = geometry.positions[c as usize];
            let [u, v] = section.uvs[c as usize];
            assert!(
                (u - x / 276.4).abs() < 1e-5 && (v - (1.0 - z / 279.6)).abs() < 1e-5,
                "{x} {z}: {u} {v}"
            );
        }
    }

    let (status, text) = get_text(address, "/api/textures/2").await;
    assert_eq!(
        (status, text.as_str()),
        (404, "no texture '2': this scene's are 0 to 1\n")
    );
    let (status, png) = get(address, "/api/textures/1").await;
    assert_eq!(status, 200);
    assert_eq!(png, &scene.textures[1].png[..]);

    // The export embeds both images and maps the textured primitives with TEXCOORD_0.
    let (status, glb) = get(address, "/api/scene.glb").await;
    assert_eq!(status, 200);
    let json_length = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_length]).unwrap();
    assert_eq!(json["images"].as_array().unwrap().len(), 2);
    let floor = json["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["name"] == "floor")
        .unwrap();
    let primitive = &floor["primitives"][0];
    assert!(
        primitive["attributes"]["TEXCOORD_0"].is_u64(),
        "{primitive}"
    );
    let material = &json["materials"][primitive["material"].as_u64().unwrap() as usize];
    assert_eq!(
        material["pbrMetallicRoughness"]["baseColorTexture"]["index"],
        0
    );
    shared.process.shutdown.cancel();
}
