// The browser viewer: fetches the geometry once, follows the WebSocket stream with the
// protocol decoder, and draws the vertex radiosity with WebGL2 the way the headless client
// does (linear radiosity interpolated over fan triangles, textured patches times texel / mean
// with the nearest texel, Reinhard tone map per pixel, sRGB).

import { ColourBuffer, NO_TEXTURE, SUBPROTOCOLS, checksum, decodeGeometry, decodeServerMessage, encodeRequestFull, sumChecksum } from "./protocol.js";
import { exposure, fanTriangles } from "./display.js";
import { togglePanel } from "./control.js";

const canvas = document.getElementById("view");
const status = document.getElementById("status");
const exposureInput = document.getElementById("exposure");
const gl = canvas.getContext("webgl2", { antialias: true });
// `?width=W&height=H` draws at a fixed size in CSS pixels (as `radcast-client view --width
// --height`), for exact comparisons; otherwise the canvas fills the window.
const query = new URLSearchParams(location.search);
if (query.has("width") && query.has("height")) {
  canvas.style.width = `${Number(query.get("width"))}px`;
  canvas.style.height = `${Number(query.get("height"))}px`;
}

const state = {
  geometry: null,
  geometryVersion: null,
  buffer: new ColourBuffer(),
  bytes: 0,
  latencyMs: null,
  serverChecksum: null,
  // The self-check's smooth reading ({rms, low, high}) from /api/solution, once there is one.
  estimate: null,
  connected: false,
  camera: null, // {target, offset (eye - target), up, fov, radius}
  emitting: [], // per object of the geometry: whether it emits now (left out of the exposure)
};

const VERTEX = `#version 300 es
in vec3 position;
in vec3 radiance;
in vec2 uv;
uniform mat4 viewProjection;
out vec3 exposed;
out vec2 textureAt;
void main() { exposed = radiance; textureAt = uv; gl_Position = viewProjection * vec4(position, 1.0); }`;
const FRAGMENT = `#version 300 es
precision highp float;
in vec3 exposed;
in vec2 textureAt;
uniform bool textured;
uniform sampler2D image;
uniform vec3 inverseMean;
out vec4 colour;
vec3 srgb(vec3 c) { return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c)); }
void main() {
  vec3 x = max(exposed, 0.0);
  if (textured) x *= texture(image, textureAt).rgb * inverseMean;
  colour = vec4(srgb(x / (1.0 + x)), 1.0);
}`;

function shader(type, source) {
  const s = gl.createShader(type);
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}

const program = gl.createProgram();
gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
gl.linkProgram(program);
const positionBuffer = gl.createBuffer();
const radianceBuffer = gl.createBuffer();
const uvBuffer = gl.createBuffer();
const indexBuffer = gl.createBuffer();
let indexCount = 0;
/** Runs of the index buffer drawn with one texture each: {texture (or NO_TEXTURE), first, count}. */
let runs = [];
/** The WebGL textures of the scene the page shows, loaded once per scene id. */
const images = { sceneId: null, textures: [] };

/** Loads `api/textures/I` for every texture the geometry names, as sRGB, nearest, repeating. */
async function loadTextures(geometry, sceneId) {
  if (images.sceneId === sceneId) return;
  const count = geometry.textures ? geometry.textures.means.length / 3 : 0;
  const loaded = [];
  for (let i = 0; i < count; i++) {
    // An <img> load, not createImageBitmap: headless Chromium's virtual time waits for it.
    const image = new Image();
    image.src = `api/textures/${i}`;
    await image.decode().catch(() => { throw new Error(`texture ${i} (api/textures/${i}) could not be loaded`); });
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, texture);
    // The texels as served: no colour-space conversion, no premultiplied alpha.
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.SRGB8_ALPHA8, gl.RGBA, gl.UNSIGNED_BYTE, image);
    for (const [name, value] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST], [gl.TEXTURE_WRAP_S, gl.REPEAT], [gl.TEXTURE_WRAP_T, gl.REPEAT]]) {
      gl.texParameteri(gl.TEXTURE_2D, name, value);
    }
    loaded.push(texture);
  }
  images.textures.forEach((t) => gl.deleteTexture(t));
  Object.assign(images, { sceneId, textures: loaded });
}

