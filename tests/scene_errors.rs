//! Bad scene files give errors that name the file, the line and what is wrong.

use solver::{MAX_REFLECTANCE, Scene, SceneError};
use std::path::{Path, PathBuf};

const MTL: &str = "newmtl white\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n";
const SQUARE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

/// Writes `scene.obj` (and `scene.mtl` when given) into a fresh folder and loads it.
fn load(obj: &str, mtl: Option<&str>) -> (Result<Scene, SceneError>, PathBuf, tempfile::TempDir) {
    let folder = tempfile::tempdir().expect("temp dir");
    if let Some(mtl) = mtl {
        std::fs::write(folder.path().join("scene.mtl"), mtl).expect("write mtl");
    }
    let path = folder.path().join("scene.obj");
    std::fs::write(&path, obj).expect("write obj");
    (solver::load_obj(&path), path, folder)
}

fn error_of(obj: &str, mtl: Option<&str>) -> (String, PathBuf) {
    let (result, path, _folder) = load(obj, mtl);
    (result.expect_err("the scene is bad").to_string(), path)
}

#[test]
fn a_good_scene_loads_with_names_and_materials() {
    let obj = format!(
        "mtllib scene.mtl\no plate\nusemtl white\n{SQUARE}f 1 2 3 4\no lamp\nusemtl lamp\n{SQUARE}f -1 -2 -3\n"
    );
    let (scene, _, _folder) = load(&obj, Some(MTL));
    let scene = scene.expect("loads");
    let names: Vec<_> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["plate", "lamp"]);
    assert_eq!(scene.faces.len(), 2);
    assert!(scene.faces[0].polygon.is_quad() && !scene.faces[1].polygon.is_quad());
    assert_eq!(scene.faces[1].emission.to_array(), [5.0; 3]);
}

#[test]
fn a_missing_file_is_named() {
    let error = solver::load_obj(Path::new("no/such/scene.obj"))
        .expect_err("missing")
        .to_string();
    assert!(
        error.starts_with("no/such/scene.obj: cannot read"),
        "{error}"
    );
}

#[test]
fn a_missing_material_library_is_named() {
    let (error, path) = error_of(
        &format!("mtllib scene.mtl\no a\nusemtl white\n{SQUARE}f 1 2 3\n"),
        None,
    );
    let mtl = path.with_extension("mtl");
    assert!(
        error.starts_with(&format!("{}: cannot read", mtl.display())),
        "{error}"
    );
}

#[test]
fn an_unknown_material_names_its_line() {
    let (error, path) = error_of(
        &format!("mtllib scene.mtl\no a\nusemtl marble\n{SQUARE}f 1 2 3\n"),
        Some(MTL),
    );
    assert_eq!(
        error,
        format!(
            "{}:3: material 'marble' is not defined in any mtllib",
            path.display()
        )
    );
}

#[test]
fn faces_without_a_material_are_refused() {
    let (error, path) = error_of(&format!("o bare\n{SQUARE}f 1 2 3\n"), None);
    assert_eq!(
        error,
        format!(
            "{}: object 'bare' has faces but no material (add `usemtl NAME`)",
            path.display()
        )
    );
}

#[test]
fn an_index_out_of_range_names_its_line() {
    let (error, path) = error_of(
        &format!("mtllib scene.mtl\no a\nusemtl white\n{SQUARE}f 1 2 9\n"),
        Some(MTL),
    );
    assert_eq!(
        error,
        format!(
            "{}:8: face refers to vertex 9, but only 4 vertices are defined before it",
            path.display()
        )
    );
}

#[test]
fn non_finite_coordinates_name_their_line() {
    for bad in ["nan", "inf", "-inf", "1e999", "abc"] {
        let (error, path) = error_of(
            &format!(
                "mtllib scene.mtl\no a\nusemtl white\nv 0 0 0\nv 1 {bad} 0\nv 0 1 0\nf 1 2 3\n"
            ),
            Some(MTL),
        );
        assert_eq!(
            error,
            format!(
                "{}:5: vertex 2 has coordinate '{bad}', which is not a finite number",
                path.display()
            )
        );
    }
}

