#pragma once
// forEachPixelMeeting: the DEM pixels whose verticals meet a drawn triangle (DrawnTriangle,
// DemOnGlobe), and the triangle's vertical error at each: what a renderer draws above the
// pixel, measured along the pixel's vertical. The tiles of a build are measured this way and
// so is every decoded tile in `terratiles check`, with the same arithmetic on the same
// numbers, so the two agree bit for bit.
//
// Which pixels to test: the box of the corners' grid positions grown by how far the drawn
// triangle's footprint can stray from the straight triangle in the grid: its chord's sideways
// bulge (a chord of length L bulges by about L^2 tan(lat) / (8 R) in a lon/lat grid, much less
// in a projected one; bounded here by L^2 (1 + |tan lat|) / (2 R)) plus `shift_m`, how far the
// corners' grid positions may be from the drawn corners (a build passes the positions before
// quantisation: the quantisation step; the check passes the decoded corners: 0). A corner at
// a pole has no column: the box then runs from the pole row to the other corners, between
// their columns the short way round. Columns of a DEM that spans 360 degrees of longitude
// wrap.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "src/geo/dem_on_globe.h"
#include "src/geo/drawn_triangle.h"

namespace terratiles {

struct GridCorner {
  double col = 0;
  double row = 0;
  bool at_pole = false;  // at a pole: col means nothing
};

// The corner at grid position (col, row) of `globe`'s DEM: at a pole when it lies exactly on
// a pole row (DemOnGlobe::poleRow).
inline GridCorner gridCornerOf(const DemOnGlobe& globe, double col, double row) {
  const bool at_pole = globe.hasPoleRows() && row == std::round(row) && row >= 0 && row < globe.dem().height &&
                       globe.poleRow(static_cast<std::int32_t>(row));
  return {col, row, at_pole};
}

// Pixels [col0, col1] x [row0, row1]; columns outside [0, width) are taken modulo the width
// when the DEM wraps around the globe (DemOnGlobe::wrapsLongitude), else clipped.
struct PixelBox {
  std::int64_t col0 = 0, col1 = -1;
  std::int32_t row0 = 0, row1 = -1;
};

PixelBox candidatePixels(const DemOnGlobe& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                         double shift_m);

// How far (in columns and rows) a drawn triangle's footprint may stray from its triangle in
// the grid: the bulge and shift above, over the smallest pixel spacing of the rows it spans.
//
// On a DEM whose columns are WGS84 longitudes (DemOnGlobe::degreesPerColumn) the columns of
// the pixels a drawn triangle meets are bounded more tightly, near a pole by far: a pixel's
// vertical (the ellipsoid's normal) lies in its meridian plane, so it meets the triangle at a
// point of the pixel's longitude, and the longitudes of a plane triangle's points lie between
// its corners' when these span less than half a turn and none is on the axis (the triangle's
// shadow on the equator plane is a triangle, and a straight line's direction from the axis
// turns one way). So only the shift moves them past the corners' columns: by at most
// asin(shift / rho) of longitude at a distance rho from the axis, less than 2 shift over the
// smallest column spacing of the rows the corners lie between (a spacing is at most rho
// times the column's angle; rho varies with height by 0.3 % at most). `longitude_columns` is
// that where the corners span at most 90 degrees, no pole row is among their rows (and the
// rows next to them) and the bound is below 45 degrees; with no shift (the drawn corners are
// the grid's) 0 where the corners span at most 90 degrees and no pole row is among their
// rows; else infinity. The box's columns grow by boxColumns(); a stray pixel is still within
// `columns` and `rows` of the triangle. (A triangle with a corner at a pole: scanMargin.)
struct PixelMargin {
  double columns = 0;
  double rows = 0;
  double longitude_columns = std::numeric_limits<double>::infinity();
  double boxColumns() const { return std::min(columns, longitude_columns); }
};
PixelMargin strayMargin(const DemOnGlobe& globe, const std::array<GridCorner, 3>& corners, double longest_edge_m,
                        double shift_m);
// The longitude bound's parts, one arithmetic for strayMargin, PixelBoxes and scanMargin:
// whether corners `span_columns` apart may take it, and the columns a corner moved by
// `shift_m` may add where the least column spacing is `column_spacing_m`.
inline bool longitudeBoundHolds(double span_columns, double degrees_per_column) {
  return degrees_per_column > 0 && span_columns * degrees_per_column <= 90;
}
inline double shiftColumns(double shift_m, double column_spacing_m) { return 2 * shift_m / column_spacing_m; }
inline bool shiftColumnsHold(double shift_columns, double degrees_per_column) {
  return shift_columns * degrees_per_column < 45;
}

// The per-row figures candidatePixels reads of a DEM's globe (DemOnGlobe::rowSpacing,
// columnSpacing, maxSinLatitude, poleRow), for a whole mosaic, collected from the globes of
// strips of its rows that span its whole width, so that the triangles a strip measures get
// boxes in the mosaic's rows without its pixels: box() is candidatePixels on the mosaic's
// globe, exactly when the figures come from one globe of the whole mosaic, else with its
// margin grown by kSlack (strips place nodata pixels at their own mean height, which moves a
// spacing by up to 1.5e-3 of it, and a row at a strip's end takes its neighbours' row
// spacing), so that it holds every pixel candidatePixels would (and, for a triangle with a
// corner at a pole, maybe more pixels of the pole row: the same point, met with the same
// offset). Memory: 26 bytes per row.
struct LatticeRows {
  static constexpr double kSlack = 1.05;
  double slack = 1;  // kSlack once a strip of fewer than all rows was collected
  std::int32_t width = 0;
  std::vector<double> row_spacing_m, column_spacing_m, max_sin_latitude;
  std::vector<std::uint8_t> pole;
  bool wraps_longitude = false;
  // DemOnGlobe::degreesPerColumn when every strip collected has the same, else 0.
  double degrees_per_column = -1;  // -1: nothing collected yet

