// `terratiles tin`: a real raster to a TIN file whose every pixel, read back from the file,
// is within the bound, measured as the build measures it: on the globe (EGM96 heights).
#include <doctest/doctest.h>

#include <filesystem>
#include <set>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "src/geo/dem_on_globe.h"
#include "formats/tin/tin_file.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "tests/test_support.h"

using namespace terratiles;


TEST_SUITE("cli") {
  TEST_CASE("tin writes the Interlaken TIN in every format within the bound on every pixel") {
    test::TempDir dir;
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    const DemGrid dem = readDem({input});
    Progress progress;
    const GeoidGrid geoid = readGeoidGrid(kDefaultGeoidPath);
    const DemOnGlobe globe(dem, &geoid);
    TinOptions options{1.0};
    options.globe = &globe;
    const std::size_t expected_triangles = buildTin(dem, options, progress).triangleCount();
    for (const char* name : {"interlaken.off", "interlaken.obj", "interlaken.ply"}) {
      CAPTURE(name);
      const std::string output = dir / name;
      const auto result = test::runTerratiles({"tin", input, "-o", output, "--tin-max-error", "1"});
      REQUIRE(result.exit_code == 0);
      const auto said = result.err.find("max error ");
      REQUIRE(said != std::string::npos);
      CHECK(result.err.find(" m (bound 1 m)", said) != std::string::npos);
      CHECK(std::stod(result.err.substr(said + 10)) <= 1.0);
      const TinMesh mesh = toGridTin(readTinFile(output), dem.origin_x, dem.origin_y, dem.pixel_size_x);
      CHECK(mesh.triangleCount() == expected_triangles);  // the file holds buildTin's TIN
      // Read back from the file's CRS coordinates: placed again within a nanometre or so.
      const TinErrorStatistics errors = test::measureOnGlobe(dem, mesh);
      CHECK(errors.max_error_m <= 1.0 + 1e-6);
      CHECK(errors.uncovered_valid_pixels == 0);
    }
    // An existing file needs --force; an unknown extension is a usage error.
    CHECK(test::runTerratiles({"tin", input, "-o", dir / "interlaken.off"}).exit_code == 4);
    CHECK(test::runTerratiles({"tin", input, "-o", dir / "interlaken.off", "--force", "-q"}).exit_code == 0);
    const auto stl = test::runTerratiles({"tin", input, "-o", dir / "x.stl"});
    CHECK(stl.exit_code == 2);
    CHECK(stl.err.find("expected .off, .obj or .ply") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path() / "x.stl"));
  }

  TEST_CASE("tin in blocks: each block read and triangulated on its own gives one seamless TIN within the bound") {
    test::TempDir dir;
    {
      // SRTM Gabon (2401 x 1201 px, longitude/latitude) in 15 blocks of 512 px: windows of 128
      // px from each block's corner are the whole build's windows, and the 1D choice of a
      // border depends only on its pixels, so the blocks make the very TIN of the whole build.
      const std::string input = test::sharedData("srtm3_N00E010-E011_4326.tif");
      const DemGrid dem = readDem({input});
      const auto whole = test::runTerratiles({"tin", input, "-o", dir / "whole.ply", "--tin-max-error", "5", "-q"});
      REQUIRE(whole.exit_code == 0);
      const auto blocks = test::runTerratiles(
          {"tin", input, "-o", dir / "blocks.ply", "--tin-max-error", "5", "--block-pixels", "512"});
      REQUIRE(blocks.exit_code == 0);
      CHECK(blocks.err.find("(15 blocks;") != std::string::npos);
      const std::size_t uncovered_whole =
          test::measureOnGlobe(dem, toGridTin(readTinFile(dir / "whole.ply"), dem.origin_x, dem.origin_y,
                                              dem.pixel_size_x)).uncovered_valid_pixels;
      const auto block_triangles = test::checkStitchedTin(dir / "blocks.ply", dem, 5.0, uncovered_whole);
      const auto whole_triangles = test::checkStitchedTin(dir / "whole.ply", dem, 5.0, uncovered_whole);
      CHECK(block_triangles.size() > 1'000'000);
      CHECK(block_triangles == whole_triangles);
    }
    {
      // Interlaken (EPSG:2056: pixels placed one by one, 48 bytes each) in 24 blocks of 64 px at
      // 0.5 m: blocks of their own windows, still one TIN within the bound.
      const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
      const DemGrid dem = readDem({input});
      const auto blocks = test::runTerratiles(
          {"tin", input, "-o", dir / "interlaken.off", "--tin-max-error", "0.5", "--block-pixels", "64", "-q"});
      REQUIRE(blocks.exit_code == 0);
      CHECK(test::checkStitchedTin(dir / "interlaken.off", dem, 0.5, 0).size() > 90'000);
    }
    // Blocks of one pixel cannot be; break lines do not cross blocks yet.
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    CHECK(test::runTerratiles({"tin", input, "-o", dir / "x.ply", "--block-pixels", "1"}).exit_code == 2);
    const auto constrained = test::runTerratiles({"tin", input, "-o", dir / "x.ply", "--block-pixels", "64",
                                                  "--constraints", test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    CHECK(constrained.exit_code == 2);
    CHECK(constrained.err.find("--constraints is not available with blocks") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path() / "x.ply"));
  }
}
