// display.js's exposure against known answers; run: node --test crates/server/web/

import { test } from "node:test";
import assert from "node:assert/strict";
import { exposure } from "./display.js";

// Two unit squares side by side: object 0 (lit, luminance 1), object 1 (an emitter, 1000).
const positions = new Float32Array([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 2, 0, 0, 3, 0, 0, 3, 1, 0, 2, 1, 0]);
const patches = new Uint32Array([0, 1, 2, 3, 4, 5, 6, 7]);
const patchObjects = new Uint32Array([0, 1]);
const radiosity = new Float32Array([...Array(12).fill(1), ...Array(12).fill(1000)]);

test("the exposure is the lit surfaces' key: emitters are left out", () => {
  assert.ok(Math.abs(exposure(positions, patches, radiosity, patchObjects, [false, true]) - 0.18) < 1e-6);
  // Not known to emit: the log-average of 1 and 1000 over equal areas is sqrt(1000).
  assert.ok(Math.abs(exposure(positions, patches, radiosity, patchObjects, []) - 0.18 / Math.sqrt(1000)) < 1e-6);
  // Everything emits: all patches count.
  assert.ok(Math.abs(exposure(positions, patches, radiosity, patchObjects, [true, true]) - 0.18 / Math.sqrt(1000)) < 1e-6);
});
