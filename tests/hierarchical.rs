//! The hierarchical path against known answers, against the dense path, and where it refines.
//! Measured values are printed for docs/ACCURACY.md (`cargo test --test hierarchical -- --nocapture`).

mod common;

use common::*;
use glam::{DVec3, dvec3};
use solver::{
    HierarchySettings, Method, Rgb, Scene, Seed, Session, SolveError, SolveRequest, Solved,
    SolverSettings, solve_scene,
};
use std::path::Path;

fn hierarchical(error: f64) -> SolveRequest {
    SolveRequest {
        hierarchy: Some(HierarchySettings {
            error,
            ..HierarchySettings::default()
        }),
        solver: SolverSettings {
            method: Method::Gmres,
            tolerance: 1e-9,
            ..SolverSettings::default()
        },
        ..SolveRequest::default()
    }
}

fn solve(scene: Scene, error: f64) -> Solved {
    solve_scene(scene, &hierarchical(error), &solver::no_progress).expect("solves")
}

/// The solved session of `scene` at `error`: its own patch system ([`Session::radiosity`])
/// and what it shows ([`Session::patch_values`], [`Session::vertex_radiosity`]).
fn solve_session(scene: &Scene, error: f64) -> Session {
    let mut session =
        Session::hierarchical(scene, &hierarchical(error), &solver::no_progress).expect("builds");
    session.solve(&solver::no_progress);
    session
}

/// The worst relative error of `values` against `expected`.
fn worst_off(values: &[Rgb], expected: f64) -> f64 {
    (values.iter())
        .map(|b| (b.x / expected - 1.0).abs())
        .fold(0.0, f64::max)
}

/// The worst relative errors against `expected` of `session`'s own patch system and of the
/// patch values it shows.
fn system_and_shown_off(session: &Session, expected: f64) -> (f64, f64) {
    (
        worst_off(session.radiosity(), expected),
        worst_off(&session.patch_values(), expected),
    )
}

#[test]
fn furnaces_stay_exact_with_and_without_an_occluder() {
    // The leaves' own system is exact (closed views sum to one); what is shown, the vertices'
    // gathers and the patches' means of them, sees visibility through sampled rays.
    for rho in [0.5, 0.9, 0.99] {
        let session = solve_session(&closed_cube(1.0, grey(rho, 1.0)), 0.1);
        let (system, shown) = system_and_shown_off(&session, 1.0 / (1.0 - rho));
        println!(
            "hierarchical furnace, rho {rho}: {} leaves, worst relative error {system:.2e}, shown {shown:.2e}",
            session.radiosity().len()
        );
        assert!(
            system < 1e-3 && shown < 1e-3,
            "rho {rho}: {system}, shown {shown}"
        );
    }
    let (rho, emission) = (0.8, 1.0);
    let session = solve_session(&occluded_furnace(grey(rho, emission)), 0.1);
    let (system, shown) = system_and_shown_off(&session, emission / (1.0 - rho));
    println!(
        "hierarchical occluded furnace: {} leaves, worst relative error {system:.2e}, shown {shown:.2e}",
        session.radiosity().len()
    );
    assert!(system < 1e-3 && shown < 0.01, "{system}, shown {shown}");
}

#[test]
fn a_furnace_stopped_at_a_tiny_link_budget_shows_its_exact_light_from_the_corners_gathers() {
    // Refinement stops at 100 links and leaves the pairs past them undecided: the leaves'
    // own system lacks their light, and what is shown holds E / (1 - rho) all the same.
    let (rho, emission) = (0.8, 1.0);
    let scene = occluded_furnace(grey(rho, emission));
    let request = SolveRequest {
        hierarchy: Some(HierarchySettings {
            error: 0.1,
            max_links: 100,
            ..HierarchySettings::default()
        }),
        ..hierarchical(0.1)
    };
    let mut session =
        Session::hierarchical(&scene, &request, &solver::no_progress).expect("builds");
    let report = session.solve(&solver::no_progress);
    let stats = report.hierarchy.expect("a hierarchy");
    assert!(
        stats.link_budget_reached && stats.deferred_pairs > 0,
        "{stats:?}"
    );
    assert!(stats.links <= 100, "{stats:?}");
    let expected = emission / (1.0 - rho);
    let (system, shown) = system_and_shown_off(&session, expected);
    let vertices = worst_off(&session.vertex_radiosity(), expected);
    println!(
        "occluded furnace at 100 links: {} pairs left undecided, system off by {system:.2e}, patches shown {shown:.2e}, vertices {vertices:.2e}",
        stats.deferred_pairs
    );
    assert!(system > 0.1, "the system lacks the pairs' light: {system}");
    assert!(shown < 0.01 && vertices < 0.03, "{shown}, {vertices}");
}

