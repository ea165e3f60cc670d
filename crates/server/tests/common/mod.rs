//! Starting `radcast-server` as an operator would, for the tests that need the real process.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::process::{Child, Command, Stdio};

/// Starts `radcast-server ARGS --addr 127.0.0.1:0` from the repository root and reads the
/// address it got from the first banner line; the rest of stdout is closed (the server must not
/// mind).
pub fn start_server(args: &[&str]) -> (Child, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_radcast-server"))
        .args(args)
        .args(["--addr", "127.0.0.1:0"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("the server starts");
    let banner = BufReader::new(child.stdout.take().expect("piped"))
        .lines()
        .next()
        .expect("a banner")
        .expect("text");
    let address = banner
        .rsplit_once("http://")
        .and_then(|(_, a)| a.trim().parse().ok())
        .unwrap_or_else(|| panic!("no address in the banner: {banner}"));
    (child, address)
}
