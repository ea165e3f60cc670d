//! The browser viewer in a real browser: headless Chromium (WebGL2 on SwiftShader) against a
//! live server reaches the final frame, and the checksum it computed equals `/api/solution`'s.
//! `.ci/run` installs Chromium when it is missing; without it this test says so and skips.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// The browser, where Debian's `chromium` package puts it.
const CHROMIUM: &str = "chromium";

/// Runs headless Chromium on `url` with `extra` flags, letting page time run `budget_ms`.
fn chromium(url: &str, budget_ms: u32, extra: &[&str]) -> Option<std::process::Output> {
    Command::new(CHROMIUM)
        .args([
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--window-size=640,520",
        ])
        .arg(format!("--virtual-time-budget={budget_ms}"))
        .args(extra)
        .arg(url)
        .output()
        .ok()
}

/// The value of `data-NAME="…"` on the page's body in `dom`.
fn body_data(dom: &str, name: &str) -> Option<String> {
    let body = &dom[dom.find("<body")?..];
    let body = &body[..body.find('>')?];
    let key = format!("data-{name}=\"");
    let start = body.find(&key)? + key.len();
    Some(body[start..start + body[start..].find('"')?].to_string())
}

#[test]
fn the_page_reaches_the_final_frame_with_the_servers_checksum() {
    if Command::new(CHROMIUM).arg("--version").output().is_err() {
        eprintln!(
            "skipped: no `{CHROMIUM}` on this machine (Debian: apt-get install chromium; .ci/run installs it)"
        );
        return;
    }
    let mut server = Command::new(env!("CARGO_BIN_EXE_radcast-server"))
        .args(["--addr", "127.0.0.1:0", "--no-cache", "--patches", "600"])
        .args(["--scene", "scenes/cornell-box.obj", "--token", "t"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("the server starts");
    let banner = BufReader::new(server.stdout.take().expect("piped"))
        .lines()
        .next()
        .expect("a banner")
        .expect("text");
    let address = banner
        .split("http://")
        .nth(1)
        .expect("an address")
        .trim()
        .to_string();
    let summary = || -> serde_json::Value {
        let text = ureq::get(format!("http://{address}/api/solution"))
            .call()
            .expect("answers")
            .into_body()
            .read_to_string()
            .expect("text");
        serde_json::from_str(&text).expect("JSON")
    };
    // The page stays open until its virtual time runs out; the solve of 600 patches ends long
    // before, and the page checks its buffer against /api/solution once it is final.
    let dom =
        chromium(&format!("http://{address}/"), 20_000, &["--dump-dom"]).expect("chromium runs");
    let dom = String::from_utf8_lossy(&dom.stdout).into_owned();
    let solution = summary();
    server.kill().expect("stops");
    server.wait().expect("reaped");
    assert_eq!(body_data(&dom, "final").as_deref(), Some("true"), "{dom}");
    assert_eq!(
        body_data(&dom, "checksum"),
        Some(solution["checksum"].to_string()),
        "{dom}"
    );
    assert!(dom.contains("matches /api/solution"), "{dom}");
}
