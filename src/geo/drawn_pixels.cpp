#include "src/geo/drawn_pixels.h"

#include <algorithm>
#include <limits>
#include <numbers>

namespace terratiles {

PixelMargin strayMargin(const DemOnGlobe& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                        double shift_m) {
  const DemGrid& dem = globe.dem();
  constexpr double kRadius_m = 6.3e6;  // below every WGS84 radius of curvature
  double row_min = 1e300, row_max = -1e300;
  for (const GridCorner& corner : corners) {
    row_min = std::min(row_min, corner.row);
    row_max = std::max(row_max, corner.row);
  }
  // Over the rows the footprint can span: the smallest spacings, and the largest |sin lat| of
  // their verticals (a pole row has none: a corner there has no column to stray by), which
  // bounds that of every corner.
  const auto first_row = static_cast<std::int32_t>(std::clamp(std::floor(row_min) - 1, 0.0, dem.height - 1.0));
  const auto last_row = static_cast<std::int32_t>(std::clamp(std::ceil(row_max) + 1, 0.0, dem.height - 1.0));
  double row_spacing = std::numeric_limits<double>::infinity(), column_spacing = row_spacing;
  double sin_lat = 0;
  for (std::int32_t row = first_row; row <= last_row; ++row) {
    if (row < dem.height - 1) row_spacing = std::min(row_spacing, globe.rowSpacing(row));
    if (!globe.poleRow(row)) column_spacing = std::min(column_spacing, globe.columnSpacing(row));
    sin_lat = std::max(sin_lat, globe.maxSinLatitude(row));
  }
  const double tan_lat = std::min(1e6, sin_lat / std::sqrt(std::max(1e-12, 1 - sin_lat * sin_lat)));
  const double bulge_m = longest_edge_m * longest_edge_m * (1 + tan_lat) / (2 * kRadius_m);
  const double margin_m = bulge_m + shift_m;
  PixelMargin margin;
  margin.rows = row_spacing > 0 ? margin_m / row_spacing : static_cast<double>(dem.height);
  margin.columns = column_spacing > 0 && std::isfinite(column_spacing) ? margin_m / column_spacing
                                                                       : static_cast<double>(dem.width);
  if (!std::isfinite(margin.rows)) margin.rows = 0;  // a single row
  return margin;
}

PixelBox candidatePixels(const DemOnGlobe& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                         double shift_m) {
  const DemGrid& dem = globe.dem();
  double row_min = 1e300, row_max = -1e300, col_min = 1e300, col_max = -1e300;
  bool at_pole = false;
  for (const GridCorner& corner : corners) {
    row_min = std::min(row_min, corner.row);
    row_max = std::max(row_max, corner.row);
    if (corner.at_pole) {
      at_pole = true;
      continue;
    }
    col_min = std::min(col_min, corner.col);
    col_max = std::max(col_max, corner.col);
  }
  PixelBox box;
  if (!(col_min <= col_max) || !(row_min <= row_max)) return box;  // no corner with a column: nothing
  const PixelMargin margin = strayMargin(globe, corners, longest_edge_m, shift_m);
  const double margin_rows = margin.rows, margin_cols = margin.columns;
  box.row0 = static_cast<std::int32_t>(std::max(0.0, std::ceil(row_min - margin_rows - 1e-9)));
  box.row1 = static_cast<std::int32_t>(std::min(dem.height - 1.0, std::floor(row_max + margin_rows + 1e-9)));
  if (at_pole) {
    // From the pole row: a corner there lies on row 0 or on the last row.
    for (const GridCorner& corner : corners) {
      if (!corner.at_pole) continue;
      if (corner.row < dem.height / 2.0) box.row0 = 0;
      else box.row1 = dem.height - 1;
    }
    // Between the other corners' columns the short way round (their wedge at the pole).
    if (globe.wrapsLongitude() && col_max - col_min > dem.width / 2.0) {
      std::swap(col_min, col_max);
      col_max += dem.width;
    }
  }
  double first = std::ceil(col_min - margin_cols - 1e-9), last = std::floor(col_max + margin_cols + 1e-9);
  if (last - first + 1 >= dem.width) {
    first = 0;
    last = dem.width - 1;
  }
  if (!globe.wrapsLongitude()) {
    first = std::max(first, 0.0);
    last = std::min(last, dem.width - 1.0);
  }
  box.col0 = static_cast<std::int64_t>(first);
  box.col1 = static_cast<std::int64_t>(last);
  return box;
}

}  // namespace terratiles
