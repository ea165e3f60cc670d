// How vertex radiosity becomes displayed colour, as crates/wire/src/display.rs does it (the
// headless client and the glTF export): fan triangles per patch, exposure 0.18 / Lavg with
// Lavg the area-weighted geometric mean of vertex luminance over the patches of objects that do
// not emit (all when every object emits; Reinhard et al. 2002), each channel x / (1 + x), then
// sRGB.

/** The corners a patch uses: three for a triangle (4th = 0xFFFFFFFF), else four. */
export function cornerCount(patches, p) {
  return patches[4 * p + 3] === 0xffffffff ? 3 : 4;
}

/** Triangle indices: each patch's fan (c0, c1, c2) and, for a quad, (c0, c2, c3). */
export function fanTriangles(patches) {
  const out = [];
  for (let p = 0; p < patches.length / 4; p++) {
    const c = (k) => patches[4 * p + k];
    out.push(c(0), c(1), c(2));
    if (cornerCount(patches, p) === 4) out.push(c(0), c(2), c(3));
  }
  return new Uint32Array(out);
}

function patchArea(positions, patches, p) {
  const at = (k) => {
    const i = patches[4 * p + k];
    return [positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]];
  };
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const [u, v] = cornerCount(patches, p) === 3 ? [sub(at(1), at(0)), sub(at(2), at(0))] : [sub(at(2), at(0)), sub(at(3), at(1))];
  const c = cross(u, v);
  return 0.5 * Math.hypot(c[0], c[1], c[2]);
}

const luminance = (r, g, b) => 0.2126 * r + 0.7152 * g + 0.0722 * b;

/**
 * Exposure 0.18 / Lavg (1 for a black scene); `radiosity` holds r, g, b per vertex, `emitting[o]`
 * whether object o emits (patches of emitting objects are left out unless all are).
 */
export function exposure(positions, patches, radiosity, patchObjects, emitting) {
  let brightest = 0;
  for (let v = 0; v < radiosity.length / 3; v++) {
    brightest = Math.max(brightest, luminance(radiosity[3 * v], radiosity[3 * v + 1], radiosity[3 * v + 2]));
  }
  if (!(brightest > 0)) return 1;
  // Black vertices would send the log-average to zero; floor them far below the brightest.
  const floor = 1e-4 * brightest;
  let logSum = 0;
  let areaSum = 0;
  const emits = (p) => Boolean(emitting[patchObjects[p]]);
  let litOnly = false;
  for (let p = 0; p < patches.length / 4 && !litOnly; p++) litOnly = !emits(p);
  for (let p = 0; p < patches.length / 4; p++) {
    if (litOnly && emits(p)) continue;
    const n = cornerCount(patches, p);
    const share = patchArea(positions, patches, p) / n;
    for (let k = 0; k < n; k++) {
      const v = patches[4 * p + k];
      logSum += share * Math.log(Math.max(luminance(radiosity[3 * v], radiosity[3 * v + 1], radiosity[3 * v + 2]), floor));
      areaSum += share;
    }
  }
  return 0.18 / Math.exp(logSum / Math.max(areaSum, Number.MIN_VALUE));
}

/** Reinhard's x / (1 + x) of exposed linear radiosity: a display value in [0, 1). */
export function toneMap(value, exposureValue) {
  const x = Math.max(value * exposureValue, 0);
  return x / (1 + x);
}