function setGeometry(geometry) {
  state.geometry = geometry;
  gl.bindBuffer(gl.ARRAY_BUFFER, positionBuffer);
  gl.bufferData(gl.ARRAY_BUFFER, geometry.positions, gl.STATIC_DRAW);
  gl.bindBuffer(gl.ARRAY_BUFFER, uvBuffer);
  gl.bufferData(gl.ARRAY_BUFFER, geometry.textures ? geometry.textures.uvs : new Float32Array(2 * (geometry.positions.length / 3)), gl.STATIC_DRAW);
  // Patches grouped by texture: one draw per texture.
  const textureOf = (p) => (geometry.textures ? geometry.textures.patchTextures[p] : NO_TEXTURE);
  const order = [...Array(geometry.patches.length / 4).keys()].sort((a, b) => textureOf(a) - textureOf(b));
  const sorted = new Uint32Array(geometry.patches.length);
  order.forEach((p, k) => sorted.set(geometry.patches.subarray(4 * p, 4 * p + 4), 4 * k));
  const triangles = fanTriangles(sorted);
  runs = [];
  let at = 0;
  order.forEach((p, k) => {
    const count = 3 * (sorted[4 * k + 3] === 0xffffffff ? 1 : 2);
    const last = runs[runs.length - 1];
    if (last && last.texture === textureOf(p)) last.count += count;
    else runs.push({ texture: textureOf(p), first: at, count });
    at += count;
  });
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indexBuffer);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, triangles, gl.STATIC_DRAW);
  indexCount = triangles.length;
  if (!state.camera) {
    state.camera = cameraFor(geometry);
    // `?control` opens the control panel at once.
    if (query.has("control")) togglePanel(state.camera.radius);
  }
}

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, k) => [a[0] * k, a[1] * k, a[2] * k];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const normalize = (a) => scale(a, 1 / Math.hypot(a[0], a[1], a[2]));
/** `v` turned by `angle` radians about the unit `axis` (Rodrigues). */
const rotate = (v, axis, angle) => {
  const [c, s] = [Math.cos(angle), Math.sin(angle)];
  return add(add(scale(v, c), scale(cross(axis, v), s)), scale(axis, dot(axis, v) * (1 - c)));
};

/**
 * The scene's own camera (eye, target, up, fov), or one framing its bounds from -z with +y up,
 * as the headless client frames it. Orbiting turns the eye about the target around `up`.
 */
function cameraFor(geometry) {
  const p = geometry.positions;
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < p.length; i++) {
    lo[i % 3] = Math.min(lo[i % 3], p[i]);
    hi[i % 3] = Math.max(hi[i % 3], p[i]);
  }
  const centre = lo.map((l, k) => 0.5 * (l + hi[k]));
  const radius = Math.max(0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]), 1e-30);
  const c = geometry.camera;
  const eye = c ? c.eye : [centre[0], centre[1], centre[2] - 1.1 * radius / Math.sin((45 * Math.PI) / 360)];
  const target = c ? [...c.target] : centre;
  return {
    target,
    offset: sub(eye, target),
    up: normalize(c ? c.up : [0, 1, 0]),
    fov: c ? c.verticalFovDegrees : 45,
    radius,
  };
}

/** The camera's orthonormal basis: `s` right, `u` up, `f` forward. */
function basis(camera) {
  const f = normalize(scale(camera.offset, -1));
  const s = normalize(cross(f, camera.up));
  return { s, u: cross(s, f), f };
}

