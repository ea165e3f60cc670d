//! Numerically hard scenes, each with a known answer. Measured values are printed for
//! docs/ACCURACY.md (`cargo test --test hard_cases -- --nocapture`).

mod common;

use common::*;
use glam::{DVec3, dvec3};
use solver::{Method, PatchTarget, Scene, SolveRequest, Solved, SolverSettings, solve_scene};
use std::f64::consts::PI;

fn solve(scene: Scene, patches: usize) -> Solved {
    let request = SolveRequest {
        patches: PatchTarget::Count(patches),
        solver: SolverSettings {
            method: Method::Gmres,
            tolerance: 1e-9,
            ..SolverSettings::default()
        },
        ..SolveRequest::default()
    };
    solve_scene(scene, &request, &solver::no_progress).expect("solves")
}

#[test]
fn touching_plates_give_rho_f_e_within_one_percent() {
    // A black emitting wall hinged to a grey floor (Howell C-14).
    let (rho, emission) = (0.7, 3.0);
    let expected = rho * howell_perpendicular(1.0, 1.0, 1.0) * emission;
    for patches in [2, 50, 800] {
        let floor = mean_of(
            &solve(
                hinge(1.0, 1.0, 1.0, grey(rho, 0.0), grey(0.0, emission)),
                patches,
            ),
            "floor",
        )
        .x;
        println!(
            "hinge, {patches} patches: {floor:.6} vs {expected:.6} ({:+.3}%)",
            100.0 * (floor / expected - 1.0)
        );
        assert!(
            (floor / expected - 1.0).abs() < 0.01,
            "{patches} patches: {floor} vs {expected}"
        );
    }
}

/// Howell B-3 summed over four corner rectangles: a point at height `h` under a `side` square
/// centred above it.
fn point_to_centred_square(side: f64, h: f64) -> f64 {
    let (x, y) = (0.5 * side / h, 0.5 * side / h);
    4.0 * (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
        + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan())
        / (2.0 * PI)
}

#[test]
fn tiny_beside_huge_in_one_scene() {
    // A 1 x 1 lamp 10 above a 1000 x 1000 floor (area ratio 1e-6), and a 1 x 1 grey tile under a
    // 1000 x 1000 glowing ceiling 20 above the floor.
    let (rho, lamp, glow) = (0.5, 1e4, 1.0);
    let mut scene = Scene::default();
    let half = 500.0;
    add_rect(
        &mut scene,
        "floor",
        dvec3(-half, 0.0, -half),
        DVec3::Z * 2.0 * half,
        DVec3::X * 2.0 * half,
        grey(rho, 0.0),
    );
    add_rect(
        &mut scene,
        "lamp",
        dvec3(-0.5, 10.0, -0.5),
        DVec3::X,
        DVec3::Z,
        grey(0.0, lamp),
    );
    add_rect(
        &mut scene,
        "ceiling",
        dvec3(-half, 20.0, -half),
        DVec3::X * 2.0 * half,
        DVec3::Z * 2.0 * half,
        grey(0.0, glow),
    );
    add_rect(
        &mut scene,
        "tile",
        dvec3(-0.5, 19.0, -0.5),
        DVec3::Z,
        DVec3::X,
        grey(rho, 0.0),
    );
    let solved = solve(scene, 400);
    let lamp_patches = solved.mesh.patches.iter().filter(|p| p.object == 1).count();
    assert_eq!(
        lamp_patches, 1,
        "the tiny lamp stays one patch beside a 1e6 floor"
    );
    // Floor: mean = rho * (A_lamp / A_floor) * F(lamp -> floor) * E, by reciprocity, plus the
    // ceiling's glow, F(floor -> ceiling) * 1 (the tile and lamp shadows are below 1e-5).
    let floor_area = (2.0 * half) * (2.0 * half);
    let ceiling_share = howell_parallel(2.0 * half, 2.0 * half, 20.0);
    let expected_floor = rho
        * (lamp * point_to_centred_square(2.0 * half, 10.0) / floor_area + glow * ceiling_share);
    let floor = mean_of(&solved, "floor").x;
    println!(
        "tiny lamp over a huge floor: floor {floor:.6e} vs {expected_floor:.6e} ({:+.3}%)",
        100.0 * (floor / expected_floor - 1.0)
    );
    assert!(
        (floor / expected_floor - 1.0).abs() < 0.01,
        "{floor} vs {expected_floor}"
    );
    // The tile sees the huge ceiling 1 above it: almost its whole hemisphere.
    let expected_tile = rho * point_to_centred_square(2.0 * half, 1.0) * glow;
    let tile = mean_of(&solved, "tile").x;
    println!(
        "tiny tile under a huge ceiling: {tile:.6} vs {expected_tile:.6} ({:+.3}%)",
        100.0 * (tile / expected_tile - 1.0)
    );
    assert!(
        (tile / expected_tile - 1.0).abs() < 0.01,
        "{tile} vs {expected_tile}"
    );
}

