#!/usr/bin/env node
// Times the npm package delatin (Agafonkin's JavaScript greedy-insertion TIN, the algorithm
// of src/tin/build_tin.h) on a raw height grid, for tools/bench/bench_tin.cpp.
//
//   node run_delatin.mjs RAW WIDTH HEIGHT MAX_ERROR RUNS OUT
//
// RAW: WIDTH * HEIGHT little-endian float32 heights, row-major, row 0 first; no NaN.
// Delatin reads the same layout: heightAt(x, y) = data[width * y + x] and its vertices are
// whole pixel indices 0..width-1, 0..height-1, the pixel centres of our GridPoint frame.
//
// One untimed warm-up build (so V8 has compiled and optimised the hot loops, as a long-lived
// page would have), then RUNS timed builds. A build is `new Delatin(data, w, h)` plus
// `run(maxError)`: the constructor already rasterises the whole grid once (its first two
// triangles), work that buildTin's timing includes too, so leaving it out would flatter
// Delatin. The run() time alone is reported as well.
//
// OUT (little-endian):
//   char[8]  "DELATIN1"
//   uint32   vertex count V, triangle count T, runs, 0
//   float64  median build seconds (constructor + run), median run() seconds,
//            Delatin's own getMaxError(), getRMSD() (per-triangle, not per-pixel)
//   uint32   coords[2 V] (x = column, y = row), triangles[3 T] (as Delatin returns them)
import { readFileSync, writeFileSync } from 'node:fs';
import { performance } from 'node:perf_hooks';
import Delatin from 'delatin';

function fail(message) {
  process.stderr.write(`run_delatin: error: ${message}\n`);
  process.exit(2);
}

const args = process.argv.slice(2);
if (args.length !== 6) {
  fail(`expected 6 arguments RAW WIDTH HEIGHT MAX_ERROR RUNS OUT, found ${args.length}`);
}
const [rawPath, widthText, heightText, maxErrorText, runsText, outPath] = args;
const width = Number(widthText);
const height = Number(heightText);
const maxError = Number(maxErrorText);
const runs = Number(runsText);
if (!Number.isInteger(width) || width < 2 || !Number.isInteger(height) || height < 2) {
  fail(`WIDTH and HEIGHT must be integers >= 2, found ${widthText} x ${heightText}`);
}
if (!(maxError > 0) || !Number.isFinite(maxError)) fail(`MAX_ERROR must be > 0, found ${maxErrorText}`);
if (!Number.isInteger(runs) || runs < 1) fail(`RUNS must be an integer >= 1, found ${runsText}`);

const bytes = readFileSync(rawPath);
if (bytes.byteLength !== width * height * 4) {
  fail(`${rawPath}: ${bytes.byteLength} bytes, expected ${width} * ${height} * 4 = ${width * height * 4}`);
}
// Copy into an aligned buffer of its own (a Buffer may be a view at any offset of a pool).
const data = new Float32Array(width * height);
new Uint8Array(data.buffer).set(bytes);
for (let i = 0; i < data.length; i++) {
  if (Number.isNaN(data[i])) fail(`${rawPath}: pixel ${i} is NaN; Delatin needs a grid without nodata`);
}

function build() {
  const start = performance.now();
  const tin = new Delatin(data, width, height);
  const constructed = performance.now();
  tin.run(maxError);
  const end = performance.now();
  return { tin, buildSeconds: (end - start) / 1000, runSeconds: (end - constructed) / 1000 };
}

function median(values) {
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.floor(sorted.length / 2)];
}

build();  // warm-up, untimed
const buildSeconds = [];
const runSeconds = [];
let last = null;
for (let r = 0; r < runs; r++) {
  last = build();
  buildSeconds.push(last.buildSeconds);
  runSeconds.push(last.runSeconds);
}

const { tin } = last;
const vertexCount = tin.coords.length / 2;
const triangleCount = tin.triangles.length / 3;
const headerBytes = 8 + 4 * 4 + 4 * 8;
const out = Buffer.alloc(headerBytes + 4 * (tin.coords.length + tin.triangles.length));
out.write('DELATIN1', 0, 'latin1');
let offset = 8;
for (const value of [vertexCount, triangleCount, runs, 0]) offset = out.writeUInt32LE(value, offset);
for (const value of [median(buildSeconds), median(runSeconds), tin.getMaxError(), tin.getRMSD()]) {
  offset = out.writeDoubleLE(value, offset);
}
for (const value of tin.coords) offset = out.writeUInt32LE(value, offset);
for (const value of tin.triangles) offset = out.writeUInt32LE(value, offset);
writeFileSync(outPath, out);