function viewProjection(camera, aspect) {
  const { target, offset, fov } = camera;
  const eye = add(target, offset);
  const distance = Math.hypot(offset[0], offset[1], offset[2]);
  const { s, u, f } = basis(camera);
  const near = Math.max(distance * 1e-3, 1e-30);
  const far = distance + 4 * camera.radius;
  const t = 1 / Math.tan((fov * Math.PI) / 360);
  // Column-major: projection * view.
  const view = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0, -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
  const proj = [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, (2 * far * near) / (near - far), 0];
  const out = new Float32Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let sum = 0;
    for (let k = 0; k < 4; k++) sum += proj[4 * k + r] * view[4 * c + k];
    out[4 * c + r] = sum;
  }
  return out;
}

/** Orbits: `yaw` about the up axis, `pitch` about the view's right, never over a pole. */
function orbit(camera, yaw, pitch) {
  const turned = rotate(camera.offset, camera.up, yaw);
  const right = normalize(cross(camera.up, turned));
  const tilted = rotate(turned, right, pitch);
  const cosine = dot(normalize(tilted), camera.up);
  camera.offset = Math.abs(cosine) < 0.995 ? tilted : turned;
}

/** Uploads the current colours, decoded and exposed: the fragment shader tone-maps them. */
function uploadColours() {
  const { geometry, buffer } = state;
  if (!geometry || !buffer.info) return;
  const radiosity = buffer.radiosity().slice();
  if (radiosity.length !== geometry.positions.length) return;
  const k = exposure(geometry.positions, geometry.patches, radiosity, geometry.patchObjects, state.emitting) * 2 ** Number(exposureInput.value);
  for (let i = 0; i < radiosity.length; i++) radiosity[i] *= k;
  gl.bindBuffer(gl.ARRAY_BUFFER, radianceBuffer);
  gl.bufferData(gl.ARRAY_BUFFER, radiosity, gl.DYNAMIC_DRAW);
  draw();
}

function draw() {
  const width = Math.round(canvas.clientWidth * devicePixelRatio);
  const height = Math.round(canvas.clientHeight * devicePixelRatio);
  if (canvas.width !== width || canvas.height !== height) { canvas.width = width; canvas.height = height; }
  gl.viewport(0, 0, width, height);
  // For tests and tools: the drawing's size in device pixels.
  document.body.dataset.canvas = `${width}x${height}`;
  gl.clearColor(0, 0, 0, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!state.camera || !indexCount || !state.buffer.info) return;
  gl.enable(gl.DEPTH_TEST);
  gl.useProgram(program);
  gl.uniformMatrix4fv(gl.getUniformLocation(program, "viewProjection"), false, viewProjection(state.camera, width / height));
  const attribute = (name, buffer, size) => {
    const at = gl.getAttribLocation(program, name);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.enableVertexAttribArray(at);
    gl.vertexAttribPointer(at, size, gl.FLOAT, false, 0, 0);
  };
  attribute("position", positionBuffer, 3);
  attribute("radiance", radianceBuffer, 3);
  attribute("uv", uvBuffer, 2);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indexBuffer);
  const uniform = (name) => gl.getUniformLocation(program, name);
  gl.uniform1i(uniform("image"), 0);
  gl.activeTexture(gl.TEXTURE0);
  for (const run of runs) {
    const texture = run.texture === NO_TEXTURE ? undefined : images.textures[run.texture];
    gl.uniform1i(uniform("textured"), texture ? 1 : 0);
    if (texture) {
      // texel / mean per channel, 0 where the mean is 0 (docs/PROTOCOL.md).
      const mean = state.geometry.textures.means.subarray(3 * run.texture, 3 * run.texture + 3);
      gl.uniform3fv(uniform("inverseMean"), mean.map((m) => (m > 0 ? 1 / m : 0)));
      gl.bindTexture(gl.TEXTURE_2D, texture);
    }
    gl.drawElements(gl.TRIANGLES, run.count, gl.UNSIGNED_INT, 4 * run.first);
  }
}

/** A ratio as a percentage with one decimal. */
const percent = (ratio) => `${(100 * ratio).toFixed(1)}%`;

