#include <doctest/doctest.h>

#include <cmath>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "tests/test_support.h"

using namespace terratiles;
using terratiles::test::sharedData;

namespace {
ErrorCode readError(const std::vector<std::string>& paths, std::string& message) {
  try {
    readDem(paths);
  } catch (const Error& e) {
    message = e.what();
    return e.code();
  }
  message.clear();
  return ErrorCode::Internal;
}
}  // namespace

TEST_SUITE("dem") {
  TEST_CASE("the Interlaken DHM25 tile reads as 350 x 240 pixels of 25 m in EPSG 2056") {
    const DemGrid dem = readDem({sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    CHECK(dem.width == 350);
    CHECK(dem.height == 240);
    CHECK(dem.pixel_size_x == 25.0);
    CHECK(dem.crs_name == "EPSG:2056");
    CHECK(dem.origin_x == 2628750.0);
    CHECK(dem.origin_y == 1176000.0);
    const DemStatistics stats = computeStatistics(dem);
    CHECK(stats.valid_pixels == dem.pixelCount());
    CHECK(stats.min_height_m > 550.0f);
    CHECK(stats.max_height_m < 2010.0f);
    CHECK(stats.max_height_m > 2000.0f);
  }

  TEST_CASE("the two adjacent Delft tiles mosaic into one grid without a seam") {
    const std::string west = sharedData("nl_ahn3_delft_tiles/delft_west_0.5m_28992.tif");
    const std::string east = sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif");
    const DemGrid mosaic = readDem({west, east});
    const DemGrid west_only = readDem({west});
    const DemGrid east_only = readDem({east});
    CHECK(mosaic.width == 383 + 144);
    CHECK(mosaic.height == 456);
    CHECK(mosaic.crs_name == "EPSG:28992");
    // Every pixel of each input lands at its place in the mosaic, nodata stays nodata.
    std::size_t compared = 0;
    for (int row = 0; row < mosaic.height; ++row) {
      for (int col = 0; col < mosaic.width; ++col) {
        const float expected =
            col < 383 ? west_only.heightAt(col, row) : east_only.heightAt(col - 383, row);
        const float found = mosaic.heightAt(col, row);
        if (std::isnan(expected)) {
          REQUIRE(std::isnan(found));
        } else {
          REQUIRE(found == expected);
          ++compared;
        }
      }
    }
    CHECK(compared > 0);
    // The files declare nodata -9999: no such value may survive as a height.
    const DemStatistics stats = computeStatistics(mosaic);
    CHECK(stats.min_height_m > -10.0f);
    // The two columns either side of the tile border both hold data: no seam.
    std::size_t seam_pairs = 0;
    for (int row = 0; row < mosaic.height; ++row) {
      if (mosaic.isValid(382, row) && mosaic.isValid(383, row)) ++seam_pairs;
    }
    CHECK(seam_pairs > 100);
  }

  TEST_CASE("an SRTM tile in EPSG 4326 reads with nodata masked") {
    const DemGrid dem = readDem({sharedData("srtm3_N57E011_4326.tif")});
    CHECK(dem.width == 1201);
    CHECK(dem.crs_name == "EPSG:4326");
    const DemStatistics stats = computeStatistics(dem);
    CHECK(stats.min_height_m >= -10.0f);
    CHECK(stats.max_height_m <= 200.0f);
  }

  TEST_CASE("bad inputs are refused with the file name and a fix") {
    std::string message;
    CHECK(readError({"/nonexistent/dem.tif"}, message) == ErrorCode::Input);
    CHECK(message == "/nonexistent/dem.tif: no such file; check the path");

    CHECK(readError({sharedData("README.md")}, message) == ErrorCode::Input);
    CHECK(message.find("README.md: not a raster that GDAL can read") != std::string::npos);

    test::TempDir dir;
    const DemGrid dem = test::makeDem(8, 8, 2.0, [](int c, int r) { return 500.0 + c + r; });
    test::writeGeoTiff(dem, dir / "nocrs.tif", false);
    CHECK(readError({dir / "nocrs.tif"}, message) == ErrorCode::Input);
    CHECK(message.find("raster has no coordinate reference system") != std::string::npos);
    CHECK(message.find("gdal_edit.py -a_srs") != std::string::npos);

    CHECK(readError({sharedData("ch_dhm25_interlaken_25m_2056.tif"),
                     sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif")},
                    message) == ErrorCode::Input);
    CHECK(message.find("CRS is EPSG:28992 but") != std::string::npos);

    const DemGrid holes = test::makeDem(8, 8, 2.0, [](int, int) { return std::nan(""); });
    test::writeGeoTiff(holes, dir / "allnodata.tif");
    CHECK(readError({dir / "allnodata.tif"}, message) == ErrorCode::Input);
    CHECK(message.find("every pixel is nodata") != std::string::npos);
  }

  TEST_CASE("inputs off the first input's pixel lattice are refused") {
    test::TempDir dir;
    DemGrid a = test::makeDem(8, 8, 2.0, [](int c, int) { return 400.0 + c; });
    DemGrid b = a;
    b.origin_x += 16.5;  // not a whole number of 2 m pixels
    test::writeGeoTiff(a, dir / "a.tif");
    test::writeGeoTiff(b, dir / "b.tif");
    std::string message;
    CHECK(readError({dir / "a.tif", dir / "b.tif"}, message) == ErrorCode::Input);
    CHECK(message.find("expected whole pixels") != std::string::npos);
  }
}
