#include <doctest/doctest.h>

#include <gdal_priv.h>
#include <gdal_utils.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "formats/dem/dem_inputs.h"
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

  TEST_CASE("a directory expands to its rasters in name order and an input list to its lines") {
    test::TempDir dir;
    namespace fs = std::filesystem;
    fs::create_directories(dir.path() / "tiles/sub");
    for (const char* name : {"b.tif", "a.TIF", "c.vrt", ".hidden.tif", "notes.txt", "sub/d.tif"}) {
      std::ofstream(dir / ("tiles/" + std::string(name))) << "x";
    }
    const std::vector<std::string> expanded = expandDemInputs({dir / "tiles"});
    REQUIRE(expanded.size() == 3);  // no hidden file, no text, no subdirectory
    CHECK(fs::path(expanded[0]).filename() == "a.TIF");
    CHECK(fs::path(expanded[1]).filename() == "b.tif");
    CHECK(fs::path(expanded[2]).filename() == "c.vrt");

    {
      std::ofstream list(dir / "list.txt");
      list << "# swissALTI3D\n\n  " << dir / "tiles/sub/d.tif" << "  \n" << dir / "tiles" << "\n";
    }
    const std::vector<std::string> listed = expandDemInputs({dir / "tiles/b.tif"}, dir / "list.txt");
    REQUIRE(listed.size() == 5);  // arguments first, then the lines, a listed directory expanded
    CHECK(fs::path(listed[0]).filename() == "b.tif");
    CHECK(fs::path(listed[1]).filename() == "d.tif");
    CHECK(fs::path(listed[2]).filename() == "a.TIF");

    const auto refused = [](const std::vector<std::string>& arguments, const std::string& list) {
      try {
        expandDemInputs(arguments, list);
      } catch (const Error& e) {
        return std::string(e.what());
      }
      return std::string();
    };
    CHECK(refused({dir / "tiles/sub/nothing"}, "").find("nothing: no such file or directory") != std::string::npos);
    CHECK(refused({}, dir / "absent.txt") == dir / "absent.txt" + ": cannot open the input list; check the path");
    CHECK(refused({}, "").find("no input raster given") != std::string::npos);
  }

  TEST_CASE("a window of the Delft mosaic reads the pixels of both tiles and nodata past the edge") {
    const std::vector<std::string> paths{sharedData("nl_ahn3_delft_tiles/delft_west_0.5m_28992.tif"),
                                         sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif")};
    const DemMosaic mosaic = scanDemMosaic(paths);
    REQUIRE(mosaic.rasters.size() == 2);
    CHECK(mosaic.width == 383 + 144);
    CHECK(mosaic.rasters[1].col0 == 383);
    const DemGrid whole = readDem(mosaic);
    // Straddles the tile border and reaches 20 px past the east and south edges.
    const PixelWindow window{370, 430, 177, 46};
    const DemGrid part = readDemWindow(mosaic, window);
    CHECK(part.origin_x == whole.origin_x + 370 * whole.pixel_size_x);
    CHECK(part.origin_y == whole.origin_y - 430 * whole.pixel_size_y);
    std::size_t compared = 0, outside = 0;
    for (int row = 0; row < part.height; ++row) {
      for (int col = 0; col < part.width; ++col) {
        const std::int64_t c = window.col0 + col, r = window.row0 + row;
        const float found = part.heightAt(col, row);
        if (c >= whole.width || r >= whole.height) {
          REQUIRE(std::isnan(found));
          ++outside;
          continue;
        }
        const float expected = whole.heightAt(static_cast<int>(c), static_cast<int>(r));
        if (std::isnan(expected)) {
          REQUIRE(std::isnan(found));
        } else {
          REQUIRE(found == expected);
          ++compared;
        }
      }
    }
    CHECK(compared > 1000);
    CHECK(outside == 177 * 46 - 157 * 26);
  }

  TEST_CASE("a VRT that resamples is read through GDAL, one that only places files through its sources") {
    test::TempDir dir;
    const std::string srtm = sharedData("srtm3_N57E011_4326.tif");
    GDALAllRegister();
    const auto translate = [&](const std::vector<std::string>& words, const std::string& path) {
      std::vector<char*> argv;
      for (const std::string& word : words) argv.push_back(const_cast<char*>(word.c_str()));
      argv.push_back(nullptr);
      GDALTranslateOptions* options = GDALTranslateOptionsNew(argv.data(), nullptr);
      GDALDatasetH source = GDALOpen(srtm.c_str(), GA_ReadOnly);
      GDALDatasetH out = GDALTranslate(path.c_str(), source, options, nullptr);
      GDALTranslateOptionsFree(options);
      REQUIRE(out != nullptr);
      GDALClose(out);
      GDALClose(source);
    };
    // Half the pixels, averaged: not a mosaic of whole files, so GDAL resamples it.
    translate({"-of", "VRT", "-outsize", "50%", "50%", "-r", "average"}, dir / "half.vrt");
    const DemGrid half = readDem({dir / "half.vrt"});
    CHECK(half.width == 600);
    CHECK(half.pixel_size_x > 0.0016);
    // Heights scaled by 2 in the VRT: read through GDAL, so the scale applies.
    translate({"-of", "VRT", "-scale", "0", "100", "0", "200", "-ot", "Float32"}, dir / "scaled.vrt");
    const DemGrid scaled = readDem({dir / "scaled.vrt"});
    const DemGrid plain = readDem({srtm});
    const int col = 600, row = 600;
    REQUIRE(plain.isValid(col, row));
    CHECK(scaled.heightAt(col, row) == doctest::Approx(2.0 * plain.heightAt(col, row)).epsilon(1e-6));
    // A plain copy as VRT places the whole file: read through it, on its own lattice.
    translate({"-of", "VRT"}, dir / "copy.vrt");
    const DemMosaic copy = scanDemMosaic({dir / "copy.vrt"});
    REQUIRE(copy.rasters.size() == 1);
    CHECK(copy.rasters[0].path == srtm);
    CHECK(readDem(copy).heights_m == plain.heights_m);
  }
}