function showStatus() {
  const info = state.buffer.info;
  const held = state.buffer.sum ? "sum" : "codes";
  const local = !info ? null : held === "sum" ? sumChecksum(state.buffer.sum) : checksum(state.buffer.colours);
  const verified = state.serverChecksum === null ? "" : local === state.serverChecksum ? " ✓ matches /api/solution" : " ✗ differs from /api/solution";
  status.textContent = [
    state.connected ? "connected" : "reconnecting…",
    info ? `version ${info.solutionVersion}${info.isFinal ? " (final)" : ""}` : "waiting for a frame",
    state.geometry ? `${state.geometry.positions.length / 3} vertices, ${state.geometry.patches.length / 4} patches` : "",
    `${(state.bytes / 1024).toFixed(1)} KiB received`,
    state.latencyMs === null ? "" : `latency ${state.latencyMs.toFixed(0)} ms`,
    local === null ? "" : `checksum ${local.toString(16).padStart(8, "0")}${verified}`,
    state.estimate === null ? "" : `estimated error ${percent(state.estimate.rms)} (${percent(state.estimate.low)}–${percent(state.estimate.high)})`,
  ].filter(Boolean).join(" · ");
  document.body.dataset.estimate = state.estimate === null ? "" : String(state.estimate.rms);
  document.body.dataset.checksum = local === null ? "" : String(local);
  // What the checksum is of: the codes of frames, or (protocol 3) the values of a sum.
  document.body.dataset.held = held;
  document.body.dataset.final = info && info.isFinal ? "true" : "false";
  document.body.dataset.version = info ? String(info.solutionVersion) : "";
  document.body.dataset.geometry = state.geometryVersion === null ? "" : String(state.geometryVersion);
  document.body.dataset.connected = String(state.connected);
}

async function fetchGeometry(version) {
  // A move may land between the notice and the fetch: fetch until the versions agree.
  for (;;) {
    const response = await fetch("api/scene");
    const geometry = decodeGeometry(new Uint8Array(await response.arrayBuffer()));
    const fetched = BigInt(response.headers.get("x-radcast-geometry-version") || "0");
    if (version === null || fetched >= version) return [geometry, fetched];
  }
}

/** Which objects emit now (`api/objects`), by the geometry's object order; true if it changed. */
async function fetchEmitting() {
  const objects = await (await fetch("api/objects")).json();
  const emits = new Map(objects.map((o) => [o.name, o.emission.some((c) => c > 0)]));
  const emitting = state.geometry ? state.geometry.objects.map((name) => emits.get(name) === true) : [];
  const changed = emitting.join() !== state.emitting.join();
  state.emitting = emitting;
  return changed;
}

async function checkWithServer() {
  if (await fetchEmitting()) uploadColours();
  const summary = await (await fetch("api/solution")).json();
  const sameVersion = state.buffer.info && BigInt(summary.solution_version) === state.buffer.info.solutionVersion;
  state.serverChecksum = !sameVersion ? null : state.buffer.sum ? summary.sum_checksum ?? null : summary.checksum;
  state.estimate = summary.report && summary.report.estimate ? summary.report.estimate.smooth : null;
  showStatus();
}