#[test]
fn reflectance_outside_zero_to_one_and_negative_emission_are_refused() {
    for (material, reason) in [
        (
            "Kd 1.5 0.5 0.5",
            "Kd [1.5, 0.5, 0.5] must have every channel in [0, 1] (1 is read as 0.99)",
        ),
        (
            "Kd -0.1 0.5 0.5",
            "Kd [-0.10000000149011612, 0.5, 0.5] must have every channel in [0, 1] (1 is read as 0.99)",
        ),
        (
            "Kd 0.5 0.5 0.5\nKe 1 -2 1",
            "Ke [1.0, -2.0, 1.0] must have every value finite, >= 0 and <= 1e24",
        ),
        (
            // Radiosity past what frames hold (it turned into inf and NaN).
            "Kd 0.5 0.5 0.5\nKe 3e38 0 0",
            "Ke [3.0000000054977558e38, 0.0, 0.0] must have every value finite, >= 0 and <= 1e24",
        ),
    ] {
        let (error, path) = error_of(
            &format!("mtllib scene.mtl\no a\nusemtl m\n{SQUARE}f 1 2 3\n"),
            Some(&format!("newmtl m\n{material}\n")),
        );
        assert_eq!(
            error,
            format!(
                "{}: material 'm': {reason}",
                path.with_extension("mtl").display()
            )
        );
    }
}

#[test]
fn a_kd_of_one_as_exported_assets_have_it_is_read_as_the_highest_reflectance_and_said() {
    let obj = format!("mtllib scene.mtl\no a\nusemtl white\n{SQUARE}f 1 2 3 4\n");
    let (scene, path, _folder) = load(&obj, Some("newmtl white\nKd 1 0.995 0.5\n"));
    let scene = scene.expect("loads");
    assert_eq!(
        scene.faces[0].reflectance.to_array(),
        [MAX_REFLECTANCE, MAX_REFLECTANCE, 0.5]
    );
    assert_eq!(
        scene.load_warnings,
        [format!(
            "{}: material 'white': Kd [1.0, 0.9950000047683716, 0.5] read as [0.99, 0.99, 0.5] (at most 0.99)",
            path.with_extension("mtl").display()
        )]
    );
}

#[test]
fn a_texture_file_that_is_not_there_leaves_kd_alone_and_is_said() {
    // Exporters write the path on the author's machine.
    let obj = format!("mtllib scene.mtl\no a\nusemtl wood\n{SQUARE}f 1 2 3 4\n");
    let (scene, path, _folder) = load(
        &obj,
        Some("newmtl wood\nKd 0.5 0.4 0.3\nmap_Kd C:/Documents and Settings/someone/oak.jpg\n"),
    );
    let scene = scene.expect("loads");
    assert_eq!(
        scene.faces[0].reflectance.to_array(),
        [0.5, 0.4, 0.3].map(|c: f32| c as f64)
    );
    assert!(scene.textures.is_empty() && scene.faces[0].texture.is_none());
    let mtl = path.with_extension("mtl");
    assert_eq!(
        scene.load_warnings,
        [format!(
            "{}: material 'wood': map_Kd {} is not there: Kd alone is used",
            mtl.display(),
            mtl.parent()
                .unwrap()
                .join("C:/Documents and Settings/someone/oak.jpg")
                .display()
        )]
    );
}

#[test]
fn zero_area_faces_are_skipped_and_counted() {
    let obj = format!(
        "mtllib scene.mtl\no a\nusemtl white\n{SQUARE}f 1 2 3 4\nf 1 2 1\nv 2 0 0\nf 1 2 5\n"
    );
    let (scene, _, _folder) = load(&obj, Some(MTL));
    let scene = scene.expect("loads");
    assert_eq!(scene.faces.len(), 1);
    assert_eq!(scene.skipped_degenerate_faces, 2);
}

#[test]
fn a_scene_of_only_degenerate_faces_is_empty() {
    let (error, path) = error_of(
        "mtllib scene.mtl\no a\nusemtl white\nv 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
        Some(MTL),
    );
    assert_eq!(
        error,
        format!(
            "{}: the scene has no faces with non-zero area",
            path.display()
        )
    );
}

#[test]
fn a_view_line_is_parsed_and_a_bad_one_names_its_line() {
    let obj = format!(
        "#@view eye 0 1 -5 target 0 1 0 up 0 1 0 fov 40\nmtllib scene.mtl\no a\nusemtl white\n{SQUARE}f 1 2 3\n"
    );
    let (scene, _, _folder) = load(&obj, Some(MTL));
    let view = scene.expect("loads").view.expect("has a view");
    assert_eq!((view.eye.z, view.vertical_fov_degrees), (-5.0, 40.0));
    let needs =
        "the view needs eye != target, an up not along the view direction and a fov in (0, 180)";
    for (view, reason) in [
        (
            "eye 0 1 -5 target 0 1 0 up 0 1 0 fov 400",
            needs.to_string(),
        ),
        // Looking straight along the up direction: no camera frame.
        ("eye 0 -5 0 target 0 1 0 up 0 1 0 fov 40", needs.to_string()),
        // Past what f32 viewers hold (a camera at 1e308 was accepted).
        (
            "eye 1e308 1 -5 target 0 1 0 up 0 1 0 fov 40",
            "expected a finite number within ±1e30 at word 2".to_string(),
        ),
    ] {
        let (error, path) = error_of(
            &format!("mtllib scene.mtl\n#@view {view}\no a\nusemtl white\n{SQUARE}f 1 2 3\n"),
            Some(MTL),
        );
        assert_eq!(error, format!("{}:2: {reason}", path.display()));
    }
}

