// The radcast wire protocol (docs/PROTOCOL.md, versions 2 and 3) in JavaScript, written from
// the document alone: the browser viewer's decoder, and a second implementation that the test
// vectors in tests/vectors/ hold to the Rust one. No dependencies; every decoder throws an
// Error naming what is wrong instead of returning garbage.

/** The newest version spoken: ask for it with the WebSocket subprotocol `radcast.3`. */
export const PROTOCOL_VERSION = 3;
/** The oldest: frames only, what a server sends when no subprotocol was asked for. */
export const PLAIN_PROTOCOL_VERSION = 2;
/** The subprotocol names to offer, newest first. */
export const SUBPROTOCOLS = ["radcast.3", "radcast.2"];

const KIND = { hello: 1, full: 2, delta: 3, geometryChanged: 4, response: 5, sum: 6, requestFull: 16 };
/** The most terms a sum frame may have. */
const MAX_TERMS = 64;
/** The largest weight a sum term may have (the emission rule), as an f32. */
const MAX_WEIGHT = Math.fround(1e24);
const FLAG_COMPRESSED = 1;
const FLAG_FINAL = 2;
/** The largest RGB9E5 value: (511 / 512) * 2^16. */
const RGB9E5_MAX = 65408;
const F32_MAX = 3.4028234663852886e38;

/** A little-endian reader over `bytes` that refuses to read past the end. */
class Reader {
  constructor(bytes, what) {
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    this.bytes = bytes;
    this.at = 0;
    this.what = what;
  }
  need(n, field) {
    if (this.at + n > this.bytes.length) {
      throw new Error(`truncated ${this.what}: ${field} needs ${n} bytes at ${this.at}, have ${this.bytes.length - this.at}`);
    }
  }
  u8(field) { this.need(1, field); return this.view.getUint8(this.at++); }
  u16(field) { this.need(2, field); const v = this.view.getUint16(this.at, true); this.at += 2; return v; }
  u32(field) { this.need(4, field); const v = this.view.getUint32(this.at, true); this.at += 4; return v; }
  u64(field) { this.need(8, field); const v = this.view.getBigUint64(this.at, true); this.at += 8; return v; }
  f32(field) { this.need(4, field); const v = this.view.getFloat32(this.at, true); this.at += 4; return v; }
  rest() { const r = this.bytes.subarray(this.at); this.at = this.bytes.length; return r; }
  end() {
    if (this.at !== this.bytes.length) {
      throw new Error(`${this.what}: ${this.bytes.length - this.at} trailing bytes`);
    }
  }
}

/** Decodes one LZ4 block (the raw block format) into exactly `size` bytes. */
export function lz4Decompress(source, size) {
  const out = new Uint8Array(size);
  let s = 0;
  let d = 0;
  const length = (base) => {
    let n = base;
    if (base === 15) {
      let b;
      do {
        if (s >= source.length) throw new Error("LZ4 block ends inside a length");
        b = source[s++];
        n += b;
      } while (b === 255);
    }
    return n;
  };
  while (s < source.length) {
    const token = source[s++];
    const literals = length(token >> 4);
    if (s + literals > source.length || d + literals > size) {
      throw new Error("LZ4 literals run past the block or the stated size");
    }
    out.set(source.subarray(s, s + literals), d);
    s += literals;
    d += literals;
    if (s === source.length) break; // the last sequence has no match
    if (s + 2 > source.length) throw new Error("LZ4 block ends inside an offset");
    const offset = source[s] | (source[s + 1] << 8);
    s += 2;
    if (offset === 0 || offset > d) throw new Error(`LZ4 offset ${offset} points before the output`);
    const match = length(token & 15) + 4;
    if (d + match > size) throw new Error("LZ4 match runs past the stated size");
    for (let k = 0; k < match; k++, d++) out[d] = out[d - offset];
  }
  if (d !== size) throw new Error(`LZ4 block decompressed to ${d} bytes, not the stated ${size}`);
  return out;
}

