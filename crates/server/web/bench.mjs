// Times the JavaScript side of a viewer (docs/BENCHMARKS.md): decoding a delta frame of N
// changed vertices and applying it to the buffer, median of 21 runs.
// Run: node crates/server/web/bench.mjs [N ...]   (default 10000 100000)
import { ColourBuffer, decodeServerMessage } from "./protocol.js";

/** A raw (uncompressed) delta frame changing every vertex of `count`, base version 1. */
function delta(count) {
  const header = 2 + 36;
  const bytes = new Uint8Array(header + count + 4 * count);
  const view = new DataView(bytes.buffer);
  bytes[0] = 3;
  bytes[1] = 2; // final
  view.setBigUint64(2, 1n, true);
  view.setBigUint64(10, 2n, true);
  view.setBigUint64(18, 0n, true);
  view.setFloat32(26, 1, true);
  view.setUint32(30, count, true);
  view.setUint32(34, count, true);
  // Gaps of 0: one varint byte each, then the codes.
  for (let i = 0; i < count; i++) view.setUint32(header + count + 4 * i, (i * 2654435761) >>> 0, true);
  return bytes;
}

function full(count) {
  const bytes = new Uint8Array(26 + 4 * count);
  const view = new DataView(bytes.buffer);
  bytes[0] = 2;
  view.setBigUint64(2, 1n, true);
  view.setFloat32(18, 1, true);
  view.setUint32(22, count, true);
  return bytes;
}

const counts = process.argv.slice(2).map(Number);
for (const count of counts.length ? counts : [10000, 100000]) {
  const base = decodeServerMessage(full(count));
  const frame = delta(count);
  const times = [];
  for (let run = 0; run < 21; run++) {
    const buffer = new ColourBuffer();
    buffer.apply(base);
    const start = performance.now();
    buffer.apply(decodeServerMessage(frame));
    times.push(performance.now() - start);
  }
  times.sort((a, b) => a - b);
  console.log(`| ${count} | ${(frame.length / 1024).toFixed(0)} KiB | ${times[10].toFixed(2)} ms |`);
}
