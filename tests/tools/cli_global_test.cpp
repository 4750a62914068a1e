// Integration test: the whole Earth (ETOPO5) in the webmercator scheme, whose polar caps
// beyond +-85.0511 deg are clamped into the first and last tile rows. Whatever the builds
// compute from those clamped points (cluster centroids, boxes) must stay inside the scheme.
// ETOPO5 is resampled to square pixels in-process with GDALWarp (gdalwarp, the program, is
// not available in CI), into the test's temporary directory.
#include <doctest/doctest.h>

#include <gdal_priv.h>
#include <gdal_utils.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "formats/gltf/read_glb.h"
#include "src/base/progress.h"
#include "src/pipeline/check_output.h"
#include "tests/test_support.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// gdalwarp -r cubic -te -180 SOUTH 180 NORTH -ts W H -ot Float32 etopo5_global_4326.tif `path`
void resampleEtopo5(int width, int height, const std::string& path, int south_deg = -90, int north_deg = 90) {
  GDALAllRegister();
  GDALDatasetH source = GDALOpen(test::sharedData("etopo5_global_4326.tif").c_str(), GA_ReadOnly);
  REQUIRE(source != nullptr);
  const std::string w = std::to_string(width), h = std::to_string(height);
  const std::string south = std::to_string(south_deg), north = std::to_string(north_deg);
  const char* args[] = {"-of", "GTiff", "-r", "cubic", "-te", "-180", south.c_str(), "180", north.c_str(),
                        "-ts", w.c_str(), h.c_str(), "-ot", "Float32", nullptr};
  GDALWarpAppOptions* options = GDALWarpAppOptionsNew(const_cast<char**>(args), nullptr);
  REQUIRE(options != nullptr);
  int usage_error = 0;
  GDALDatasetH written = GDALWarp(path.c_str(), nullptr, 1, &source, options, &usage_error);
  GDALWarpAppOptionsFree(options);
  CHECK(usage_error == 0);
  REQUIRE(written != nullptr);
  GDALClose(written);
  GDALClose(source);
}

struct GlobalCase {
  int width = 0;
  int height = 0;
  double tin_max_error_m = 0;
  std::string scheme;
  std::vector<std::string> options;  // more build options
};

}  // namespace