#[test]
fn scaling_the_scene_changes_neither_leaves_nor_radiosity() {
    let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).expect("shipped scene loads");
    let base = solve(scene.clone(), 0.2);
    for factor in [1e-14, 1e17] {
        let scaled = solve(scene.scaled(factor), 0.2);
        assert_eq!(
            scaled.radiosity.len(),
            base.radiosity.len(),
            "scale {factor}"
        );
        for (a, b) in base.vertex_radiosity.iter().zip(&scaled.vertex_radiosity) {
            assert!(
                (*a - *b).abs().max_element() <= 1e-4 * a.max_element().max(1e-3),
                "scale {factor}: {a} vs {b}"
            );
        }
    }
}

#[test]
fn plates_and_hinge_give_rho_f_e() {
    let (rho, emission) = (0.6, 10.0);
    let plates = solve(
        parallel_plates(1.0, 1.0, 1.0, grey(rho, 0.0), grey(0.0, emission)),
        0.03,
    );
    let (got, expected) = (
        mean_of(&plates, "receiver").x,
        rho * howell_parallel(1.0, 1.0, 1.0) * emission,
    );
    println!(
        "hierarchical plates: {got:.6} vs {expected:.6} ({:+.3}%)",
        100.0 * (got / expected - 1.0)
    );
    assert!((got / expected - 1.0).abs() < 0.01, "{got} vs {expected}");
    let hinge = solve(
        hinge(1.0, 1.0, 1.0, grey(rho, 0.0), grey(0.0, emission)),
        0.03,
    );
    let (got, expected) = (
        mean_of(&hinge, "floor").x,
        rho * howell_perpendicular(1.0, 1.0, 1.0) * emission,
    );
    println!(
        "hierarchical hinge: {got:.6} vs {expected:.6} ({:+.3}%)",
        100.0 * (got / expected - 1.0)
    );
    assert!((got / expected - 1.0).abs() < 0.01, "{got} vs {expected}");
}

/// The area mean over `object` of what viewers see: each patch's corner values interpolated
/// linearly over its fan triangles.
fn smooth_mean(solved: &Solved, object: &str) -> f64 {
    let (mut light, mut area) = (0.0, 0.0);
    for patch in solved
        .mesh
        .patches
        .iter()
        .filter(|p| solved.scene.objects[p.object as usize].name == object)
    {
        let corners = &patch.corners[..patch.corner_count()];
        let at = |i: usize| solved.mesh.positions[corners[i] as usize];
        let value = |i: usize| solved.vertex_radiosity[corners[i] as usize].x;
        for k in 1..corners.len() - 1 {
            let a = 0.5 * (at(k) - at(0)).cross(at(k + 1) - at(0)).length();
            light += a * (value(0) + value(k) + value(k + 1)) / 3.0;
            area += a;
        }
    }
    light / area
}

#[test]
fn a_plate_of_triangle_soup_under_a_lamp_keeps_its_light_in_what_viewers_see() {
    // The plates of Howell's C-11, the receiver as 16 x 16 squares of two triangles each with
    // vertices of their own (soup, as exported models are): what viewers are shown over it
    // must hold the light the solution gives it, and that the exact factor gives.
    let (rho, emission, n) = (0.6, 10.0, 16);
    let mut scene = Scene::default();
    let receiver = scene.add_object("receiver");
    let step = 1.0 / n as f64;
    for i in 0..n {
        for j in 0..n {
            let o = dvec3(i as f64 * step, j as f64 * step, 0.0);
            let (x, y) = (DVec3::X * step, DVec3::Y * step);
            scene.add_polygon(receiver, &[o, o + x, o + x + y], grey(rho, 0.0));
            scene.add_polygon(receiver, &[o, o + x + y, o + y], grey(rho, 0.0));
        }
    }
    add_rect(
        &mut scene,
        "emitter",
        dvec3(0.0, 0.0, 1.0),
        DVec3::Y,
        DVec3::X,
        grey(0.0, emission),
    );
    let expected = rho * howell_parallel(1.0, 1.0, 1.0) * emission;
    for error in [0.1, 0.03] {
        let solved = solve(scene.clone(), error);
        let (flat, smooth) = (
            mean_of(&solved, "receiver").x,
            smooth_mean(&solved, "receiver"),
        );
        println!(
            "soup plate, knob {error}: {} leaves, flat {:+.3}%, smooth {:+.3}% against {expected:.5}",
            solved.radiosity.len(),
            100.0 * (flat / expected - 1.0),
            100.0 * (smooth / expected - 1.0)
        );
        assert!(
            (flat / expected - 1.0).abs() < 1e-3,
            "flat {flat} vs {expected}"
        );
        assert!(
            (smooth / expected - 1.0).abs() < 1e-3,
            "smooth {smooth} vs {expected}"
        );
    }
}

