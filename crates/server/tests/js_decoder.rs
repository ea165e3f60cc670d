//! The browser's JavaScript protocol decoder (crates/server/web/protocol.js) against the test
//! vectors the Rust wire crate writes: Node's built-in test runner, run from `cargo test` so
//! the one test command covers both languages.

use std::process::Command;

#[test]
fn the_javascript_decoder_reads_every_vector_as_rust_does() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");
    let output = match Command::new("node")
        .args(["--test", "crates/server/web/"])
        .current_dir(root)
        .output()
    {
        Ok(output) => output,
        Err(error) if std::env::var_os("RADCAST_SKIP_NODE").is_some() => {
            eprintln!("skipped: node did not run ({error}) and RADCAST_SKIP_NODE is set");
            return;
        }
        Err(error) => panic!(
            "node (Node.js 18 or later) runs the JavaScript decoder's tests and did not start: {error}; install it, or set RADCAST_SKIP_NODE=1 to skip them"
        ),
    };
    let report = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success() && report.contains("# fail 0"),
        "{report}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    // Every vector is a test of its own: all of them ran.
    let vectors = std::fs::read_dir(format!("{root}/tests/vectors"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "bin")
        })
        .count();
    let passed: usize = report
        .lines()
        .find_map(|l| l.strip_prefix("# pass "))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or(0);
    assert!(
        passed > vectors,
        "{passed} tests passed for {vectors} vectors\n{report}"
    );
}
