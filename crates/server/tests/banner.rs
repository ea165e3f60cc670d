//! The start banner as an operator sees it.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

#[test]
fn a_token_the_operator_supplied_is_never_printed() {
    let cache = std::env::temp_dir().join(format!("radcast-banner-{}", std::process::id()));
    let mut server = Command::new(env!("CARGO_BIN_EXE_radcast-server"))
        .args(["--token", "s3cret-operator-token", "--addr", "127.0.0.1:0"])
        .args(["--scene", "scenes/shadow-slab.obj", "--cache-dir"])
        .arg(&cache)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("the server starts");
    let mut banner = Vec::new();
    for line in BufReader::new(server.stdout.take().expect("piped")).lines() {
        let line = line.expect("text");
        let last = line.trim_start().starts_with("control:");
        banner.push(line);
        if last {
            break;
        }
    }
    server.kill().expect("stops");
    server.wait().expect("reaped");
    let _ = std::fs::remove_dir_all(&cache);
    let control = banner.last().expect("a banner");
    assert!(control.contains("Bearer $RADCAST_TOKEN"), "{banner:?}");
    assert!(banner.iter().all(|l| !l.contains("s3cret")), "{banner:?}");
}
