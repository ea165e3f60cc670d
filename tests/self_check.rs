//! The self-check's estimate against errors known exactly: a solution of the plates, right to
//! a fraction of a percent, and the same solution made 10% too bright everywhere.

mod common;

use common::*;
use solver::check::{CheckSettings, self_check};
use solver::visibility::Occluders;
use solver::{PatchTarget, Rgb, SolveRequest, Solved, solve_scene};

/// The plates (a grey one under a lamp one) solved densely on `patches` patches, and their
/// occluders.
fn solved_plates(patches: usize) -> (Solved, Occluders) {
    let request = SolveRequest {
        patches: PatchTarget::Count(patches),
        ..SolveRequest::default()
    };
    let scene = parallel_plates(1.0, 1.0, 1.0, grey(0.6, 0.0), grey(0.0, 10.0));
    let solved = solve_scene(scene, &request, &solver::no_progress).expect("solves");
    let occluders = Occluders::new(&solved.scene);
    (solved, occluders)
}

#[test]
fn the_estimate_recovers_a_known_error_within_its_interval_for_every_seed() {
    let (solved, occluders) = solved_plates(400);
    let brighter = |values: &[Rgb]| values.iter().map(|b| *b * 1.1).collect::<Vec<_>>();
    let (flat, smooth) = (
        brighter(&solved.radiosity),
        brighter(&solved.vertex_radiosity),
    );
    for seed in 1..=8 {
        let settings = CheckSettings {
            seed,
            ..CheckSettings::default()
        };
        let check = |radiosity: &[Rgb], corners: &[Rgb]| {
            self_check(
                &solved.scene,
                &occluders,
                &solved.mesh,
                (radiosity, corners),
                &settings,
                &solver::no_progress,
            )
        };
        let right = check(&solved.radiosity, &solved.vertex_radiosity);
        let off = check(&flat, &smooth);
        println!(
            "seed {seed}: right smooth {:.4} [{:.4}, {:.4}] flat {:.4}; 10% off: smooth {:.4} [{:.4}, {:.4}] energy {:+.4}, flat {:.4} [{:.4}, {:.4}]; noise {:.4}, {} probes, {:.2} s",
            right.smooth.rms,
            right.smooth.low,
            right.smooth.high,
            right.flat.rms,
            off.smooth.rms,
            off.smooth.low,
            off.smooth.high,
            off.smooth.energy,
            off.flat.rms,
            off.flat.low,
            off.flat.high,
            off.noise,
            off.probes,
            off.seconds
        );
        // The solution is right to a fraction of a percent at what viewers see (the 1% noise
        // of 256 probes x 1,024 paths is taken out), and 10% off when made 10% brighter.
        assert!(right.smooth.high < 0.01, "seed {seed}: {right:?}");
        assert!(
            off.smooth.low <= 0.1 && 0.1 <= off.smooth.high,
            "seed {seed}: {off:?}"
        );
        assert!(
            (off.smooth.energy - 0.1).abs() < 0.005,
            "seed {seed}: {off:?}"
        );
        // Patch means carry their own error (about 2% here) under the 10%.
        assert!(
            off.flat.low <= 0.105 && off.flat.high >= 0.1,
            "seed {seed}: {off:?}"
        );
        assert_eq!(off.probes, 256);
    }
}

#[test]
fn the_check_shows_its_probes_as_it_traces_them_and_stops_within_its_time() {
    let (solved, occluders) = solved_plates(100);
    let check = |settings: &CheckSettings| {
        let shown = std::sync::Mutex::new(Vec::new());
        let estimate = self_check(
            &solved.scene,
            &occluders,
            &solved.mesh,
            (&solved.radiosity, &solved.vertex_radiosity),
            settings,
            &|p| shown.lock().unwrap().extend(p.describe()),
        );
        (estimate, shown.into_inner().unwrap())
    };
    // With no time limit, every probe, the count shown reaching them all.
    let (all, shown) = check(&CheckSettings::default());
    assert_eq!(all.probes, 256);
    assert!(
        shown.iter().all(|line| line.starts_with("self-check: ")),
        "{shown:?}"
    );
    assert!(
        shown.contains(&"self-check: 256 of 256 probes".to_string()),
        "{shown:?}"
    );
    // With none to spare, only the first ones: the time is looked at between chunks.
    let hurried = CheckSettings {
        seconds: Some(0.0),
        ..CheckSettings::default()
    };
    assert_eq!(check(&hurried).0.probes, solver::check::FIRST_PROBES);
}

