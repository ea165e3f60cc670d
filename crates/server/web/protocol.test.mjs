// The JavaScript decoder against the vectors the Rust wire crate writes (tests/vectors/):
// every message decodes to the values in expected.json, and every hostile one is refused.
// Run: node --test crates/server/web/

import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import { dirname, join } from "node:path";
import {
  ColourBuffer, checksum, decodeColour, decodeGeometry, decodeServerMessage, encodeRequestFull, sumChecksum,
} from "./protocol.js";

const folder = join(dirname(fileURLToPath(import.meta.url)), "../../../tests/vectors");
const expected = JSON.parse(readFileSync(join(folder, "expected.json"), "utf8"));
const bytes = (name) => new Uint8Array(readFileSync(join(folder, `${name}.bin`)));
const isGeometry = (name) => name.startsWith("geometry") && name !== "geometry-changed";

/** A decoded message in the shape of expected.json (u64s as decimal strings). */
function describe(m) {
  const info = (i) => ({
    solution_version: i.solutionVersion.toString(),
    sent_at: i.sentAt.toString(),
    scale: i.scale,
    vertex_count: i.vertexCount,
    is_final: i.isFinal,
  });
  switch (m.kind) {
    case "hello":
      return {
        kind: "hello",
        protocol_version: m.protocolVersion,
        scene_id: m.sceneId.toString(),
        geometry_version: m.geometryVersion.toString(),
        vertex_count: m.vertexCount,
      };
    case "full":
      return {
        kind: "full",
        info: info(m.info),
        colours: [...m.colours],
        checksum: checksum(m.colours),
        radiosity_of_first: decodeColour(m.colours[0], m.info.scale),
      };
    case "delta":
      return {
        kind: "delta",
        base_version: m.baseVersion.toString(),
        info: info(m.info),
        indices: [...m.indices],
        colours: [...m.colours],
      };
    case "geometry-changed":
      return { kind: "geometry-changed", geometry_version: m.geometryVersion.toString() };
    case "response":
      return {
        kind: "response",
        response_id: m.responseId,
        scale: m.scale,
        vertex_count: m.vertexCount,
        codes: [...m.codes],
      };
    case "sum":
      return {
        kind: "sum",
        info: info(m.info),
        terms: m.terms.map((t) => ({ response_id: t.responseId, weight: t.weight })),
      };
  }
}

function describeGeometry(g) {
  const groups = (array, n) => Array.from({ length: array.length / n }, (_, i) => [...array.slice(n * i, n * i + n)]);
  return {
    positions: groups(g.positions, 3),
    patches: groups(g.patches, 4),
    patch_objects: [...g.patchObjects],
    objects: g.objects,
    camera: g.camera && {
      eye: g.camera.eye, target: g.camera.target, up: g.camera.up,
      vertical_fov_degrees: g.camera.verticalFovDegrees,
    },
    textures: g.textures && {
      means: groups(g.textures.means, 3),
      patch_textures: [...g.textures.patchTextures],
      uvs: groups(g.textures.uvs, 2),
    },
  };
}

/** expected.json holds f32 values printed by Rust's shortest round-trip: compare as f32. */
function roundF32(value) {
  if (typeof value === "number") return Math.fround(value);
  if (Array.isArray(value)) return value.map(roundF32);
  if (value && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, roundF32(v)]));
  }
  return value;
}

for (const [name, value] of Object.entries(expected)) {
  if (name === "evaluation") continue; // no file: the sum of other vectors, tested below
  test(name, () => {
    const file = bytes(name);
    if (value === "refused") {
      assert.throws(() => decodeServerMessage(file));
      assert.throws(() => decodeGeometry(file));
      return;
    }
    if (name === "request-full") {
      assert.deepEqual([...file], [...encodeRequestFull()]);
      return;
    }
    const decoded = isGeometry(name) ? describeGeometry(decodeGeometry(file)) : describe(decodeServerMessage(file));
    assert.deepEqual(roundF32(decoded), roundF32(value));
  });
}

test("a buffer follows a full frame and its deltas, and refuses a foreign base", () => {
  const buffer = new ColourBuffer();
  assert.equal(buffer.apply(decodeServerMessage(bytes("full-lz4"))), true);
  assert.equal(buffer.apply(decodeServerMessage(bytes("delta-raw"))), true);
  assert.equal(buffer.apply(decodeServerMessage(bytes("delta-lz4"))), true);
  assert.equal(buffer.apply(decodeServerMessage(bytes("delta-empty-final"))), true);
  assert.equal(buffer.info.solutionVersion, 8n);
  assert.equal(buffer.info.isFinal, true);
  const full = expected["full-lz4"].colours;
  const changed = [...full];
  expected["delta-raw"].indices.forEach((index, k) => { changed[index] = expected["delta-raw"].colours[k]; });
  expected["delta-lz4"].indices.forEach((index, k) => { changed[index] = expected["delta-lz4"].colours[k]; });
  assert.deepEqual([...buffer.colours], changed);
  // A delta against version 5 no longer applies: the viewer asks for a full frame.
  assert.equal(buffer.apply(decodeServerMessage(bytes("delta-raw"))), false);
});

test("the sum of the checked-in responses is, bit for bit, what the Rust viewer computes", () => {
  const evaluation = expected.evaluation;
  const buffer = new ColourBuffer();
  for (const name of evaluation.responses) buffer.apply(decodeServerMessage(bytes(name)));
  buffer.apply(decodeServerMessage(bytes(evaluation.sum)));
  const values = buffer.radiosity();
  assert.deepEqual([...values], evaluation.values.flat().map(Math.fround));
  assert.equal(sumChecksum(values), evaluation.sum_checksum);
  assert.equal(buffer.info.solutionVersion, 9n);
  // A delta cannot apply to a sum; a geometry change forgets the responses.
  assert.equal(buffer.apply(decodeServerMessage(bytes("delta-empty-final"))), false);
  buffer.apply(decodeServerMessage(bytes("geometry-changed")));
  assert.throws(() => buffer.apply(decodeServerMessage(bytes(evaluation.sum))), /does not hold/);
});