TEST_SUITE("integration") {
  TEST_CASE("ETOPO5 of the whole Earth builds with its polar caps at several sizes and TIN errors") {
    test::TempDir dir;
    // Sizes and errors picked to keep the test short: about 55 s in all on 2 idle cores
    // (Release), each build's time below; the resampling takes under a second per size.
    const std::vector<GlobalCase> cases = {
        {360, 180, 2.0, "webmercator", {}},   // about 7 s
        {720, 360, 50.0, "webmercator", {}},  // about 7 s
        // About 17 s. Zoom 4 has a cluster of Antarctic faces that all sit on the clamped
        // edge: its centroid came out at lat -85.051128779806973 (27 ulps past the limit) and
        // the build stopped with "beyond the Web Mercator limit" (as 6000 x 3000 at 10 m did,
        // after minutes, with the default options).
        {720, 360, 10.0, "webmercator", {"--tile-triangles", "4096"}},
        {720, 360, 10.0, "geographic", {}},    // about 8 s
        {1080, 540, 50.0, "webmercator", {}},  // about 16 s
    };
    std::string resampled_size;
    std::string input;
    for (const GlobalCase& c : cases) {
      const std::string size = std::to_string(c.width) + "x" + std::to_string(c.height);
      CAPTURE(size);
      CAPTURE(c.tin_max_error_m);
      CAPTURE(c.scheme);
      if (size != resampled_size) {
        input = dir / ("etopo5_" + size + ".tif");
        resampleEtopo5(c.width, c.height, input);
        resampled_size = size;
      }
      const std::string out = dir / ("out_" + size + "_" + std::to_string(c.tin_max_error_m) + "_" + c.scheme);
      const auto start = std::chrono::steady_clock::now();
      std::vector<std::string> args = {"build", input, "-o", out, "-q", "--no-report", "--scheme", c.scheme,
                                       "--tin-max-error", std::to_string(c.tin_max_error_m)};
      std::string more_options;
      for (const std::string& option : c.options) {
        args.push_back(option);
        more_options += " " + option;
      }
      CAPTURE(more_options);
      const test::CliResult result = test::runTerratiles(args);
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      MESSAGE("ETOPO5 " << size << " --scheme " << c.scheme << " --tin-max-error " << c.tin_max_error_m
                        << more_options << ": " << seconds << " s");
      CHECK_MESSAGE(result.err.empty(), result.err);
      REQUIRE(result.exit_code == 0);
      REQUIRE(fs::exists(out + "/tileset.json"));
      std::ifstream in(out + "/tileset.json");
      const nlohmann::json tileset = nlohmann::json::parse(in);
      CHECK(tileset["asset"]["version"] == "1.1");
      // The polar caps are drawn (in the first and last rows), at their true latitudes:
      // the pixel centres nearest the poles are at +-(90 - 90 / height) deg.
      const nlohmann::json& region = tileset["root"]["boundingVolume"]["region"];
      REQUIRE(region.size() == 6);
      CHECK(region[1].get<double>() * kDegPerRad < -89.0);
      CHECK(region[3].get<double>() * kDegPerRad > 89.0);
      fs::remove_all(out);
    }
  }

  TEST_CASE("a global raster whose last row stops short of the North Pole passes the check") {
    // 5' pixels from 45 to 90 deg N (about 25 s): the top row is at 89.958 deg, where columns
    // are 6.8 m apart, while the data's border vertices are snapped to the grid of the
    // coarsest zoom (8 m, shared down the chain of outlines), so they decode up to 0.15
    // columns from their pixel centres. The check put them back only within a tenth of a
    // column and found 10 border pixels left out; it now takes a tenth of the pixel's
    // north-south size as its cap.
    test::TempDir dir;
    const std::string input = dir / "etopo5_north.tif";
    resampleEtopo5(4320, 540, input, 45, 90);
    const test::CliResult built =
        test::runTerratiles({"build", input, "-o", dir / "out", "-q", "--no-report", "--tin-max-error", "10"});
    CAPTURE(built.err);
    REQUIRE(built.exit_code == 0);
    Progress quiet(ProgressMode::Quiet);
    CheckOptions check;
    check.cuts = 300;
    const CheckReport report = checkOutput(dir / "out", check, quiet);
    MESSAGE(describeCheck(report));
    test::checkSeamless(report);
    CHECK(report.left_out_pixels == 0);
  }

  TEST_CASE("a global raster whose border vertices decode on the antimeridian near the pole passes the check") {
    // 1.25' pixels from 88 to 90 deg N (about 15 s): the top row is at 89.9896 deg, where
    // columns are 0.42 m apart, and 1 m position steps put border vertices of the first and
    // last columns at longitude 180 exactly. The check put such a vertex at column -0.5, so the
    // last column's tiles had outline edges and triangles across the whole grid in it: the
    // top row's last pixels seemed left out (24), and vertices of other tiles seemed to lie on
    // those edges (ETOPO5 at 8640 x 4320 px: 56 pixels and 60 vertices).
    test::TempDir dir;
    const std::string input = dir / "etopo5_pole.tif";
    resampleEtopo5(17280, 96, input, 88, 90);
    const test::CliResult built = test::runTerratiles({"build", input, "-o", dir / "out", "-q", "--no-report",
                                                       "--tin-max-error", "10", "--position-step", "1"});
    CAPTURE(built.err);
    REQUIRE(built.exit_code == 0);
    // The case this test is for: vertices near the pole decoded on the antimeridian.
    std::size_t on_antimeridian = 0;
    for (const auto& entry : fs::recursive_directory_iterator(dir / "out/tiles")) {
      if (entry.path().extension() != ".glb") continue;
      const GlbMesh mesh = readGlbFile(entry.path().string()).mesh;
      for (std::size_t v = 0; v < mesh.vertexCount(); ++v) {
        const double x = mesh.translation[0] + mesh.positions[3 * v];
        const double y = -(mesh.translation[2] + mesh.positions[3 * v + 2]);
        if (y == 0 && x < 0 && std::hypot(x, y) < 2e3) ++on_antimeridian;
      }
    }
    MESSAGE(on_antimeridian << " decoded vertices on the antimeridian within 2 km of the pole");
    REQUIRE(on_antimeridian > 0);
    Progress quiet(ProgressMode::Quiet);
    CheckOptions check;
    check.cuts = 300;
    const CheckReport report = checkOutput(dir / "out", check, quiet);
    MESSAGE(describeCheck(report));
    test::checkSeamless(report);
    CHECK(report.left_out_pixels == 0);
    CHECK(report.uncovered_valid_pixels == 0);
    CHECK(report.missing_border_vertices == 0);
    // The same in strips of 16 rows (6 strips, each with the rows its tallest triangle reaches).
    CheckOptions strips = check;
    strips.strip_pixels = 1;
    test::checkSameReport(checkOutput(dir / "out", strips, quiet), report);
  }
}
