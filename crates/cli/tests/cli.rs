//! The `radcast` command as a user runs it.

use std::process::Command;

fn radcast(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_radcast"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .output()
        .expect("radcast runs")
}

/// Runs a command that must succeed; returns its output, with the stderr text.
fn radcast_ok(args: &[&str]) -> (std::process::Output, String) {
    let output = radcast(args);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "{stderr}");
    (output, stderr)
}

/// Runs a command that must succeed and print one JSON object; returns it and the stderr text.
fn radcast_json(args: &[&str]) -> (serde_json::Value, String) {
    let (output, stderr) = radcast_ok(args);
    (
        serde_json::from_slice(&output.stdout).expect("one JSON object on stdout"),
        stderr,
    )
}

#[test]
fn every_solve_estimates_its_error_and_warns_when_it_is_large() {
    let solve = |patches: &str, extra: &[&str]| {
        radcast_json(
            &[
                &[
                    "solve",
                    "scenes/cornell-box.obj",
                    "--json",
                    "--patches",
                    patches,
                ][..],
                extra,
            ]
            .concat(),
        )
    };
    let (fine, quiet) = solve("1000", &[]);
    let estimate = &fine["estimate"];
    for reading in ["smooth", "flat"] {
        let value = |key: &str| estimate[reading][key].as_f64().expect(key);
        assert!(
            0.0 <= value("low") && value("low") <= value("rms") && value("rms") <= value("high"),
            "{reading}: {estimate}"
        );
        assert!(value("energy").abs() < 0.1, "{reading}: {estimate}");
    }
    // At least its first 64 probes, whatever the solve's time; a few per cent at 1,000 patches
    // (the stored reference reads 2.4% smooth).
    assert!(estimate["probes"].as_u64().unwrap() >= 64, "{estimate}");
    assert!(
        estimate["smooth"]["low"].as_f64().unwrap() < 0.05,
        "{estimate}"
    );
    assert!(estimate["noise"].as_f64().unwrap() > 0.0 && estimate["seconds"].as_f64().is_some());
    assert!(!quiet.contains("self-check"), "{quiet}");
    // Twelve dense patches for the whole box: far off, and said so with the figure.
    let (coarse, warned) = solve("12", &["--method", "gmres"]);
    let low = coarse["estimate"]["smooth"]["low"].as_f64().unwrap();
    assert!(low > 0.05, "{}", coarse["estimate"]);
    assert!(
        warned.contains(&format!(
            "warning: the self-check estimates {:.1}% smooth RMS error (at least {:.1}%), past 5%",
            100.0 * coarse["estimate"]["smooth"]["rms"].as_f64().unwrap(),
            100.0 * low
        )),
        "{warned}"
    );
    let (unchecked, _) = solve("1000", &["--check", "off"]);
    assert!(unchecked.get("estimate").is_none(), "{unchecked}");
}

#[test]
fn solve_json_reports_every_promised_field() {
    let (report, _) = radcast_json(&[
        "solve",
        "scenes/cornell-box.obj",
        "--patches",
        "200",
        "--method",
        "gauss-seidel",
        "--json",
    ]);
    assert_eq!(report["method"], "gauss-seidel");
    assert!(
        report["patches"].as_u64().unwrap().abs_diff(200) <= 20,
        "{}",
        report["patches"]
    );
    assert_eq!(report["triangles"], 38);
    assert!(report["iterations"].as_u64().unwrap() > 0);
    assert!(report["residual"].as_f64().unwrap() <= 1e-6);
    for stage in ["load", "mesh", "form_factors", "solve", "total"] {
        assert!(report["seconds"][stage].as_f64().unwrap() >= 0.0, "{stage}");
    }
    let objects = report["objects"].as_array().unwrap();
    let names: Vec<_> = objects
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "floor",
            "ceiling",
            "light",
            "back_wall",
            "right_wall",
            "left_wall",
            "short_block",
            "tall_block"
        ]
    );
    // The red wall is red and the green wall green: colour bleeding from the published materials.
    let rgb = |name: &str| -> Vec<f64> {
        let o = objects.iter().find(|o| o["name"] == name).unwrap();
        o["radiosity"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_f64().unwrap())
            .collect()
    };
    assert!(rgb("left_wall")[0] > 5.0 * rgb("left_wall")[1]);
    assert!(rgb("right_wall")[1] > 2.0 * rgb("right_wall")[0]);
    // The floor gets light, the emitter keeps at least its emission.
    assert!(rgb("floor").iter().all(|c| *c > 0.0));
    assert!(rgb("light")[0] >= 17.0);
}

