// DemOnGlobe keeps a WGS84 longitude and latitude DEM's pixels as factors per row and column
// and a height per pixel (8 bytes instead of 48): every pixel's point and vertical, and the
// vectorised scans' four-pixel loads, must be those of placing the pixel itself, bit for bit.
#include <doctest/doctest.h>

#include <cstring>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "src/geo/dem_on_globe.h"
#include "src/geo/dem_on_globe_lanes.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

bool sameBits(const EcefPoint& p, const EcefPoint& q) { return std::memcmp(&p, &q, sizeof p) == 0; }
bool sameBits(const UnitVector& p, const UnitVector& q) { return std::memcmp(&p, &q, sizeof p) == 0; }

#if defined(__x86_64__)
// pixelLanes's four pixels, stored: [k] = {x, y, z, ux, uy, uz} of pixel (col + k, row).
__attribute__((target("avx2"))) void storeLanes(const DemOnGlobe& globe, std::int32_t col, std::int32_t row,
                                                double out[6][4]) {
  const PixelLanes lanes = pixelLanes(globe, col, row, globe.dem().index(col, row));
  const __m256d parts[6] = {lanes.x, lanes.y, lanes.z, lanes.ux, lanes.uy, lanes.uz};
  for (int p = 0; p < 6; ++p) _mm256_storeu_pd(out[p], parts[p]);
}
#endif

// Pixels placed on their own (DemOnGlobe::place, as a vertex is placed) against point(), and
// four-pixel loads against point() and up(), over a lattice of pixels every `step` columns
// and rows plus the last column and row. Returns the pixels compared.
std::size_t comparePixels(const DemOnGlobe& globe, std::int32_t step) {
  const DemGrid& dem = globe.dem();
  std::size_t compared = 0;
  const auto check = [&](std::int32_t col, std::int32_t row) {
    const float h = dem.heightAt(col, row);
    if (!std::isnan(h)) {
      const EcefPoint placed = globe.place(GridPoint{double(col), double(row), double(h)});
      REQUIRE_MESSAGE(sameBits(placed, globe.point(col, row)), "pixel (" << col << ", " << row << ")");
      REQUIRE(sameBits(globe.point(col, row), globe.point(dem.index(col, row))));
      REQUIRE(sameBits(globe.up(col, row), globe.up(dem.index(col, row))));
      ++compared;
    }
#if defined(__x86_64__)
    if (__builtin_cpu_supports("avx2") && col + 3 < dem.width) {
      double lanes[6][4];
      storeLanes(globe, col, row, lanes);
      for (int k = 0; k < 4; ++k) {
        REQUIRE(sameBits(EcefPoint{lanes[0][k], lanes[1][k], lanes[2][k]}, globe.point(col + k, row)));
        REQUIRE(sameBits(UnitVector{lanes[3][k], lanes[4][k], lanes[5][k]}, globe.up(col + k, row)));
      }
    }
#endif
  };
  for (std::int32_t row = 0; row < dem.height; row += step) {
    for (std::int32_t col = 0; col < dem.width; col += step) check(col, row);
    check(dem.width - 1, row);
  }
  for (std::int32_t col = 0; col < dem.width; col += step) check(col, dem.height - 1);
  return compared;
}

}  // namespace

TEST_SUITE("dem_on_globe") {
  TEST_CASE("WGS84 rasters keep factors, bit for bit the placed pixels (SRTM Gabon, SRTM N57E011, ETOPO5)") {
    const GeoidGrid egm96 = readGeoidGrid(kDefaultGeoidPath);
    for (const std::string name : {"srtm3_N00E010-E011_4326.tif", "srtm3_N57E011_4326.tif", "etopo5_global_4326.tif"}) {
      CAPTURE(name);
      const DemGrid dem = readDem({test::sharedData(name)});
      const DemOnGlobe globe(dem, &egm96);
      REQUIRE(globe.factors() != nullptr);  // 8 bytes per pixel, not 48
      CHECK(comparePixels(globe, 37) > 1000);
      // Ellipsoidal heights (no geoid) too.
      const DemOnGlobe ellipsoidal(dem, nullptr);
      REQUIRE(ellipsoidal.factors() != nullptr);
      CHECK(comparePixels(ellipsoidal, 101) > 100);
    }
  }

  TEST_CASE("projected rasters keep their points (swissALTI3D-like LV95 Interlaken, UTM Minnesota)") {
    const GeoidGrid egm96 = readGeoidGrid(kDefaultGeoidPath);
    for (const std::string name : {"ch_dhm25_interlaken_25m_2056.tif", "us_mn_lidar_dtm_1m_26915.tif"}) {
      CAPTURE(name);
      const DemGrid dem = readDem({test::sharedData(name)});
      const DemOnGlobe globe(dem, &egm96);
      CHECK(globe.factors() == nullptr);
      CHECK(comparePixels(globe, 17) > 300);
    }
  }
}
