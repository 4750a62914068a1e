#include "src/tin/measure_tin.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "src/base/error.h"

namespace terratiles {

namespace {

// Both measures: per triangle, forEachTriangle(a, b, c, t, visit) calls visit(pixel, error_m)
// for the pixels triangle t covers.
template <typename ForEachPixel>
TinErrorStatistics measure(const DemGrid& dem, const TinMesh& mesh, ForEachPixel&& forEachPixel) {
  TinErrorStatistics stats;
  std::vector<std::uint8_t> covered(dem.pixelCount(), 0);
  double sum_squares = 0;
  const auto& idx = mesh.triangle_indices;
  for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
    const GridPoint& a = mesh.vertices[idx[t]];
    const GridPoint& b = mesh.vertices[idx[t + 1]];
    const GridPoint& c = mesh.vertices[idx[t + 2]];
    const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
    if (area2 == 0) {
      ++stats.degenerate_triangles;
      continue;
    }
    forEachPixel(t, [&](std::size_t i, double offset_m) {
      const float h = dem.heights_m[i];
      if (std::isnan(h)) {
        if (!(covered[i] & 2)) ++stats.covered_nodata_pixels;
        covered[i] |= 2;
        return true;
      }
      const double error = std::fabs(offset_m);
      stats.max_error_m = std::max(stats.max_error_m, error);
      if (!(covered[i] & 1)) {
        covered[i] |= 1;
        sum_squares += error * error;
        ++stats.measured_pixels;
      }
      return true;
    });
  }
  for (std::size_t i = 0; i < covered.size(); ++i) {
    if (!(covered[i] & 1) && !std::isnan(dem.heights_m[i])) ++stats.uncovered_valid_pixels;
  }
  stats.rms_error_m =
      stats.measured_pixels ? std::sqrt(sum_squares / static_cast<double>(stats.measured_pixels)) : 0;
  return stats;
}

}  // namespace

TinErrorStatistics measureTin(const DemGrid& dem, const TinMesh& mesh) {
  const auto& idx = mesh.triangle_indices;
  return measure(dem, mesh, [&](std::size_t t, auto&& visit) {
    forEachCoveredPixel(dem, mesh.vertices[idx[t]], mesh.vertices[idx[t + 1]], mesh.vertices[idx[t + 2]],
                        [&](std::size_t i, double surface_m) { return visit(i, surface_m - dem.heights_m[i]); });
  });
}

TinErrorStatistics measureTin(const DemOnGlobe& globe, const TinMesh& mesh, std::span<const EcefPoint> vertex_ecef) {
  TERRATILES_ASSERT(vertex_ecef.size() == mesh.vertices.size());
  const auto& idx = mesh.triangle_indices;
  return measure(globe.dem(), mesh, [&](std::size_t t, auto&& visit) {
    forEachCoveredPixelOnGlobe(globe, mesh.vertices[idx[t]], mesh.vertices[idx[t + 1]], mesh.vertices[idx[t + 2]],
                               vertex_ecef[idx[t]], vertex_ecef[idx[t + 1]], vertex_ecef[idx[t + 2]], visit);
  });
}

}  // namespace terratiles
