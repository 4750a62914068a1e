// The candidate pixels of a drawn triangle hold every pixel its verticals meet, also where the
// longitude bound (PixelMargin::longitude_columns) narrows them: near ETOPO5's poles, where
// the bulge alone would spread a box over hundreds of columns, and with corners moved by a
// quantisation shift. The pixels met are found by testing every column of the box's rows.

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "formats/dem/read_dem.h"
#include "src/geo/drawn_pixels.h"
#include "src/tin/measure_tin.h"
#include "tests/test_support.h"

namespace terratiles {
namespace {

struct Sampled {
  std::array<GridPoint, 3> corners;
  std::array<GridCorner, 3> grid;
};

// Three corners within `size` pixels of a pixel near a pole (or anywhere), on pixel centres
// or between them (as a placement off the lattice puts them), none on a pole row.
Sampled sampleTriangle(const DemOnGlobe& globe, std::mt19937& random, bool near_pole) {
  const DemGrid& dem = globe.dem();
  std::uniform_real_distribution<double> unit(0, 1);
  const double size = std::pow(10.0, 0.3 + 2.0 * unit(random));
  const double col = unit(random) * (dem.width - 1);
  const bool north = unit(random) < 0.5;
  double row = unit(random) * (dem.height - 1);
  if (near_pole) row = north ? 1 + 150 * unit(random) * unit(random) : dem.height - 2 - 150 * unit(random) * unit(random);
  const bool on_lattice = unit(random) < 0.5;
  // A third of the triangles near a pole have a corner on the pole row (the pole vertex).
  const bool pole_corner = near_pole && unit(random) < 0.33;
  Sampled s;
  for (std::size_t k = 0; k < 3; ++k) {
    double c = std::clamp(col + (unit(random) - 0.5) * size, 0.0, dem.width - 1.0);
    double r = std::clamp(row + (unit(random) - 0.5) * size, 0.5, dem.height - 1.5);
    if (on_lattice) {
      c = std::round(c);
      r = std::clamp(std::round(r), 1.0, dem.height - 2.0);
    }
    if (k == 0 && pole_corner) r = north ? 0 : dem.height - 1;
    const float h = dem.heightAt(static_cast<std::int32_t>(std::round(c)), static_cast<std::int32_t>(std::round(r)));
    s.corners[k] = {c, r, std::isnan(h) ? 0.0 : static_cast<double>(h)};
    s.grid[k] = {c, r, globe.poleRow(static_cast<std::int32_t>(r)) && r == std::round(r)};
  }
  return s;
}

}  // namespace

TEST_SUITE("drawn_pixels") {
  TEST_CASE("every pixel a drawn triangle meets is a candidate, with the longitude bound (ETOPO5, poles)") {
    const DemGrid dem = readDem({test::sharedData("etopo5_global_4326.tif")});
    const DemOnGlobe globe(dem, nullptr);
    REQUIRE(globe.degreesPerColumn() == doctest::Approx(1.0 / 12));
    std::mt19937 random(17);
    std::uniform_real_distribution<double> unit(0, 1);
    std::size_t met = 0, narrowed = 0, narrowed_met = 0, scanned_met = 0, scanned_at_pole = 0;
    for (int i = 0; i < 600; ++i) {
      const Sampled s = sampleTriangle(globe, random, i % 4 != 0);
      // Drawn corners moved by up to shift_m each (a quantisation grid's): up to a column's
      // spacing there (tens of metres next to a pole), to push pixels across the bound.
      const auto centre_row = static_cast<std::int32_t>(std::round(s.grid[0].row));
      const double shift_m = i % 3 == 0 ? 0.0 : globe.columnSpacing(centre_row) * std::pow(10.0, -2 + 2 * unit(random));
      std::array<EcefPoint, 3> drawn_corners;
      for (std::size_t k = 0; k < 3; ++k) {
        EcefPoint p = globe.place(s.corners[k]);
        const double u = 2 * unit(random) - 1, angle = 2 * 3.141592653589793 * unit(random);
        const double length = shift_m * unit(random), across = std::sqrt(1 - u * u);
        p.x += length * across * std::cos(angle);
        p.y += length * across * std::sin(angle);
        p.z += length * u;
        drawn_corners[k] = p;
      }
      const DrawnTriangle triangle(drawn_corners[0], drawn_corners[1], drawn_corners[2]);
      if (triangle.degenerate()) continue;
      const PixelMargin margin = strayMargin(globe, s.grid, triangle.longestEdge(), shift_m);
      const PixelBox box = candidatePixels(globe, s.grid, triangle.longestEdge(), shift_m);
      const bool narrower = margin.longitude_columns < margin.columns && box.col1 - box.col0 + 1 < dem.width;
      narrowed += narrower ? 1 : 0;
      // Every column of the box's rows and the rows next to the corners: each pixel met lies
      // within the box (its columns wrapped too).
      double row_min = 1e300, row_max = -1e300;
      for (const GridCorner& corner : s.grid) {
        row_min = std::min(row_min, corner.row);
        row_max = std::max(row_max, corner.row);
      }
      PixelBox rows;
      rows.row0 = std::min(box.row0, static_cast<std::int32_t>(std::floor(row_min)) - 1);
      rows.row1 = std::max(box.row1, static_cast<std::int32_t>(std::ceil(row_max)) + 1);
      rows.col0 = 0;
      rows.col1 = dem.width - 1;
      // (A pole row's pixels are one point: a triangle with a corner there meets all of them,
      // and its box holds those between its other corners' columns.)
      forEachPixelMeeting(globe, triangle, rows, [&](std::size_t pixel, double) {
        const auto col = static_cast<std::int64_t>(pixel % static_cast<std::size_t>(dem.width));
        const auto row = static_cast<std::int32_t>(pixel / static_cast<std::size_t>(dem.width));
        if (s.grid[0].at_pole && globe.poleRow(row)) return;
        const bool inside = (col >= box.col0 && col <= box.col1) || (col + dem.width >= box.col0 && col + dem.width <= box.col1) ||
                            (col - dem.width >= box.col0 && col - dem.width <= box.col1);
        REQUIRE_MESSAGE(inside, "pixel column " << col << " row " << row << " outside the box's " << box.col0 << ".."
                                                << box.col1 << " (shift " << shift_m << " m)");
        REQUIRE(row >= box.row0);
        REQUIRE(row <= box.row1);
        ++met;
        narrowed_met += narrower ? 1 : 0;
      });
      // forEachCoveredPixelOnGlobe (the simplifier's measure, no shift) visits them too, on a
      // triangle with an area in the grid (a mesh has no other).
      const GridPoint &a = s.corners[0], &b = s.corners[1], &c = s.corners[2];
      if (shift_m == 0 && (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col) != 0) {
        std::vector<std::size_t> visited;
        forEachCoveredPixelOnGlobe(globe, s.corners[0], s.corners[1], s.corners[2], drawn_corners[0], drawn_corners[1],
                                   drawn_corners[2], [&](std::size_t pixel, double) {
                                     visited.push_back(pixel);
                                     return true;
                                   });
        std::sort(visited.begin(), visited.end());
        // (Not the pole rows' strays: the scan measures a pole row in the grid only.)
        // Nor where the vertical runs within a thousandth of a radian along the triangle's
        // plane: there Moeller-Trumbore's determinant vanishes and meets() may say yes for a
        // vertical far from it (a triangle in the meridian plane of a pole corner and two
        // corners on one meridian "meets" pixels on the opposite meridian).
        const double normal_length = std::hypot(triangle.normal[0], triangle.normal[1], triangle.normal[2]);
        forEachPixelMeeting(globe, triangle, rows, [&](std::size_t pixel, double) {
          const UnitVector up = globe.up(pixel);
          const double along = triangle.normal[0] * up[0] + triangle.normal[1] * up[1] + triangle.normal[2] * up[2];
          if (std::fabs(along) < 1e-3 * normal_length) return;
          if (globe.poleRow(static_cast<std::int32_t>(pixel / static_cast<std::size_t>(dem.width)))) return;
          REQUIRE(std::binary_search(visited.begin(), visited.end(), pixel));
          ++scanned_met;
          scanned_at_pole += s.grid[0].at_pole ? 1 : 0;
        });
      }
    }
    MESSAGE(met << " pixels met, " << narrowed << " boxes narrowed by the longitude bound, holding " << narrowed_met
                << " of them; the scan visits " << scanned_met << " met pixels, " << scanned_at_pole
                << " of triangles with a pole corner");
    CHECK(narrowed > 200);
    CHECK(narrowed_met > 10000);
    CHECK(scanned_at_pole > 1000);
  }

  TEST_CASE("the longitude bound only on WGS84 longitude and latitude (not LV95)") {
    const DemGrid dem = readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    const DemOnGlobe globe(dem, nullptr);
    CHECK(globe.degreesPerColumn() == 0);
    const std::array<GridCorner, 3> grid{GridCorner{10, 10, false}, GridCorner{20, 12, false}, GridCorner{14, 30, false}};
    CHECK(std::isinf(strayMargin(globe, grid, 600.0, 0.01).longitude_columns));
  }
}

}  // namespace terratiles