/** The payload of a frame: as sent, or decompressed (`u32 size` + one LZ4 block). */
function payload(reader, compressed, limit, what) {
  if (!compressed) return reader.rest();
  const size = reader.u32("uncompressed size");
  if (size > limit) throw new Error(`${what}: uncompressed size ${size} exceeds ${limit}`);
  return lz4Decompress(reader.rest(), size);
}

function codes(bytes, count, what) {
  if (bytes.length !== 4 * count) {
    throw new Error(`${what}: expected ${4 * count} bytes of codes, got ${bytes.length}`);
  }
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const out = new Uint32Array(count);
  for (let i = 0; i < count; i++) out[i] = view.getUint32(4 * i, true);
  return out;
}

function checkScale(scale) {
  const maxScale = Math.fround(F32_MAX / RGB9E5_MAX);
  if (!(scale > 0 && scale <= maxScale)) {
    throw new Error(`scale ${scale} must be positive and at most ${maxScale}`);
  }
}

function frameInfo(solutionVersion, sentAt, scale, vertexCount, flags) {
  checkScale(scale);
  return { solutionVersion, sentAt, scale, vertexCount, isFinal: (flags & FLAG_FINAL) !== 0 };
}

/** The flags each kind may carry. */
const ALLOWED_FLAGS = {
  [KIND.full]: FLAG_COMPRESSED | FLAG_FINAL,
  [KIND.delta]: FLAG_COMPRESSED | FLAG_FINAL,
  [KIND.response]: FLAG_COMPRESSED,
  [KIND.sum]: FLAG_FINAL,
};

/**
 * Decodes a server message. Returns `{kind: "hello" | "full" | "delta" | "geometry-changed" |
 * "response" | "sum", …}` with u64 fields as BigInt.
 */
export function decodeServerMessage(bytes) {
  const r = new Reader(bytes, "message");
  const kind = r.u8("kind");
  const flags = r.u8("flags");
  const allowed = ALLOWED_FLAGS[kind] ?? 0;
  if (flags & ~allowed) throw new Error(`unknown flags 0x${flags.toString(16)} for kind ${kind}`);
  switch (kind) {
    case KIND.hello: {
      const protocolVersion = r.u16("protocol_version");
      if (protocolVersion < PLAIN_PROTOCOL_VERSION || protocolVersion > PROTOCOL_VERSION) {
        throw new Error(`protocol version ${protocolVersion} is not supported (this side speaks ${PLAIN_PROTOCOL_VERSION} to ${PROTOCOL_VERSION})`);
      }
      const hello = {
        kind: "hello",
        protocolVersion,
        sceneId: r.u64("scene_id"),
        geometryVersion: r.u64("geometry_version"),
        vertexCount: r.u32("vertex_count"),
      };
      r.end();
      return hello;
    }
    case KIND.full: {
      const info = frameInfo(r.u64("solution_version"), r.u64("sent_at"), r.f32("scale"), r.u32("vertex_count"), flags);
      const body = payload(r, flags & FLAG_COMPRESSED, 4 * info.vertexCount, "full frame");
      return { kind: "full", info, colours: codes(body, info.vertexCount, "full frame") };
    }
    case KIND.delta: {
      const baseVersion = r.u64("base_version");
      const info = frameInfo(r.u64("solution_version"), r.u64("sent_at"), r.f32("scale"), r.u32("vertex_count"), flags);
      const changes = r.u32("change_count");
      if (changes > info.vertexCount) throw new Error(`change count ${changes} exceeds vertex count ${info.vertexCount}`);
      const body = payload(r, flags & FLAG_COMPRESSED, 9 * changes, "delta frame");
      const indices = new Uint32Array(changes);
      let at = 0;
      let previous = -1;
      for (let k = 0; k < changes; k++) {
        let gap = 0;
        let shift = 0;
        for (;;) {
          if (at >= body.length) throw new Error("delta frame ends inside an index");
          const b = body[at++];
          gap += (b & 0x7f) * 2 ** shift;
          shift += 7;
          if ((b & 0x80) === 0) break;
          if (shift > 35) throw new Error("delta index varint is too long");
        }
        const index = previous + 1 + gap;
        if (index >= info.vertexCount) throw new Error(`delta index ${index} is not below vertex count ${info.vertexCount}`);
        indices[k] = index;
        previous = index;
      }
      const colours = codes(body.subarray(at), changes, "delta frame");
      return { kind: "delta", baseVersion, info, indices, colours };
    }
    case KIND.geometryChanged: {
      const message = { kind: "geometry-changed", geometryVersion: r.u64("geometry_version") };
      r.end();
      return message;
    }
    case KIND.response: {
      const responseId = r.u32("response_id");
      const scale = r.f32("scale");
      checkScale(scale);
      const vertexCount = r.u32("vertex_count");
      const body = payload(r, flags & FLAG_COMPRESSED, 4 * vertexCount, "response");
      return { kind: "response", responseId, scale, vertexCount, codes: codes(body, vertexCount, "response") };
    }
    case KIND.sum: {
      const solutionVersion = r.u64("solution_version");
      const sentAt = r.u64("sent_at");
      const vertexCount = r.u32("vertex_count");
      const termCount = r.u32("term_count");
      if (termCount > MAX_TERMS) throw new Error(`sum term count ${termCount} exceeds ${MAX_TERMS}`);
      const terms = [];
      for (let k = 0; k < termCount; k++) {
        const responseId = r.u32("term response_id");
        const weight = [r.f32("weight"), r.f32("weight"), r.f32("weight")];
        if (!weight.every((w) => Number.isFinite(w) && w >= 0 && w <= MAX_WEIGHT)) {
          throw new Error(`sum weight ${weight} must be finite, at least 0 and at most 1e24`);
        }
        terms.push({ responseId, weight });
      }
      r.end();
      return { kind: "sum", info: frameInfo(solutionVersion, sentAt, 1, vertexCount, flags), terms };
    }
    default:
      throw new Error(`unknown message kind ${kind}`);
  }
}