#[test]
fn no_light_leaks_through_a_closed_wall() {
    let solved = solve(two_rooms_one_lamp(), 0.05);
    let room_b = brightness_of(&solved, "b");
    let (brightest, lit) = (
        room_b.iter().cloned().fold(0.0, f64::max),
        mean_of(&solved, "a").x,
    );
    println!(
        "room b: {} leaves, brightest {brightest:e}; room a mean {lit}",
        room_b.len()
    );
    // Round-off of the Krylov solve, not transport: no link carries light across the wall.
    assert!(
        !room_b.is_empty() && brightest < 1e-12 * lit,
        "light leaked into room b: {brightest:e}"
    );
    assert!(lit > 0.1);
}

#[test]
fn leaves_gather_at_the_shadow_boundary_not_where_light_is_flat() {
    // A small lamp 20 above a 4 x 4 floor lights it almost evenly (within 2%); a 1 x 1 slab 0.5
    // above the floor casts a sharp shadow whose edge lies at |x| = 0.5 * 20 / 19.5.
    let mut scene = Scene::default();
    add_rect(
        &mut scene,
        "floor",
        dvec3(-2.0, 0.0, -2.0),
        DVec3::Z * 4.0,
        DVec3::X * 4.0,
        grey(0.5, 0.0),
    );
    add_rect(
        &mut scene,
        "lamp",
        dvec3(-0.25, 20.0, -0.25),
        DVec3::X * 0.5,
        DVec3::Z * 0.5,
        grey(0.0, 1e4),
    );
    add_rect(
        &mut scene,
        "slab",
        dvec3(-0.5, 0.5, -0.5),
        DVec3::X,
        DVec3::Z,
        grey(0.5, 0.0),
    );
    add_rect(
        &mut scene,
        "slab",
        dvec3(-0.5, 0.5, -0.5),
        DVec3::Z,
        DVec3::X,
        grey(0.5, 0.0),
    );
    let solved = solve(scene, 0.05);
    let edge = 0.5 * 20.0 / 19.5;
    let count = |x: std::ops::Range<f64>| {
        solved
            .mesh
            .patches
            .iter()
            .filter(|p| {
                p.object == 0 && x.contains(&p.centroid.x.abs()) && p.centroid.z.abs() < 0.3
            })
            .count()
    };
    let (boundary, flat) = (count(edge - 0.125..edge + 0.125), count(1.3..1.55));
    println!(
        "leaves in two 0.25 x 0.6 strips: {boundary} across the shadow edge, {flat} where light is flat ({} in all)",
        solved.radiosity.len()
    );
    assert!(
        boundary >= 8 * flat.max(1),
        "shadow edge {boundary} vs flat {flat}"
    );
}

#[test]
fn hierarchical_and_dense_agree_on_the_cornell_box() {
    let scene = solver::load_obj(Path::new("scenes/cornell-box.obj")).expect("loads");
    let error = 0.05;
    let dense = solve_scene(
        scene.clone(),
        &SolveRequest {
            patches: solver::PatchTarget::Count(2500),
            ..SolveRequest::default()
        },
        &solver::no_progress,
    )
    .expect("solves");
    let hierarchical = solve(scene, error);
    let (mut weighted, mut area) = (0.0, 0.0);
    for (d, h) in dense
        .report
        .objects
        .iter()
        .zip(&hierarchical.report.objects)
        .filter(|(d, _)| d.name != "light")
    {
        let difference = d
            .radiosity
            .iter()
            .zip(h.radiosity)
            .map(|(a, b)| (b / a - 1.0).abs())
            .fold(0.0, f64::max);
        println!(
            "{}: hierarchical and dense means differ by {difference:.4}",
            d.name
        );
        weighted += difference * d.area;
        area += d.area;
        assert!(difference < error, "{}: {difference}", d.name);
    }
    // Links read each source's linear model where they see it, so their errors do not all
    // lean one way and the mean difference stays well inside the knob (docs/ACCURACY.md).
    println!(
        "area-weighted mean difference {:.4} ({} leaves vs 2500 patches)",
        weighted / area,
        hierarchical.radiosity.len()
    );
    assert!(weighted / area < error / 2.0, "{}", weighted / area);
}

#[test]
fn a_method_that_needs_single_rows_is_refused_with_the_reason() {
    let mut request = hierarchical(0.1);
    request.solver.method = Method::GaussSeidel;
    let Err(error) = solve_scene(
        closed_cube(1.0, grey(0.5, 1.0)),
        &request,
        &solver::no_progress,
    ) else {
        panic!("gauss-seidel cannot run on links")
    };
    assert!(matches!(error, SolveError::Method(_)));
    assert_eq!(
        error.to_string(),
        "gauss-seidel updates one patch at a time and needs single form-factor rows; this transport only offers whole products (use jacobi or gmres)"
    );
}

