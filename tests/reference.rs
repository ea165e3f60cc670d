//! The path-traced reference against exact answers, its determinism, and the error metric.

mod common;

use common::*;
use glam::dvec3;
use solver::accuracy::{check_probes_match, evaluate};
use solver::reference::{Probe, place_probes, trace_probes};
use solver::visibility::Occluders;
use solver::{Method, PatchTarget, Rgb, SolveRequest, SolverSettings, solve_scene};
use std::f64::consts::PI;

fn trace(scene: &solver::Scene, probes: usize, samples: u32, seed: u64) -> Vec<Probe> {
    let occluders = Occluders::new(scene);
    trace_probes(
        scene,
        &occluders,
        &place_probes(scene, probes, seed),
        samples,
        seed,
        &solver::no_progress,
    )
}

#[test]
fn the_tracer_reproduces_the_furnace() {
    let scene = closed_cube(1.0, grey(0.5, 1.0));
    for probe in trace(&scene, 20, 16_000, 3) {
        for (b, se) in probe.radiosity.iter().zip(probe.standard_error) {
            // E / (1 - rho) = 2, within five standard errors.
            assert!((b - 2.0).abs() <= 5.0 * se + 1e-9, "{b} ± {se}");
            assert!(se < 0.08, "standard error {se}");
        }
    }
}

/// Howell B-3: from a point to a parallel `a x b` rectangle whose corner is straight above it.
fn point_to_corner_rectangle(a: f64, b: f64, height: f64) -> f64 {
    let (x, y) = (a / height, b / height);
    (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
        + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan())
        / (2.0 * PI)
}

/// The exact form factor from point `(x, y)` of an `a x b` plate to the parallel one `height`
/// above it: the emitter split at the point's projection into four corner rectangles.
fn point_to_plate(x: f64, y: f64, (a, b): (f64, f64), height: f64) -> f64 {
    [(x, y), (a - x, y), (x, b - y), (a - x, b - y)]
        .iter()
        .map(|&(u, v)| point_to_corner_rectangle(u, v, height))
        .sum()
}

#[test]
fn the_tracer_matches_the_analytic_point_form_factor() {
    // A black emitter over a grey plate: B(x) = rho * F(x -> emitter) * E exactly at every point.
    let (rho, emission) = (0.5, 4.0);
    let scene = parallel_plates(1.0, 1.0, 1.0, grey(rho, 0.0), grey(0.0, emission));
    for probe in trace(&scene, 40, 4000, 5).iter().filter(|p| p.face == 0) {
        let [x, y, _] = probe.position;
        let expected = rho * point_to_plate(x, y, (1.0, 1.0), 1.0) * emission;
        assert!(
            (probe.radiosity[0] - expected).abs() <= 5.0 * probe.standard_error[0] + 1e-9,
            "at ({x}, {y}): {} vs {expected}",
            probe.radiosity[0]
        );
    }
}

#[test]
fn under_a_sky_the_tracer_draws_by_solid_angle_and_its_noise_stays_low() {
    // A 40 m square sky 1 m over a ground of its size: drawn by area, a point's 1,000 paths
    // would weigh emitter points by a cos^2 / r^2 running from 1 overhead to 1e-6 at the far
    // edge (relative noise about sqrt(A / pi F) / sqrt(n): 70%); by solid angle, by a cosine
    // alone (about 2%). Exact: rho F E.
    let (rho, emission, side) = (0.5, 4.0, 40.0);
    let scene = parallel_plates(side, side, 1.0, grey(rho, 0.0), grey(0.0, emission));
    let probes: Vec<Probe> = trace(&scene, 40, 1000, 7);
    let on_ground: Vec<&Probe> = probes.iter().filter(|p| p.face == 0).collect();
    assert!(
        on_ground.len() > 10,
        "{} probes on the ground",
        on_ground.len()
    );
    for probe in on_ground {
        let [x, y, _] = probe.position;
        let expected = rho * point_to_plate(x, y, (side, side), 1.0) * emission;
        let (estimate, noise) = (probe.radiosity[0], probe.standard_error[0]);
        assert!(
            (estimate - expected).abs() <= 5.0 * noise + 1e-9,
            "at ({x}, {y}): {estimate} vs {expected}"
        );
        assert!(
            noise < 0.05 * expected,
            "at ({x}, {y}): ±{noise} of {expected}"
        );
    }
}

#[test]
fn the_same_seed_gives_the_same_reference_on_any_thread_count() {
    let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).unwrap();
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| trace(&scene, 16, 64, 9));
    let many = trace(&scene, 16, 64, 9);
    assert_eq!(single, many);
    assert_ne!(trace(&scene, 16, 64, 10), many);
}

