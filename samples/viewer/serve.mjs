#!/usr/bin/env node
// Tiny static server for the terratiles CesiumJS viewer (node built-ins only).
//
//   node samples/viewer/serve.mjs OUTDIR [--port N]
//
// Serves, on 127.0.0.1 only:
//   /            -> samples/viewer/index.html and main.js
//   /cesium/...  -> samples/viewer/node_modules/cesium/Build/Cesium/...
//   /data/...    -> OUTDIR/... (the terratiles output: tileset.json and *.glb, or layer.json
//                   and gzip'd *.terrain, sent with Content-Encoding: gzip)
//
// The module can also be imported: `startServer({ outDir, port })` resolves
// to `{ server, port, url, close() }` (port 0 picks a free port).

import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const HERE = path.dirname(fileURLToPath(import.meta.url));
export const HOST = '127.0.0.1';
export const DEFAULT_PORT = 8080;
export const CESIUM_DIR = path.join(HERE, 'node_modules', 'cesium', 'Build', 'Cesium');

const MIME = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8',
  '.cjs': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8',
  '.json': 'application/json; charset=utf-8',
  '.geojson': 'application/geo+json',
  '.xml': 'application/xml',
  '.txt': 'text/plain; charset=utf-8',
  '.wasm': 'application/wasm',
  '.glb': 'model/gltf-binary',
  '.gltf': 'model/gltf+json',
  '.b3dm': 'application/octet-stream',
  '.i3dm': 'application/octet-stream',
  '.pnts': 'application/octet-stream',
  '.cmpt': 'application/octet-stream',
  '.subtree': 'application/octet-stream',
  '.terrain': 'application/vnd.quantized-mesh',
  '.bin': 'application/octet-stream',
  '.png': 'image/png',
  '.jpg': 'image/jpeg',
  '.jpeg': 'image/jpeg',
  '.webp': 'image/webp',
  '.ktx2': 'image/ktx2',
  '.gif': 'image/gif',
  '.svg': 'image/svg+xml',
  '.ico': 'image/x-icon',
  '.woff': 'font/woff',
  '.woff2': 'font/woff2',
  '.ttf': 'font/ttf',
  '.map': 'application/json; charset=utf-8',
};

export function mimeType(file) {
  return MIME[path.extname(file).toLowerCase()] || 'application/octet-stream';
}

// Resolve a URL path below `root`; returns null when it escapes `root`.
function resolveUnder(root, relUrlPath) {
  let rel;
  try {
    rel = decodeURIComponent(relUrlPath);
  } catch {
    return null;
  }
  if (rel.includes('\0')) return null;
  const full = path.resolve(root, '.' + path.posix.normalize('/' + rel));
  const rootResolved = path.resolve(root);
  if (full !== rootResolved && !full.startsWith(rootResolved + path.sep)) return null;
  return full;
}

function send(res, status, body, headers = {}) {
  res.writeHead(status, { 'Content-Type': 'text/plain; charset=utf-8', ...headers });
  res.end(body);
}

function isGzip(file) {
  const head = Buffer.alloc(2);
  let fd = null;
  try {
    fd = fs.openSync(file, 'r');
    return fs.readSync(fd, head, 0, 2, 0) === 2 && head[0] === 0x1f && head[1] === 0x8b;
  } catch {
    return false;
  } finally {
    if (fd !== null) fs.closeSync(fd);
  }
}

function sendFile(req, res, file, { noCache = false } = {}) {
  fs.stat(file, (err, st) => {
    if (err || !st.isFile()) {
      send(res, 404, `Not found: ${req.url}\n`);
      return;
    }
    const headers = {
      'Content-Type': mimeType(file),
      'Content-Length': st.size,
      'Cache-Control': noCache ? 'no-store' : 'public, max-age=3600',
      'Access-Control-Allow-Origin': '*',
    };
    // quantized-mesh tiles are stored gzip'd: the client inflates them.
    if (path.extname(file) === '.terrain' && isGzip(file)) headers['Content-Encoding'] = 'gzip';
    res.writeHead(200, headers);
    if (req.method === 'HEAD') {
      res.end();
      return;
    }
    const stream = fs.createReadStream(file);
    stream.on('error', () => res.destroy());
    stream.pipe(res);
  });
}