#[test]
fn a_colour_without_three_numbers_names_its_mtl_line() {
    // tobj panicked on these: truncated files end like this.
    let obj = format!("mtllib scene.mtl\no a\nusemtl white\n{SQUARE}f 1 2 3\n");
    for (bad, found) in [
        ("newmtl white\nKd 0.5 0.5\n", "Kd 0.5 0.5"),
        ("newmtl white\nKd 0.5 0.5 0.5\nKe\n", "Ke"),
        ("newmtl white\nKd 0.5 zero 0.5\n", "Kd 0.5 zero 0.5"),
    ] {
        let (error, path) = error_of(&obj, Some(bad));
        let line = bad.lines().position(|l| l == found).unwrap() + 1;
        let expected = format!(
            "{}:{line}: {} needs three numbers (r g b), found '{found}'",
            path.with_extension("mtl").display(),
            &found[..2]
        );
        assert_eq!(error, expected);
    }
}

#[test]
fn a_scene_or_material_file_that_is_not_a_file_is_refused_unread() {
    // A device would be read until memory runs out.
    let (error, _) = error_of(
        &format!("mtllib /dev/zero\no a\nusemtl white\n{SQUARE}f 1 2 3\n"),
        None,
    );
    assert_eq!(error, "/dev/zero: not a regular file");
    let error = solver::load_obj(Path::new("/dev/zero"))
        .expect_err("a device")
        .to_string();
    assert_eq!(error, "/dev/zero: not a regular file");
}

/// Every scene in tests/fuzz/scenes (inputs that once broke radcast) gives what its first
/// line promises: `# expect: solves` (dense and hierarchical, every value finite and >= 0) or
/// `# expect: TEXT` (a load or solve error containing TEXT).
#[test]
fn every_fuzz_regression_scene_gives_its_expected_outcome() {
    let folder = std::path::Path::new("tests/fuzz/scenes");
    let mut scenes: Vec<_> = std::fs::read_dir(folder)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "obj"))
        .collect();
    scenes.sort();
    assert!(scenes.len() >= 6, "{scenes:?}");
    for path in scenes {
        let text = std::fs::read_to_string(&path).unwrap();
        let expect = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# expect: "))
            .unwrap_or_else(|| panic!("{}: no '# expect:' line", path.display()));
        for hierarchical in [false, true] {
            let request = solver::SolveRequest {
                patches: solver::PatchTarget::Count(48),
                hierarchy: hierarchical.then_some(solver::HierarchySettings {
                    error: 0.5,
                    ..Default::default()
                }),
                ..Default::default()
            };
            let outcome = solver::solve_file(&path, &request, &solver::no_progress);
            match (expect, outcome) {
                ("solves", Ok(solved)) => {
                    assert!(
                        solved
                            .radiosity
                            .iter()
                            .chain(&solved.vertex_radiosity)
                            .flat_map(|b| b.to_array())
                            .all(|c| c.is_finite() && c >= 0.0),
                        "{}",
                        path.display()
                    );
                    let lit = solved.radiosity.iter().any(|b| b.max_element() > 0.0);
                    assert!(lit, "{}: solved black", path.display());
                    if !hierarchical {
                        assert!(
                            solved.mesh.patches.len() <= 96,
                            "{}: {} patches for 48",
                            path.display(),
                            solved.mesh.patches.len()
                        );
                    }
                }
                ("solves", Err(error)) => panic!("{}: {error}", path.display()),
                (expected, Ok(_)) => panic!("{}: solved, expected '{expected}'", path.display()),
                (expected, Err(error)) => assert!(
                    error.to_string().contains(expected),
                    "{}: '{error}' lacks '{expected}'",
                    path.display()
                ),
            }
        }
    }
}

#[test]
fn bad_texture_coordinates_name_their_line() {
    let (error, path) = error_of(
        &format!("mtllib scene.mtl\no a\nusemtl white\n{SQUARE}vt 0 inf\nf 1/1 2/1 3/1\n"),
        Some(MTL),
    );
    assert_eq!(
        error,
        format!(
            "{}:8: texture coordinate 1 has 'inf', which is not a finite number within ±1e6",
            path.display()
        )
    );
    let (error, path) = error_of(
        &format!("mtllib scene.mtl\no a\nusemtl white\n{SQUARE}vt 0 0\nf 1/1 2/2 3/1\n"),
        Some(MTL),
    );
    assert_eq!(
        error,
        format!(
            "{}:9: face refers to texture coordinate 2, but only 1 are defined before it",
            path.display()
        )
    );
}
