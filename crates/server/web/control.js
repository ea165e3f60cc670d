// The control panel: with the bearer token typed in (kept in this page's memory only, never in
// the URL or storage), set each emitter's colour and intensity and move and turn objects, through the
// control API (PUT /api/objects/NAME/emission and /transform). Every open page follows the
// result through its own stream.

const panel = document.getElementById("control");
const token = document.getElementById("token");
const table = document.getElementById("objects");
const report = document.getElementById("control-status");

const toSrgb = (c) => (c <= 0.0031308 ? 12.92 * c : 1.055 * c ** (1 / 2.4) - 0.055);
const toLinear = (c) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);

/** An emission as a picker colour (its chromaticity, sRGB hex) and an intensity (its largest channel). */
function split(emission) {
  const intensity = Math.max(...emission);
  if (!(intensity > 0)) return ["#ffffff", 0];
  const hex = emission.map((c) => Math.round(255 * toSrgb(c / intensity)).toString(16).padStart(2, "0")).join("");
  return [`#${hex}`, intensity];
}

function join(hex, intensity) {
  return [1, 3, 5].map((i) => toLinear(parseInt(hex.slice(i, i + 2), 16) / 255) * intensity);
}

/** PUTs `{[what]: value}`: `emission` to the object's emission, `translate` or `rotate` to its transform. */
async function put(name, what, value) {
  const response = await fetch(`api/objects/${encodeURIComponent(name)}/${what === "emission" ? "emission" : "transform"}`, {
    method: "PUT",
    headers: { "Content-Type": "application/json", Authorization: `Bearer ${token.value}` },
    body: JSON.stringify({ [what]: value }),
  });
  const body = await response.json().catch(() => ({}));
  report.textContent = response.ok ? `${name}: ${what} queued` : `${name}: ${response.status} ${body.error || ""}`;
}

/** Fills the table: a colour and intensity for emitters, move buttons for every object. */
export async function showControls(sceneRadius) {
  const objects = await (await fetch("api/objects")).json();
  const step = Math.max(sceneRadius * 0.05, 1e-30);
  table.replaceChildren();
  for (const { name, emission } of objects) {
    const row = table.insertRow();
    row.insertCell().textContent = name;
    const light = row.insertCell();
    if (Math.max(...emission) > 0) {
      const [hex, intensity] = split(emission);
      const colour = Object.assign(document.createElement("input"), { type: "color", value: hex });
      const strength = Object.assign(document.createElement("input"), { type: "number", min: 0, step: "any", value: intensity });
      const set = Object.assign(document.createElement("button"), { type: "button", textContent: "set" });
      set.onclick = () => put(name, "emission", join(colour.value, Number(strength.value)));
      light.append(colour, strength, set);
    }
    const move = row.insertCell();
    for (const [label, offset] of [["−x", [-1, 0, 0]], ["+x", [1, 0, 0]], ["−y", [0, -1, 0]], ["+y", [0, 1, 0]], ["−z", [0, 0, -1]], ["+z", [0, 0, 1]]]) {
      const button = Object.assign(document.createElement("button"), { type: "button", textContent: label });
      button.onclick = () => put(name, "translate", offset.map((o) => o * step));
      move.append(button);
    }
    // Turns about the object's centre, 15 degrees about the vertical (the scene's y).
    for (const [label, degrees] of [["⟲", 15], ["⟳", -15]]) {
      const button = Object.assign(document.createElement("button"), { type: "button", textContent: label, title: `rotate ${degrees}° about y` });
      button.onclick = () => put(name, "rotate", { axis: [0, 1, 0], degrees });
      move.append(button);
    }
  }
}

export function togglePanel(sceneRadius) {
  panel.hidden = !panel.hidden;
  if (!panel.hidden) showControls(sceneRadius).catch((e) => { report.textContent = e.message; });
}
