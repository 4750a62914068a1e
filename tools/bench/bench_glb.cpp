// terratiles_bench_glb: what a built output's tiles cost to store and to decode.
//
//   terratiles_bench_glb OUTDIR... [--runs 5]
//
// For every OUTDIR (a `terratiles build` output of any --format): tiles, triangles, bytes per
// triangle (as stored, and gzip'd as a server sends them: quantized-mesh tiles are stored
// gzip'd), and the median over --runs of decoding every tile, natively, as million triangles
// per second: Draco GLBs (a tileset) through the Draco decoder CesiumJS ships; meshopt GLBs
// (3D Tiles terrain) through meshoptimizer's decoders (positions, normals with the octahedral
// filter, triangles, the four edge lists); quantized-mesh tiles (gunzip, zig-zag deltas,
// high-water-mark indices, edges, oct-encoded normals). Every decoder produces positions,
// normals and indices, so the figures compare. Comparing outputs of one DEM built with
// different --format, --draco-speed or --position-step shows the size/speed trade.

#include <algorithm>
#include <cmath>
#include <string_view>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <meshoptimizer.h>
#include <zlib.h>

#include <nlohmann/json.hpp>

#include "formats/gltf/read_glb.h"
#include "formats/quantized_mesh/write_quantized_mesh.h"
#include "src/base/error.h"

namespace {

struct TileFile {
  std::string name;
  std::vector<std::uint8_t> bytes;
};

std::vector<TileFile> readTiles(const std::filesystem::path& outdir) {
  std::vector<TileFile> tiles;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(outdir)) {
    if (!entry.is_regular_file() || (entry.path().extension() != ".glb" && entry.path().extension() != ".terrain")) {
      continue;
    }
    std::ifstream in(entry.path(), std::ios::binary);
    tiles.push_back({entry.path().string(), {std::istreambuf_iterator<char>(in), {}}});
  }
  std::sort(tiles.begin(), tiles.end(), [](const TileFile& a, const TileFile& b) { return a.name < b.name; });
  return tiles;
}

enum class TileKind { DracoGlb, MeshoptGlb, QuantizedMesh };

TileKind tileKind(const TileFile& tile) {
  if (tile.name.ends_with(".terrain")) return TileKind::QuantizedMesh;
  const std::uint32_t json_length = tile.bytes[12] | tile.bytes[13] << 8 | tile.bytes[14] << 16 |
                                    static_cast<std::uint32_t>(tile.bytes[15]) << 24;
  const std::string_view json(reinterpret_cast<const char*>(tile.bytes.data()) + 20, json_length);
  return json.find("EXT_meshopt_compression") != std::string_view::npos ? TileKind::MeshoptGlb : TileKind::DracoGlb;
}

