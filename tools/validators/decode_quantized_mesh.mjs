// Decodes quantized-mesh-1.0 terrain tiles with loaders.gl (npm @loaders.gl/terrain, an
// independent decoder: its QuantizedMeshLoader and the decoder behind it) and prints one JSON
// object per file on stdout: the header, the vertices' u, v and height, the triangles, the
// four edge lists, the extensions (id, length; the normals' bytes, the metadata's JSON) and
// what QuantizedMeshLoader made of the tile (its vertex and index counts). A gzip'd tile
// (as served) is inflated first. Exit code 0 when every file decoded, 1 otherwise, 2 on bad
// usage.
import { readFileSync } from 'node:fs';
import { gunzipSync } from 'node:zlib';
import { createRequire } from 'node:module';
import { dirname, join } from 'node:path';
import { pathToFileURL } from 'node:url';

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error('usage: node decode_quantized_mesh.mjs TILE.terrain...');
  process.exit(2);
}

const require = createRequire(import.meta.url);
const { QuantizedMeshLoader } = await import('@loaders.gl/terrain');
// The decoder QuantizedMeshLoader uses, for the fields the loader drops (header, edges,
// extensions). The package does not export it, so it is imported by its file.
const distDir = dirname(require.resolve('@loaders.gl/terrain'));  // .../dist/index.cjs
const { default: decode } = await import(pathToFileURL(join(distDir, 'lib/decode-quantized-mesh.js')));

let failed = 0;
for (const file of files) {
  try {
    let bytes = readFileSync(file);
    const gzip = bytes.length >= 2 && bytes[0] === 0x1f && bytes[1] === 0x8b;
    if (gzip) bytes = gunzipSync(bytes);
    // A fresh ArrayBuffer: the decoder views it from offset 0.
    const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
    const tile = decode(buffer);
    const count = tile.vertexData.length / 3;
    // The extensions after the edge lists, walked here for their ids and the metadata JSON
    // (the decoder keeps only the normals and the water mask).
    const wide = count > 65536 ? 4 : 2;
    const view = new DataView(buffer);
    let at = 88 + 4 + 6 * count;
    if (at % wide) at += wide - (at % wide);
    at += 4 + tile.triangleIndices.length * wide;
    for (const edge of [tile.westIndices, tile.southIndices, tile.eastIndices, tile.northIndices]) {
      at += 4 + edge.length * wide;
    }
    const extensions = [];
    while (at < view.byteLength) {
      const id = view.getUint8(at);
      const length = view.getUint32(at + 1, true);
      const extension = { id, length };
      if (id === 4) {
        const jsonLength = view.getUint32(at + 5, true);
        extension.json = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, at + 9, jsonLength)));
      }
      extensions.push(extension);
      at += 5 + length;
    }
    // A copy: both decode the indices in place, in the buffer they are given.
    const mesh = QuantizedMeshLoader.parseSync(buffer.slice(0), {});
    console.log(JSON.stringify({
      file,
      gzip,
      bytes: bytes.length,
      end: at,
      header: tile.header,
      u: Array.from(tile.vertexData.subarray(0, count)),
      v: Array.from(tile.vertexData.subarray(count, 2 * count)),
      height: Array.from(tile.vertexData.subarray(2 * count)),
      triangles: Array.from(tile.triangleIndices),
      west: Array.from(tile.westIndices),
      south: Array.from(tile.southIndices),
      east: Array.from(tile.eastIndices),
      north: Array.from(tile.northIndices),
      normals: tile.extensions?.vertexNormals ? Array.from(tile.extensions.vertexNormals) : [],
      extensions,
      loader: { vertices: mesh.attributes.POSITION.value.length / 3, indices: mesh.indices.value.length },
    }));
  } catch (error) {
    failed += 1;
    console.log(JSON.stringify({ file, error: String(error) }));
  }
}
process.exitCode = failed ? 1 : 0;  // not process.exit(): it would cut a piped stdout short
