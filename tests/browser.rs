//! The browser viewer in a real browser: headless Chromium (WebGL2 on SwiftShader) against a
//! live server reaches the final frame, its checksum equals `/api/solution`'s, and its picture
//! agrees with the headless client's at the same camera and size. `.ci/run` installs Chromium
//! when it is missing; without it this test says so and skips.

use client::render::{Model, TextureImage, View, render};
use server::Limits;
use server::http::routes;
use server::publish::prepare::{prepare, shared_for};
use server::publish::solver_thread;
use solver::{PatchTarget, SolveRequest};
use std::process::Command;
use std::sync::Arc;
use std::time::Duration;

const CHROMIUM: &str = "chromium";

/// Whether Chromium is absent, said on stderr: the browser tests then skip.
fn chromium_missing() -> bool {
    let missing = Command::new(CHROMIUM).arg("--version").output().is_err();
    if missing {
        eprintln!(
            "skipped: no `{CHROMIUM}` on this machine (Debian: apt-get install chromium; .ci/run installs it)"
        );
    }
    missing
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_shows_the_final_frame_as_the_headless_client_draws_it() {
    if chromium_missing() {
        return;
    }
    compare_page_with_client("scenes/cornell-box.obj".as_ref()).await;
    // Textures: the page multiplies the light by texel / mean with the nearest texel, as the
    // client does.
    compare_page_with_client("scenes/tiled-cornell-box.obj".as_ref()).await;
    // A camera whose up is +x (rolled a quarter turn): the page must honour the scene's up.
    let rolled = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string("scenes/cornell-box.obj").unwrap();
    let view = text.lines().find(|l| l.starts_with("#@view")).unwrap();
    std::fs::write(
        rolled.path().join("cornell-box.obj"),
        text.replace(
            view,
            "#@view eye 278 273 -800 target 278 273 0 up 1 0 0 fov 39.3077",
        ),
    )
    .unwrap();
    std::fs::copy(
        "scenes/cornell-box.mtl",
        rolled.path().join("cornell-box.mtl"),
    )
    .unwrap();
    compare_page_with_client(&rolled.path().join("cornell-box.obj")).await;
}

/// Serves `scene`, lets headless Chromium show it, and compares the page with the headless
/// client's picture of the same frame at the same camera and size.
async fn compare_page_with_client(scene: &std::path::Path) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    let shared = serve(scene, listener);
    until_final(&shared).await;

    // A fixed canvas size, so the page and the client draw the same pixels. Driven over the
    // DevTools protocol in real time: under `--virtual-time-budget` the page's time ran on
    // while an image (a texture) decoded off the main thread, and the budget ran out first.
    let mut page = Page::open(&format!("http://{address}/?width=640&height=480")).await;
    // A viewport that holds the whole canvas (a DevTools-driven window may be shorter).
    let metrics =
        serde_json::json!({"width": 640, "height": 560, "deviceScaleFactor": 1, "mobile": false});
    page.call("Emulation.setDeviceMetricsOverride", metrics)
        .await;
    let shown = page.until(
        "d.final === 'true' && d.checksum !== '' && d.estimate !== '' && \
         document.getElementById('status').textContent.includes('matches /api/solution') && \
         document.getElementById('status').textContent.includes('estimated error')",
    );
    let state = tokio::time::timeout(Duration::from_secs(60), shown)
        .await
        .expect("the page shows the final frame, checked against /api/solution, within 60 s");
    let size = page.eval("document.body.dataset.canvas").await;
    let screenshot = base64::Engine::decode(
        &base64::engine::general_purpose::STANDARD,
        page.screenshot().await,
    )
    .unwrap();
    drop(page);
    shared.edits.close();
    let current = shared.hub.current();
    assert_eq!(
        state["checksum"].as_str(),
        Some(served_checksum(&state, &current).as_str()),
        "{state}"
    );
    let served_estimate = shared.report.lock().unwrap().as_ref().unwrap().estimate;
    assert_eq!(
        state["estimate"]
            .as_str()
            .and_then(|e| e.parse::<f64>().ok()),
        served_estimate.map(|e| e.smooth.rms),
        "the status line shows the server's self-check: {state}"
    );

    // The same frame drawn by the headless client at the page's camera and canvas size.
    let size = size.as_str().expect("the page names its canvas size");
    let (width, height) = size.split_once('x').unwrap();
    let (width, height): (u32, u32) = (width.parse().unwrap(), height.parse().unwrap());
    let served = shared.hub.geometry();
    let geometry = served.model.clone();
    let textures: Vec<TextureImage> = served
        .textures
        .iter()
        .map(|png| TextureImage::from_png(png).unwrap())
        .collect();
    let mut buffer = wire::ColourBuffer::default();
    buffer
        .apply(&wire::ServerMessage::decode(&current.full).unwrap())
        .unwrap();
    let emitting = shared
        .emissions
        .lock()
        .unwrap()
        .iter()
        .map(|(_, e)| e.iter().any(|c| *c > 0.0))
        .collect();
    let view = View::for_scene(&geometry);
    let model = Model {
        geometry: (*geometry).clone(),
        textures,
        emitting,
    };
    let expected = render(&model, &buffer, &view, width, height);
    let decoder = png::Decoder::new(std::io::Cursor::new(&screenshot));
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
        std::fs::write(std::path::Path::new(&dir).join("page.png"), &screenshot).unwrap();
        expected
            .write_png(&std::path::Path::new(&dir).join("client.png"))
            .unwrap();
    }
    differences.sort_unstable();
    let median = differences[differences.len() / 2];
    let p99 = differences[differences.len() * 99 / 100];
    let mean = differences.iter().sum::<u32>() as f64 / differences.len() as f64;
    eprintln!(
        "{}: browser against headless client: median {median}, mean {mean:.2}, 99th percentile {p99}",
        scene.display()
    );
    // Bound, in 8-bit sRGB units per channel (measured: median 0, mean 0.26, 99th percentile
    // 7): the rasterizers differ only at triangle edges (multisampling, coverage rules);
    // inside faces both interpolate the same values and tone-map them the same way.
    assert!(
        median <= 1 && mean <= 1.0 && p99 <= 32,
        "{}: median {median}, mean {mean:.2}, 99th percentile {p99} over {width}x{height}",
        scene.display()
    );
    shared.process.shutdown.cancel();
}