/** The one message a viewer sends: "send me a full frame". */
export function encodeRequestFull() {
  return new Uint8Array([KIND.requestFull, 0]);
}

/** Decodes `/api/scene`: positions, patches (4 corners each), objects, camera, textures (or null). */
export function decodeGeometry(bytes) {
  const magic = "RCGEO1";
  for (let i = 0; i < magic.length; i++) {
    if (bytes[i] !== magic.charCodeAt(i)) throw new Error("not radcast geometry (no RCGEO1 tag)");
  }
  const r = new Reader(bytes.subarray(magic.length), "geometry");
  const count = (field, bytesEach) => {
    const n = r.u64(`${field} length`);
    if (n * BigInt(bytesEach) > BigInt(bytes.length)) throw new Error(`${field}: length ${n} exceeds the message`);
    return Number(n);
  };
  const vertices = count("positions", 12);
  const positions = new Float32Array(3 * vertices);
  for (let i = 0; i < positions.length; i++) {
    positions[i] = r.f32("position");
    if (!Number.isFinite(positions[i])) throw new Error(`position ${Math.floor(i / 3)} is not finite`);
  }
  const patchCount = count("patches", 16);
  const patches = new Uint32Array(4 * patchCount);
  for (let i = 0; i < patches.length; i++) patches[i] = r.u32("patch corner");
  const patchObjects = new Uint32Array(count("patch_objects", 4));
  for (let i = 0; i < patchObjects.length; i++) patchObjects[i] = r.u32("patch object");
  const objectCount = count("objects", 8);
  const objects = [];
  const text = new TextDecoder("utf-8", { fatal: true });
  for (let i = 0; i < objectCount; i++) {
    const n = count("object name", 1);
    r.need(n, "object name");
    objects.push(text.decode(bytes.subarray(magic.length + r.at, magic.length + r.at + n)));
    r.at += n;
  }
  let camera = null;
  const tag = r.u8("camera tag");
  if (tag === 1) {
    const triple = (field) => [r.f32(field), r.f32(field), r.f32(field)];
    camera = { eye: triple("eye"), target: triple("target"), up: triple("up"), verticalFovDegrees: r.f32("fov") };
  } else if (tag !== 0) {
    throw new Error(`camera tag ${tag} is neither 0 nor 1`);
  }
  // Sections (u32 tag, u64 byte length, body) until the end; unknown tags are skipped.
  let textures = null;
  while (r.at < r.bytes.length) {
    const sectionTag = r.u32("section tag");
    const length = r.u64("section length");
    if (length > BigInt(r.bytes.length - r.at)) throw new Error(`section ${sectionTag}: length ${length} exceeds the message`);
    const end = r.at + Number(length);
    if (sectionTag === TEXTURES_SECTION) {
      if (textures) throw new Error("two texture sections");
      textures = readTextures(r, count, end);
    }
    r.at = end;
  }
  r.end();
  if (patchObjects.length !== patchCount) {
    throw new Error(`patch objects: expected ${patchCount}, got ${patchObjects.length}`);
  }
  for (let p = 0; p < patchCount; p++) {
    const used = patches[4 * p + 3] === 0xffffffff ? 3 : 4;
    for (let k = 0; k < used; k++) {
      if (patches[4 * p + k] >= vertices) throw new Error(`patch ${p} refers to vertex ${patches[4 * p + k]} of ${vertices}`);
    }
    if (patchObjects[p] >= objectCount) throw new Error(`patch ${p} refers to object ${patchObjects[p]} of ${objectCount}`);
  }
  if (textures) checkTextures(textures, patchCount, vertices);
  return { positions, patches, patchObjects, objects, camera, textures };
}

