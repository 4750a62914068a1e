// terratiles_bench_glb: what a built tileset's GLB tiles cost to store and to decode.
//
//   terratiles_bench_glb OUTDIR... [--runs 5]
//
// For every OUTDIR (a `terratiles build` output): tiles, triangles, bytes per triangle, and
// the median over --runs of decoding every tile (Draco through the same decoder CesiumJS
// ships, compiled natively here), as million triangles per second. Comparing outputs of one
// DEM built with different --draco-speed or --position-step shows the size/speed trade.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "formats/gltf/read_glb.h"
#include "src/base/error.h"

namespace {

struct TileFile {
  std::string name;
  std::vector<std::uint8_t> bytes;
};

std::vector<TileFile> readTiles(const std::filesystem::path& outdir) {
  std::vector<TileFile> tiles;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(outdir)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".glb") continue;
    std::ifstream in(entry.path(), std::ios::binary);
    tiles.push_back({entry.path().string(), {std::istreambuf_iterator<char>(in), {}}});
  }
  std::sort(tiles.begin(), tiles.end(), [](const TileFile& a, const TileFile& b) { return a.name < b.name; });
  return tiles;
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
  std::printf("%-40s %6s %10s %12s %7s %12s %10s\n", "output", "tiles", "triangles", "bytes", "B/tri",
              "decode ms", "Mtri/s");
  try {
    for (const std::string& outdir : outdirs) {
      const std::vector<TileFile> tiles = readTiles(outdir);
      std::size_t triangles = 0, bytes = 0;
      std::vector<double> seconds;
      for (int run = 0; run < runs; ++run) {
        std::size_t run_triangles = 0;
        const auto start = std::chrono::steady_clock::now();
        for (const TileFile& tile : tiles) {
          run_triangles += terratiles::decodeGlb(tile.bytes, tile.name).mesh.triangle_indices.size() / 3;
        }
        seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        triangles = run_triangles;
      }
      for (const TileFile& tile : tiles) bytes += tile.bytes.size();
      std::nth_element(seconds.begin(), seconds.begin() + runs / 2, seconds.end());
      const double median = seconds[static_cast<std::size_t>(runs / 2)];
      std::printf("%-40s %6zu %10zu %12zu %7.3f %12.2f %10.2f\n", outdir.c_str(), tiles.size(), triangles, bytes,
                  triangles ? static_cast<double>(bytes) / static_cast<double>(triangles) : 0.0, median * 1000,
                  median > 0 ? static_cast<double>(triangles) / median / 1e6 : 0.0);
    }
  } catch (const terratiles::Error& error) {
    std::fprintf(stderr, "terratiles_bench_glb: %s\n", error.what());
    return 1;
  }
  return 0;
}
