// `terratiles tin`: a real raster to a TIN file whose every pixel, read back from the file,
// is within the bound, measured as the build measures it: on the globe (EGM96 heights).
#include <doctest/doctest.h>

#include <filesystem>

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
}
