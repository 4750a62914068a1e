// LatticeRows: candidate boxes in a mosaic's rows from the figures of its strips, which hold
// every pixel candidatePixels finds on the whole DEM's globe, so a strip's measure meets
// exactly the pixels, with the same offsets, that the whole DEM's measure meets there.

#include <doctest/doctest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <vector>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "src/geo/drawn_pixels.h"
#include "src/geo/geoid.h"
#include "tests/test_support.h"

namespace terratiles {
namespace {

// Rows [row0, row0 + rows) of `dem`, as readDemWindow would cut them from a mosaic.
DemGrid rowsOf(const DemGrid& dem, std::int32_t row0, std::int32_t rows) {
  DemGrid window = dem;
  window.heights_m.assign(dem.heights_m.begin() + static_cast<std::ptrdiff_t>(dem.index(0, row0)),
                          dem.heights_m.begin() + static_cast<std::ptrdiff_t>(dem.index(0, row0 + rows)));
  window.height = rows;
  window.row_offset = row0;
  window.lattice_origin_x = dem.origin_x;
  window.lattice_origin_y = dem.origin_y;
  window.origin_y = dem.origin_y - row0 * dem.pixel_size_y;
  return window;
}

void checkStrips(const DemGrid& dem, const GeoidGrid* geoid, std::int32_t strip_rows) {
  const DemOnGlobe whole(dem, geoid);
  std::vector<DemGrid> windows;
  for (std::int32_t r0 = 0; r0 < dem.height; r0 += strip_rows) {
    windows.push_back(rowsOf(dem, r0, std::min(strip_rows, dem.height - r0)));
  }
  std::vector<std::unique_ptr<DemOnGlobe>> strips;
  LatticeRows rows(dem.width, dem.height);
  for (const DemGrid& window : windows) {
    strips.push_back(std::make_unique<DemOnGlobe>(window, geoid));
    rows.collect(*strips.back(), window.row_offset);
  }
  rows.finish();

  std::mt19937 random(11);
  std::uniform_real_distribution<double> unit(0, 1);
  std::size_t met = 0, spanning = 0, extra_pole_pixels = 0;
  for (int i = 0; i < 2000; ++i) {
    // Corners at pixel centres, from a pixel across to a third of the raster (many strips).
    const double size = std::pow(10.0, 0.5 + 2.5 * unit(random));
    const double col = unit(random) * (dem.width - 1), row = unit(random) * (dem.height - 1);
    std::array<GridPoint, 3> corners;
    std::array<EcefPoint, 3> ecef;
    std::array<GridCorner, 3> grid;
    for (std::size_t k = 0; k < 3; ++k) {
      const double c = std::round(std::clamp(col + (unit(random) - 0.5) * size, 0.0, dem.width - 1.0));
      const double r = std::round(std::clamp(row + (unit(random) - 0.5) * size, 0.0, dem.height - 1.0));
      const float h = dem.heightAt(static_cast<std::int32_t>(c), static_cast<std::int32_t>(r));
      corners[k] = {c, r, std::isnan(h) ? 0.0 : static_cast<double>(h) + (unit(random) - 0.5) * 40};
      ecef[k] = whole.place(corners[k]);
      grid[k] = {c, r, whole.poleRow(static_cast<std::int32_t>(r))};
    }
    const DrawnTriangle triangle(ecef[0], ecef[1], ecef[2]);
    if (triangle.degenerate()) continue;
    const double shift_m = 0.0068;
    const PixelBox expected = candidatePixels(whole, grid, triangle.longestEdge(), shift_m);
    const PixelBox box = rows.box(grid, triangle.longestEdge(), shift_m);
    if (expected.row1 < expected.row0) continue;
    REQUIRE(box.row0 <= expected.row0);
    REQUIRE(box.row1 >= expected.row1);
    if (box.col1 - box.col0 + 1 < dem.width) {
      REQUIRE(box.col0 <= expected.col0);
      REQUIRE(box.col1 >= expected.col1);
    }
    // The whole DEM's valid pixels met, and the strips' (each cut to its rows).
    std::vector<std::pair<std::size_t, double>> reference, cut;
    forEachPixelMeeting(whole, triangle, expected, [&](std::size_t pixel, double offset_m) {
      if (!std::isnan(dem.heights_m[pixel])) reference.emplace_back(pixel, offset_m);
    });
    std::size_t strips_met = 0;
    for (std::size_t s = 0; s < strips.size(); ++s) {
      const std::int64_t first = windows[s].row_offset;
      PixelBox in_strip = box;
      in_strip.row0 = static_cast<std::int32_t>(std::max<std::int64_t>(box.row0 - first, 0));
      in_strip.row1 = static_cast<std::int32_t>(std::min<std::int64_t>(box.row1 - first, windows[s].height - 1));
      if (in_strip.row1 < in_strip.row0) continue;
      ++strips_met;
      forEachPixelMeeting(*strips[s], triangle, in_strip, [&](std::size_t pixel, double offset_m) {
        const std::size_t in_dem = pixel + static_cast<std::size_t>(first) * static_cast<std::size_t>(dem.width);
        if (!std::isnan(dem.heights_m[in_dem])) cut.emplace_back(in_dem, offset_m);
      });
    }
    spanning += strips_met > 1 ? 1 : 0;
    std::sort(reference.begin(), reference.end());
    std::sort(cut.begin(), cut.end());
    // Every pixel the whole DEM's measure meets, with its offset bit for bit; more only on a
    // pole row (all its pixels are the pole, met with the pole's offset).
    std::size_t r = 0;
    for (const auto& [pixel, offset_m] : cut) {
      if (r < reference.size() && reference[r].first == pixel) {
        REQUIRE(std::bit_cast<std::uint64_t>(offset_m) == std::bit_cast<std::uint64_t>(reference[r].second));
        ++r;
        continue;
      }
      const auto pixel_row = static_cast<std::int32_t>(pixel / static_cast<std::size_t>(dem.width));
      REQUIRE(whole.poleRow(pixel_row));
      const auto same_row = std::find_if(reference.begin(), reference.end(), [&](const auto& p) {
        return p.first / static_cast<std::size_t>(dem.width) == static_cast<std::size_t>(pixel_row);
      });
      REQUIRE(same_row != reference.end());
      CHECK(offset_m == doctest::Approx(same_row->second).epsilon(1e-9));
      ++extra_pole_pixels;
    }
    REQUIRE(r == reference.size());
    met += cut.size();
  }
  MESSAGE(met << " pixels met, " << spanning << " triangles over several strips, " << extra_pole_pixels
               << " more pole-row pixels");
  CHECK(met > 10000);
  CHECK(spanning > 100);
}

// Collected from the whole DEM's globe at once, the boxes are candidatePixels' exactly.
void checkWhole(const DemGrid& dem) {
  const DemOnGlobe whole(dem, nullptr);
  LatticeRows rows(dem.width, dem.height);
  rows.collect(whole, 0);
  rows.finish();
  REQUIRE(rows.slack == 1);
  std::mt19937 random(5);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int i = 0; i < 2000; ++i) {
    std::array<GridCorner, 3> grid;
    std::array<EcefPoint, 3> ecef;
    for (std::size_t k = 0; k < 3; ++k) {
      const double c = std::round(unit(random) * (dem.width - 1)), r = std::round(unit(random) * (dem.height - 1));
      grid[k] = {c, r, whole.poleRow(static_cast<std::int32_t>(r))};
      ecef[k] = whole.place(GridPoint{c, r, 100.0});
    }
    const DrawnTriangle triangle(ecef[0], ecef[1], ecef[2]);
    if (triangle.degenerate()) continue;
    const PixelBox expected = candidatePixels(whole, grid, triangle.longestEdge(), 0.01);
    const PixelBox box = rows.box(grid, triangle.longestEdge(), 0.01);
    REQUIRE(box.row0 == expected.row0);
    REQUIRE(box.row1 == expected.row1);
    REQUIRE(box.col0 == expected.col0);
    REQUIRE(box.col1 == expected.col1);
  }
}

}  // namespace

TEST_SUITE("lattice_rows") {
  TEST_CASE("collected from one globe of the whole DEM, the boxes are candidatePixels' (ETOPO5)") {
    checkWhole(readDem({test::sharedData("etopo5_global_4326.tif")}));
  }

  TEST_CASE("strips' boxes hold the whole DEM's candidates, and strips meet its pixels with its offsets") {
    // Interlaken (LV95, stored points, geoid), N57E011 (factors), ETOPO5 (the whole globe: wrapping
    // columns, pole rows, chords of thousands of km).
    const GeoidGrid swiss = readGeoidGrid(test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif"));
    checkStrips(readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")}), &swiss, 37);
    checkStrips(readDem({test::sharedData("srtm3_N57E011_4326.tif")}), nullptr, 100);
    checkStrips(readDem({test::sharedData("etopo5_global_4326.tif")}), nullptr, 64);
  }
}

}  // namespace terratiles