#[test]
fn probes_spread_by_area() {
    // A 3 x 1 plate beside a 1 x 1 plate: three quarters of the probes on the big one.
    let mut scene = solver::Scene::default();
    add_rect(
        &mut scene,
        "big",
        dvec3(0.0, 0.0, 0.0),
        dvec3(3.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
        grey(0.5, 0.0),
    );
    add_rect(
        &mut scene,
        "small",
        dvec3(5.0, 0.0, 0.0),
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
        grey(0.5, 0.0),
    );
    let probes = place_probes(&scene, 4000, 1);
    let on_big = probes.iter().filter(|(face, _)| *face == 0).count() as f64 / 4000.0;
    assert!((on_big - 0.75).abs() < 0.03, "{on_big}");
    assert!(
        probes
            .iter()
            .all(|(face, p)| if *face == 0 { p.x <= 3.0 } else { p.x >= 5.0 })
    );
}

#[test]
fn a_solve_with_exact_probes_has_no_error_and_a_wrong_one_does() {
    let scene = closed_cube(1.0, grey(0.5, 1.0));
    let request = SolveRequest {
        patches: PatchTarget::Count(150),
        solver: SolverSettings {
            method: Method::Gmres,
            tolerance: 1e-9,
            ..Default::default()
        },
        ..Default::default()
    };
    let solved = solve_scene(scene.clone(), &request, &solver::no_progress).unwrap();
    // Exact probes: 2 everywhere, placed over every face (all emit). Probes on emitting faces
    // do not count, so make the floor dark: only the floor's count.
    let mut dark_floor = scene.clone();
    dark_floor.faces[0].emission = Rgb::ZERO;
    let exact: Vec<Probe> = place_probes(&scene, 50, 2)
        .into_iter()
        .map(|(face, p)| Probe {
            position: p.to_array(),
            face,
            object: String::new(),
            radiosity: [2.0; 3],
            standard_error: [0.0; 3],
        })
        .collect();
    let error = evaluate(
        &dark_floor,
        &solved.mesh,
        &solved.radiosity,
        &solved.vertex_radiosity,
        &exact,
    );
    assert!(error.probes > 0 && error.probes < 50);
    assert!(
        error.smooth.rms < 1e-6 && error.flat.rms < 1e-6 && error.smooth.energy.abs() < 1e-6,
        "{error:?}"
    );
    let halve = |values: &[Rgb]| values.iter().map(|b| *b * 0.5).collect::<Vec<_>>();
    let error = evaluate(
        &dark_floor,
        &solved.mesh,
        &halve(&solved.radiosity),
        &halve(&solved.vertex_radiosity),
        &exact,
    );
    assert!(
        (error.flat.rms - 0.5).abs() < 1e-6 && (error.smooth.energy + 0.5).abs() < 1e-6,
        "{error:?}"
    );
}

#[test]
fn the_error_is_split_by_object_and_the_wrong_one_holds_all_of_it() {
    // Two unlit squares, probes reading 2 on both; the solution reads 2 on the floor and 3 on
    // the wall: the wall is 50% off and holds all the squared error, the floor none.
    let mut scene = solver::Scene::default();
    for (name, origin) in [
        ("floor", dvec3(0.0, 0.0, 0.0)),
        ("wall", dvec3(5.0, 0.0, 0.0)),
    ] {
        add_rect(
            &mut scene,
            name,
            origin,
            dvec3(0.0, 0.0, 1.0),
            dvec3(1.0, 0.0, 0.0),
            grey(0.5, 0.0),
        );
    }
    let mesh = solver::Mesh::build(&scene, PatchTarget::Count(32));
    let reads = |object: u32| if object == 0 { 2.0 } else { 3.0 };
    let radiosity: Vec<Rgb> = mesh
        .patches
        .iter()
        .map(|p| Rgb::splat(reads(p.object)))
        .collect();
    let mut corners = vec![Rgb::ZERO; mesh.positions.len()];
    for patch in &mesh.patches {
        for &c in &patch.corners[..patch.corner_count()] {
            corners[c as usize] = Rgb::splat(reads(patch.object));
        }
    }
    let probes: Vec<Probe> = place_probes(&scene, 200, 5)
        .into_iter()
        .map(|(face, p)| Probe {
            position: p.to_array(),
            face: scene.faces[face as usize].source,
            object: String::new(),
            radiosity: [2.0; 3],
            standard_error: [0.0; 3],
        })
        .collect();
    let error = evaluate(&scene, &mesh, &radiosity, &corners, &probes);
    let [floor, wall] = &error.objects[..] else {
        panic!("two objects: {:?}", error.objects);
    };
    assert_eq!((floor.name.as_str(), wall.name.as_str()), ("floor", "wall"));
    assert_eq!(floor.probes + wall.probes, 200);
    assert!(floor.probes > 50 && wall.probes > 50, "{error:?}");
    for reading in [floor.flat, floor.smooth] {
        assert!(
            reading.rms < 1e-12 && reading.energy.abs() < 1e-12,
            "{floor:?}"
        );
    }
    for reading in [wall.flat, wall.smooth] {
        assert!((reading.rms - 0.5).abs() < 1e-12, "{wall:?}");
        assert!((reading.energy - 0.5).abs() < 1e-12, "{wall:?}");
    }
    assert!(floor.smooth_share.abs() < 1e-12 && (wall.smooth_share - 1.0).abs() < 1e-12);
    // The whole scene's RMS weighs each object by its probes.
    let expected = (wall.probes as f64 / 200.0).sqrt() * 0.5;
    assert!((error.smooth.rms - expected).abs() < 1e-12, "{error:?}");
}

#[test]
fn the_worst_probes_are_listed_worst_first_with_their_share_of_the_error() {
    // A floor that reads 2 everywhere, and references of 2 but at two probes: 1 at the 7th
    // (off by 1 on each channel) and 2.5 at the 20th (off by 0.5): they are the only ones
    // listed, the 7th first with 1 / (1 + 0.25) of the squared error, where they lie.
    let mut scene = solver::Scene::default();
    let (x, z) = (dvec3(1.0, 0.0, 0.0), dvec3(0.0, 0.0, 1.0));
    add_rect(
        &mut scene,
        "floor",
        dvec3(0.0, 0.0, 0.0),
        z,
        x,
        grey(0.5, 0.0),
    );
    let mesh = solver::Mesh::build(&scene, PatchTarget::Count(16));
    let radiosity = vec![Rgb::splat(2.0); mesh.patches.len()];
    let corners = vec![Rgb::splat(2.0); mesh.positions.len()];
    let reference_at = |i: usize| match i {
        7 => 1.0,
        20 => 2.5,
        _ => 2.0,
    };
    let probes: Vec<Probe> = (place_probes(&scene, 50, 3).into_iter().enumerate())
        .map(|(i, (face, p))| Probe {
            position: p.to_array(),
            face: scene.faces[face as usize].source,
            object: String::new(),
            radiosity: [reference_at(i); 3],
            standard_error: [0.0; 3],
        })
        .collect();
    let error = evaluate(&scene, &mesh, &radiosity, &corners, &probes);
    let listed: Vec<([f64; 3], [f64; 3], f64)> = (error.worst.iter())
        .map(|w| (w.position, w.reference, w.smooth_share))
        .collect();
    let expected = vec![
        (probes[7].position, [1.0; 3], 0.8),
        (probes[20].position, [2.5; 3], 0.2),
    ];
    assert_eq!(listed.len(), 2, "{:?}", error.worst);
    for (got, want) in listed.iter().zip(&expected) {
        assert_eq!((got.0, got.1), (want.0, want.1));
        assert!((got.2 - want.2).abs() < 1e-12, "{got:?} against {want:?}");
    }
    for w in &error.worst {
        assert_eq!((w.face, w.object.as_str()), (0, "floor"));
        assert_eq!((w.smooth, w.flat), ([2.0; 3], [2.0; 3]));
    }
}

#[test]
fn probes_go_only_where_the_error_is_measured_not_on_emitters() {
    // A sky nine times the floor's area: every probe still lands on the floor.
    let mut scene = solver::Scene::default();
    add_rect(
        &mut scene,
        "sky",
        dvec3(0.0, 5.0, 0.0),
        dvec3(0.0, 0.0, 3.0),
        dvec3(3.0, 0.0, 0.0),
        grey(0.0, 1.0),
    );
    add_rect(
        &mut scene,
        "floor",
        dvec3(1.0, 0.0, 1.0),
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 0.0, 1.0),
        grey(0.5, 0.0),
    );
    let probes = place_probes(&scene, 500, 3);
    assert!(probes.iter().all(|(face, _)| *face == 1));
    // A scene of emitters only keeps its probes on them.
    scene.faces[1].emission = Rgb::splat(1.0);
    assert_eq!(place_probes(&scene, 500, 3).len(), 500);
}