/** Tag of the texture section; its textures are served as PNG at `api/textures/INDEX`. */
const TEXTURES_SECTION = 1;
/** A patch without a texture. */
export const NO_TEXTURE = 0xffffffff;

/** The texture section's body: means (linear RGB), a texture per patch, (u, v) per position. */
function readTextures(r, count, end) {
  const means = new Float32Array(3 * count("texture means", 12));
  for (let i = 0; i < means.length; i++) means[i] = r.f32("texture mean");
  const patchTextures = new Uint32Array(count("patch textures", 4));
  for (let i = 0; i < patchTextures.length; i++) patchTextures[i] = r.u32("patch texture");
  const uvs = new Float32Array(2 * count("texture coordinates", 8));
  for (let i = 0; i < uvs.length; i++) uvs[i] = r.f32("texture coordinate");
  if (r.at !== end) throw new Error(`texture section: ${end - r.at} bytes left over`);
  return { means, patchTextures, uvs };
}

function checkTextures(t, patchCount, vertices) {
  if (t.patchTextures.length !== patchCount) throw new Error(`patch textures: expected ${patchCount}, got ${t.patchTextures.length}`);
  if (t.uvs.length !== 2 * vertices) throw new Error(`texture coordinates: expected ${vertices}, got ${t.uvs.length / 2}`);
  if (!t.means.every((m) => Number.isFinite(m) && m >= 0)) throw new Error("a texture mean is not finite and >= 0");
  const textureCount = t.means.length / 3;
  t.patchTextures.forEach((texture, p) => {
    if (texture !== NO_TEXTURE && texture >= textureCount) throw new Error(`patch ${p} refers to texture ${texture} of ${textureCount}`);
  });
  if (!t.uvs.every(Number.isFinite)) throw new Error("texture coordinates are not finite");
}

/** One RGB9E5 code times the frame scale: linear radiosity, W/m². */
export function decodeColour(code, scale) {
  const exponent = code >>> 27;
  const unit = 2 ** (exponent - 15 - 9) * scale;
  return [(code & 0x1ff) * unit, ((code >>> 9) & 0x1ff) * unit, ((code >>> 18) & 0x1ff) * unit];
}

