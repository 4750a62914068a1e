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
    // Barycentric weights of the pixel centre (col, row); inside when all are >= -eps.
    const double eps = 1e-9 * std::fabs(area2);
    const int min_col = std::max(0, static_cast<int>(std::ceil(std::min({a.col, b.col, c.col}) - 1e-9)));
    const int max_col = std::min(dem.width - 1, static_cast<int>(std::floor(std::max({a.col, b.col, c.col}) + 1e-9)));
    const int min_row = std::max(0, static_cast<int>(std::ceil(std::min({a.row, b.row, c.row}) - 1e-9)));
    const int max_row = std::min(dem.height - 1, static_cast<int>(std::floor(std::max({a.row, b.row, c.row}) + 1e-9)));
    for (int row = min_row; row <= max_row; ++row) {
      for (int col = min_col; col <= max_col; ++col) {
        const double wa = ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col)) / area2;
        const double wb = ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col)) / area2;
        const double wc = 1.0 - wa - wb;
        if (wa * std::fabs(area2) < -eps || wb * std::fabs(area2) < -eps ||
            wc * std::fabs(area2) < -eps) {
          continue;
        }
        const std::size_t i = dem.index(col, row);
        const float h = dem.heights_m[i];
        if (std::isnan(h)) {
          if (!(covered[i] & 2)) ++stats.covered_nodata_pixels;
          covered[i] |= 2;
          continue;
        }
        const double error = std::fabs(wa * a.height_m + wb * b.height_m + wc * c.height_m - h);
        stats.max_error_m = std::max(stats.max_error_m, error);
        if (!(covered[i] & 1)) {
          covered[i] |= 1;
          sum_squares += error * error;
          ++stats.measured_pixels;
        }
      }
    }
  }
  for (std::size_t i = 0; i < covered.size(); ++i) {
    if (!(covered[i] & 1) && !std::isnan(dem.heights_m[i])) ++stats.uncovered_valid_pixels;
  }
  stats.rms_error_m =
      stats.measured_pixels ? std::sqrt(sum_squares / static_cast<double>(stats.measured_pixels)) : 0;
  return stats;
}

}  // namespace terratiles