#[test]
fn probes_inside_a_solid_count_and_are_also_counted_apart() {
    // A 4 x 4 floor with a closed box (faces outward) standing through it over [1, 2] x [1, 2]:
    // everything is shown as 2 and the reference says 2, but 0 on the floor under the box,
    // inside the solid. Every probe counts in the smooth RMS; those under the box are the
    // buried ones, and at the others (what a viewer can see) the reading is exact.
    let mut scene = solver::Scene::default();
    let (x, y, z) = (
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
        dvec3(0.0, 0.0, 1.0),
    );
    add_rect(
        &mut scene,
        "floor",
        dvec3(0.0, 0.0, 0.0),
        z * 4.0,
        x * 4.0,
        grey(0.5, 0.0),
    );
    let (low, high) = (dvec3(1.0, -0.5, 1.0), dvec3(2.0, 0.5, 2.0));
    let sides = [
        (low, x, z),
        (dvec3(1.0, 0.5, 1.0), z, x),
        (low, z, y),
        (dvec3(2.0, -0.5, 1.0), y, z),
        (low, y, x),
        (dvec3(1.0, -0.5, 2.0), x, y),
    ];
    for (origin, u, v) in sides {
        add_rect(&mut scene, "box", origin, u, v, grey(0.5, 0.0));
    }
    let mesh = solver::Mesh::build(&scene, PatchTarget::Count(64));
    let radiosity = vec![Rgb::splat(2.0); mesh.patches.len()];
    let corners = vec![Rgb::splat(2.0); mesh.positions.len()];
    let under_the_box = |p: glam::DVec3| {
        p.y.abs() < 1e-9 && (low.x..high.x).contains(&p.x) && (low.z..high.z).contains(&p.z)
    };
    let probes: Vec<Probe> = (place_probes(&scene, 400, 11).into_iter())
        .map(|(face, p)| Probe {
            position: p.to_array(),
            face: scene.faces[face as usize].source,
            object: String::new(),
            radiosity: [if under_the_box(p) { 0.0 } else { 2.0 }; 3],
            standard_error: [0.0; 3],
        })
        .collect();
    let buried = (probes.iter())
        .filter(|p| under_the_box(glam::DVec3::from(p.position)))
        .count();
    assert!(buried > 5, "{buried} probes under the box");
    let error = evaluate(&scene, &mesh, &radiosity, &corners, &probes);
    assert_eq!((error.probes, error.buried_probes), (400, buried));
    assert!(error.visible_smooth.rms < 1e-12, "{error:?}");
    // Off by 2 on every channel at the buried probes, against 2 at every visible one.
    let expected = (buried as f64 / (400 - buried) as f64).sqrt();
    assert!((error.smooth.rms - expected).abs() < 1e-12, "{error:?}");
}

