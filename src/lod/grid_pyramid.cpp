#include "src/lod/grid_pyramid.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "src/base/error.h"
#include "src/tin/grid_tin.h"

namespace terratiles {
namespace {

std::int32_t zoomsForRoot(const DemGrid& dem, std::int32_t tile_cells) {
  const std::int32_t cells = std::max(dem.width, dem.height) - 1;
  std::int32_t zoom = 0;
  while (static_cast<std::int64_t>(tile_cells) << zoom < cells) ++zoom;
  return zoom;
}

struct ErrorAccumulator {
  double max_m = 0;
  double sum_squares = 0;
  std::size_t count = 0;
  void add(double error_m) {
    max_m = std::max(max_m, error_m);
    sum_squares += error_m * error_m;
    ++count;
  }
  double rms() const { return count ? std::sqrt(sum_squares / static_cast<double>(count)) : 0.0; }
};

// Measures the level's surface against every valid DEM pixel, per tile, cell by cell.
void measureLevel(const DemGrid& dem, PyramidLevel& level, std::int32_t tiles_x,
                  Progress& progress) {
  const std::vector<std::int32_t> cols = gridSamplePositions(dem.width, level.step);
  const std::vector<std::int32_t> rows = gridSamplePositions(dem.height, level.step);
  std::map<std::int64_t, ErrorAccumulator> per_tile;
  ErrorAccumulator whole;
  for (std::size_t j = 0; j + 1 < rows.size(); ++j) {
    for (std::size_t i = 0; i + 1 < cols.size(); ++i) {
      const std::int32_t c0 = cols[i], c1 = cols[i + 1], r0 = rows[j], r1 = rows[j + 1];
      const std::int64_t tile =
          static_cast<std::int64_t>(r0 / level.tile_pixels) * tiles_x + c0 / level.tile_pixels;
      ErrorAccumulator& acc = per_tile[tile];
      for (std::int32_t r = r0; r <= r1; ++r) {
        for (std::int32_t c = c0; c <= c1; ++c) {
          const float h = dem.heightAt(c, r);
          if (std::isnan(h)) continue;
          const double surface = interpolateCell(dem, c0, r0, c1, r1, c, r);
          if (std::isnan(surface)) continue;  // half-cell left out for nodata
          const double error = std::fabs(surface - h);
          acc.add(error);
          whole.add(error);
        }
      }
    }
    progress.advance();
  }
  for (PyramidTile& tile : level.tiles) {
    const auto found = per_tile.find(static_cast<std::int64_t>(tile.key.y) * tiles_x + tile.key.x);
    if (found == per_tile.end()) continue;
    tile.max_error_m = found->second.max_m;
    tile.rms_error_m = found->second.rms();
    tile.measured_pixels = found->second.count;
  }
  level.max_error_m = whole.max_m;
  level.rms_error_m = whole.rms();
}

}  // namespace

GridPyramid buildGridPyramid(const DemGrid& dem, const GridPyramidOptions& options,
                             Progress& progress) {
  TERRATILES_ASSERT(options.tile_cells >= 1);
  const std::int32_t max_zoom =
      options.max_zoom >= 0 ? options.max_zoom : zoomsForRoot(dem, options.tile_cells);

  GridPyramid pyramid;
  pyramid.levels.resize(static_cast<std::size_t>(max_zoom) + 1);
  std::uint64_t total_rows = 0;
  for (std::int32_t zoom = 0; zoom <= max_zoom; ++zoom) {
    total_rows += gridSamplePositions(dem.height, 1 << (max_zoom - zoom)).size();
  }
  progress.beginStage("levels of detail", total_rows);
  for (std::int32_t zoom = max_zoom; zoom >= 0; --zoom) {
    PyramidLevel& level = pyramid.levels[static_cast<std::size_t>(zoom)];
    level.zoom = zoom;
    level.step = 1 << (max_zoom - zoom);
    level.tile_pixels = options.tile_cells * level.step;
    level.mesh = triangulateGrid(dem, level.step);

    const std::int32_t tiles_x = (dem.width - 2) / level.tile_pixels + 1;
    std::map<std::int64_t, std::size_t> tile_slot;  // ordered: tiles sorted by (y, x)
    const auto& idx = level.mesh.triangle_indices;
    for (std::size_t t = 0; t < idx.size(); t += 3) {
      // The centroid lies strictly inside one grid cell, and tile borders are cell borders.
      const auto& a = level.mesh.vertices[idx[t]];
      const auto& b = level.mesh.vertices[idx[t + 1]];
      const auto& c = level.mesh.vertices[idx[t + 2]];
      const auto tx = static_cast<std::int32_t>((a.col + b.col + c.col) / 3.0) / level.tile_pixels;
      const auto ty = static_cast<std::int32_t>((a.row + b.row + c.row) / 3.0) / level.tile_pixels;
      const std::int64_t key = static_cast<std::int64_t>(ty) * tiles_x + tx;
      auto [it, inserted] = tile_slot.try_emplace(key, 0);
      if (inserted) {
        it->second = level.tiles.size();
        level.tiles.push_back({TileKey{zoom, tx, ty}, {}, 0, 0, 0});
      }
      level.tiles[it->second].faces.push_back(static_cast<std::uint32_t>(t / 3));
    }
    std::sort(level.tiles.begin(), level.tiles.end(), [](const PyramidTile& l, const PyramidTile& r) {
      return std::tie(l.key.y, l.key.x) < std::tie(r.key.y, r.key.x);
    });
    measureLevel(dem, level, tiles_x, progress);
  }
  progress.endStage();
  return pyramid;
}

}  // namespace terratiles
