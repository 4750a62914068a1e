#pragma once
// measureTin: the vertical error of a TIN against its DEM, on every pixel.
//
// Rasterises every triangle of `mesh` (GridPoint frame: col, row in pixels) onto the DEM grid
// and measures it at each pixel centre the triangle covers (a pixel on a shared edge is
// measured once per triangle touching it): on the globe, the offset from the pixel's DEM
// point to the triangle's plane in ECEF along the pixel's vertical (the triangle as a
// renderer draws it, DemOnGlobe); without a globe, the linearly interpolated height against
// the DEM's. Also counts pixels no triangle covers and nodata pixels a triangle covers, so
// tests can assert "every valid pixel is within E" and "no triangle covers nodata" from one
// pass. O(pixels covered). Does not modify anything.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>

#include "src/dem/dem_grid.h"
#include "src/geo/dem_on_globe.h"
#include "src/geo/drawn_pixels.h"
#include "src/geo/drawn_triangle.h"
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

// In the grid frame: heights interpolated linearly (a flat earth).
TinErrorStatistics measureTin(const DemGrid& dem, const TinMesh& mesh);
// On the globe: vertex_ecef holds every vertex of mesh placed by globe.place.
TinErrorStatistics measureTin(const DemOnGlobe& globe, const TinMesh& mesh, std::span<const EcefPoint> vertex_ecef);

// The DEM pixels the triangle (a, b, c) covers, by measureTin's rule: pixel centres at whole
// (col, row) inside or on the triangle (barycentric weights >= -1e-9 relative), clipped to the
// grid. Calls visit(pixel_index, height_of_the_triangle_there) for each, row by row; stops
// early when visit returns false. Nothing is visited for a triangle of zero area. Shared so
// that whatever bounds a triangle's error (the simplifier's budget) agrees with measureTin.
// forEachCoveredPixel's doubled signed area in the grid, its tolerance (1e-9 of the area)
// and the grid's pixels within the triangle's bounding box (empty when max < min).
struct CoveredPixelBox {
  double area2 = 0;
  double eps = 0;
  int min_col = 0, max_col = -1, min_row = 0, max_row = -1;
};
inline CoveredPixelBox coveredPixelBox(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c) {
  CoveredPixelBox box;
  box.area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
  box.eps = 1e-9 * std::fabs(box.area2);
  box.min_col = std::max(0, static_cast<int>(std::ceil(std::min({a.col, b.col, c.col}) - 1e-9)));
  box.max_col = std::min(dem.width - 1, static_cast<int>(std::floor(std::max({a.col, b.col, c.col}) + 1e-9)));
  box.min_row = std::max(0, static_cast<int>(std::ceil(std::min({a.row, b.row, c.row}) - 1e-9)));
  box.max_row = std::min(dem.height - 1, static_cast<int>(std::floor(std::max({a.row, b.row, c.row}) + 1e-9)));
  return box;
}

