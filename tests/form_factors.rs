//! Form factors against Howell's closed forms, reciprocity, and closed-box row sums.

mod common;

use common::*;
use solver::PatchTarget;

#[test]
fn closed_forms_reproduce_the_published_values() {
    // Howell's catalog values quoted in shared/REFERENCE.md.
    assert!((howell_parallel(1.0, 1.0, 1.0) - 0.199825).abs() < 1e-6);
    assert!((howell_parallel(2.0, 2.0, 1.0) - 0.41525).abs() < 1e-5);
    assert!((howell_perpendicular(1.0, 1.0, 1.0) - 0.200044).abs() < 1e-6);
}

/// From one patch per plate (every pair in the near field) to a fine mesh.
const MESHES: [PatchTarget; 5] = [
    PatchTarget::Count(2),
    PatchTarget::Count(8),
    PatchTarget::Count(50),
    PatchTarget::Count(200),
    PatchTarget::Count(1000),
];

#[test]
fn parallel_rectangles_match_howell_c11() {
    for (a, b, c) in [(1.0, 1.0, 1.0), (2.0, 2.0, 1.0), (3.0, 1.0, 0.5)] {
        let scene = parallel_plates(a, b, c, grey(0.5, 0.0), grey(0.0, 1.0));
        for target in MESHES {
            let (mesh, factors) = form_factors(&scene, target);
            let f = object_form_factor(&mesh, &factors, 0, 1);
            let expected = howell_parallel(a, b, c);
            assert!(
                (f - expected).abs() < 1e-3,
                "{a}x{b} at {c}, {target:?}: {f} vs {expected}"
            );
        }
    }
}

#[test]
fn perpendicular_rectangles_sharing_an_edge_match_howell_c14() {
    for (w, h, l) in [(1.0, 1.0, 1.0), (1.0, 2.0, 1.0), (0.5, 3.0, 2.0)] {
        let scene = hinge(w, h, l, grey(0.5, 0.0), grey(0.5, 0.0));
        for target in MESHES {
            let (mesh, factors) = form_factors(&scene, target);
            let f = object_form_factor(&mesh, &factors, 0, 1);
            let expected = howell_perpendicular(w, h, l);
            assert!(
                (f - expected).abs() < 1e-3,
                "w={w} h={h} l={l}, {target:?}: {f} vs {expected}"
            );
        }
    }
}

#[test]
fn reciprocity_holds_between_the_faces_of_a_box() {
    let scene = closed_cube(1.0, grey(0.5, 0.0));
    for target in [PatchTarget::Count(6), PatchTarget::Count(600)] {
        let (mesh, factors) = form_factors(&scene, target);
        let area = |object: u32| {
            mesh.patches
                .iter()
                .filter(|p| p.object == object)
                .map(|p| p.area)
                .sum::<f64>()
        };
        for a in 0..6 {
            for b in 0..6 {
                let (ab, ba) = (
                    area(a) * object_form_factor(&mesh, &factors, a, b),
                    area(b) * object_form_factor(&mesh, &factors, b, a),
                );
                // A_a F_ab = A_b F_ba; each direction has its own receiver quadrature.
                assert!(
                    (ab - ba).abs() <= 1e-3 * ab.max(ba) + 1e-12,
                    "{target:?}, faces {a}, {b}: {ab} vs {ba}"
                );
            }
        }
    }
}

#[test]
fn every_row_of_a_closed_box_sums_to_one() {
    let scene = closed_cube(2.0, grey(0.5, 0.0));
    for target in [PatchTarget::Count(6), PatchTarget::Count(300)] {
        let (mesh, factors) = form_factors(&scene, target);
        for i in 0..mesh.patches.len() {
            let sum: f64 = factors.row(i).iter().map(|&f| f as f64).sum();
            assert!((sum - 1.0).abs() < 1e-3, "{target:?} row {i} sums to {sum}");
        }
    }
}
