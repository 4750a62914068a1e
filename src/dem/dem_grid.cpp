#include "src/dem/dem_grid.h"

#include <algorithm>

namespace terratiles {

DemStatistics computeStatistics(const DemGrid& dem) {
  DemStatistics stats;
  float lo = std::numeric_limits<float>::infinity();
  float hi = -std::numeric_limits<float>::infinity();
  for (float h : dem.heights_m) {
    if (std::isnan(h)) continue;
    ++stats.valid_pixels;
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
  if (stats.valid_pixels > 0) {
    stats.min_height_m = lo;
    stats.max_height_m = hi;
  }
  return stats;
}

}  // namespace terratiles
