#!/usr/bin/env node
// Render check for a terratiles 3D Tiles output, in headless Chromium (SwiftShader WebGL).
//
//   node tools/render_check/render_check.mjs OUTDIR [options]
//
// Serves samples/viewer and OUTDIR on a free 127.0.0.1 port, opens the viewer,
// waits until the initial view has all its tiles loaded, then moves the camera
// down towards the data centre in one step per tileset depth so every depth gets
// selected for rendering, samples the tileset surface height at the centre (and
// at four more points), and reports a JSON result.
//
// Exit status: 0 = ok, 1 = check failed, 2 = usage or setup error.
// Needs: npm ci in tools/render_check and samples/viewer; Debian's chromium.

import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

import { launchChromium } from './headless_chromium.mjs';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const REPO = path.resolve(HERE, '..', '..');
const SERVE_MJS = path.join(REPO, 'samples', 'viewer', 'serve.mjs');

const USAGE = `Usage: node tools/render_check/render_check.mjs OUTDIR [options]

Checks that OUTDIR/tileset.json renders in CesiumJS (headless Chromium, SwiftShader).

Options:
  --json FILE              also write the JSON result to FILE
  --screenshot FILE        PNG of the initial (overview) view
  --screenshot-close FILE  PNG of the closest zoom step
  --timeout S              seconds to wait for the initial view and for each
                           zoom step to finish loading (default 120)
  --expect-lon DEG --expect-lat DEG [--tolerance-deg T]
                           assert the tileset centre (root region centre);
                           default tolerance 0.05 deg
  --expect-height M [--height-tolerance T]
                           assert the sampled surface height at the centre;
                           default tolerance 50 m
  --chromium PATH          browser binary (default $CHROMIUM or /usr/bin/chromium)
  --width N --height N     viewport size (default 1280x800)
  --sse N                  tileset maximumScreenSpaceError (default 16)
  --params QUERY           extra viewer URL parameters, e.g. 'colorize=1&bv=1'
  --quiet                  no progress messages on stderr
  -h, --help               this text
`;

function parseArgs(argv) {
  const o = {
    outDir: null,
    json: null,
    screenshot: null,
    screenshotClose: null,
    timeoutS: 120,
    expectLon: null,
    expectLat: null,
    toleranceDeg: 0.05,
    expectHeight: null,
    heightTolerance: 50,
    chromium: process.env.CHROMIUM || '/usr/bin/chromium',
    width: 1280,
    height: 800,
    sse: 16,
    params: '',
    quiet: false,
  };
  const num = (name, v) => {
    const n = Number(v);
    if (v === undefined || !Number.isFinite(n)) throw new Error(`${name} needs a number`);
    return n;
  };
  for (let i = 0; i < argv.length; i++) {
    let a = argv[i];
    let val;
    const eq = a.indexOf('=');
    if (a.startsWith('--') && eq > 0) {
      val = a.slice(eq + 1);
      a = a.slice(0, eq);
    }
    const next = () => (val !== undefined ? val : argv[++i]);
    switch (a) {
      case '-h':
      case '--help':
        process.stdout.write(USAGE);
        process.exit(0);
        break;
      case '--json': o.json = next(); break;
      case '--screenshot': o.screenshot = next(); break;
      case '--screenshot-close': o.screenshotClose = next(); break;
      case '--timeout': o.timeoutS = num(a, next()); break;
      case '--expect-lon': o.expectLon = num(a, next()); break;
      case '--expect-lat': o.expectLat = num(a, next()); break;
      case '--tolerance-deg': o.toleranceDeg = num(a, next()); break;
      case '--expect-height': o.expectHeight = num(a, next()); break;
      case '--height-tolerance': o.heightTolerance = num(a, next()); break;
      case '--chromium': o.chromium = next(); break;
      case '--width': o.width = num(a, next()); break;
      case '--height': o.height = num(a, next()); break;
      case '--sse': o.sse = num(a, next()); break;
      case '--params': o.params = String(next() || '').replace(/^[?&]/, ''); break;
      case '--quiet': o.quiet = true; break;
      default:
        if (a.startsWith('-')) throw new Error(`unknown option ${a}`);
        if (o.outDir !== null) throw new Error(`unexpected argument ${a}`);
        o.outDir = a;
    }
  }
  if (o.outDir === null) throw new Error('OUTDIR is required');
  if ((o.expectLon === null) !== (o.expectLat === null)) {
    throw new Error('--expect-lon and --expect-lat go together');
  }
  return o;
}

