// terratiles_tiling_experiments: the paper's comparison of cluster-to-tile assignments
// (sections 3.5.4, figs 29, 31, 33) on real rasters, printed as tables.
//
//   terratiles_tiling_experiments RASTER[:TIN_MAX_ERROR]... [--scheme webmercator|geographic|local]
//                                 [--tile-triangles 4096]
//
// For each raster: the greedy TIN, one cluster level per zoom (METIS, 50 % of the edges per
// level, no error budget, as the paper simplified), split into 128 and 256 clusters per
// finest TIN (the paper's figures) and into 4, 8 and 16 per tile. For every split, both
// merge and duplicate assign the clusters to the tiles of every zoom. Redundancy = triangles
// of all tiles of a zoom / triangles of the level (every face once); the paper measured
// bytes (merge 1.36x, duplicate 3.3x at 128 clusters, 2x clusters duplicate 1.26x merge).
// Then, like fig 33, the max vertical error of every level, so merge and duplicate can be
// compared at similar redundancy: duplicate simplifies the METIS clusters as they are, merge
// joins the clusters that cross the same tiles first (paper fig 34, as build does).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/lod/build_levels.h"
#include "src/tiling/assign_clusters.h"
#include "src/tin/build_tin.h"
#include "tools/bench/bench_support.h"

namespace terratiles {
namespace {

// Redundancy of each zoom (finest first) and of all zooms together.
struct Redundancy {
  std::vector<double> per_zoom;
  double total = 0;
};

Redundancy redundancyOf(const TileFrame& frame, const std::vector<Level>& levels, std::int32_t max_zoom,
                        Assignment assignment) {
  Redundancy out;
  std::vector<TileKey> finer, own;
  double tile_triangles = 0, level_triangles = 0;
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const auto zoom = max_zoom - static_cast<std::int32_t>(l);
    double sum = 0;
    for (const TileFaces& tile : assignClusters(frame, levels[l], zoom, assignment, finer, own)) {
      sum += static_cast<double>(tile.faces.size());
    }
    finer = std::move(own);
    const auto triangles = static_cast<double>(levels[l].mesh.triangleCount());
    out.per_zoom.push_back(sum / triangles);
    tile_triangles += sum;
    level_triangles += triangles;
  }
  out.total = tile_triangles / level_triangles;
  return out;
}

int runExperiments(int argc, char** argv) {
  std::vector<bench::RasterSpec> rasters;
  TileSchemeKind scheme = TileSchemeKind::WebMercator;
  std::int32_t tile_triangles = 4096;
  const std::string usage =
      "usage: terratiles_tiling_experiments RASTER[:TIN_MAX_ERROR]... [--scheme webmercator|geographic|local] "
      "[--tile-triangles 4096]";
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::printf("%s\n", usage.c_str());
      return 0;
    }
    if (arg == "--scheme" || arg == "--tile-triangles") {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " needs a value; " + usage);
      const std::string value = argv[++i];
      if (arg == "--scheme") scheme = parseTileSchemeKind(value);
      else tile_triangles = static_cast<std::int32_t>(bench::parseNumber(value, "--tile-triangles"));
      continue;
    }
    if (!arg.empty() && arg[0] == '-') throw Error(ErrorCode::Usage, "unknown option " + arg + "; " + usage);
    rasters.push_back(bench::parseRasterSpec(arg));
  }
  if (rasters.empty()) throw Error(ErrorCode::Usage, "no raster given; " + usage);

  std::printf("== redundancy of merge and duplicate (paper figs 29, 31: merge 1.36x, duplicate 3.3x at 128 "
              "clusters per TIN) and level errors (fig 33)\n"
              "scheme %s, finest tiles of about %d triangles; levels simplified to 50 %% of the edges, no error "
              "budget; redundancy = triangles of all tiles / triangles of the level\n",
              std::string(tileSchemeName(scheme)).c_str(), tile_triangles);
  std::printf("%-34s %-14s %8s %9s %9s  %-34s %-34s %-34s %s\n", "raster @ TIN max error", "split", "clusters",
              "merge", "duplicate", "merge per zoom (finest first)", "duplicate per zoom", "merge max error per level [m]",
              "duplicate max error per level [m]");
  for (const bench::RasterSpec& raster : rasters) {
    std::fprintf(stderr, "%s: reading and building the TIN\n", raster.path.c_str());
    const DemGrid dem = readDem({raster.path});
    Progress quiet(ProgressMode::Quiet);
    const TinMesh tin = buildTin(dem, TinOptions{raster.tin_max_error_m}, quiet);
    const TileFrame frame(scheme, dem);
    const ZoomPlan base = planZooms(frame, tin, tile_triangles, -1, 1);
    if (base.clusters_per_level.empty()) {
      std::printf("%s: one zoom only; nothing to assign\n", raster.path.c_str());
      continue;
    }
    const std::int32_t finest_tiles = base.clusters_per_level.front();
    const std::string label = bench::rasterLabel(raster);
    struct Split {
      std::string name;
      std::int32_t per_tile;
    };
    std::vector<Split> splits;
    for (const std::int32_t per_tin : {128, 256}) {
      splits.push_back({std::to_string(per_tin) + " per TIN", std::max(1, (per_tin + finest_tiles / 2) / finest_tiles)});
    }
    for (const std::int32_t per_tile : {4, 8, 16}) splits.push_back({std::to_string(per_tile) + " per tile", per_tile});
    for (const Split& split : splits) {
      std::fprintf(stderr, "%s: %s\n", label.c_str(), split.name.c_str());
      const ZoomPlan plan = planZooms(frame, tin, tile_triangles, -1, split.per_tile);
      LevelOptions options;
      options.clusters_per_level = plan.clusters_per_level;
      options.coarser_levels = plan.max_zoom - plan.min_zoom;
      // Duplicate simplifies the METIS clusters as they are; merge joins those that cross the
      // same tiles (as build does by default), which unlocks their common borders.
      const std::vector<Level> levels = buildLevels(dem, tin, options, {}, quiet);
      options.regroup_clusters = joinTileClusters(frame, plan.max_zoom);
      const std::vector<Level> joined = buildLevels(dem, tin, options, {}, quiet);
      const Redundancy merge = redundancyOf(frame, joined, plan.max_zoom, Assignment::Merge);
      const Redundancy duplicate = redundancyOf(frame, levels, plan.max_zoom, Assignment::Duplicate);
      const auto list = [](const std::vector<double>& values, const char* format) {
        std::string text;
        char number[32];
        for (const double v : values) {
          std::snprintf(number, sizeof number, format, v);
          if (!text.empty()) text += ' ';
          text += number;
        }
        return text;
      };
      std::vector<double> merge_errors, duplicate_errors;
      for (const Level& level : joined) merge_errors.push_back(level.error.max_error_m);
      for (const Level& level : levels) duplicate_errors.push_back(level.error.max_error_m);
      std::printf("%-34s %-14s %8d %8.3fx %8.3fx  %-34s %-34s %-34s %s\n", label.c_str(), split.name.c_str(),
                  plan.clusters_per_level.front(), merge.total, duplicate.total, list(merge.per_zoom, "%.2f").c_str(),
                  list(duplicate.per_zoom, "%.2f").c_str(), list(merge_errors, "%.2f").c_str(),
                  list(duplicate_errors, "%.2f").c_str());
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace
}  // namespace terratiles

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_tiling_experiments",
                                       [&] { return terratiles::runExperiments(argc, argv); });
}
