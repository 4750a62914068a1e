#include "src/geo/drawn_pixels.h"

#include <algorithm>
#include <limits>
#include <numbers>

namespace terratiles {
namespace {

// The per-row figures of a whole DEM's globe, as DemOnGlobe gives them.
struct GlobeRows {
  const DemOnGlobe& globe;
  std::int32_t width() const { return globe.dem().width; }
  std::int32_t height() const { return globe.dem().height; }
  double rowSpacing(std::int32_t row) const { return globe.rowSpacing(row); }
  double columnSpacing(std::int32_t row) const { return globe.columnSpacing(row); }
  double maxSinLatitude(std::int32_t row) const { return globe.maxSinLatitude(row); }
  bool poleRow(std::int32_t row) const { return globe.poleRow(row); }
  bool wrapsLongitude() const { return globe.wrapsLongitude(); }
  double degreesPerColumn() const { return globe.degreesPerColumn(); }
  double slack() const { return 1; }
};

// The same of a mosaic, collected strip by strip (LatticeRows), with its slack.
struct CollectedRows {
  const LatticeRows& rows;
  std::int32_t width() const { return rows.width; }
  std::int32_t height() const { return static_cast<std::int32_t>(rows.pole.size()); }
  double rowSpacing(std::int32_t row) const { return rows.row_spacing_m[static_cast<std::size_t>(row)]; }
  double columnSpacing(std::int32_t row) const { return rows.column_spacing_m[static_cast<std::size_t>(row)]; }
  double maxSinLatitude(std::int32_t row) const { return rows.max_sin_latitude[static_cast<std::size_t>(row)]; }
  bool poleRow(std::int32_t row) const { return rows.pole[static_cast<std::size_t>(row)] != 0; }
  bool wrapsLongitude() const { return rows.wraps_longitude; }
  double degreesPerColumn() const { return std::max(0.0, rows.degrees_per_column); }
  double slack() const { return rows.slack; }
};

template <typename Rows>
PixelMargin strayMarginOf(const Rows& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                          double shift_m) {
  struct {
    std::int32_t width, height;
  } dem{globe.width(), globe.height()};
  constexpr double kRadius_m = 6.3e6;  // below every WGS84 radius of curvature
  double row_min = 1e300, row_max = -1e300, col_min = 1e300, col_max = -1e300;
  for (const GridCorner& corner : corners) {
    row_min = std::min(row_min, corner.row);
    row_max = std::max(row_max, corner.row);
    col_min = std::min(col_min, corner.col);
    col_max = std::max(col_max, corner.col);
  }
  // Over the rows the footprint can span: the smallest spacings, and the largest |sin lat| of
  // their verticals (a pole row has none: a corner there has no column to stray by), which
  // bounds that of every corner.
  const auto first_row = static_cast<std::int32_t>(std::clamp(std::floor(row_min) - 1, 0.0, dem.height - 1.0));
  const auto last_row = static_cast<std::int32_t>(std::clamp(std::ceil(row_max) + 1, 0.0, dem.height - 1.0));
  double row_spacing = std::numeric_limits<double>::infinity(), column_spacing = row_spacing;
  double sin_lat = 0;
  bool pole_row = false, pole_row_among_corners = false;
  for (std::int32_t row = first_row; row <= last_row; ++row) {
    if (row < dem.height - 1) row_spacing = std::min(row_spacing, globe.rowSpacing(row));
    sin_lat = std::max(sin_lat, globe.maxSinLatitude(row));
    if (!globe.poleRow(row)) {
      column_spacing = std::min(column_spacing, globe.columnSpacing(row));
      continue;
    }
    pole_row = true;
    pole_row_among_corners = pole_row_among_corners || (row >= std::floor(row_min) && row <= std::ceil(row_max));
  }
  const double tan_lat = std::min(1e6, sin_lat / std::sqrt(std::max(1e-12, 1 - sin_lat * sin_lat)));
  const double bulge_m = longest_edge_m * longest_edge_m * (1 + tan_lat) / (2 * kRadius_m);
  const double margin_m = (bulge_m + shift_m) * globe.slack();
  PixelMargin margin;
  margin.rows = row_spacing > 0 ? margin_m / row_spacing : static_cast<double>(dem.height);
  margin.columns = column_spacing > 0 && std::isfinite(column_spacing) ? margin_m / column_spacing
                                                                       : static_cast<double>(dem.width);
  if (!std::isfinite(margin.rows)) margin.rows = 0;  // a single row
  const double degrees = globe.degreesPerColumn();
  if (longitudeBoundHolds(col_max - col_min, degrees)) {
    if (shift_m == 0 && !pole_row_among_corners) {
      margin.longitude_columns = 0;  // the drawn corners are the grid's, none on the axis
    } else if (!pole_row && column_spacing > 0 && std::isfinite(column_spacing)) {
      const double shift_columns = shiftColumns(shift_m * globe.slack(), column_spacing);
      if (shiftColumnsHold(shift_columns, degrees)) margin.longitude_columns = shift_columns;
    }
  }
  return margin;
}

template <typename Rows>
PixelBox candidatePixelsOf(const Rows& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                           double shift_m) {
  struct {
    std::int32_t width, height;
  } dem{globe.width(), globe.height()};
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
  const PixelMargin margin = strayMarginOf(globe, corners, longest_edge_m, shift_m);
  const double margin_rows = margin.rows, margin_cols = margin.boxColumns();
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

}  // namespace

PixelMargin strayMargin(const DemOnGlobe& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                        double shift_m) {
  return strayMarginOf(GlobeRows{globe}, corners, longest_edge_m, shift_m);
}

PixelBox candidatePixels(const DemOnGlobe& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                         double shift_m) {
  return candidatePixelsOf(GlobeRows{globe}, corners, longest_edge_m, shift_m);
}

void LatticeRows::collect(const DemOnGlobe& window, std::int64_t first_row) {
  const DemGrid& dem = window.dem();
  if (pole.empty()) return;
  wraps_longitude = window.wrapsLongitude();
  if (degrees_per_column < 0) degrees_per_column = window.degreesPerColumn();
  else if (degrees_per_column != window.degreesPerColumn()) degrees_per_column = 0;
  if (first_row != 0 || static_cast<std::size_t>(dem.height) != pole.size()) slack = kSlack;
  for (std::int32_t r = 0; r < dem.height; ++r) {
    const std::int64_t row = first_row + r;
    if (row < 0 || row >= static_cast<std::int64_t>(pole.size())) continue;
    const auto i = static_cast<std::size_t>(row);
    column_spacing_m[i] = window.columnSpacing(r);
    max_sin_latitude[i] = window.maxSinLatitude(r);
    pole[i] = window.poleRow(r) ? 1 : 0;
    if (r + 1 < dem.height) row_spacing_m[i] = window.rowSpacing(r);
  }
}

void LatticeRows::finish() {
  // A strip's last row has no spacing to the next row there: its neighbours' (the spacings
  // change slowly from row to row; kSlack covers the difference).
  const std::size_t rows = row_spacing_m.size();
  for (std::size_t i = 0; i < rows; ++i) {
    if (!std::isnan(row_spacing_m[i])) continue;
    double spacing = std::numeric_limits<double>::infinity();
    if (i > 0 && !std::isnan(row_spacing_m[i - 1])) spacing = std::min(spacing, row_spacing_m[i - 1]);
    if (i + 1 < rows && !std::isnan(row_spacing_m[i + 1])) spacing = std::min(spacing, row_spacing_m[i + 1]);
    row_spacing_m[i] = spacing;
  }
}

PixelBox LatticeRows::box(const std::array<GridCorner, 3>& corners, double longest_edge_m, double shift_m) const {
  return candidatePixelsOf(CollectedRows{*this}, corners, longest_edge_m, shift_m);
}

}  // namespace terratiles