function connect() {
  // Relative to the page, so an edge serves it under /scenes/NAME/ too.
  // Protocol 3 where the server speaks it: each light's response once, then only emissions.
  const socket = new WebSocket(new URL("ws", location.href.replace(/^http/, "ws")), SUBPROTOCOLS);
  socket.binaryType = "arraybuffer";
  let queue = Promise.resolve();
  socket.onopen = () => { state.connected = true; showStatus(); };
  socket.onmessage = (event) => {
    const bytes = new Uint8Array(event.data);
    // Messages apply in order, geometry fetches included.
    queue = queue.then(async () => {
      state.bytes += bytes.length;
      const message = decodeServerMessage(bytes);
      if (message.kind === "response") {
        state.buffer.apply(message);
        return;
      }
      if (message.kind === "hello" || message.kind === "geometry-changed") {
        if (message.kind === "hello") state.sceneId = message.sceneId;
        state.buffer.apply(message);
        if (state.geometryVersion !== message.geometryVersion) {
          const [geometry, version] = await fetchGeometry(message.geometryVersion);
          await loadTextures(geometry, state.sceneId);
          setGeometry(geometry);
          await fetchEmitting();
          state.geometryVersion = version;
        }
        return;
      }
      if (!state.buffer.apply(message)) {
        socket.send(encodeRequestFull());
        return;
      }
      state.latencyMs = Date.now() - Number(message.info.sentAt / 1000n);
      state.serverChecksum = null;
      uploadColours();
      showStatus();
      if (message.info.isFinal) {
        if (!document.body.dataset.firstFinalMs) {
          document.body.dataset.firstFinalMs = performance.now().toFixed(0);
          if (query.has("frames")) timeFrames(Number(query.get("frames")));
        }
        await checkWithServer();
      }
    }).catch((error) => { status.textContent = `error: ${error.message}`; socket.close(); });
  };
  socket.onclose = () => {
    state.connected = false;
    state.buffer = new ColourBuffer();
    showStatus();
    setTimeout(connect, 1000);
  };
}

/** `?frames=N`: draws N frames, each read back (so finished), and records the median in ms. */
function timeFrames(count) {
  const times = [];
  const pixel = new Uint8Array(4);
  for (let i = 0; i < count; i++) {
    const start = performance.now();
    orbit(state.camera, 0.01, 0);
    draw();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
    times.push(performance.now() - start);
  }
  times.sort((a, b) => a - b);
  document.body.dataset.frameMs = times[Math.floor(times.length / 2)].toFixed(1);
}

// Orbit (drag), pan (shift-drag or right-drag), zoom (wheel); on touch one finger orbits and
// two pinch to zoom.
const pointers = new Map();
let drag = null;
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("pointerdown", (e) => {
  pointers.set(e.pointerId, [e.clientX, e.clientY]);
  drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
  canvas.setPointerCapture(e.pointerId);
});
const release = (e) => { pointers.delete(e.pointerId); drag = null; };
canvas.addEventListener("pointerup", release);
canvas.addEventListener("pointercancel", release);
canvas.addEventListener("pointermove", (e) => {
  if (!state.camera || !pointers.has(e.pointerId)) return;
  const c = state.camera;
  if (pointers.size === 2) {
    const [a, b] = [...pointers.values()];
    const before = Math.hypot(a[0] - b[0], a[1] - b[1]);
    pointers.set(e.pointerId, [e.clientX, e.clientY]);
    const [p, q] = [...pointers.values()];
    const after = Math.hypot(p[0] - q[0], p[1] - q[1]);
    if (before > 0 && after > 0) c.offset = scale(c.offset, before / after);
    draw();
    return;
  }
  pointers.set(e.pointerId, [e.clientX, e.clientY]);
  if (!drag) return;
  const dx = e.clientX - drag.x;
  const dy = e.clientY - drag.y;
  drag.x = e.clientX;
  drag.y = e.clientY;
  if (drag.pan) {
    const distance = Math.hypot(c.offset[0], c.offset[1], c.offset[2]);
    const step = (distance * 2 * Math.tan((c.fov * Math.PI) / 360)) / canvas.clientHeight;
    const { s, u } = basis(c);
    c.target = add(c.target, add(scale(s, -dx * step), scale(u, dy * step)));
  } else {
    orbit(c, -dx * 0.005, -dy * 0.005);
  }
  draw();
});
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  if (state.camera) { state.camera.offset = scale(state.camera.offset, Math.exp(e.deltaY * 0.001)); draw(); }
}, { passive: false });
exposureInput.addEventListener("input", () => uploadColours());
document.getElementById("control-toggle").addEventListener("click", () => togglePanel(state.camera ? state.camera.radius : 1));
window.addEventListener("resize", draw);

showStatus();
connect();