template <typename Visit>
void forEachCoveredPixel(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                         Visit&& visit) {
  const CoveredPixelBox box = coveredPixelBox(dem, a, b, c);
  const double area2 = box.area2, eps = box.eps;
  if (area2 == 0) return;
  for (int row = box.min_row; row <= box.max_row; ++row) {
    for (int col = box.min_col; col <= box.max_col; ++col) {
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

// forEachCoveredPixel on the globe: the same pixels, each with the signed vertical offset of
// the drawn triangle (corners pa, pb, pc in ECEF) from the pixel's DEM point (positive: the
// triangle is above), then the pixels outside it in the grid whose verticals meet the drawn
// triangle (a long chord strays from its grid triangle by its bulge, strayMargin; at high
// latitudes by columns), each with the offset where it meets. A pixel on a pole row
// (DemOnGlobe::poleRow: all its pixels are one point), and every pixel of a triangle
// degenerate in ECEF (two corners at a pole), is measured in the grid: the linearly
// interpolated height minus the DEM's. A nodata pixel is visited too (with an offset from its
// placeholder point). visit returns false to stop.
// One pixel by forEachCoveredPixelOnGlobe's rule for pixels inside the triangle in the grid
// (the stray pixels outside it are left out): whether the pixel at (col, row) is inside, and
// if so *offset_m, the offset the scan visits it with. For a remembered pixel, tested before a
// whole scan: what it finds there, the scan would find too.
inline bool coveredInsideOnGlobe(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                                 const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, std::int32_t col,
                                 std::int32_t row, double* offset_m) {
  const DemGrid& dem = globe.dem();
  const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
  if (area2 == 0) return false;
  // Inside the scan's box before its margin (which only grows it).
  if (col < std::ceil(std::min({a.col, b.col, c.col}) - 1e-9) || col > std::floor(std::max({a.col, b.col, c.col}) + 1e-9) ||
      row < std::ceil(std::min({a.row, b.row, c.row}) - 1e-9) || row > std::floor(std::max({a.row, b.row, c.row}) + 1e-9) ||
      col < 0 || row < 0 || col >= dem.width || row >= dem.height) {
    return false;
  }
  const double sign = area2 > 0 ? 1.0 : -1.0;
  const double eps = 1e-9 * std::fabs(area2);
  const double ea = sign * ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col));
  const double eb = sign * ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col));
  const double ec = std::fabs(area2) - ea - eb;
  if (!(ea >= -eps && eb >= -eps && ec >= -eps)) return false;
  const std::size_t pixel = dem.index(col, row);
  const DrawnTriangle drawn(pa, pb, pc);
  if (drawn.degenerate() || (globe.hasPoleRows() && globe.poleRow(row))) {
    const double wa = ea * sign / area2, wb = eb * sign / area2;
    *offset_m = wa * a.height_m + wb * b.height_m + (1.0 - wa - wb) * c.height_m - dem.heights_m[pixel];
  } else {
    *offset_m = drawn.offset(globe.point(col, row), globe.up(col, row));
  }
  return true;
}

// forEachCoveredPixelOnGlobe's margin (the simplifier's budget scan, budget_scan.cpp, takes
// the same): strayMargin of the corners (at a pole: exactly on a pole row), with no shift. With a
// corner at a pole, and the others at most 90 degrees of longitude apart on a WGS84
// longitude and latitude DEM, the scan's box needs hardly more columns than its corners':
// the triangle's shadow on the equator plane has a corner at the axis, or as near it as the
// placement puts the pole (nanometres), so its points at a distance rho from the axis lie
// between the other corners' longitudes, give or take asin(that distance / rho), less than
// twice it over the least column spacing in columns (DemOnGlobe::leastColumnSpacing; as for
// PixelMargin's shift). The scan leaves pole-row pixels outside the triangle in the grid
// alone.
inline PixelMargin scanMargin(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                              const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double longest_edge_m) {
  const std::array<GridCorner, 3> corners{gridCornerOf(globe, a.col, a.row), gridCornerOf(globe, b.col, b.row),
                                          gridCornerOf(globe, c.col, c.row)};
  const std::array<bool, 3> at_pole{corners[0].at_pole, corners[1].at_pole, corners[2].at_pole};
  PixelMargin margin = strayMargin(globe, corners, longest_edge_m, 0.0);
  if (!(at_pole[0] || at_pole[1] || at_pole[2]) || globe.degreesPerColumn() <= 0) return margin;
  const std::array<const GridPoint*, 3> grid{&a, &b, &c};
  const std::array<const EcefPoint*, 3> drawn{&pa, &pb, &pc};
  double col_min = 1e300, col_max = -1e300, off_axis_m = 0;
  for (std::size_t k = 0; k < 3; ++k) {
    if (at_pole[k]) {
      off_axis_m = std::max(off_axis_m, std::hypot(drawn[k]->x, drawn[k]->y));
      continue;
    }
    col_min = std::min(col_min, grid[k]->col);
    col_max = std::max(col_max, grid[k]->col);
  }
  const double degrees = globe.degreesPerColumn(), least_spacing_m = globe.leastColumnSpacing();
  const double off_axis_columns = least_spacing_m > 0 ? shiftColumns(off_axis_m, least_spacing_m) : 1e300;
  if (col_min <= col_max && longitudeBoundHolds(col_max - col_min, degrees) && off_axis_columns * degrees < 1e-3) {
    margin.longitude_columns = off_axis_columns;
  }
  return margin;
}