// ---------------------------------------------------------------------------
// Static look at the tileset: tiles per depth, geometric errors, content files.
// Depths follow CesiumJS: the root of an external tileset is one level below
// the tile that references it.

function readJson(file) {
  return JSON.parse(fs.readFileSync(file, 'utf8'));
}

function contentUris(tile) {
  const list = [];
  if (tile.content && (tile.content.uri || tile.content.url)) list.push(tile.content.uri || tile.content.url);
  for (const c of tile.contents || []) if (c.uri || c.url) list.push(c.uri || c.url);
  return list;
}

function uriToFile(baseDir, uri) {
  const clean = uri.split(/[?#]/)[0];
  let rel;
  try {
    rel = decodeURIComponent(clean);
  } catch {
    rel = clean;
  }
  return path.resolve(baseDir, rel);
}

// Checks the GLB container: magic, version, length and a parseable JSON chunk.
function checkGlb(file) {
  const fd = fs.openSync(file, 'r');
  try {
    const size = fs.fstatSync(fd).size;
    const head = Buffer.alloc(20);
    if (fs.readSync(fd, head, 0, 20, 0) < 20) return { error: 'shorter than a GLB header' };
    if (head.readUInt32LE(0) !== 0x46546c67) return { error: 'not a GLB (bad magic)' };
    if (head.readUInt32LE(4) !== 2) return { error: `GLB version ${head.readUInt32LE(4)}` };
    if (head.readUInt32LE(8) !== size) return { error: `GLB length ${head.readUInt32LE(8)} != file size ${size}` };
    const jsonLen = head.readUInt32LE(12);
    if (head.readUInt32LE(16) !== 0x4e4f534a) return { error: 'first chunk is not JSON' };
    if (20 + jsonLen > size) return { error: 'JSON chunk runs past the end' };
    const jbuf = Buffer.alloc(jsonLen);
    fs.readSync(fd, jbuf, 0, jsonLen, 20);
    const gltf = JSON.parse(jbuf.toString('utf8'));
    return { extensionsUsed: gltf.extensionsUsed || [] };
  } catch (e) {
    return { error: e.message };
  } finally {
    fs.closeSync(fd);
  }
}

function analyseTileset(tilesetFile) {
  const depths = {}; // depth -> {tiles, contentTiles, geometricErrorMin, geometricErrorMax}
  const missingContent = [];
  const glbErrors = [];
  const extensionsSeen = new Set();
  const notes = [];
  let glbChecked = 0;
  let tileCount = 0;
  const root = readJson(tilesetFile);
  // For the camera steps: along the way down to the centre, per depth, the tile
  // containing the centre (its geometric error and region top).
  const centreChain = {};
  let centre = null;
  const reg = root.root && root.root.boundingVolume && root.root.boundingVolume.region;
  if (Array.isArray(reg) && reg.length === 6) {
    let lonC = (reg[0] + reg[2]) / 2;
    if (reg[2] < reg[0]) lonC += lonC > 0 ? -Math.PI : Math.PI;
    centre = { lon: lonC, lat: (reg[1] + reg[3]) / 2 };
  }
  const visitedJson = new Set([path.resolve(tilesetFile)]);
  const buildFile = path.join(path.dirname(tilesetFile), 'build.json');
  let implicitAsExplicit = null;
  if (fs.existsSync(buildFile)) {
    const facts = readJson(buildFile);
    if (facts.explicit_tileset && facts.explicit_tileset.root) implicitAsExplicit = facts.explicit_tileset.root;
  }

  function inRegion(tile) {
    const r = tile.boundingVolume && tile.boundingVolume.region;
    if (!centre || !Array.isArray(r)) return false;
    const lonIn = r[0] <= r[2] ? centre.lon >= r[0] && centre.lon <= r[2] : centre.lon >= r[0] || centre.lon <= r[2];
    return lonIn && centre.lat >= r[1] && centre.lat <= r[3];
  }

  // Levels as the viewer counts them: the zoom in a terratiles content name, else the depth.
  const zoomInName = /(?:^|\/)tiles\/(?:(?:west|east)\/)?(\d+)\/\d+\/\d+\.glb$/;
  function walk(tile, treeDepth, baseDir, onCentrePath) {
    tileCount++;
    const named = contentUris(tile).map((u) => zoomInName.exec(u)).find((m) => m);
    const depth = named ? Number(named[1]) : treeDepth;
    if (tile.implicitTiling && implicitAsExplicit) {
      // A terratiles implicit output: build.json holds the same tree explicitly (same
      // contents, errors and regions); walk that instead of the subtree files.
      const root = implicitAsExplicit;
      implicitAsExplicit = null;
      walk(root, treeDepth, baseDir, onCentrePath);
      return;
    }
    // Tiles without content draw nothing: they get no level of their own; nor does a tile whose
    // content is an external tileset (its root, walked below, is the tile that draws).
    const d = contentUris(tile).some((u) => !/\.json$/i.test(u))
      ? (depths[depth] ||= { tiles: 0, contentTiles: 0, geometricErrorMin: Infinity, geometricErrorMax: -Infinity })
      : { tiles: 0, contentTiles: 0, geometricErrorMin: Infinity, geometricErrorMax: -Infinity };
    d.tiles++;
    if (Number.isFinite(tile.geometricError)) {
      d.geometricErrorMin = Math.min(d.geometricErrorMin, tile.geometricError);
      d.geometricErrorMax = Math.max(d.geometricErrorMax, tile.geometricError);
    }
    if (tile.implicitTiling) notes.push(`implicit tiling at depth ${depth} is not expanded by this check`);
    const here = onCentrePath && inRegion(tile);
    let renderable = false;
    const externals = [];
    for (const uri of contentUris(tile)) {
      const file = uriToFile(baseDir, uri);
      if (!fs.existsSync(file)) {
        missingContent.push(path.relative(path.dirname(tilesetFile), file));
        renderable = true; // it was meant to be rendered
        continue;
      }
      if (/\.json$/i.test(file)) {
        externals.push(file);
        continue;
      }
      renderable = true;
      if (/\.glb$/i.test(file)) {
        glbChecked++;
        const r = checkGlb(file);
        if (r.error) glbErrors.push({ file: path.relative(path.dirname(tilesetFile), file), error: r.error });
        else r.extensionsUsed.forEach((x) => extensionsSeen.add(x));
      }
    }
    if (renderable) d.contentTiles++;
    if (here && renderable && !(depth in centreChain)) {
      const r = tile.boundingVolume.region;
      centreChain[depth] = { geometricError: tile.geometricError, regionTop: r[5], regionBottom: r[4] };
    }
    for (const child of tile.children || []) walk(child, treeDepth + 1, baseDir, here);
    for (const ext of externals) {
      if (visitedJson.has(ext)) {
        notes.push(`external tileset cycle at ${ext}`);
        continue;
      }
      visitedJson.add(ext);
      const sub = readJson(ext);
      if (sub.root) walk(sub.root, treeDepth + 1, path.dirname(ext), here);
    }
  }
  walk(root.root, 0, path.dirname(tilesetFile), true);
  for (const d of Object.values(depths)) {
    if (!Number.isFinite(d.geometricErrorMin)) d.geometricErrorMin = null;
    if (!Number.isFinite(d.geometricErrorMax)) d.geometricErrorMax = null;
  }
  const region = Array.isArray(reg)
    ? {
        westDeg: deg(reg[0]), southDeg: deg(reg[1]), eastDeg: deg(reg[2]), northDeg: deg(reg[3]),
        minHeight_m: reg[4], maxHeight_m: reg[5],
      }
    : null;
  return {
    asset: root.asset,
    rootGeometricError: root.geometricError,
    rootRefine: root.root && root.root.refine,
    region,
    centre: centre ? { lon: deg(centre.lon), lat: deg(centre.lat) } : null,
    depths,
    centreChain,
    tileCount,
    missingContent,
    glbChecked,
    glbErrors,
    extensionsUsed: [...extensionsSeen].sort(),
    notes: [...new Set(notes)],
  };
}

function deg(r) {
  return (r * 180) / Math.PI;
}

// ---------------------------------------------------------------------------

async function main() {
  let opts;
  try {
    opts = parseArgs(process.argv.slice(2));
  } catch (e) {
    process.stderr.write(`render_check: ${e.message}\n\n${USAGE}`);
    return 2;
  }
  const t0 = Date.now();
  const log = (msg) => {
    if (!opts.quiet) process.stderr.write(`[render_check ${((Date.now() - t0) / 1000).toFixed(1)}s] ${msg}\n`);
  };
  const outDir = path.resolve(opts.outDir);
  const tilesetFile = path.join(outDir, 'tileset.json');
  if (!fs.existsSync(tilesetFile)) {
    process.stderr.write(`render_check: no tileset.json in ${outDir}\n`);
    return 2;
  }
  if (!fs.existsSync(opts.chromium)) {
    process.stderr.write(
      `render_check: browser not found at ${opts.chromium} (apt-get install -y chromium, or pass --chromium PATH)\n`,
    );
    return 2;
  }
  let chromium;
  try {
    ({ chromium } = await import('playwright-core'));
  } catch {
    process.stderr.write(`render_check: playwright-core missing: (cd ${path.relative(process.cwd(), HERE) || '.'} && npm ci)\n`);
    return 2;
  }
  const { startServer } = await import(SERVE_MJS);

  let stat;
  try {
    stat = analyseTileset(tilesetFile);
  } catch (e) {
    process.stderr.write(`render_check: cannot read the tileset: ${e.message}\n`);
    return 2;
  }
  const expectedDepths = Object.keys(stat.depths)
    .map(Number)
    .filter((d) => stat.depths[d].contentTiles > 0)
    .sort((a, b) => a - b);
  log(
    `tileset: ${stat.tileCount} tiles, content at depths ${expectedDepths.join(',')}, ` +
      `centre ${stat.centre ? `${stat.centre.lat.toFixed(4)}N ${stat.centre.lon.toFixed(4)}E` : '?'}`,
  );

  const result = {
    ok: false,
    reasons: [],
    outDir,
    tilesetGeometricError: stat.rootGeometricError,
    centerLonLatDeg: stat.centre ? [stat.centre.lon, stat.centre.lat] : null,
    region: stat.region,
    surfaceHeightAtCenter_m: null,
    tilesByLevel: {},
    failedTiles: [],
    consoleErrors: [],
    httpErrors: [],
    missingContent: stat.missingContent,
    glbChecked: stat.glbChecked,
    glbErrors: stat.glbErrors,
    extensionsUsed: stat.extensionsUsed,
    surfaceSamples: [],
    steps: [],
    warnings: [...stat.notes],
    boundingSphere: null,
    screenshot: opts.screenshot ? path.resolve(opts.screenshot) : null,
    screenshotClose: opts.screenshotClose ? path.resolve(opts.screenshotClose) : null,
    seconds: {},
    browser: null,
  };

  let server = null;
  let context = null;
  let stLast = {}; // the viewer status last read
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'tt-render-check-'));
  const timeoutMs = opts.timeoutS * 1000;
  try {
    server = await startServer({ outDir, port: 0 });
    const url = `${server.url}?tileset=/data/tileset.json&sse=${opts.sse}${opts.params ? '&' + opts.params : ''}`;
    log(`serving ${outDir} at ${server.url}`);

    context = await launchChromium(chromium, {
      executablePath: opts.chromium,
      userDataDir,
      width: opts.width,
      height: opts.height,
    });
    result.browser = context.browser() ? context.browser().version() : null;
    const page = context.pages()[0] || (await context.newPage());
    page.setDefaultTimeout(timeoutMs);

    page.on('console', (msg) => {
      if (msg.type() === 'error') result.consoleErrors.push(msg.text());
    });
    page.on('pageerror', (err) => result.consoleErrors.push(`pageerror: ${err.message}`));
    page.on('requestfailed', (req) =>
      result.httpErrors.push({ url: req.url(), error: (req.failure() && req.failure().errorText) || 'failed' }),
    );
    page.on('response', (resp) => {
      if (resp.status() >= 400) result.httpErrors.push({ url: resp.url(), status: resp.status() });
    });

    log(`opening ${url} (chromium ${result.browser})`);
    await page.goto(url, { waitUntil: 'load', timeout: 60000 });
    const webgl = await page.evaluate(() => {
      const c = document.createElement('canvas');
      const gl = c.getContext('webgl2') || c.getContext('webgl');
      if (!gl) return null;
      const dbg = gl.getExtension('WEBGL_debug_renderer_info');
      return dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    });
    result.webglRenderer = webgl;
    if (!webgl) throw new Error('no WebGL in the browser');

    // --- initial view ------------------------------------------------------
    const tLoad = Date.now();
    try {
      await page.waitForFunction(
        () => window.terratiles && (window.terratiles.ready || window.terratiles.error),
        null,
        { timeout: timeoutMs, polling: 500 },
      );
    } catch {
      result.reasons.push(`initial view not loaded within ${opts.timeoutS} s`);
    }
    result.seconds.initialLoad = (Date.now() - tLoad) / 1000;
    let st = await page.evaluate(() => window.terratiles);
    stLast = st;
    if (st.error) result.reasons.push(`tileset failed to load: ${st.error}`);
    if (st.renderError) result.reasons.push(`render error: ${st.renderError}`);
    result.boundingSphere = st.boundingSphere;
    log(
      `initial view: ${st.ready ? 'loaded' : 'NOT loaded'} after ${result.seconds.initialLoad.toFixed(1)} s, ` +
        `rendered per level (zoom) ${JSON.stringify(st.renderedByLevel)}`,
    );
    result.initialView = {
      ready: st.ready,
      visibleByLevel: st.visibleByLevel,
      cameraHeight_m: st.camera && st.camera.height,
    };
    if (st.ready && !Object.values(st.visibleByLevel).some((n) => n > 0)) {
      // The overview shows the whole bounding sphere; CesiumJS draws nothing when
      // the tileset-level geometricError gives a screen-space error below the limit.
      result.reasons.push(
        `nothing drawn in the overview view (camera ${Math.round(st.camera.height)} m high, ` +
          `tileset geometricError ${stat.rootGeometricError}): is the top-level geometricError too small?`,
      );
    }
    if (opts.screenshot) {
      await page.screenshot({ path: opts.screenshot, timeout: timeoutMs });
      log(`screenshot ${opts.screenshot}`);
    }

    // --- zoom towards the centre, one step per depth ----------------------
    if (st.ready && !st.error && stat.centre) {
      const k = await page.evaluate(() => {
        const v = window.terratilesApi.viewer;
        return v.scene.drawingBufferHeight / v.camera.frustum.sseDenominator;
      });
      // A tile of geometric error g is refined when g*k/d > sse, d = distance to it.
      const refineDist = (g) => (g * k) / opts.sse;
      const plan = [];
      const chainDepths = Object.keys(stat.centreChain).map(Number).sort((a, b) => a - b);
      for (let i = 0; i < chainDepths.length; i++) {
        const dpt = chainDepths[i];
        const c = stat.centreChain[dpt];
        const parent = i > 0 ? stat.centreChain[chainDepths[i - 1]] : null;
        const lo = c.geometricError > 0 ? refineDist(c.geometricError) : 0; // closer -> children
        const hi = parent && parent.geometricError > 0 ? refineDist(parent.geometricError) : Infinity;
        let dist;
        if (Number.isFinite(hi) && lo > 0) dist = Math.sqrt(lo * hi);
        else if (Number.isFinite(hi)) dist = hi / 3;
        else dist = lo * 1.5;
        if (!(dist > 0) || !Number.isFinite(dist)) continue;
        if (hi <= lo) result.warnings.push(`depth ${dpt}: geometric error not below its parent's`);
        plan.push({ depth: dpt, range: Math.max(dist, 20), targetHeight: c.regionTop });
      }
      const runStep = async (step) => {
        const ts = Date.now();
        const f0 = await page.evaluate(
          ([lon, lat, h, r]) => {
            window.terratilesApi.lookAt(lon, lat, h, r, -89.5, 0);
            return window.terratiles.frame;
          },
          [stat.centre.lon, stat.centre.lat, step.targetHeight, step.range],
        );
        let settled = true;
        try {
          await page.waitForFunction(
            (f) => window.terratiles.frame > f + 10 && window.terratiles.stableFrames >= 5,
            f0,
            { timeout: timeoutMs, polling: 250 },
          );
        } catch {
          settled = false;
          result.warnings.push(`zoom step to ${Math.round(step.range)} m did not finish loading within ${opts.timeoutS} s`);
        }
        st = await page.evaluate(() => window.terratiles);
        const rec = {
          forDepth: step.depth,
          range_m: Math.round(step.range),
          cameraHeight_m: st.camera ? Math.round(st.camera.height) : null,
          settled,
          seconds: (Date.now() - ts) / 1000,
          visibleByLevel: st.visibleByLevel,
        };
        result.steps.push(rec);
        log(
          `zoom step ${step.depth === null ? '(sweep)' : `depth ${step.depth}`}: camera ${rec.cameraHeight_m} m, ` +
            `${settled ? 'settled' : 'NOT settled'} in ${rec.seconds.toFixed(1)} s, visible ${JSON.stringify(st.visibleByLevel)}`,
        );
      };
      for (const step of plan) await runStep(step);
      // Fallback: a plain geometric sweep when some depth has still not been drawn
      // (e.g. the centre falls into a gap of an irregular tree).
      const unrendered = () => expectedDepths.filter((d) => !(st.renderedByLevel[d] > 0));
      const errors = Object.values(stat.depths)
        .flatMap((d) => [d.geometricErrorMin, d.geometricErrorMax])
        .filter((g) => g > 0);
      if (errors.length && unrendered().length) {
        const rMax = refineDist(Math.max(...errors)) * 2;
        const rMin = Math.max(refineDist(Math.min(...errors)) / 2, 10);
        const top = stat.region ? stat.region.maxHeight_m : 0;
        const n = 8;
        log(`depth(s) ${unrendered().join(',')} not rendered yet: sweeping ${Math.round(rMax)} m .. ${Math.round(rMin)} m`);
        for (let i = 0; i < n && unrendered().length; i++) {
          await runStep({ depth: null, range: rMax * (rMin / rMax) ** (i / (n - 1)), targetHeight: top });
        }
      }
      if (opts.screenshotClose && plan.length) {
        // Same distance as the deepest step, tilted so the relief shows.
        const last = plan[plan.length - 1];
        const f0 = await page.evaluate(
          ([lon, lat, h, r]) => {
            window.terratilesApi.lookAt(lon, lat, h, r, -35, 0);
            return window.terratiles.frame;
          },
          [stat.centre.lon, stat.centre.lat, last.targetHeight, last.range * 1.5],
        );
        await page
          .waitForFunction((f) => window.terratiles.frame > f + 10 && window.terratiles.stableFrames >= 5, f0, {
            timeout: timeoutMs,
            polling: 250,
          })
          .catch(() => result.warnings.push('close-up view did not finish loading before its screenshot'));
        await page.screenshot({ path: opts.screenshotClose, timeout: timeoutMs });
        log(`screenshot ${opts.screenshotClose}`);
      }

      // --- surface height at the centre and four more points ---------------
      const tSample = Date.now();
      const pts = [[0.5, 0.5], [0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]];
      const reg = stat.region;
      for (const [fx, fy] of pts) {
        let lon = stat.centre.lon;
        let lat = stat.centre.lat;
        if (reg && !(fx === 0.5 && fy === 0.5)) {
          let span = reg.eastDeg - reg.westDeg;
          if (span < 0) span += 360;
          lon = reg.westDeg + span * fx;
          lat = reg.southDeg + (reg.northDeg - reg.southDeg) * fy;
        }
        let h = null;
        let err = null;
        try {
          h = await Promise.race([
            page.evaluate(([lo, la]) => window.terratilesApi.sampleHeight(lo, la), [lon, lat]),
            new Promise((_, rej) => setTimeout(() => rej(new Error('timeout')), timeoutMs)),
          ]);
        } catch (e) {
          err = e.message;
        }
        result.surfaceSamples.push({ lon, lat, height_m: h, ...(err ? { error: err } : {}) });
        if (!reg) break;
      }
      result.seconds.heightSampling = (Date.now() - tSample) / 1000;
      result.surfaceHeightAtCenter_m = result.surfaceSamples[0] ? result.surfaceSamples[0].height_m : null;
      log(`surface height at centre: ${result.surfaceHeightAtCenter_m}`);
      st = await page.evaluate(() => window.terratiles);
    }

    // --- collect -----------------------------------------------------------
    stLast = st;
    result.failedTiles = st.failedTiles;
    result.tilesLoadedEvents = st.tilesLoaded;
    if (st.renderError) result.reasons.push(`render error: ${st.renderError}`);
    const allDepths = new Set([
      ...Object.keys(stat.depths),
      ...Object.keys(st.tilesByLevel),
      ...Object.keys(st.renderedByLevel),
    ]);
    for (const d of [...allDepths].map(Number).sort((a, b) => a - b)) {
      const s = stat.depths[d] || {};
      result.tilesByLevel[d] = {
        inTileset: s.contentTiles ?? 0,
        loaded: st.tilesByLevel[d] || 0,
        rendered: st.renderedByLevel[d] || 0,
        geometricError: s.geometricErrorMax ?? st.geometricErrorByLevel[d] ?? null,
      };
    }
  } catch (e) {
    result.reasons.push(`check aborted: ${e.message}`);
  } finally {
    if (context) await context.close().catch(() => {});
    if (server) await server.close().catch(() => {});
    fs.rmSync(userDataDir, { recursive: true, force: true });
  }
  result.seconds.total = (Date.now() - t0) / 1000;

  // --- verdict ---------------------------------------------------------------
  const R = result.reasons;
  if (result.failedTiles.length) R.push(`${result.failedTiles.length} tile(s) failed to load`);
  if (stat.missingContent.length) R.push(`${stat.missingContent.length} content file(s) missing`);
  if (stat.glbErrors.length) R.push(`${stat.glbErrors.length} invalid GLB file(s)`);
  const dataHttpErrors = result.httpErrors.filter((h) => /\/data\//.test(h.url));
  if (dataHttpErrors.length) R.push(`${dataHttpErrors.length} failed request(s) under /data/`);
  const notRendered = expectedDepths.filter((d) => !(result.tilesByLevel[d] && result.tilesByLevel[d].rendered > 0));
  if (notRendered.length) R.push(`no tile rendered at level(s) ${notRendered.join(',')}`);
  // The geometricError CesiumJS gave a loaded tile must be one the tileset holds at that level
  // (implicit tiling: from the tile metadata, not the root's error halved per level).
  for (const [level, used] of Object.entries(stLast.geometricErrorByLevel || {})) {
    const s = stat.depths[level];
    if (!s || s.geometricErrorMin === null) continue;
    const slack = 1e-9 * Math.max(1, Math.abs(used));
    if (used < s.geometricErrorMin - slack || used > s.geometricErrorMax + slack) {
      R.push(`level ${level}: CesiumJS used geometricError ${used}, the tileset has ${s.geometricErrorMin}..${s.geometricErrorMax}`);
    }
  }
  if (opts.expectLon !== null && result.centerLonLatDeg) {
    const [lon, lat] = result.centerLonLatDeg;
    const dLon = Math.abs(((lon - opts.expectLon + 540) % 360) - 180);
    const dLat = Math.abs(lat - opts.expectLat);
    result.expectCenter = { lon: opts.expectLon, lat: opts.expectLat, toleranceDeg: opts.toleranceDeg, dLon, dLat };
    if (dLon > opts.toleranceDeg || dLat > opts.toleranceDeg) {
      R.push(`centre ${lon.toFixed(4)},${lat.toFixed(4)} is not within ${opts.toleranceDeg} deg of ${opts.expectLon},${opts.expectLat}`);
    }
  } else if (opts.expectLon !== null) {
    R.push('centre unknown (root has no region bounding volume)');
  }
  const h = result.surfaceHeightAtCenter_m;
  if (opts.expectHeight !== null) {
    result.expectHeight = { height_m: opts.expectHeight, tolerance_m: opts.heightTolerance };
    if (h === null || h === undefined) R.push('no tileset surface found at the centre');
    else if (Math.abs(h - opts.expectHeight) > opts.heightTolerance) {
      R.push(`surface height ${h.toFixed(1)} m at the centre is not within ${opts.heightTolerance} m of ${opts.expectHeight} m`);
    }
  }
  if (result.surfaceSamples.length && stat.region) {
    const span = stat.region.maxHeight_m - stat.region.minHeight_m;
    const tol = Math.max(5, 0.02 * span);
    for (const s of result.surfaceSamples) {
      if (s.height_m === null || s.height_m === undefined) {
        result.warnings.push(`no tileset surface at ${s.lon.toFixed(4)},${s.lat.toFixed(4)}`);
      } else if (s.height_m < stat.region.minHeight_m - tol || s.height_m > stat.region.maxHeight_m + tol) {
        R.push(
          `surface height ${s.height_m.toFixed(1)} m at ${s.lon.toFixed(4)},${s.lat.toFixed(4)} is outside the root region ` +
            `heights [${stat.region.minHeight_m}, ${stat.region.maxHeight_m}]`,
        );
      }
    }
    if (result.surfaceSamples.every((s) => s.height_m === null || s.height_m === undefined)) {
      R.push('no tileset surface found at any sample point (misplaced or mis-oriented tiles?)');
    }
  }
  result.ok = R.length === 0;

  const text = JSON.stringify(result, null, 2) + '\n';
  process.stdout.write(text);
  if (opts.json) fs.writeFileSync(opts.json, text);
  log(`${result.ok ? 'OK' : 'FAILED: ' + R.join('; ')} (${result.seconds.total.toFixed(1)} s)`);
  return result.ok ? 0 : 1;
}

main().then(
  (code) => process.exit(code),
  (e) => {
    process.stderr.write(`render_check: ${e.stack || e}\n`);
    process.exit(2);
  },
);