#[test]
fn bad_input_exits_non_zero_with_the_reason() {
    let output = radcast(&["solve", "scenes/does-not-exist.obj"]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("scenes/does-not-exist.obj: cannot read"),
        "{stderr}"
    );

    let output = radcast(&["solve", "scenes/cornell-box.obj", "--method", "magic"]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("unknown method 'magic' (expected auto, hierarchical or one of: jacobi, gauss-seidel, progressive, gmres)"), "{stderr}");

    let output = radcast(&["solve", "scenes/cornell-box.obj", "--tolerance", "NaN"]);
    assert!(!output.status.success());
    assert!(
        String::from_utf8_lossy(&output.stderr).contains("--tolerance must be in (0, 1), got NaN")
    );

    let output = radcast(&[
        "solve",
        "scenes/cornell-box.obj",
        "--method",
        "hierarchical",
        "--error",
        "0",
    ]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("--error must be in (0, 1), got 0"));
}

#[test]
fn hierarchical_json_adds_elements_links_and_peak_memory_and_says_each_stage_as_it_begins() {
    let (report, stderr) = radcast_json(&[
        "solve",
        "scenes/cornell-box.obj",
        "--method",
        "hierarchical",
        "--error",
        "0.2",
        "--json",
    ]);
    assert_eq!(report["method"], "hierarchical");
    let (elements, links) = (
        report["elements"].as_u64().unwrap(),
        report["links"].as_u64().unwrap(),
    );
    // The leaves are the patches; each input face is at least one.
    assert_eq!(report["patches"].as_u64(), Some(elements));
    assert!(
        elements >= 20 && links > elements,
        "{elements} leaves, {links} links"
    );
    assert!(report["peak_memory_bytes"].as_u64().unwrap() > 0);
    assert!(report["residual"].as_f64().unwrap() <= 1e-6);
    // The steps that count nothing are named as they begin, in the order they run.
    let stages = [
        "loading scenes/cornell-box.obj: faces cut at contacts and sections",
        "cluster tree over 54 faces",
        "where light reaches: buried points and closed views",
    ];
    let at: Vec<Option<usize>> = stages.iter().map(|s| stderr.find(s)).collect();
    assert!(at.iter().all(Option::is_some), "{stderr}");
    assert!(at.windows(2).all(|w| w[0] < w[1]), "{stderr}");
}

#[test]
fn reference_writes_into_a_folder_it_creates() {
    let folder = std::env::temp_dir().join(format!("radcast-reference-{}", std::process::id()));
    let out = folder.join("new").join("slab.json");
    radcast_ok(&[
        "reference",
        "scenes/shadow-slab.obj",
        "--probes",
        "3",
        "--samples",
        "16",
        "--out",
        out.to_str().unwrap(),
    ]);
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(written["probes"].as_array().map(Vec::len), Some(3));
    std::fs::remove_dir_all(&folder).unwrap();
}