std::uint32_t readUint32(const std::uint8_t* p) {
  return p[0] | p[1] << 8 | p[2] << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

[[noreturn]] void malformed(const std::string& name, const std::string& what) {
  throw terratiles::Error(terratiles::ErrorCode::Input, name + ": " + what);
}

// A meshopt GLB (encodeTerrainGlb's layout): every view decoded into its elements, normals
// through the octahedral filter. Returns the triangles.
std::size_t decodeMeshoptGlb(const TileFile& tile, std::vector<std::uint8_t>& scratch) {
  const std::uint32_t json_length = readUint32(tile.bytes.data() + 12);
  const nlohmann::json gltf = nlohmann::json::parse(tile.bytes.begin() + 20, tile.bytes.begin() + 20 + json_length);
  const std::uint8_t* binary = tile.bytes.data() + 28 + json_length;
  std::size_t triangles = 0;
  for (const nlohmann::json& view : gltf["bufferViews"]) {
    const nlohmann::json& meshopt = view["extensions"]["EXT_meshopt_compression"];
    const std::size_t count = meshopt["count"], stride = meshopt["byteStride"];
    const std::uint8_t* data = binary + meshopt["byteOffset"].get<std::size_t>();
    const std::size_t size = meshopt["byteLength"];
    scratch.resize(count * stride);
    const std::string mode = meshopt["mode"];
    int status = 0;
    if (mode == "ATTRIBUTES") {
      status = meshopt_decodeVertexBuffer(scratch.data(), count, stride, data, size);
      if (meshopt.contains("filter")) meshopt_decodeFilterOct(scratch.data(), count, stride);
    } else if (mode == "TRIANGLES") {
      status = meshopt_decodeIndexBuffer(scratch.data(), count, stride, data, size);
      triangles += count / 3;
    } else {
      status = meshopt_decodeIndexSequence(scratch.data(), count, stride, data, size);
    }
    if (status != 0) malformed(tile.name, "meshopt could not decode a " + mode + " view");
  }
  return triangles;
}

// A gzip'd quantized-mesh tile, decoded as a client does. Returns the triangles.
std::size_t decodeQuantizedMesh(const TileFile& tile, std::vector<std::uint8_t>& raw, std::vector<float>& vertices,
                                std::vector<std::uint32_t>& indices) {
  z_stream stream{};
  if (inflateInit2(&stream, 16 + MAX_WBITS) != Z_OK) malformed(tile.name, "zlib");
  raw.resize(std::max<std::size_t>(raw.size(), tile.bytes.size() * 4));
  stream.next_in = const_cast<Bytef*>(tile.bytes.data());
  stream.avail_in = static_cast<uInt>(tile.bytes.size());
  std::size_t written = 0;
  for (;;) {
    stream.next_out = raw.data() + written;
    stream.avail_out = static_cast<uInt>(raw.size() - written);
    const int status = inflate(&stream, Z_NO_FLUSH);
    written = raw.size() - stream.avail_out;
    if (status == Z_STREAM_END) break;
    if (status != Z_OK && status != Z_BUF_ERROR) malformed(tile.name, "not gzip");
    if (stream.avail_out == 0) raw.resize(raw.size() * 2);
  }
  inflateEnd(&stream);
  const std::uint8_t* p = raw.data() + 88;
  const std::uint32_t count = readUint32(p);
  p += 4;
  vertices.resize(std::size_t{count} * 3);
  for (int axis = 0; axis < 3; ++axis) {
    int value = 0;
    for (std::uint32_t i = 0; i < count; ++i, p += 2) {
      const int zigzag = p[0] | p[1] << 8;
      value += (zigzag >> 1) ^ -(zigzag & 1);
      vertices[3 * i + axis] = static_cast<float>(value) / terratiles::kQuantizedMax;
    }
  }
  const bool wide = count > 65536;
  if (wide && (p - raw.data()) % 4) p += 4 - (p - raw.data()) % 4;
  const std::uint32_t triangles = readUint32(p);
  p += 4;
  indices.resize(std::size_t{triangles} * 3);
  std::uint32_t highest = 0;
  for (std::uint32_t& index : indices) {
    const std::uint32_t code = wide ? readUint32(p) : static_cast<std::uint32_t>(p[0] | p[1] << 8);
    p += wide ? 4 : 2;
    index = highest - code;
    if (code == 0) ++highest;
  }
  for (int side = 0; side < 4; ++side) {
    const std::uint32_t n = readUint32(p);
    p += 4;
    for (std::uint32_t i = 0; i < n; ++i, p += wide ? 4 : 2) indices.push_back(wide ? readUint32(p) : p[0] | p[1] << 8);
  }
  // Extensions: octvertexnormals decoded to unit vectors.
  const std::uint8_t* end = raw.data() + written;
  while (p + 5 <= end) {
    const int id = p[0];
    const std::uint32_t length = readUint32(p + 1);
    p += 5;
    if (id == 1) {
      for (std::uint32_t i = 0; i < count; ++i) {
        float x = p[2 * i] / 255.0f * 2 - 1, y = p[2 * i + 1] / 255.0f * 2 - 1;
        const float z = 1 - (std::fabs(x) + std::fabs(y));
        if (z < 0) {
          const float old_x = x;
          x = (1 - std::fabs(y)) * (old_x < 0 ? -1.0f : 1.0f);
          y = (1 - std::fabs(old_x)) * (y < 0 ? -1.0f : 1.0f);
        }
        const float length_xyz = std::sqrt(x * x + y * y + z * z);
        vertices.push_back(x / length_xyz);
      }
    }
    p += length;
  }
  return triangles;
}

// The bytes gzip (level 6, as web servers use) makes of a tile; quantized-mesh tiles are
// stored gzip'd already.
std::size_t gzipSize(const TileFile& tile, TileKind kind) {
  if (kind == TileKind::QuantizedMesh) return tile.bytes.size();
  return terratiles::gzipBytes(tile.bytes).size();
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> outdirs;
  int runs = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--runs" && i + 1 < argc) {
      runs = std::max(1, std::atoi(argv[++i]));
    } else {
      outdirs.push_back(arg);
    }
  }
  if (outdirs.empty()) {
    std::fprintf(stderr, "usage: terratiles_bench_glb OUTDIR... [--runs 5]\n");
    return 2;
  }
  std::printf("%-40s %-15s %6s %10s %12s %7s %10s %12s %10s\n", "output", "tiles are", "tiles", "triangles",
              "bytes", "B/tri", "gzip B/tri", "decode ms", "Mtri/s");
  try {
    for (const std::string& outdir : outdirs) {
      const std::vector<TileFile> tiles = readTiles(outdir);
      std::size_t triangles = 0, bytes = 0, gzip_bytes = 0;
      std::vector<TileKind> kinds;
      for (const TileFile& tile : tiles) kinds.push_back(tileKind(tile));
      std::vector<double> seconds;
      std::vector<std::uint8_t> scratch;
      std::vector<float> vertices;
      std::vector<std::uint32_t> indices;
      for (int run = 0; run < runs; ++run) {
        std::size_t run_triangles = 0;
        const auto start = std::chrono::steady_clock::now();
        for (std::size_t i = 0; i < tiles.size(); ++i) {
          const TileFile& tile = tiles[i];
          switch (kinds[i]) {
            case TileKind::DracoGlb:
              run_triangles += terratiles::decodeGlb(tile.bytes, tile.name).mesh.triangle_indices.size() / 3;
              break;
            case TileKind::MeshoptGlb: run_triangles += decodeMeshoptGlb(tile, scratch); break;
            case TileKind::QuantizedMesh: run_triangles += decodeQuantizedMesh(tile, scratch, vertices, indices); break;
          }
        }
        seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        triangles = run_triangles;
      }
      for (std::size_t i = 0; i < tiles.size(); ++i) {
        bytes += tiles[i].bytes.size();
        gzip_bytes += gzipSize(tiles[i], kinds[i]);
      }
      const char* kind_names[3] = {"Draco GLB", "meshopt GLB", "quantized-mesh"};
      std::nth_element(seconds.begin(), seconds.begin() + runs / 2, seconds.end());
      const double median = seconds[static_cast<std::size_t>(runs / 2)];
      std::printf("%-40s %-15s %6zu %10zu %12zu %7.3f %10.3f %12.2f %10.2f\n", outdir.c_str(),
                  tiles.empty() ? "-" : kind_names[static_cast<int>(kinds.front())], tiles.size(), triangles, bytes,
                  triangles ? static_cast<double>(bytes) / static_cast<double>(triangles) : 0.0,
                  triangles ? static_cast<double>(gzip_bytes) / static_cast<double>(triangles) : 0.0, median * 1000,
                  median > 0 ? static_cast<double>(triangles) / median / 1e6 : 0.0);
    }
  } catch (const terratiles::Error& error) {
    std::fprintf(stderr, "terratiles_bench_glb: %s\n", error.what());
    return 1;
  }
  return 0;
}
