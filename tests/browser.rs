//! The browser viewer in a real browser: headless Chromium (WebGL2 on SwiftShader) against a
//! live server reaches the final frame, its checksum equals `/api/solution`'s, and its picture
//! agrees with the headless client's at the same camera and size. `.ci/run` installs Chromium
//! when it is missing; without it this test says so and skips.

use client::render::{View, render};
use server::prepared::{prepare, shared_for};
use server::{Limits, listen, solving};
use solver::{PatchTarget, SolveRequest};
use std::process::Command;
use std::time::Duration;

const CHROMIUM: &str = "chromium";

/// The value of `data-NAME="…"` on the page's body in `dom`.
fn body_data(dom: &str, name: &str) -> Option<String> {
    let body = &dom[dom.find("<body")?..];
    let body = &body[..body.find('>')?];
    let key = format!("data-{name}=\"");
    let start = body.find(&key)? + key.len();
    Some(body[start..start + body[start..].find('"')?].to_string())
}

/// Headless Chromium on `url`, page time running `budget_ms`; its stdout.
fn chromium(url: &str, extra: &[&str]) -> String {
    let output = Command::new(CHROMIUM)
        .args(["--headless", "--no-sandbox", "--use-angle=swiftshader"])
        .args(["--enable-unsafe-swiftshader", "--window-size=640,560"])
        .args(["--virtual-time-budget=20000", "--hide-scrollbars"])
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium runs");
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_shows_the_final_frame_as_the_headless_client_draws_it() {
    if Command::new(CHROMIUM).arg("--version").output().is_err() {
        eprintln!(
            "skipped: no `{CHROMIUM}` on this machine (Debian: apt-get install chromium; .ci/run installs it)"
        );
        return;
    }
    let request = SolveRequest {
        patches: PatchTarget::Count(600),
        ..SolveRequest::default()
    };
    let prepared = prepare("scenes/cornell-box.obj".as_ref(), request).unwrap();
    let shared = shared_for(&prepared, Limits::default(), "t".into());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(listen::serve(listener, shared.clone()));
    solving::start(prepared, shared.clone(), None);
    let mut published = shared.hub.subscribe();
    tokio::time::timeout(Duration::from_secs(60), published.wait_for(|p| p.is_final))
        .await
        .expect("the solve ends")
        .unwrap();

    // A fixed canvas size, so both runs and the client draw the same pixels.
    let url = format!("http://{address}/?width=640&height=480");
    let shot = tempfile::tempdir().unwrap();
    let png = shot.path().join("page.png");
    // One run dumps the page and screenshots it at the end of its page time, so the picture
    // is the state the page reports. Headless Chromium under virtual time now and then never
    // gets its WebSocket through (the page then says "reconnecting"): up to three runs.
    let dom = tokio::task::spawn_blocking({
        let png = png.clone();
        move || {
            let screenshot = format!("--screenshot={}", png.display());
            let mut dom = String::new();
            for _ in 0..3 {
                dom = chromium(&url, &["--dump-dom", &screenshot]);
                if body_data(&dom, "final").as_deref() == Some("true") {
                    break;
                }
            }
            dom
        }
    })
    .await
    .unwrap();
    shared.edits.close();
    let current = shared.hub.current();
    assert_eq!(body_data(&dom, "final").as_deref(), Some("true"), "{dom}");
    assert_eq!(
        body_data(&dom, "checksum"),
        Some(current.checksum.to_string()),
        "{dom}"
    );
    assert!(dom.contains("matches /api/solution"), "{dom}");

    // The same frame drawn by the headless client at the page's camera and canvas size.
    let size = body_data(&dom, "canvas").expect("the page names its canvas size");
    let (width, height) = size.split_once('x').unwrap();
    let (width, height): (u32, u32) = (width.parse().unwrap(), height.parse().unwrap());
    let geometry = shared.hub.geometry().model.clone();
    let mut buffer = wire::ColourBuffer::default();
    buffer
        .apply(&wire::ServerMessage::decode(&current.full).unwrap())
        .unwrap();
    let expected = render(
        &geometry,
        &buffer,
        &View::for_scene(&geometry),
        width,
        height,
    );
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut pixels).unwrap();
    let channels = frame.color_type.samples();
    let mut differences: Vec<u32> = Vec::new();
    for y in 0..height {
        for x in 0..width {
            let at = (y as usize * frame.width as usize + x as usize) * channels;
            let got = &pixels[at..at + 3];
            let want = expected.pixel(x, y);
            differences.extend((0..3).map(|c| got[c].abs_diff(want[c]) as u32));
        }
    }
    if let Some(dir) = std::env::var_os("RADCAST_BROWSER_DEBUG") {
        std::fs::copy(&png, std::path::Path::new(&dir).join("page.png")).unwrap();
        expected
            .write_png(&std::path::Path::new(&dir).join("client.png"))
            .unwrap();
    }
    differences.sort_unstable();
    let median = differences[differences.len() / 2];
    let p99 = differences[differences.len() * 99 / 100];
    let mean = differences.iter().sum::<u32>() as f64 / differences.len() as f64;
    eprintln!(
        "browser against headless client: median {median}, mean {mean:.2}, 99th percentile {p99}"
    );
    // Bound, in 8-bit sRGB units per channel (measured: median 0, mean 0.26, 99th percentile
    // 7): the rasterizers differ only at triangle edges (multisampling, coverage rules);
    // inside faces both interpolate the same values and tone-map them the same way.
    assert!(
        median <= 1 && mean <= 1.0 && p99 <= 32,
        "median {median}, mean {mean:.2}, 99th percentile {p99} over {width}x{height}"
    );
}
