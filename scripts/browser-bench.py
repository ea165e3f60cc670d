#!/usr/bin/env python3
"""Times the browser viewer in headless Chromium (docs/BENCHMARKS.md): from opening the page to
its first final picture, and the median time to draw a frame (`?frames=11`, each finished with
gl.finish()). Real time, no virtual clock; Chromium drives the page over DevTools.

Usage: scripts/browser-bench.py URL      (a running radcast-server's http://HOST:PORT/)
"""
import base64, json, os, socket, struct, subprocess, sys, time, urllib.request

def websocket(url):
    host, port, path = url.split("//")[1].split("/")[0].split(":")[0], int(url.split(":")[2].split("/")[0]), "/" + url.split("/", 3)[3]
    s = socket.create_connection((host, port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
    reply = b""
    while b"\r\n\r\n" not in reply:
        reply += s.recv(1)
    return s

def send(s, text):
    data = text.encode()
    mask = os.urandom(4)
    header = bytes([0x81]) + (bytes([0x80 | len(data)]) if len(data) < 126 else bytes([0x80 | 126]) + struct.pack(">H", len(data)))
    s.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

def receive(s):
    def exactly(n):
        out = b""
        while len(out) < n:
            out += s.recv(n - len(out))
        return out
    first, second = exactly(2)
    n = second & 0x7F
    if n == 126: n = struct.unpack(">H", exactly(2))[0]
    elif n == 127: n = struct.unpack(">Q", exactly(8))[0]
    return exactly(n).decode()

def main():
    url = sys.argv[1].rstrip("/") + "/?width=800&height=560&frames=11"
    browser = subprocess.Popen(["chromium", "--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                                "--window-size=800,600", "--remote-debugging-port=0", "about:blank"], stderr=subprocess.PIPE, text=True)
    for line in browser.stderr:
        if "DevTools listening on" in line:
            port = line.split(":")[2].split("/")[0]
            break
    targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
    s = websocket(next(t for t in targets if t["type"] == "page")["webSocketDebuggerUrl"])
    ids = iter(range(1, 10**9))
    def call(method, params):
        i = next(ids)
        send(s, json.dumps({"id": i, "method": method, "params": params}))
        while True:
            reply = json.loads(receive(s))
            if reply.get("id") == i:
                return reply
    call("Page.navigate", {"url": url})
    expression = ("new Promise(done => { const check = () => { const d = document.body && document.body.dataset;"
                  " if (d && d.frameMs) done([d.firstFinalMs, d.frameMs, d.checksum]); else setTimeout(check, 20); }; check(); })")
    for _ in range(20):
        reply = call("Runtime.evaluate", {"expression": expression, "awaitPromise": True, "returnByValue": True})
        if "error" not in reply and "exceptionDetails" not in reply["result"]:
            break
        time.sleep(0.2)
    first_final, frame, checksum = reply["result"]["result"]["value"]
    print(f"first final picture {first_final} ms after navigation start; frame {frame} ms (median of 11); checksum {checksum}")
    browser.kill()

main()