  LatticeRows(std::int32_t columns, std::int64_t rows)
      : width(columns),
        row_spacing_m(static_cast<std::size_t>(rows), std::numeric_limits<double>::quiet_NaN()),
        column_spacing_m(static_cast<std::size_t>(rows), 0.0),
        max_sin_latitude(static_cast<std::size_t>(rows), 1.0),
        pole(static_cast<std::size_t>(rows), 0) {}
  // Takes the figures of `window`'s rows (every column of rows first_row ... of the mosaic).
  void collect(const DemOnGlobe& window, std::int64_t first_row);
  // After every row was collected once.
  void finish();
  // candidatePixels in the mosaic's pixels, grown as above.
  PixelBox box(const std::array<GridCorner, 3>& corners, double longest_edge_m, double shift_m) const;
};

// visit(pixel index, signed offset: the triangle above the DEM point when positive) for every
// pixel of `box` whose vertical meets `triangle`, row by row.
template <typename Visit>
void forEachPixelMeeting(const DemOnGlobe& globe, const DrawnTriangle& triangle, const PixelBox& box, Visit&& visit) {
  if (triangle.degenerate()) return;
  const DemGrid& dem = globe.dem();
  const std::int32_t first_row = std::max(0, box.row0), last_row = std::min(dem.height - 1, box.row1);
  const auto test = [&](std::int32_t col, std::int32_t row) {
    double offset_m = 0;
    if (triangle.meets(globe.point(col, row), globe.up(col, row), &offset_m)) visit(dem.index(col, row), offset_m);
  };
  if (globe.wrapsLongitude()) {
    for (std::int32_t row = first_row; row <= last_row; ++row) {
      for (std::int64_t c = box.col0; c <= box.col1; ++c) {
        std::int64_t col = c % dem.width;
        if (col < 0) col += dem.width;
        test(static_cast<std::int32_t>(col), row);
      }
    }
    return;
  }
  // Columns outside the grid are skipped: the same pixels in the same order as above.
  const std::int64_t first_col = std::max<std::int64_t>(0, box.col0);
  const std::int64_t last_col = std::min<std::int64_t>(dem.width - 1, box.col1);
  for (std::int32_t row = first_row; row <= last_row; ++row) {
    for (std::int64_t col = first_col; col <= last_col; ++col) test(static_cast<std::int32_t>(col), row);
  }
}

}  // namespace terratiles
