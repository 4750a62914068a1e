// `terratiles levels`: a real raster to its cluster levels of detail, each level read back
// from its file within the budget it reports, levels.json agreeing with the files; errors
// measured as the build measures them, on the globe (EGM96 heights).
#include <doctest/doctest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "formats/dem/read_dem.h"
#include "formats/tin/tin_file.h"
#include "src/tin/measure_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

TEST_SUITE("cli") {
  TEST_CASE("levels writes the Interlaken levels with errors within their budgets") {
    test::TempDir dir;
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    const DemGrid dem = readDem({input});
    const std::string output = dir / "levels";
    const auto result = test::runTerratiles({"levels", input, "-o", output, "--random-constraints", "50"});
    REQUIRE(result.exit_code == 0);
    CHECK(result.err.find("levels to") != std::string::npos);
    std::ifstream file(std::filesystem::path(output) / "levels.json");
    const nlohmann::json summary = nlohmann::json::parse(file);
    CHECK(summary["level_error_growth"] == 2.0);
    CHECK(summary["constrained_edges"].get<int>() > 50);
    const auto& levels = summary["levels"];
    REQUIRE(levels.size() >= 5);
    std::size_t previous_triangles = 0;
    for (std::size_t l = 0; l < levels.size(); ++l) {
      CAPTURE(l);
      const TinMesh mesh = toGridTin(readTinFile((std::filesystem::path(output) / levels[l]["file"].get<std::string>()).string()),
                                     dem.origin_x, dem.origin_y, dem.pixel_size_x);
      CHECK(mesh.triangleCount() == levels[l]["triangles"].get<std::size_t>());
      const TinErrorStatistics errors = test::measureOnGlobe(dem, mesh);
      CHECK(errors.max_error_m == doctest::Approx(levels[l]["max_error_m"].get<double>()).epsilon(1e-6));
      CHECK(errors.uncovered_valid_pixels == 0);
      // Level l's budget is 0.5 m * 2^l (level 0: the TIN's own bound).
      CHECK(errors.max_error_m <= 0.5 * std::pow(2.0, static_cast<double>(l)) + 1e-6);
      if (l > 0) CHECK(mesh.triangleCount() < previous_triangles * 9 / 10);
      previous_triangles = mesh.triangleCount();
    }
    // A second run needs --force; bad options are usage errors; nothing is left half-written.
    CHECK(test::runTerratiles({"levels", input, "-o", output}).exit_code == 4);
    CHECK(test::runTerratiles({"levels", input, "-o", output, "-f", "-q", "--levels", "2"}).exit_code == 0);
    CHECK(test::runTerratiles({"levels", input, "-o", dir / "x", "--level-ratio", "1.5"}).exit_code == 2);
    CHECK(test::runTerratiles({"levels", input, "-o", dir / "y", "--partitioner", "kway"}).exit_code == 2);
    const auto bad_stop = test::runTerratiles({"levels", input, "-o", dir / "z", "--tail-stop", "5,1000"});
    CHECK(bad_stop.exit_code == 2);
    CHECK(bad_stop.err.find("--tail-stop is '5,1000'") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path() / "z"));
    CHECK_FALSE(std::filesystem::exists(dir.path() / "x"));
  }

  TEST_CASE("levels in blocks: every level of every block on its own, stitched, within its budget, outlines kept") {
    test::TempDir dir;
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    const DemGrid dem = readDem({input});
    const std::string output = dir / "levels";
    // 12 blocks of 100 px (the raster is 400 x 210), four coarser levels each.
    const auto result = test::runTerratiles({"levels", input, "-o", output, "--levels", "4", "--block-pixels", "100"});
    REQUIRE(result.exit_code == 0);
    CHECK(result.err.find("(12 blocks of 100 px") != std::string::npos);
    std::ifstream file(std::filesystem::path(output) / "levels.json");
    const nlohmann::json summary = nlohmann::json::parse(file);
    CHECK(summary["blocks"] == 12);
    const auto& levels = summary["levels"];
    REQUIRE(levels.size() == 5);
    // The block borders' vertices of level 0 (the TIN), in every level.
    const auto onBlockBorder = [&](const std::array<double, 3>& p) {
      const double col = (p[0] - dem.origin_x) / dem.pixel_size_x - 0.5, row = (dem.origin_y - p[1]) / dem.pixel_size_y - 0.5;
      const auto onLine = [](double x) { return std::fabs(x - 100 * std::round(x / 100)) < 1e-6 && std::round(x) > 0; };
      return (onLine(col) && col < dem.width - 1.5) || (onLine(row) && row < dem.height - 1.5);
    };
    std::vector<std::array<double, 3>> border;
    std::size_t previous_triangles = 0;
    for (std::size_t l = 0; l < levels.size(); ++l) {
      CAPTURE(l);
      const std::string path = (std::filesystem::path(output) / levels[l]["file"].get<std::string>()).string();
      // Level l's budget is 0.5 m * 2^l (level 0: the TIN's own bound).
      const auto triangles = test::checkStitchedTin(path, dem, 0.5 * std::pow(2.0, static_cast<double>(l)), 0);
      CHECK(triangles.size() == levels[l]["triangles"].get<std::size_t>());
      if (l > 0) CHECK(triangles.size() < previous_triangles);
      previous_triangles = triangles.size();
      std::vector<std::array<double, 3>> positions = readTinFile(path).positions;
      std::sort(positions.begin(), positions.end());
      if (l == 0) {
        for (const auto& p : positions) {
          if (onBlockBorder(p)) border.push_back(p);
        }
        CHECK(border.size() > 100);
      }
      CHECK(std::includes(positions.begin(), positions.end(), border.begin(), border.end()));
    }
    // Blocks need a fixed number of levels.
    const auto no_levels = test::runTerratiles({"levels", input, "-o", dir / "z", "--block-pixels", "100"});
    CHECK(no_levels.exit_code == 2);
    CHECK(no_levels.err.find("--block-pixels needs --levels N") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path() / "z"));
  }
}