template <typename Visit>
void forEachCoveredPixelOnGlobe(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                                const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, Visit&& visit) {
  const DemGrid& dem = globe.dem();
  const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
  if (area2 == 0) return;
  const DrawnTriangle drawn(pa, pb, pc);
  const bool degenerate = drawn.degenerate();
  const bool poles = globe.hasPoleRows();
  PixelMargin margin;
  if (!degenerate) margin = scanMargin(globe, a, b, c, pa, pb, pc, drawn.longestEdge());
  const double margin_px = std::max(margin.columns, margin.rows);
  // Inside (or on) the triangle in the grid: each edge function, signed so that the inside is
  // positive, at least -eps (a relative tolerance of 1e-9 of the doubled area). Outside, a
  // pixel may still be drawn above when it lies within the margin of every edge: the edge
  // function over the edge's length is the distance from the edge.
  const double sign = area2 > 0 ? 1.0 : -1.0;
  const double eps = 1e-9 * std::fabs(area2);
  const double edge_length[3] = {std::sqrt((c.col - b.col) * (c.col - b.col) + (c.row - b.row) * (c.row - b.row)),
                                 std::sqrt((a.col - c.col) * (a.col - c.col) + (a.row - c.row) * (a.row - c.row)),
                                 std::sqrt((b.col - a.col) * (b.col - a.col) + (b.row - a.row) * (b.row - a.row))};
  const double reach[3] = {-margin_px * edge_length[0], -margin_px * edge_length[1], -margin_px * edge_length[2]};
  const int min_col = static_cast<int>(std::max(0.0, std::ceil(std::min({a.col, b.col, c.col}) - margin.boxColumns() - 1e-9)));
  const int max_col = static_cast<int>(std::min(dem.width - 1.0, std::floor(std::max({a.col, b.col, c.col}) + margin.boxColumns() + 1e-9)));
  const int min_row = static_cast<int>(std::max(0.0, std::ceil(std::min({a.row, b.row, c.row}) - margin.rows - 1e-9)));
  const int max_row = static_cast<int>(std::min(dem.height - 1.0, std::floor(std::max({a.row, b.row, c.row}) + margin.rows + 1e-9)));
  for (int row = min_row; row <= max_row; ++row) {
    const bool pole_row = poles && globe.poleRow(row);
    for (int col = min_col; col <= max_col; ++col) {
      const double ea = sign * ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col));
      const double eb = sign * ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col));
      const double ec = std::fabs(area2) - ea - eb;
      const std::size_t pixel = dem.index(col, row);
      if (ea >= -eps && eb >= -eps && ec >= -eps) {
        double offset_m;
        if (degenerate || pole_row) {
          const double wa = ea * sign / area2, wb = eb * sign / area2;
          offset_m = wa * a.height_m + wb * b.height_m + (1.0 - wa - wb) * c.height_m - dem.heights_m[pixel];
        } else {
          offset_m = drawn.offset(globe.point(col, row), globe.up(col, row));
        }
        if (!visit(pixel, offset_m)) return;
        continue;
      }
      if (degenerate || pole_row) continue;
      // Outside in the grid: within the margin of every edge, and met as drawn?
      if (ea < reach[0] || eb < reach[1] || ec < reach[2]) continue;
      double offset_m = 0;
      if (drawn.meets(globe.point(col, row), globe.up(col, row), &offset_m) && !visit(pixel, offset_m)) return;
    }
  }
}

}  // namespace terratiles