const CRC_TABLE = (() => {
  const table = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    table[n] = c >>> 0;
  }
  return table;
})();

/** CRC-32 (zlib's) of the codes as little-endian u32s: `/api/solution`'s `checksum`. */
export function checksum(colours) {
  let crc = 0xffffffff;
  for (const code of colours) {
    for (let shift = 0; shift < 32; shift += 8) {
      crc = CRC_TABLE[(crc ^ (code >>> shift)) & 0xff] ^ (crc >>> 8);
    }
  }
  return (crc ^ 0xffffffff) >>> 0;
}

/** CRC-32 (zlib's) of a sum's values as little-endian f32s: `/api/solution`'s `sum_checksum`. */
export function sumChecksum(values) {
  const bytes = new Uint8Array(4 * values.length);
  const view = new DataView(bytes.buffer);
  values.forEach((v, i) => view.setFloat32(4 * i, v, true));
  let crc = 0xffffffff;
  for (const b of bytes) crc = CRC_TABLE[(crc ^ b) & 0xff] ^ (crc >>> 8);
  return (crc ^ 0xffffffff) >>> 0;
}

/**
 * A viewer's copy of the colours: full frames replace it, deltas against the held version
 * apply; with protocol 3, responses are kept (until the geometry changes) and a sum frame sets
 * the values to its weighted sum of them.
 */
export class ColourBuffer {
  constructor() {
    this.info = null;
    this.colours = new Uint32Array(0);
    /** Response id -> its values, r, g, b per vertex (f32, as decoded). */
    this.responses = new Map();
    /** The last sum's values (r, g, b per vertex) while a sum is the state held, else null. */
    this.sum = null;
  }
  /**
   * Applies a decoded message; returns false for a delta whose base is not held as codes (ask
   * for a full frame). Throws for a sum that names a response not held.
   */
  apply(message) {
    if (message.kind === "full") {
      this.colours = message.colours.slice();
      this.info = message.info;
      this.sum = null;
    } else if (message.kind === "delta") {
      const held = this.sum === null && this.info && this.info.solutionVersion;
      if (held !== message.baseVersion || this.colours.length !== message.info.vertexCount) return false;
      message.indices.forEach((index, k) => { this.colours[index] = message.colours[k]; });
      this.info = message.info;
    } else if (message.kind === "geometry-changed") {
      this.responses.clear();
    } else if (message.kind === "response") {
      const values = new Float32Array(3 * message.vertexCount);
      message.codes.forEach((code, v) => values.set(decodeColour(code, message.scale), 3 * v));
      this.responses.set(message.responseId, values);
    } else if (message.kind === "sum") {
      this.sum = evaluateSum(this.responses, message);
      this.info = message.info;
    }
    return true;
  }
  /** Linear radiosity, W/m², r, g, b per vertex. */
  radiosity() {
    if (this.sum) return this.sum;
    const values = new Float32Array(3 * this.colours.length);
    if (this.info) this.colours.forEach((code, v) => values.set(decodeColour(code, this.info.scale), 3 * v));
    return values;
  }
}

/**
 * A sum frame's values: per vertex and channel, from 0, add weight times value term by term in
 * the frame's order in double precision (each product of two f32s is exact), then round to f32.
 */
function evaluateSum(responses, sum) {
  const count = 3 * sum.info.vertexCount;
  const terms = sum.terms.map((term) => {
    const values = responses.get(term.responseId);
    if (!values) throw new Error(`the sum names response ${term.responseId}, which this viewer does not hold`);
    if (values.length !== count) throw new Error(`response ${term.responseId} has ${values.length / 3} vertices, the sum ${count / 3}`);
    return [term.weight, values];
  });
  const out = new Float32Array(count);
  for (let i = 0; i < count; i++) {
    let total = 0;
    for (const [weight, values] of terms) total += weight[i % 3] * values[i];
    out[i] = total;
  }
  return out;
}
