#!/usr/bin/env node
// Terrain check: CesiumJS (samples/viewer, headless Debian chromium) takes a terratiles
// terrain layer as the globe's terrain (quantized-mesh: CesiumTerrainProvider; 3D Tiles
// terrain: Cesium3DTilesTerrainProvider) with the bundled
// NaturalEarthII imagery draped on it, then samples it and draws a polyline clamped to it.
//
//   node tools/render_check/terrain_check.mjs OUTDIR --points FILE [options]
//
// OUTDIR holds layer.json or a 3D Tiles terrain tileset.json. FILE is JSON: [[lon, lat], ...] degrees. Prints (and with --json
// writes) one JSON object: ready (the first view's tiles all loaded), error, failedTiles,
// consoleErrors, httpErrors, heights (sampleTerrainMostDetailed at the points: metres above
// the ellipsoid, null where there is no terrain), polyline (the clamped polyline's state after
// rendering), renderError, seconds. It judges nothing: the caller compares. Exit 0 when the
// page ran, 2 on bad usage or a missing browser.
//
//   --json FILE        also write the result to FILE
//   --screenshot FILE  PNG of the first view, with the polyline
//   --timeout S        seconds to wait for the first view (default 240)
//   --chromium PATH    browser binary (default $CHROMIUM or /usr/bin/chromium)
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

import { launchChromium } from './headless_chromium.mjs';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const SERVE_MJS = path.join(HERE, '..', '..', 'samples', 'viewer', 'serve.mjs');

function usage(message) {
  process.stderr.write(`terrain_check: ${message}\nusage: node terrain_check.mjs OUTDIR --points FILE ` +
    '[--json FILE] [--screenshot FILE] [--timeout S] [--chromium PATH]\n');
  process.exit(2);
}

const opts = { timeoutS: 240, chromium: process.env.CHROMIUM || '/usr/bin/chromium' };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  const value = () => (i + 1 < argv.length ? argv[++i] : usage(`${a} needs a value`));
  if (a === '--points') opts.points = value();
  else if (a === '--json') opts.json = value();
  else if (a === '--screenshot') opts.screenshot = value();
  else if (a === '--timeout') opts.timeoutS = Number(value());
  else if (a === '--chromium') opts.chromium = value();
  else if (a.startsWith('-')) usage(`unknown option ${a}`);
  else if (!opts.outDir) opts.outDir = a;
  else usage(`unexpected argument ${a}`);
}
if (!opts.outDir || !opts.points) usage('OUTDIR and --points are required');
if (!fs.existsSync(path.join(opts.outDir, 'layer.json')) && !fs.existsSync(path.join(opts.outDir, 'tileset.json'))) {
  usage(`no layer.json or tileset.json in ${opts.outDir}`);
}
if (!fs.existsSync(opts.chromium)) usage(`browser not found at ${opts.chromium} (apt-get install -y chromium)`);
const points = JSON.parse(fs.readFileSync(opts.points, 'utf8'));

const { chromium } = await import('playwright-core');
const { startServer } = await import(SERVE_MJS);
const t0 = Date.now();
const result = {
  ready: false, error: null, failedTiles: [], consoleErrors: [], httpErrors: [], heights: [], polyline: null,
  renderError: null, seconds: 0,
};
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'tt-terrain-check-'));
const server = await startServer({ outDir: opts.outDir, port: 0 });
let context = null;
try {
  context = await launchChromium(chromium, { executablePath: opts.chromium, userDataDir, width: 1024, height: 700 });
  const page = context.pages()[0] || (await context.newPage());
  page.setDefaultTimeout(opts.timeoutS * 1000);
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.consoleErrors.push(`pageerror: ${e.message}`));
  page.on('requestfailed', (r) => result.httpErrors.push({ url: r.url(), error: r.failure()?.errorText || 'failed' }));
  page.on('response', (r) => { if (r.status() >= 400) result.httpErrors.push({ url: r.url(), status: r.status() }); });
  await page.goto(server.viewerUrl, { waitUntil: 'load', timeout: 60000 });
  await page.waitForFunction(() => window.terratiles && (window.terratiles.ready || window.terratiles.error), null,
    { timeout: opts.timeoutS * 1000, polling: 500 });
  Object.assign(result, await page.evaluate(() => ({
    ready: window.terratiles.ready, error: window.terratiles.error, failedTiles: window.terratiles.failedTiles,
  })));
  if (result.ready) {
    result.heights = await page.evaluate((p) => window.terratilesApi.sampleTerrain(p), points);
    // A polyline clamped to the terrain across the data, drawn for a few frames.
    result.polyline = await page.evaluate(async () => {
      const { viewer } = window.terratilesApi;
      const r = window.terratiles.region;
      const entity = viewer.entities.add({
        polyline: {
          positions: Cesium.Cartesian3.fromDegreesArray([r.west, r.south, r.east, r.north]),
          clampToGround: true, width: 4, material: Cesium.Color.ORANGE,
        },
      });
      const start = window.terratiles.frame;
      for (let i = 0; i < 600 && window.terratiles.frame < start + 30; i++) {
        await new Promise((f) => setTimeout(f, 100));
      }
      return {
        frames: window.terratiles.frame - start,
        show: entity.isShowing,
        groundPrimitives: viewer.scene.groundPrimitives.length,
      };
    });
    if (opts.screenshot) await page.screenshot({ path: opts.screenshot });
  }
  result.renderError = await page.evaluate(() => window.terratiles.renderError);
} finally {
  if (context) await context.close();
  await server.close();
  fs.rmSync(userDataDir, { recursive: true, force: true });
}
result.seconds = (Date.now() - t0) / 1000;
const text = JSON.stringify(result) + '\n';
process.stdout.write(text);
if (opts.json) fs.writeFileSync(opts.json, text);