/// A page in headless Chromium, driven over the DevTools protocol.
struct Page {
    browser: std::process::Child,
    socket: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    next_id: u64,
}

impl Page {
    async fn open(url: &str) -> Page {
        use std::io::BufRead;
        let mut browser = Command::new(CHROMIUM)
            .args(["--headless", "--no-sandbox", "--use-angle=swiftshader"])
            .args(["--enable-unsafe-swiftshader", "--window-size=640,560"])
            .args(["--remote-debugging-port=0", url])
            .stderr(std::process::Stdio::piped())
            .stdout(std::process::Stdio::null())
            .spawn()
            .expect("chromium starts");
        let stderr = browser.stderr.take().unwrap();
        let endpoint = tokio::task::spawn_blocking(move || {
            std::io::BufReader::new(stderr)
                .lines()
                .map_while(Result::ok)
                .find_map(|l| l.split("DevTools listening on ").nth(1).map(str::to_string))
                .expect("chromium names its DevTools endpoint")
        })
        .await
        .unwrap();
        let port = endpoint
            .split(':')
            .nth(2)
            .unwrap()
            .split('/')
            .next()
            .unwrap()
            .to_string();
        let targets: serde_json::Value = tokio::task::spawn_blocking(move || {
            let text = ureq::get(format!("http://127.0.0.1:{port}/json/list"))
                .call()
                .unwrap()
                .into_body()
                .read_to_string()
                .unwrap();
            serde_json::from_str(&text).unwrap()
        })
        .await
        .unwrap();
        let page = targets
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["type"] == "page")
            .expect("a page target");
        let (socket, _) =
            tokio_tungstenite::connect_async(page["webSocketDebuggerUrl"].as_str().unwrap())
                .await
                .expect("DevTools connects");
        Page {
            browser,
            socket,
            next_id: 1,
        }
    }

    /// Calls a DevTools method and returns its reply (`result` or `error`).
    async fn call(&mut self, method: &str, params: serde_json::Value) -> serde_json::Value {
        use futures_util::{SinkExt, StreamExt};
        let id = self.next_id;
        self.next_id += 1;
        let request = serde_json::json!({ "id": id, "method": method, "params": params });
        self.socket
            .send(tokio_tungstenite::tungstenite::Message::Text(
                request.to_string().into(),
            ))
            .await
            .unwrap();
        loop {
            let message = tokio::time::timeout(Duration::from_secs(60), self.socket.next())
                .await
                .expect("DevTools answers")
                .expect("open")
                .expect("a message");
            if let tokio_tungstenite::tungstenite::Message::Text(text) = message {
                let reply: serde_json::Value = serde_json::from_str(&text).unwrap();
                if reply["id"] == id {
                    return reply;
                }
            }
        }
    }

    /// Evaluates `expression` in the page (awaiting a promise) and returns its value. A
    /// navigation under way destroys the context an evaluation started in: it is tried again
    /// in the new one (a few times).
    async fn eval(&mut self, expression: &str) -> serde_json::Value {
        let mut last = serde_json::Value::Null;
        for _ in 0..5 {
            last = self
                .call(
                    "Runtime.evaluate",
                    serde_json::json!({ "expression": expression, "awaitPromise": true, "returnByValue": true }),
                )
                .await;
            let failed =
                last.get("error").is_some() || last["result"].get("exceptionDetails").is_some();
            if !failed {
                return last["result"]["result"]["value"].clone();
            }
        }
        panic!("{expression}: {last}")
    }

    /// Waits in the page until `condition` (a JS expression over `d`, the body's dataset) holds;
    /// returns the dataset then.
    async fn until(&mut self, condition: &str) -> serde_json::Value {
        self.eval(&format!(
            "new Promise(done => {{ const check = () => {{ const d = document.body.dataset; \
             if ({condition}) done({{final: d.final, checksum: d.checksum, held: d.held, version: d.version, \
             geometry: d.geometry, connected: d.connected, estimate: d.estimate}}); else setTimeout(check, 10); }}; \
             check(); }})"
        ))
        .await
    }

    async fn screenshot(&mut self) -> String {
        self.call("Page.captureScreenshot", serde_json::json!({}))
            .await["result"]["data"]
            .as_str()
            .unwrap()
            .to_string()
    }
}

