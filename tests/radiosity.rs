//! Radiosity answers known in closed form, and agreement between the solvers.

mod common;

use common::*;
use solver::{Method, PatchTarget, Rgb, SolveRequest, SolverSettings, solve_scene};

fn solve_with(
    scene: solver::Scene,
    patches: usize,
    method: Method,
    tolerance: f64,
) -> solver::Solved {
    let request = SolveRequest {
        patches: PatchTarget::Count(patches),
        solver: SolverSettings {
            method,
            tolerance,
            ..SolverSettings::default()
        },
        ..SolveRequest::default()
    };
    solve_scene(scene, &request, &solver::no_progress).expect("scene solves")
}

#[test]
fn furnace_gives_emission_over_one_minus_reflectance_with_every_method() {
    for rho in [0.5, 0.9] {
        for method in Method::ALL {
            let solved = solve_with(closed_cube(1.0, grey(rho, 1.0)), 150, method, 1e-7);
            let expected = 1.0 / (1.0 - rho);
            assert!(solved.report.converged, "{method} at rho {rho}");
            for b in &solved.radiosity {
                let worst = (*b - Rgb::splat(expected)).abs().max_element() / expected;
                assert!(worst < 1e-3, "{method} at rho {rho}: {b} vs {expected}");
            }
        }
    }
}

#[test]
fn bright_enclosures_converge_in_few_gmres_iterations() {
    for rho in [0.99, 0.999] {
        let solved = solve_with(closed_cube(1.0, grey(rho, 1.0)), 150, Method::Gmres, 1e-7);
        let expected = 1.0 / (1.0 - rho);
        let worst = solved
            .radiosity
            .iter()
            .map(|b| (b.x - expected).abs() / expected)
            .fold(0.0, f64::max);
        assert!(worst < 1e-3, "rho {rho}: worst relative error {worst}");
        // Jacobi would need ln(1e-7) / ln(rho) sweeps: 1,604 at 0.99 and 16,110 at 0.999.
        assert!(
            solved.report.iterations <= 60,
            "rho {rho}: {} iterations",
            solved.report.iterations
        );
    }
}

#[test]
fn receiver_mean_is_reflectance_times_form_factor_times_emission() {
    let (rho, emission) = (0.6, 10.0);
    let expected = rho * howell_parallel(1.0, 1.0, 1.0) * emission;
    for patches in [2, 1000] {
        let solved = solve_with(
            parallel_plates(1.0, 1.0, 1.0, grey(rho, 0.0), grey(0.0, emission)),
            patches,
            Method::Gmres,
            1e-9,
        );
        let receiver = &solved.report.objects[0];
        for channel in receiver.radiosity {
            assert!(
                (channel - expected).abs() < 1e-3 * emission * rho,
                "{patches} patches: {channel} vs {expected}"
            );
        }
        // The emitter is black: it keeps its own emission, up to the solver tolerance.
        for channel in solved.report.objects[1].radiosity {
            assert!((channel - emission).abs() < 1e-6 * emission, "{channel}");
        }
    }
}

#[test]
fn all_methods_agree_on_the_cornell_box() {
    let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).expect("shipped scene loads");
    let tolerance = 1e-8;
    let answers: Vec<_> = Method::ALL
        .iter()
        .map(|&m| solve_with(scene.clone(), 300, m, tolerance))
        .collect();
    let reference = &answers[3].radiosity;
    // |B - B*| <= |r| / (1 - rho_max); rho_max is 0.78 here.
    let bound = 2.0 * tolerance / (1.0 - 0.78);
    for solved in &answers {
        assert!(solved.report.converged, "{}", solved.report.method);
        let diff = solved
            .radiosity
            .iter()
            .zip(reference)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0, f64::max);
        let scale = reference
            .iter()
            .map(|b| b.max_element())
            .fold(0.0, f64::max);
        assert!(
            diff <= bound * scale,
            "{} differs by {diff}",
            solved.report.method
        );
    }
}

#[test]
fn a_scene_without_emitters_solves_to_zeros() {
    for method in Method::ALL {
        let solved = solve_with(closed_cube(1.0, grey(0.9, 0.0)), 50, method, 1e-6);
        assert!(solved.radiosity.iter().all(|b| *b == Rgb::ZERO), "{method}");
        assert_eq!(solved.report.residual, 0.0);
    }
}

#[test]
fn scaling_the_scene_leaves_radiosity_unchanged() {
    let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).expect("shipped scene loads");
    let base = solve_with(scene.clone(), 300, Method::Gmres, 1e-8);
    // From well under a nanometre to far past the BVH's f32 range (obvhs indexed out of bounds
    // past about 1e17; at 1e-10 the floor came out 38% too bright).
    for factor in [1e-14, 1e-10, 1e-3, 1e3, 1e17] {
        let scaled = solve_with(scene.scaled(factor), 300, Method::Gmres, 1e-8);
        let pairs = base
            .radiosity
            .iter()
            .zip(&scaled.radiosity)
            .chain(base.vertex_radiosity.iter().zip(&scaled.vertex_radiosity));
        for (a, b) in pairs {
            assert!(
                (*a - *b).abs().max_element() <= 1e-4 * a.max_element().max(1e-3),
                "scale {factor}: {a} vs {b}"
            );
        }
    }
}

#[test]
fn what_viewers_see_of_a_lit_plate_holds_its_light() {
    // A 1 x 1 plate 0.4 under an equal black lamp: the light it reflects is rho E F (Howell
    // C-11), and the direct light curves strongly across its patches. Interpolating exact point
    // values would lose part of it; the corners also carry what interpolation misses, so the
    // mean of the smooth reading is the plate's light.
    let (rho, emission, gap) = (0.6, 10.0, 0.4);
    let expected = rho * emission * howell_parallel(1.0, 1.0, gap);
    for patches in [20, 80] {
        let solved = solve_with(
            parallel_plates(1.0, 1.0, gap, grey(rho, 0.0), grey(0.0, emission)),
            patches,
            Method::Gmres,
            1e-9,
        );
        let shown = smooth_mean(&solved, "receiver");
        println!("{patches} patches: smooth mean {shown} against {expected}");
        for channel in shown.to_array() {
            assert!(
                (channel - expected).abs() < 5e-3 * expected,
                "{patches} patches: viewers see {channel} on average, the plate reflects {expected}"
            );
        }
    }
}