/// `--target-error` on the Cornell box, both ways: a hierarchy refined from where it is (each
/// step's knob half the last, from 0.8, but where the first step's link budget stopped it;
/// its leaves never fewer) and a dense mesh solved again
/// twice as fine. Each stops at the first step whose bound is within the target, and the
/// answer is within it against the stored reference too.
#[test]
fn a_solve_to_a_target_stops_within_it_and_is_within_it_on_the_cornell_box() {
    let path = "scenes/reference/cornell-box.json";
    let text = std::fs::read_to_string(path).expect("the shipped reference");
    let reference: solver::reference::Reference = serde_json::from_str(&text).expect(path);
    let target = solver::Target {
        error: 0.05,
        seconds: None,
    };
    let dense = SolveRequest {
        patches: PatchTarget::Count(100),
        ..SolveRequest::default()
    };
    let hierarchical = dense.with_method(
        solver::MethodChoice::Hierarchical,
        solver::HierarchySettings::default(),
    );
    for request in [hierarchical, dense] {
        let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).unwrap();
        let request = SolveRequest {
            target: Some(target),
            ..request
        };
        let solved = solve_scene(scene, &request, &solver::no_progress).unwrap();
        let report = solved.report.target.clone().expect("a target was asked");
        let steps = &report.steps;
        println!("{report:?}");
        assert!(report.reached && report.stopped == "reached", "{report:?}");
        let last = steps.last().unwrap();
        assert!(last.high <= target.error, "{report:?}");
        assert!(
            steps[..steps.len() - 1]
                .iter()
                .all(|s| s.high > target.error),
            "stopped at the first step within the target: {report:?}"
        );
        assert_eq!(
            solved.report.estimate.map(|e| e.smooth.high),
            Some(last.high)
        );
        for pair in steps.windows(2) {
            match (pair[0].knob, pair[1].knob) {
                (Some(coarse), Some(fine)) => {
                    // A first step stopped at its link budget goes on at its knob under the
                    // whole budget; every other step halves the knob.
                    let raised = pair[0].max_links < pair[1].max_links;
                    if fine != coarse || !raised {
                        assert_eq!(fine, (coarse / 2.0).max(0.03), "{report:?}");
                    }
                    assert!(pair[1].patches >= pair[0].patches, "{report:?}");
                }
                _ => assert!(pair[1].patches > pair[0].patches, "{report:?}"),
            }
        }
        assert_eq!(steps[0].knob.is_some(), request.hierarchy.is_some());
        if let Some(knob) = steps[0].knob {
            assert_eq!(knob, solver::STARTING_KNOB);
            let whole = solver::HierarchySettings::default().max_links;
            assert!(
                steps.iter().all(|s| s.max_links <= Some(whole)),
                "{report:?}"
            );
        }
        let measured = solver::accuracy::evaluate(
            &solved.scene,
            &solved.mesh,
            &solved.radiosity,
            &solved.vertex_radiosity,
            &reference.probes,
        );
        assert!(
            measured.smooth.rms <= target.error,
            "{} against the reference: {report:?}",
            measured.smooth.rms
        );
    }
}

/// A hierarchical solve, default settings, to the smooth RMS `error`.
fn hierarchical_to(error: f64) -> SolveRequest {
    SolveRequest {
        target: Some(solver::Target {
            error,
            seconds: None,
        }),
        ..SolveRequest::default().with_method(
            solver::MethodChoice::Hierarchical,
            solver::HierarchySettings::default(),
        )
    }
}

/// A solve to a target makes at most `8 n log2 n` links in its first step (`n` faces): the
/// shadow slab's 4 faces, 64. Its first step stops there (68 links, "about"), within 5% but
/// not within 2%, and goes on at the same knob under the whole link budget, which every
/// later step keeps.
#[test]
fn a_first_step_stopped_at_its_link_budget_goes_on_at_its_knob_under_the_whole_budget() {
    let whole = solver::HierarchySettings::default().max_links;
    let solve_to = |error: f64| {
        let request = hierarchical_to(error);
        let scene = solver::load_obj("scenes/shadow-slab.obj".as_ref()).unwrap();
        solve_scene(scene, &request, &solver::no_progress)
            .unwrap()
            .report
    };
    let within_five = solve_to(0.05);
    let steps = within_five.target.expect("a target was asked").steps;
    assert_eq!(steps.len(), 1, "{steps:?}");
    assert_eq!(steps[0].max_links, Some(64));
    let first = within_five.hierarchy.unwrap();
    // The pairs past the budget are left to the corners' gathers, not sampled into links.
    assert!(
        first.link_budget_reached && first.deferred_pairs > 0,
        "{first:?}"
    );
    assert!(first.links <= 64, "{first:?}");

    let within_two = solve_to(0.02);
    let steps = within_two.target.expect("a target was asked").steps;
    assert!(steps.len() >= 2, "{steps:?}");
    assert_eq!(
        (steps[1].knob, steps[1].max_links),
        (steps[0].knob, Some(whole))
    );
    assert!(
        steps[1..].iter().all(|s| s.max_links == Some(whole)),
        "{steps:?}"
    );
    // The next step decided them under the whole budget.
    let last = within_two.hierarchy.unwrap();
    assert!(
        !last.link_budget_reached && last.deferred_pairs == 0,
        "{last:?}"
    );
}

/// A hierarchy solved to a target is built again after a move at the knob the run reached,
/// not at the `--error` floor it did not need.
#[test]
fn a_move_rebuilds_a_hierarchy_solved_to_a_target_at_the_knob_it_reached() {
    // The Cornell box reads about 5% at the starting knob: 3% takes steps, and is reached
    // above the 0.03 floor.
    let request = hierarchical_to(0.03);
    let target = request.target.unwrap();
    let scene = solver::load_obj("scenes/cornell-box.obj".as_ref()).unwrap();
    let (mut session, report) =
        solver::session_to_target(&scene, &request, &target, &solver::no_progress, &mut |_| {})
            .unwrap();
    let run = report.target.expect("a target was asked");
    let reached = run.steps.last().unwrap().knob.unwrap();
    assert!(
        run.steps.len() >= 2 && reached > request.hierarchy.unwrap().error,
        "refined further, and stopped before the floor: {run:?}"
    );
    session
        .move_object("short_block", glam::dvec3(20.0, 0.0, 0.0))
        .unwrap();
    let moved = session.solve(&solver::no_progress);
    assert_eq!(moved.hierarchy.unwrap().knob_used, reached);
}