#[test]
fn links_grow_in_proportion_to_faces_not_to_their_square() {
    // The generated town (triangle soup under a sky) at 12,500 and 100,000 triangles: eight
    // times the faces. Pairwise factors would grow 64 times; the hierarchy's links must stay
    // near the 8 of a linear cost. (Counts, not seconds: the 100,000 take ~20 s on 2 cores.)
    let dir = std::env::temp_dir().join(format!("radcast-scaling-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let links = |triangles: usize| {
        let town = solver::generate::town(triangles, 1, "town.mtl");
        let path = dir.join(format!("town-{triangles}.obj"));
        std::fs::write(&path, &town.obj).expect("writes");
        std::fs::write(dir.join("town.mtl"), &town.mtl).expect("writes");
        let scene = solver::load_obj(&path).expect("loads");
        let faces = scene.faces.len();
        let stats = solve(scene, 0.9).report.hierarchy.expect("hierarchical");
        println!(
            "{triangles} triangles: {faces} faces, {} leaves, {} links ({:.1} a face)",
            stats.elements,
            stats.links,
            stats.links as f64 / faces as f64
        );
        assert!(!stats.leaf_budget_reached && !stats.link_budget_reached);
        (faces, stats.links)
    };
    let (small_faces, small) = links(12_500);
    let (large_faces, large) = links(100_000);
    let _ = std::fs::remove_dir_all(&dir);
    let face_ratio = large_faces as f64 / small_faces as f64;
    assert!(
        large_faces >= 100_000 && face_ratio > 7.0,
        "{large_faces} / {small_faces}"
    );
    let link_ratio = large as f64 / small as f64;
    assert!(
        link_ratio < 1.5 * face_ratio,
        "links grew {link_ratio:.1} times for {face_ratio:.1} times the faces"
    );
}

#[test]
fn another_gather_seed_draws_another_pattern_the_report_names_it_and_the_light_holds() {
    // A 2 x 2 floor under a lamp with a plate between them: the floor's penumbra is where
    // the gathers' shadow rays decide what viewers see.
    let mut scene = Scene::default();
    add_rect(
        &mut scene,
        "floor",
        DVec3::ZERO,
        DVec3::X * 2.0,
        DVec3::Y * 2.0,
        grey(0.5, 0.0),
    );
    let lamp = (dvec3(0.5, 0.5, 1.0), DVec3::Y, DVec3::X);
    add_rect(&mut scene, "lamp", lamp.0, lamp.1, lamp.2, grey(0.0, 10.0));
    let plate = (dvec3(0.7, 0.7, 0.5), DVec3::Y * 0.6, DVec3::X * 0.6);
    add_rect(
        &mut scene,
        "plate",
        plate.0,
        plate.1,
        plate.2,
        grey(0.5, 0.0),
    );
    let seeded = |seed: u64| {
        let request = SolveRequest {
            seed: Seed(seed),
            ..hierarchical(0.1)
        };
        solve_scene(scene.clone(), &request, &solver::no_progress).expect("solves")
    };
    let (first, again, other) = (seeded(0), seeded(0), seeded(9));
    assert_eq!(first.vertex_radiosity, again.vertex_radiosity);
    assert_eq!((first.report.seed, other.report.seed), (0, 9));
    let (a, b) = (smooth_mean(&first, "floor"), smooth_mean(&other, "floor"));
    println!("floor's smooth mean: seed 0 {a:.5}, seed 9 {b:.5}");
    assert_ne!(first.vertex_radiosity, other.vertex_radiosity);
    assert!((b / a - 1.0).abs() < 0.01, "seed 0 {a}, seed 9 {b}");
}

#[test]
fn a_hierarchys_patch_values_are_the_means_of_what_viewers_are_shown_over_them() {
    let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).expect("shipped scene loads");
    let solved = solve(scene.clone(), 0.3);
    assert_eq!(
        solved.radiosity,
        solved.mesh.patch_means(&solved.vertex_radiosity)
    );
    // A dense mesh's patches hold their own system's solution, exact to the mesh.
    let request = SolveRequest {
        hierarchy: None,
        ..hierarchical(0.3)
    };
    let dense = solve_scene(scene.clone(), &request, &solver::no_progress).expect("solves");
    let mesh = solver::starting_mesh(&scene, &request).expect("meshes");
    let mut session = Session::new(&scene, &mesh, &request, &solver::no_progress).expect("builds");
    session.solve(&solver::no_progress);
    assert_eq!(dense.radiosity, session.radiosity());
}
