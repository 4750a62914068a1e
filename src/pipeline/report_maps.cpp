#include "src/pipeline/report_maps.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

#include "src/pipeline/report_html.h"
#include "src/tin/measure_tin.h"

namespace terratiles {
namespace {
constexpr int kErrorClasses = 10;
}  // namespace

ZoomMaps drawZoomMaps(const DemGrid& dem, const TinMesh& mesh, const FacePartition* partition,
                      const TileFrame* frame, std::int32_t zoom, double error_scale_m, const ZoomSurface& surface,
                      int max_side_px) {
  // Per DEM pixel: the cluster (or face) covering it, and the drawn surface's error. A pixel
  // several faces cover shows the last of them (the largest face index: taken with an atomic
  // maximum, the same for any thread count).
  std::vector<std::uint32_t> last_face(dem.pixelCount(), 0);  // face + 1; 0: none
  const auto& idx = mesh.triangle_indices;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.triangleCount(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& faces) {
                      for (std::size_t f = faces.begin(); f < faces.end(); ++f) {
                        const auto mark = static_cast<std::uint32_t>(f + 1);
                        forEachCoveredPixel(dem, mesh.vertices[idx[3 * f]], mesh.vertices[idx[3 * f + 1]],
                                            mesh.vertices[idx[3 * f + 2]], [&](std::size_t pixel, double) {
                                              std::atomic_ref<std::uint32_t> slot(last_face[pixel]);
                                              std::uint32_t seen = slot.load(std::memory_order_relaxed);
                                              while (seen < mark &&
                                                     !slot.compare_exchange_weak(seen, mark, std::memory_order_relaxed)) {
                                              }
                                              return true;
                                            });
                      }
                    });
  std::vector<std::int32_t> cluster(dem.pixelCount(), -1);
  std::vector<float> error(dem.pixelCount(), std::nanf(""));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, dem.pixelCount(), 1 << 14),
                    [&](const tbb::blocked_range<std::size_t>& pixels) {
                      for (std::size_t pixel = pixels.begin(); pixel < pixels.end(); ++pixel) {
                        if (last_face[pixel] > 0) {
                          cluster[pixel] = partition ? partition->cluster_of_face[last_face[pixel] - 1] : 0;
                        }
                        if (surface.drawn(pixel) && !std::isnan(dem.heights_m[pixel])) {
                          error[pixel] = static_cast<float>(surface.error(pixel));
                        }
                      }
                    });

  const int scale = std::max(1, static_cast<int>(std::ceil(static_cast<double>(std::max(dem.width, dem.height)) /
                                                           std::max(16, max_side_px))));
  const int width = (dem.width + scale - 1) / scale, height = (dem.height + scale - 1) / scale;
  ZoomMaps maps;
  maps.zoom = zoom;
  maps.error_scale_m = error_scale_m;
  maps.cluster_count = partition ? partition->cluster_count : 0;
  maps.clusters = RgbImage(width, height, 235);
  maps.error = RgbImage(width, height, 235);

  // Map pixel -> the DEM pixel at its block's centre, and its tile.
  std::vector<std::int32_t> map_cluster(static_cast<std::size_t>(width) * height, -1);
  std::vector<GridPoint> centres;
  centres.reserve(map_cluster.size());
  for (int my = 0; my < height; ++my) {
    for (int mx = 0; mx < width; ++mx) {
      const int col = std::min(dem.width - 1, mx * scale + scale / 2);
      const int row = std::min(dem.height - 1, my * scale + scale / 2);
      map_cluster[static_cast<std::size_t>(my) * width + mx] = cluster[dem.index(col, row)];
      centres.push_back({static_cast<double>(col), static_cast<double>(row), 0});
    }
  }
  std::vector<TileKey> tile(map_cluster.size());
  if (frame) {
    const std::vector<std::array<double, 2>> points = frame->toScheme(centres);
    tbb::parallel_for(std::size_t{0}, points.size(), [&](std::size_t i) { tile[i] = frame->tileAt(points[i], zoom); });
  }

  tbb::parallel_for(0, height, [&](int my) {
    for (int mx = 0; mx < width; ++mx) {
      const std::size_t i = static_cast<std::size_t>(my) * width + mx;
      // The largest error in the block.
      float worst = std::nanf("");
      for (int row = my * scale; row < std::min(dem.height, (my + 1) * scale); ++row) {
        for (int col = mx * scale; col < std::min(dem.width, (mx + 1) * scale); ++col) {
          const float e = error[dem.index(col, row)];
          if (!std::isnan(e) && !(e <= worst)) worst = e;
        }
      }
      if (!std::isnan(worst)) {
        // In kErrorClasses steps: a classed map reads better and its PNG is a tenth the size.
        const double t = error_scale_m > 0 ? std::min(1.0, worst / error_scale_m) : 0.0;
        const auto c = errorColour(std::min(1.0, std::floor(t * kErrorClasses) / (kErrorClasses - 1)));
        std::copy(c.begin(), c.end(), maps.error.at(mx, my));
      }
      const std::int32_t id = map_cluster[i];
      if (id < 0) continue;
      const auto c = partition ? clusterColour(static_cast<std::uint32_t>(id))
                               : clusterColour(static_cast<std::uint32_t>(tile[i].x * 7919 + tile[i].y));
      std::copy(c.begin(), c.end(), maps.clusters.at(mx, my));
    }
  });
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
        cluster_border |= partition && map_cluster[j] != map_cluster[i];
        tile_border |= frame && !(tile[j] == tile[i]);
      }
      std::uint8_t* p = maps.clusters.at(mx, my);
      if (tile_border) {
        p[0] = p[1] = p[2] = 255;
      } else if (cluster_border) {
        p[0] = p[1] = p[2] = 20;
      }
    }
  }
  return maps;
}

}  // namespace terratiles
