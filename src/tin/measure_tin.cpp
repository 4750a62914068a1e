#include "src/tin/measure_tin.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace terratiles {

TinErrorStatistics measureTin(const DemGrid& dem, const TinMesh& mesh) {
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
    forEachCoveredPixel(dem, a, b, c, [&](std::size_t i, double surface_m) {
      const float h = dem.heights_m[i];
      if (std::isnan(h)) {
        if (!(covered[i] & 2)) ++stats.covered_nodata_pixels;
        covered[i] |= 2;
        return true;
      }
      const double error = std::fabs(surface_m - h);
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

}  // namespace terratiles
