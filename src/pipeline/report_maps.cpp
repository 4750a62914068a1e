#include "src/pipeline/report_maps.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

#include "src/pipeline/report_html.h"
#include "src/tin/measure_tin.h"

namespace terratiles {
namespace {
constexpr int kErrorClasses = 10;

// A map pixel shows the DEM pixel at its block's centre (the last block's centre clamped
// into the raster): along one axis of `size` DEM pixels, map pixel m's.
int blockCentre(int m, int scale, int size) { return std::min(size - 1, m * scale + scale / 2); }
}  // namespace

ClusterMap mapClusters(const DemGrid& dem, const TinMesh& mesh, const FacePartition* partition, int max_side_px) {
  const int scale = std::max(1, static_cast<int>(std::ceil(static_cast<double>(std::max(dem.width, dem.height)) /
                                                           std::max(16, max_side_px))));
  const int width = (dem.width + scale - 1) / scale, height = (dem.height + scale - 1) / scale;
  ClusterMap map;
  map.width = width;
  map.height = height;
  map.scale = scale;
  map.cluster_count = partition ? partition->cluster_count : 0;
  map.by_cluster = partition != nullptr;

  const auto centreCol = [&](int mx) { return blockCentre(mx, scale, dem.width); };
  const auto centreRow = [&](int my) { return blockCentre(my, scale, dem.height); };
  // The map pixels whose centres lie in [first, last] along one axis (centres ascend).
  const auto centresWithin = [&](int first, int last, int count, auto centre) {
    int lo = std::max(0, (first - scale / 2 + scale - 1) / scale);
    if (first - scale / 2 < 0) lo = 0;
    while (lo > 0 && centre(lo - 1) >= first) --lo;
    while (lo < count && centre(lo) < first) ++lo;
    int hi = lo;
    while (hi < count && centre(hi) <= last) ++hi;
    return std::array<int, 2>{lo, hi};  // [lo, hi)
  };
  // Per map pixel: the face covering its centre with the largest index (taken with an atomic
  // maximum, the same for any thread count), by forEachCoveredPixel's test of the centres alone.
  std::vector<std::uint32_t> last_face(static_cast<std::size_t>(width) * height, 0);  // face + 1; 0: none
  const auto& idx = mesh.triangle_indices;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, mesh.triangleCount(), 4096), [&](const tbb::blocked_range<std::size_t>& faces) {
        for (std::size_t f = faces.begin(); f < faces.end(); ++f) {
          const GridPoint& a = mesh.vertices[idx[3 * f]];
          const GridPoint& b = mesh.vertices[idx[3 * f + 1]];
          const GridPoint& c = mesh.vertices[idx[3 * f + 2]];
          const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
          if (area2 == 0) continue;
          const double eps = 1e-9 * std::fabs(area2);
          const int min_col = std::max(0, static_cast<int>(std::ceil(std::min({a.col, b.col, c.col}) - 1e-9)));
          const int max_col =
              std::min(dem.width - 1, static_cast<int>(std::floor(std::max({a.col, b.col, c.col}) + 1e-9)));
          const int min_row = std::max(0, static_cast<int>(std::ceil(std::min({a.row, b.row, c.row}) - 1e-9)));
          const int max_row =
              std::min(dem.height - 1, static_cast<int>(std::floor(std::max({a.row, b.row, c.row}) + 1e-9)));
          if (min_col > max_col || min_row > max_row) continue;
          const auto rows = centresWithin(min_row, max_row, height, centreRow);
          if (rows[0] >= rows[1]) continue;
          const auto cols = centresWithin(min_col, max_col, width, centreCol);
          const auto mark = static_cast<std::uint32_t>(f + 1);
          for (int my = rows[0]; my < rows[1]; ++my) {
            const double row = centreRow(my);
            for (int mx = cols[0]; mx < cols[1]; ++mx) {
              const double col = centreCol(mx);
              const double wa = ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col)) / area2;
              const double wb = ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col)) / area2;
              const double wc = 1.0 - wa - wb;
              if (wa * std::fabs(area2) < -eps || wb * std::fabs(area2) < -eps || wc * std::fabs(area2) < -eps) {
                continue;
              }
              std::atomic_ref<std::uint32_t> slot(last_face[static_cast<std::size_t>(my) * width + mx]);
              std::uint32_t seen = slot.load(std::memory_order_relaxed);
              while (seen < mark && !slot.compare_exchange_weak(seen, mark, std::memory_order_relaxed)) {
              }
            }
          }
        }
      });

  // Map pixel -> its cluster.
  map.cluster.assign(static_cast<std::size_t>(width) * height, -1);
  for (std::size_t i = 0; i < map.cluster.size(); ++i) {
    if (last_face[i] > 0) map.cluster[i] = partition ? partition->cluster_of_face[last_face[i] - 1] : 0;
  }
  return map;
}