#[test]
fn with_no_method_asked_a_solve_says_which_it_chose_and_why() {
    // The Cornell box: 54 faces once its floor is cut around the blocks, 1,000 patches asked.
    let (report, stderr) = radcast_json(&["solve", "scenes/cornell-box.obj", "--json"]);
    assert!(
        stderr.contains(
            "method: auto chose dense gmres on 1003 patches (54 faces, at least 4 patches a face)"
        ),
        "{stderr}"
    );
    assert_eq!(report["method"], "gmres");
    // A furnished room of 30 pieces has more faces than 1,000 patches can give 4 each.
    let folder = tempfile::tempdir().unwrap();
    let room = folder.path().join("room.obj");
    radcast_ok(&[
        "generate",
        "--pieces",
        "30",
        "--out",
        room.to_str().unwrap(),
    ]);
    let (report, stderr) = radcast_json(&[
        "solve",
        room.to_str().unwrap(),
        "--error",
        "0.3",
        "--check",
        "off",
        "--json",
    ]);
    assert!(
        stderr.contains("method: auto chose hierarchical at --error 0.3 (")
            && stderr.contains(" patches gives fewer than 4 a face)"),
        "{stderr}"
    );
    assert_eq!(report["method"], "hierarchical");
    // Asked for by name, the method is used without a word.
    let (report, stderr) = radcast_json(&[
        "solve",
        "scenes/cornell-box.obj",
        "--method",
        "hierarchical",
        "--error",
        "0.3",
        "--check",
        "off",
        "--json",
    ]);
    assert_eq!(report["method"], "hierarchical");
    assert!(!stderr.contains("method: auto"), "{stderr}");
}

#[test]
fn generate_writes_a_room_that_loads() {
    let folder = std::env::temp_dir().join(format!("radcast-generate-{}", std::process::id()));
    let out = folder.join("room.obj");
    let (_, stderr) = radcast_ok(&[
        "generate",
        "--pieces",
        "30",
        "--seed",
        "5",
        "--out",
        out.to_str().unwrap(),
    ]);
    // 30 pieces, floor, ceiling, walls and one lamp per 4 m of a 10.25 m square ceiling (3 x 3).
    assert!(stderr.contains(": 42 objects,"), "{stderr}");
    assert!(folder.join("room.mtl").exists());
    std::fs::remove_dir_all(&folder).unwrap();
}

/// The smallest sweep: one dense count at one ray a pair, one knob, one run each.
const SMALL_SWEEP: [&str; 8] = [
    "--counts",
    "60",
    "--sweep-rays",
    "1",
    "--sweep-error",
    "0.3",
    "--repeat",
    "1",
];

#[test]
fn bench_error_makes_the_reference_of_a_scene_that_has_none() {
    let folder = std::env::temp_dir().join(format!("radcast-own-{}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    for file in ["shadow-slab.obj", "shadow-slab.mtl"] {
        let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/");
        std::fs::copy(format!("{shipped}{file}"), folder.join(file)).unwrap();
    }
    let scene = folder.join("shadow-slab.obj");
    let reference = folder.join("reference").join("shadow-slab.json");
    let sweep = |out: &str| {
        let out = folder.join(out);
        let place = ["--out-dir", out.to_str().unwrap()];
        radcast_ok(
            &[
                &["bench", "--error", scene.to_str().unwrap()],
                &SMALL_SWEEP[..],
                &place,
            ]
            .concat(),
        )
        .1
    };
    let said = sweep("first");
    assert!(
        said.contains(&format!(
            "{}: no reference: path-tracing one (1000 probes x 4096 paths)",
            reference.display()
        )),
        "{said}"
    );
    let made: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&reference).expect("written")).unwrap();
    assert_eq!(made["probes"].as_array().map(Vec::len), Some(1000));
    assert_eq!(made["samples"].as_u64(), Some(4096));
    let table = std::fs::read_to_string(folder.join("first/speed-vs-error.md")).expect("table");
    assert!(table.contains("| hierarchical E=0.3 |"), "{table}");
    // Made once: the next sweep reads it.
    assert!(!sweep("second").contains("no reference"));
    std::fs::remove_dir_all(&folder).unwrap();
}

