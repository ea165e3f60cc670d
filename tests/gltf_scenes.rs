//! glTF 2.0 input: a scene in glTF loads as the same faces and materials as its OBJ twin, and
//! what is not supported is refused with the reason.

use solver::Scene;
use std::path::Path;

fn load(name: &str) -> Result<Scene, solver::SceneError> {
    solver::load_scene(&Path::new("tests/gltf").join(name))
}

#[test]
fn a_gltf_scene_loads_as_its_obj_twin() {
    // Node transforms (a scaled and moved floor, a moved lamp), base colour times the linear
    // mean of a white-and-black texture (0.5 x 0.5), and emission = pi x emissiveFactor x
    // KHR_materials_emissive_strength: the OBJ twin was written by hand with those values.
    let gltf = load("lamp-over-textured-floor.gltf").expect("loads");
    let obj = load("lamp-over-textured-floor.obj").expect("loads");
    let names = |s: &Scene| s.objects.iter().map(|o| o.name.clone()).collect::<Vec<_>>();
    let mut gltf_names = names(&gltf);
    gltf_names.sort();
    assert_eq!(gltf_names, names(&obj));
    assert_eq!(gltf.faces.len(), obj.faces.len());
    for face in &obj.faces {
        let name = &obj.objects[face.object as usize].name;
        let twin = gltf
            .faces
            .iter()
            .find(|f| {
                gltf.objects[f.object as usize].name == *name
                    && f.polygon
                        .corners()
                        .iter()
                        .zip(face.polygon.corners())
                        .all(|(a, b)| a.distance(*b) < 1e-6)
            })
            .unwrap_or_else(|| panic!("no glTF face at {:?}", face.polygon.corners()));
        assert!(
            (twin.reflectance - face.reflectance).abs().max_element() < 1e-12
                // tobj reads MTL values as f32.
                && (twin.emission - face.emission).abs().max_element() < 1e-6 * face.emission.max_element().max(1.0),
            "{name}: {:?} {:?} vs {:?} {:?}",
            twin.reflectance,
            twin.emission,
            face.reflectance,
            face.emission
        );
    }
    // And so it solves to the same light.
    let request = solver::SolveRequest {
        patches: solver::PatchTarget::Count(200),
        ..Default::default()
    };
    let [a, b] =
        [gltf, obj].map(|s| solver::solve_scene(s, &request, &solver::no_progress).unwrap());
    let mean = |s: &solver::Solved| {
        let floor = s
            .scene
            .objects
            .iter()
            .position(|o| o.name == "floor")
            .unwrap() as u32;
        let (sum, area) = s
            .mesh
            .patches
            .iter()
            .zip(&s.radiosity)
            .filter(|(p, _)| p.object == floor)
            .fold((solver::Rgb::ZERO, 0.0), |(sum, area), (p, b)| {
                (sum + *b * p.area, area + p.area)
            });
        sum / area
    };
    assert!((mean(&a) - mean(&b)).abs().max_element() <= 1e-6 * mean(&b).max_element());
    assert!(mean(&a).max_element() > 0.0);
}

#[test]
fn a_binary_gltf_loads_as_its_text_twin() {
    let [glb, gltf] = [
        "lamp-over-textured-floor.glb",
        "lamp-over-textured-floor.gltf",
    ]
    .map(|name| load(name).expect("loads"));
    assert_eq!(glb.faces, gltf.faces);
}

#[test]
fn what_gltf_input_does_not_support_is_refused_with_the_reason() {
    let lines = load("lines-primitive.gltf").unwrap_err().to_string();
    assert!(
        lines.ends_with("object 'floor' primitive 0: mode Lines is not supported (triangles only)"),
        "{lines}"
    );
    let device = load("device-buffer.gltf").unwrap_err().to_string();
    assert_eq!(device, "/dev/zero: not a regular file");
    let missing = load("no-such-file.glb").unwrap_err().to_string();
    assert!(
        missing.contains("no-such-file.glb: cannot read"),
        "{missing}"
    );
}

#[test]
fn an_obj_map_kd_is_kd_times_the_textures_linear_mean() {
    let textured = load("map-kd.obj").expect("loads");
    let twin = load("lamp-over-textured-floor.obj").expect("loads");
    let floor = |s: &Scene| {
        let id = s.objects.iter().position(|o| o.name == "floor").unwrap() as u32;
        s.faces.iter().find(|f| f.object == id).unwrap().reflectance
    };
    assert!((floor(&textured) - floor(&twin)).abs().max_element() < 1e-7);
    // A texture file that is not there leaves Kd alone, and says so.
    let missing = load("map-kd-missing.obj").expect("loads");
    assert!(missing.textures.is_empty());
    assert_eq!(floor(&missing), solver::Rgb::splat(0.5));
    assert_eq!(
        missing.load_warnings,
        [
            "tests/gltf/map-kd-missing.mtl: material 'textured': map_Kd tests/gltf/no-such-texture.png is not there: Kd alone is used"
        ]
    );
}

#[test]
fn gltf_texture_coordinates_map_each_face_into_its_base_colour_texture() {
    // A 2 x 1 m floor moved 1 m along x, TEXCOORD_0 = (local x, local z): the white-black
    // texture twice across. Base colour 0.5 times the texture's linear mean 0.5.
    let scene = load("textured-floor.gltf").expect("loads");
    assert_eq!(scene.textures.len(), 1);
    assert!(
        (scene.textures[0].mean - solver::Rgb::splat(0.5))
            .abs()
            .max_element()
            < 1e-12
    );
    assert_eq!(scene.faces.len(), 2);
    for face in &scene.faces {
        assert!(
            (face.reflectance - solver::Rgb::splat(0.25))
                .abs()
                .max_element()
                < 1e-12
        );
        let map = face.texture.as_ref().expect("the floor is textured");
        assert_eq!(map.texture, 0);
        for &p in face.polygon.corners() {
            let [u, v] = map.uv_at(p);
            assert!(
                (u - (p.x - 1.0)).abs() < 1e-9 && (v - p.z).abs() < 1e-9,
                "{p}: {u} {v}"
            );
        }
    }
    let nan = load("textured-floor-nan-uv.gltf").unwrap_err().to_string();
    assert!(
        nan.ends_with(
            "object 'floor' primitive 0: TEXCOORD_0: vertex 1 has [NaN, 0.0], not finite within ±1e6"
        ),
        "{nan}"
    );
}