#[test]
fn a_reference_traced_for_another_scene_is_refused_naming_a_probe() {
    let scene = parallel_plates(1.0, 1.0, 1.0, grey(0.5, 0.0), grey(0.0, 4.0));
    let probes = trace(&scene, 20, 16, 1);
    assert_eq!(check_probes_match(&scene, &probes), Ok(()));
    // The same faces in another order, as a file with a face added before them numbers
    // every later face anew: each probe names a face that lies elsewhere.
    let mut reordered = scene.clone();
    reordered.faces.reverse();
    for (i, face) in reordered.faces.iter_mut().enumerate() {
        face.source = i as u32;
    }
    let refused = check_probes_match(&reordered, &probes).unwrap_err();
    let first = &probes[0];
    assert_eq!(first.object, "receiver");
    assert_eq!(
        refused,
        format!(
            "probe 0 at {:?} lies on face 0 of object 'receiver' where the reference was \
             traced, but here that face is of object 'emitter', 1.000e0 from the probe: the \
             reference was traced for another scene (trace one for this scene with `radcast \
             reference`)",
            first.position
        )
    );
    // A probe moved off its face, and one naming a face the scene lacks.
    let mut moved = probes.clone();
    moved[3].position[2] += 0.5;
    let refused = check_probes_match(&scene, &moved).unwrap_err();
    assert!(refused.starts_with("probe 3 at "), "{refused}");
    assert!(
        refused.contains("that face lies 5.000e-1 from the probe"),
        "{refused}"
    );
    let mut missing = probes;
    missing[5].face = 7;
    let refused = check_probes_match(&scene, &missing).unwrap_err();
    assert!(refused.contains("that face does not exist"), "{refused}");
}