#[test]
fn hdr_emitters_keep_the_encoding_bound() {
    // Two lamps nine decades apart in one box.
    let mut scene = closed_cube(1.0, grey(0.5, 0.0));
    add_rect(
        &mut scene,
        "sun",
        dvec3(0.1, 0.99, 0.1),
        DVec3::X * 0.2,
        DVec3::Z * 0.2,
        grey(0.0, 1e6),
    );
    add_rect(
        &mut scene,
        "candle",
        dvec3(0.7, 0.01, 0.7),
        DVec3::Z * 0.2,
        DVec3::X * 0.2,
        grey(0.0, 1e-3),
    );
    let solved = solve(scene, 300);
    assert!(
        solved
            .radiosity
            .iter()
            .all(|b| b.is_finite() && b.min_element() >= 0.0)
    );
    let values: Vec<[f32; 3]> = solved
        .radiosity
        .iter()
        .map(|b| b.as_vec3().to_array())
        .collect();
    let brightest = values.iter().flatten().cloned().fold(0.0, f32::max);
    let scale = wire::scale_for(brightest);
    for rgb in &values {
        let back = wire::decode_colour(wire::encode_colour(*rgb, scale), scale);
        let max = rgb.iter().cloned().fold(0.0, f32::max);
        let bound = (wire::rgb9e5::RELATIVE_ERROR_BOUND * max).max(2f32.powi(-24) * scale);
        assert!(
            rgb.iter().zip(back).all(|(a, b)| (a - b).abs() <= bound),
            "{rgb:?} -> {back:?}"
        );
    }
    // Both lamps encode to their own value within 2^-9, although they are 1e9 apart.
    for lamp in ["sun", "candle"] {
        let b = mean_of(&solved, lamp).x as f32;
        let back = wire::decode_colour(wire::encode_colour([b; 3], scale), scale)[0];
        println!("{lamp}: {b:.6e} -> {back:.6e}");
        assert!(
            (back / b - 1.0).abs() <= wire::rgb9e5::RELATIVE_ERROR_BOUND,
            "{lamp}: {b} -> {back}"
        );
    }
}

#[test]
fn an_occluder_inside_a_closed_enclosure_keeps_the_furnace_exact() {
    // A closed box (outward faces) floating inside the closed room; everything emits and reflects alike.
    let (rho, emission) = (0.8, 1.0);
    let scene = occluded_furnace(grey(rho, emission));
    let solved = solve(scene, 400);
    let expected = emission / (1.0 - rho);
    let worst = solved
        .radiosity
        .iter()
        .map(|b| (b.x / expected - 1.0).abs())
        .fold(0.0, f64::max);
    println!("occluded furnace, rho {rho}: worst relative error {worst:.2e}");
    assert!(worst < 1e-3, "{worst}");
}

#[test]
fn no_light_leaks_through_a_closed_wall() {
    let solved = solve(two_rooms_one_lamp(), 600);
    let lit = brightness_of(&solved, "b");
    println!(
        "room b: {} patches, brightest {:e}",
        lit.len(),
        lit.iter().cloned().fold(0.0, f64::max)
    );
    assert!(
        !lit.is_empty() && lit.iter().all(|b| *b == 0.0),
        "light leaked into room b"
    );
    assert!(mean_of(&solved, "a").x > 0.1);
}