impl Drop for Page {
    fn drop(&mut self) {
        let _ = self.browser.kill();
        let _ = self.browser.wait();
    }
}

/// Serves `scene` (600 patches) on `listener`, solving in the background, until its
/// `shutdown` is cancelled.
fn serve(scene: &std::path::Path, listener: tokio::net::TcpListener) -> Arc<server::Shared> {
    let request = SolveRequest {
        patches: PatchTarget::Count(600),
        ..SolveRequest::default()
    };
    let prepared = prepare(scene, request).unwrap();
    let shared = shared_for(&prepared, Limits::default(), "t".into());
    tokio::spawn(routes::serve(listener, shared.clone()));
    solver_thread::start(prepared, shared.clone(), None);
    shared
}

/// Waits until `shared` has published its final solution.
async fn until_final(shared: &server::Shared) {
    let mut published = shared.hub.subscribe();
    tokio::time::timeout(Duration::from_secs(60), published.wait_for(|p| p.is_final))
        .await
        .expect("the solve ends")
        .unwrap();
}

/// Serves the Cornell box on `address` (see [`serve`]).
async fn serve_on(address: std::net::SocketAddr) -> Arc<server::Shared> {
    let listener = tokio::net::TcpListener::bind(address)
        .await
        .expect("the port is free");
    serve("scenes/cornell-box.obj".as_ref(), listener)
}