ZoomMaps drawClusterMap(const DemGrid& dem, const ClusterMap& clusters, const TileFrame* frame, std::int32_t zoom) {
  const int scale = clusters.scale, width = clusters.width, height = clusters.height;
  const std::vector<std::int32_t>& map_cluster = clusters.cluster;
  const bool by_cluster = clusters.by_cluster;
  ZoomMaps maps;
  maps.zoom = zoom;
  maps.width = width;
  maps.height = height;
  maps.scale = scale;
  maps.cluster_count = clusters.cluster_count;
  RgbImage image(width, height, 235);
  // Map pixel -> its tile.
  std::vector<GridPoint> centres;
  centres.reserve(map_cluster.size());
  for (int my = 0; my < height; ++my) {
    for (int mx = 0; mx < width; ++mx) {
      centres.push_back({static_cast<double>(blockCentre(mx, scale, dem.width)),
                         static_cast<double>(blockCentre(my, scale, dem.height)), 0});
    }
  }
  std::vector<TileKey> tile(map_cluster.size());
  if (frame) {
    const std::vector<std::array<double, 2>> points = frame->toScheme(centres);
    tbb::parallel_for(std::size_t{0}, points.size(), [&](std::size_t i) { tile[i] = frame->tileAt(points[i], zoom); });
  }
  for (std::size_t i = 0; i < map_cluster.size(); ++i) {
    const std::int32_t id = map_cluster[i];
    if (id < 0) continue;
    const auto c = by_cluster ? clusterColour(static_cast<std::uint32_t>(id))
                              : clusterColour(static_cast<std::uint32_t>(tile[i].x * 7919 + tile[i].y));
    std::copy(c.begin(), c.end(), image.at(static_cast<int>(i % width), static_cast<int>(i / width)));
  }
  // Outlines over the colours: cluster borders black, tile outlines white (on top), where a
  // map pixel differs from its right or lower neighbour.
  for (int my = 0; my < height; ++my) {
    for (int mx = 0; mx < width; ++mx) {
      const std::size_t i = static_cast<std::size_t>(my) * width + mx;
      if (map_cluster[i] < 0) continue;
      bool cluster_border = false, tile_border = false;
      for (const auto& [dx, dy] : {std::pair{1, 0}, std::pair{0, 1}}) {
        if (mx + dx >= width || my + dy >= height) continue;
        const std::size_t j = static_cast<std::size_t>(my + dy) * width + mx + dx;
        if (map_cluster[j] < 0) continue;
        cluster_border |= by_cluster && map_cluster[j] != map_cluster[i];
        tile_border |= frame && !(tile[j] == tile[i]);
      }
      std::uint8_t* p = image.at(mx, my);
      if (tile_border) {
        p[0] = p[1] = p[2] = 255;
      } else if (cluster_border) {
        p[0] = p[1] = p[2] = 20;
      }
    }
  }
  maps.clusters_png = encodePng(image);
  return maps;
}

void drawErrorMap(const DemGrid& dem, double error_scale_m, const ZoomSurface& surface, ZoomMaps& maps) {
  const int scale = maps.scale, width = maps.width, height = maps.height;
  maps.error_scale_m = error_scale_m;
  RgbImage image(width, height, 235);
  tbb::parallel_for(0, height, [&](int my) {
    for (int mx = 0; mx < width; ++mx) {
      // The largest error in the block (of the valid pixels the zoom draws).
      float worst = std::nanf("");
      for (int row = my * scale; row < std::min(dem.height, (my + 1) * scale); ++row) {
        for (int col = mx * scale; col < std::min(dem.width, (mx + 1) * scale); ++col) {
          const std::size_t pixel = dem.index(col, row);
          if (!surface.drawn(pixel) || std::isnan(dem.heights_m[pixel])) continue;
          const auto e = static_cast<float>(surface.error(pixel));
          if (!std::isnan(e) && !(e <= worst)) worst = e;
        }
      }
      if (std::isnan(worst)) continue;
      // In kErrorClasses steps: a classed map reads better and its PNG is a tenth the size.
      const double t = error_scale_m > 0 ? std::min(1.0, worst / error_scale_m) : 0.0;
      const auto c = errorColour(std::min(1.0, std::floor(t * kErrorClasses) / (kErrorClasses - 1)));
      std::copy(c.begin(), c.end(), image.at(mx, my));
    }
  });
  maps.error_png = encodePng(image);
}

}  // namespace terratiles
