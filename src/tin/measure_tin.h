#pragma once
// measureTin: the vertical error of a TIN against its DEM, on every pixel.
//
// Rasterises every triangle of `mesh` (GridPoint frame: col, row in pixels) onto the DEM grid
// and compares the linearly interpolated height with the DEM at each pixel centre the
// triangle covers (a pixel on a shared edge is measured once per triangle touching it). Also
// counts pixels no triangle covers and nodata pixels a triangle covers, so tests can assert
// "every valid pixel is within E" and "no triangle covers nodata" from one pass. O(pixels
// covered). Does not modify anything.

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "src/dem/dem_grid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

struct TinErrorStatistics {
  double max_error_m = 0;          // over valid pixels covered by the TIN
  double rms_error_m = 0;
  std::size_t measured_pixels = 0;      // valid pixels covered (each counted once)
  std::size_t uncovered_valid_pixels = 0;  // valid pixels no triangle covers
  std::size_t covered_nodata_pixels = 0;   // nodata pixels inside some triangle
  std::size_t degenerate_triangles = 0;    // zero area in the grid plane
};

TinErrorStatistics measureTin(const DemGrid& dem, const TinMesh& mesh);

// The DEM pixels the triangle (a, b, c) covers, by measureTin's rule: pixel centres at whole
// (col, row) inside or on the triangle (barycentric weights >= -1e-9 relative), clipped to the
// grid. Calls visit(pixel_index, height_of_the_triangle_there) for each, row by row; stops
// early when visit returns false. Nothing is visited for a triangle of zero area. Shared so
// that whatever bounds a triangle's error (the simplifier's budget) agrees with measureTin.
template <typename Visit>
void forEachCoveredPixel(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                         Visit&& visit) {
  const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
  if (area2 == 0) return;
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
      if (wa * std::fabs(area2) < -eps || wb * std::fabs(area2) < -eps || wc * std::fabs(area2) < -eps) {
        continue;
      }
      if (!visit(dem.index(col, row), wa * a.height_m + wb * b.height_m + wc * c.height_m)) return;
    }
  }
}

}  // namespace terratiles