export function createHandler({ outDir, log = false }) {
  const viewerFiles = new Map([
    ['/', 'index.html'],
    ['/index.html', 'index.html'],
    ['/main.js', 'main.js'],
  ]);
  return (req, res) => {
    if (log) {
      res.on('finish', () => console.log(`${res.statusCode} ${req.method} ${req.url}`));
    }
    if (req.method !== 'GET' && req.method !== 'HEAD') {
      send(res, 405, 'Method not allowed\n', { Allow: 'GET, HEAD' });
      return;
    }
    const urlPath = new URL(req.url, 'http://localhost').pathname;
    if (viewerFiles.has(urlPath)) {
      sendFile(req, res, path.join(HERE, viewerFiles.get(urlPath)), { noCache: true });
      return;
    }
    if (urlPath === '/favicon.ico') {
      res.writeHead(204);
      res.end();
      return;
    }
    if (urlPath.startsWith('/cesium/')) {
      const file = resolveUnder(CESIUM_DIR, urlPath.slice('/cesium/'.length));
      if (!file) return send(res, 403, 'Forbidden\n');
      sendFile(req, res, file);
      return;
    }
    if (urlPath.startsWith('/data/')) {
      const file = resolveUnder(outDir, urlPath.slice('/data/'.length));
      if (!file) return send(res, 403, 'Forbidden\n');
      sendFile(req, res, file, { noCache: true });
      return;
    }
    send(res, 404, `Not found: ${req.url}\n`);
  };
}

export function checkCesiumInstalled() {
  if (!fs.existsSync(path.join(CESIUM_DIR, 'Cesium.js'))) {
    throw new Error(
      `CesiumJS not found at ${CESIUM_DIR}.\n` +
        `Install it first:  (cd ${path.relative(process.cwd(), HERE) || '.'} && npm ci)`,
    );
  }
}

// Whether tileset.json is 3D Tiles terrain (terratiles build --format terrain).
function isTerrainTileset(file) {
  try {
    return JSON.parse(fs.readFileSync(file, 'utf8')).extras?.terratiles?.format === '3d-tiles-terrain';
  } catch {
    return false;
  }
}

export function startServer({ outDir, port = DEFAULT_PORT, log = false }) {
  checkCesiumInstalled();
  const root = path.resolve(outDir);
  if (!fs.existsSync(root) || !fs.statSync(root).isDirectory()) {
    return Promise.reject(new Error(`OUTDIR is not a directory: ${root}`));
  }
  const server = http.createServer(createHandler({ outDir: root, log }));
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, HOST, () => {
      server.off('error', reject);
      const actualPort = server.address().port;
      const url = `http://${HOST}:${actualPort}/`;
      resolve({
        server,
        port: actualPort,
        url,
        // A terrain layer (layer.json) is shown as the globe's terrain, a tileset on it.
        viewerUrl: fs.existsSync(path.join(root, 'layer.json'))
          ? `${url}?terrain=/data/layer.json`
          : isTerrainTileset(path.join(root, 'tileset.json'))
            ? `${url}?terrain=/data/tileset.json`
            : `${url}?tileset=/data/tileset.json`,
        close: () =>
          new Promise((r) => {
            server.closeAllConnections?.();
            server.close(() => r());
          }),
      });
    });
  });
}

function usage(code) {
  const msg =
    'Usage: node samples/viewer/serve.mjs OUTDIR [--port N] [--log]\n' +
    '  Serves the CesiumJS viewer and OUTDIR (under /data/) on 127.0.0.1.\n' +
    `  --port N   port to listen on (default ${DEFAULT_PORT}; 0 = any free port)\n` +
    '  --log      log every request\n';
  (code ? process.stderr : process.stdout).write(msg);
  process.exit(code);
}

async function main(argv) {
  let outDir = null;
  let port = DEFAULT_PORT;
  let log = false;
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === '-h' || a === '--help') usage(0);
    else if (a === '--port') port = Number(argv[++i]);
    else if (a.startsWith('--port=')) port = Number(a.slice(7));
    else if (a === '--log') log = true;
    else if (a.startsWith('-')) usage(2);
    else if (outDir === null) outDir = a;
    else usage(2);
  }
  if (outDir === null || !Number.isInteger(port) || port < 0 || port > 65535) usage(2);
  try {
    const s = await startServer({ outDir, port, log });
    console.log(`Serving ${path.resolve(outDir)} under /data/`);
    console.log(`Viewer: ${s.viewerUrl}`);
    const stop = () => s.close().then(() => process.exit(0));
    process.on('SIGINT', stop);
    process.on('SIGTERM', stop);
  } catch (e) {
    console.error(`serve.mjs: ${e.message}`);
    process.exit(1);
  }
}

if (process.argv[1] && import.meta.url === pathToFileURL(path.resolve(process.argv[1])).href) {
  main(process.argv.slice(2));
}