#[test]
fn bench_error_writes_its_table_and_plot_under_the_given_name() {
    let folder = std::env::temp_dir().join(format!("radcast-bench-{}", std::process::id()));
    let args = [
        &["bench", "--error", "scenes/shadow-slab.obj"][..],
        &SMALL_SWEEP,
    ]
    .concat();
    radcast_ok(
        &[
            &args[..],
            &[
                "--out-dir",
                folder.to_str().unwrap(),
                "--name",
                "slab-check",
            ],
        ]
        .concat(),
    );
    let table =
        std::fs::read_to_string(folder.join("slab-check.md")).expect("the table is written");
    assert!(table.contains("--repeat 1 --name slab-check`"), "{table}");
    assert!(
        table.contains("Plot: [slab-check.svg](slab-check.svg)"),
        "{table}"
    );
    assert!(table.contains("| hierarchical E=0.3 |"), "{table}");
    assert!(
        std::fs::read_to_string(folder.join("slab-check.svg"))
            .expect("the plot is written")
            .starts_with("<svg")
    );
    std::fs::remove_dir_all(&folder).unwrap();
}

#[test]
fn a_leaf_budget_coarsens_the_knob_and_says_so() {
    let solve = |error: &str, extra: &[&str]| {
        radcast_json(
            &[
                &[
                    "solve",
                    "scenes/cornell-box.obj",
                    "--method",
                    "hierarchical",
                    "--json",
                    "--error",
                    error,
                ],
                extra,
            ]
            .concat(),
        )
    };
    let (free, quiet) = solve("0.1", &[]);
    assert_eq!(
        (
            free["knob_used"].as_f64(),
            free["leaf_budget_reached"].as_bool()
        ),
        (Some(0.1), Some(false))
    );
    assert!(!quiet.contains("warning"), "{quiet}");
    // Half the leaves the knob wants: refinement goes on at a doubled knob where it would pass
    // them: 0.2, or coarser for what the generations before spent at 0.1, up to the first
    // doubling past 0.5, after which elements stop splitting instead.
    let budget = free["elements"].as_u64().unwrap() / 2;
    let (bounded, warned) = solve("0.1", &["--max-leaves", &budget.to_string()]);
    let knob = bounded["knob_used"].as_f64().unwrap();
    assert!([0.2, 0.4, 0.8].contains(&knob), "{knob}");
    assert_eq!(bounded["leaf_budget_reached"].as_bool(), Some(false));
    assert!(bounded["elements"].as_u64().unwrap() <= budget);
    assert!(warned.contains(&format!("warning: --error 0.1 needs more than --max-leaves {budget} leaves or --max-links 10000000 links here; refinement went on at --error {knob} where it would have passed them")), "{warned}");
    // Past a knob of 0.5 there is nothing coarser to try: elements stop splitting at the budget.
    let (frozen, warned) = solve("0.6", &["--max-leaves", "60"]);
    assert_eq!(
        (
            frozen["knob_used"].as_f64(),
            frozen["leaf_budget_reached"].as_bool()
        ),
        (Some(0.6), Some(true))
    );
    let leaves = frozen["elements"].as_u64().unwrap();
    assert!(leaves <= 60);
    assert!(
        warned.contains(&format!("warning: element splits stopped at {leaves} leaves, where the next ones would have passed --max-leaves 60 even at --error 0.6")),
        "{warned}"
    );
    let refused = radcast(&[
        "solve",
        "scenes/cornell-box.obj",
        "--method",
        "hierarchical",
        "--max-leaves",
        "0",
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--max-leaves must be at least 1"));
}

/// The CI slice of `radcast fuzz`: a fixed seed, a few hundred scenes and thousands of
/// messages, no finding (docs/RELIABILITY.md has the long runs).
#[test]
fn a_seeded_fuzz_slice_finds_nothing() {
    let findings = tempfile::tempdir().unwrap();
    for (target, cases) in [("scene", "2000"), ("wire", "10000")] {
        let (output, _) = radcast_ok(&[
            "fuzz",
            target,
            "--cases",
            cases,
            "--seed",
            "2026",
            "--findings",
            findings.path().to_str().unwrap(),
        ]);
        let summary = String::from_utf8_lossy(&output.stdout);
        assert!(
            summary.starts_with(&format!("{target}: {cases} cases"))
                && summary.contains(", 0 findings;"),
            "{summary}"
        );
    }
}

#[test]
fn a_scene_that_emits_no_light_is_warned_about_before_the_solve() {
    let folder = tempfile::tempdir().unwrap();
    std::fs::write(
        folder.path().join("dark.mtl"),
        "newmtl grey\nKd 0.5 0.5 0.5\n",
    )
    .unwrap();
    let scene = folder.path().join("dark.obj");
    std::fs::write(
        &scene,
        "mtllib dark.mtl\no floor\nusemtl grey\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 4 3 2 1\n",
    )
    .unwrap();
    for method in ["gmres", "hierarchical"] {
        let (report, stderr) = radcast_json(&[
            "solve",
            scene.to_str().unwrap(),
            "--method",
            method,
            "--json",
        ]);
        assert!(
            stderr.contains(
                "warning: no material emits light (no positive Ke): every radiosity is 0"
            ),
            "{method}: {stderr}"
        );
        assert!(
            report["objects"][0]["radiosity"]
                .as_array()
                .unwrap()
                .iter()
                .all(|c| c.as_f64() == Some(0.0)),
            "{report}"
        );
    }
}

#[test]
fn a_solve_to_a_target_says_where_it_stopped_and_refuses_what_cannot_work() {
    let (value, stderr) = radcast_json(&[
        "solve",
        "scenes/cornell-box.obj",
        "--method",
        "hierarchical",
        "--target-error",
        "0.08",
        "--json",
    ]);
    let target = &value["target"];
    assert_eq!(target["error"], 0.08, "{value}");
    assert_eq!(target["reached"], true, "{value}");
    assert_eq!(target["stopped"], "reached", "{value}");
    let steps = target["steps"].as_array().unwrap();
    let last = steps.last().unwrap();
    assert_eq!(last["high"], value["estimate"]["smooth"]["high"], "{value}");
    assert_eq!(last["knob"], value["knob_used"], "{value}");
    // Each step that fell short says so, and what comes next.
    assert_eq!(
        stderr.matches("self-check: ").count(),
        steps.len() - 1,
        "{stderr}"
    );

    for (args, reason) in [
        (
            &["--target-error", "1.5"][..],
            "--target-error must be in (0, 1), got 1.5",
        ),
        (
            &["--target-error", "0.05", "--time-limit", "0"],
            "--time-limit must be a positive number of seconds, got 0",
        ),
        (
            &["--target-error", "0.05", "--check", "off"],
            "--target-error needs the self-check: drop --check off",
        ),
        (
            &["--time-limit", "10", "--patches", "500"],
            "--time-limit bounds a solve to a target: give --target-error",
        ),
        (
            &["--target-error", "five"],
            "expected a number or `off`, got \"five\"",
        ),
    ] {
        let output = radcast(&[&["solve", "scenes/cornell-box.obj"][..], args].concat());
        assert!(!output.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
    }
}

#[test]
fn with_no_resolution_asked_a_solve_goes_to_five_per_cent_and_with_one_it_solves_once() {
    // Nothing fixes the resolution: the default target holds.
    let (report, _) = radcast_json(&["solve", "scenes/shadow-slab.obj", "--json"]);
    assert_eq!(report["target"]["error"], 0.05, "{report}");
    // --patches, --patch-size or --error fix it, and so does `--target-error off` or
    // `--check off`: one solve, at what was asked.
    for args in [
        &["--patches", "300"][..],
        &["--patch-size", "0.5"],
        &["--method", "hierarchical", "--error", "0.3"],
        &["--target-error", "off"],
        &["--check", "off"],
    ] {
        let (report, _) =
            radcast_json(&[&["solve", "scenes/shadow-slab.obj", "--json"][..], args].concat());
        assert!(report.get("target").is_none(), "{args:?}: {report}");
    }
    // Asked for with a resolution, the target holds, from that resolution.
    let (report, _) = radcast_json(&[
        "solve",
        "scenes/shadow-slab.obj",
        "--patches",
        "300",
        "--target-error",
        "0.2",
        "--json",
    ]);
    assert_eq!(report["target"]["error"], 0.2, "{report}");
    assert_eq!(
        report["target"]["steps"][0]["patches"]
            .as_u64()
            .map(|p| p.abs_diff(300) <= 30),
        Some(true),
        "{report}"
    );
}