async fn put(address: std::net::SocketAddr, path: &str, body: &str) -> u16 {
    let (url, body) = (format!("http://{address}{path}"), body.to_string());
    tokio::task::spawn_blocking(move || {
        ureq::put(&url)
            .header("Authorization", "Bearer t")
            .send(body.as_bytes())
            .map(|r| r.status().as_u16())
            .unwrap_or(0)
    })
    .await
    .unwrap()
}

/// The checksum the server gives for what the page's `state` says it holds: the codes of frames,
/// or (protocol 3) the values of a sum.
fn served_checksum(state: &serde_json::Value, current: &server::publish::hub::Published) -> String {
    match state["held"].as_str() {
        Some("sum") => current.sum.as_ref().expect("a sum was sent").checksum,
        _ => current.checksum,
    }
    .to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_follows_edits_moves_and_a_server_restart() {
    if chromium_missing() {
        return;
    }
    let address = {
        let probe = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        probe.local_addr().unwrap()
    };
    let shared = serve_on(address).await;
    let mut page = Page::open(&format!("http://{address}/?width=640&height=480")).await;
    let first = page.until("d.final === 'true' && d.checksum !== ''").await;
    // A mouse drag orbits the camera: the picture changes.
    let still = page.screenshot().await;
    for (kind, x) in [
        ("mousePressed", 300),
        ("mouseMoved", 340),
        ("mouseReleased", 340),
    ] {
        page.call(
            "Input.dispatchMouseEvent",
            serde_json::json!({ "type": kind, "x": x, "y": 200, "button": "left", "buttons": 1, "clickCount": 1 }),
        )
        .await;
    }
    let before = page.screenshot().await;
    assert_ne!(before, still, "dragging orbits the view");

    // An emission edit: the page shows the new final version, and its pixels change.
    let edited = std::time::Instant::now();
    assert_eq!(
        put(
            address,
            "/api/objects/light/emission",
            r#"{"emission": [4, 12, 20]}"#
        )
        .await,
        202
    );
    let version = first["version"].as_str().unwrap().parse::<u64>().unwrap();
    let after_edit = page
        .until(&format!(
            "d.final === 'true' && Number(d.version) > {version}"
        ))
        .await;
    let edit_seconds = edited.elapsed().as_secs_f64();
    assert_eq!(
        after_edit["checksum"].as_str().unwrap(),
        served_checksum(&after_edit, &shared.hub.current())
    );
    assert_eq!(
        after_edit["held"], "sum",
        "an edit reaches the page as a sum"
    );
    assert_ne!(page.screenshot().await, before, "the picture changed");
    eprintln!("emission edit to the page's final picture: {edit_seconds:.3} s");
    assert!(edit_seconds < 5.0, "{edit_seconds} s");

    // A move: the page fetches the new geometry.
    assert_eq!(
        put(
            address,
            "/api/objects/short_block/transform",
            r#"{"translate": [30, 0, 0]}"#
        )
        .await,
        202
    );
    let moved = page.until("d.geometry === '2' && d.final === 'true'").await;
    assert_eq!(
        moved["checksum"].as_str().unwrap(),
        served_checksum(&moved, &shared.hub.current())
    );

    // A restart: the page reconnects to the new server and follows its solution.
    shared.edits.close();
    shared.process.shutdown.cancel();
    page.until("d.connected === 'false'").await;
    let restarted = serve_on(address).await;
    let back = page
        .until("d.connected === 'true' && d.final === 'true' && d.geometry === '1'")
        .await;
    until_final(&restarted).await;
    assert_eq!(
        back["checksum"].as_str().unwrap(),
        served_checksum(&back, &restarted.hub.current())
    );
    restarted.edits.close();
    restarted.process.shutdown.cancel();
}
