// Integration tests: `terratiles build` in-process on the real rasters in ../shared/data,
// then everything asserted on the written output: tileset.json structure, decoded GLBs,
// placement on the globe, and the Khronos glTF validator.
#include <doctest/doctest.h>

#include <GeographicLib/Geocentric.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>

#include "formats/dem/read_dem.h"
#include "formats/gltf/read_glb.h"
#include "tests/test_support.h"

using namespace terratiles;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

struct TreeStats {
  std::size_t tiles = 0;
  std::size_t contents = 0;
  int depth = 0;
};

// Checks one tile and its subtree; returns the decoded content's height range via stats.
void checkTile(const json& tile, const fs::path& root_dir, double parent_error, int depth,
               const json* parent_region, TreeStats& stats, double min_h, double max_h) {
  ++stats.tiles;
  stats.depth = std::max(stats.depth, depth);
  const double error = tile.at("geometricError").get<double>();
  CHECK(error >= 0);
  CHECK(error <= parent_error);  // geometricError decreases towards the leaves
  const json& region = tile.at("boundingVolume").at("region");
  REQUIRE(region.size() == 6);
  CHECK(region[0].get<double>() <= region[2].get<double>());
  CHECK(region[1].get<double>() <= region[3].get<double>());
  CHECK(region[4].get<double>() <= region[5].get<double>());
  if (parent_region) {  // parents contain their children
    CHECK((*parent_region)[0].get<double>() <= region[0].get<double>());
    CHECK((*parent_region)[1].get<double>() <= region[1].get<double>());
    CHECK((*parent_region)[2].get<double>() >= region[2].get<double>());
    CHECK((*parent_region)[3].get<double>() >= region[3].get<double>());
    CHECK((*parent_region)[4].get<double>() <= region[4].get<double>());
    CHECK((*parent_region)[5].get<double>() >= region[5].get<double>());
  }
  if (tile.contains("content")) {
    ++stats.contents;
    const fs::path glb = root_dir / tile["content"]["uri"].get<std::string>();
    REQUIRE(fs::exists(glb));
    const DecodedGlb decoded = readGlbFile(glb.string());
    CHECK(decoded.draco);
    REQUIRE(decoded.mesh.triangle_indices.size() >= 3);
    // Every decoded vertex lies inside the tile's region (content overlaps are allowed by
    // 3D Tiles, but our region is computed from this very content) and within the DEM's
    // height range, to the quantisation step.
    const auto& earth = GeographicLib::Geocentric::WGS84();
    const double tolerance_m = 0.02, tolerance_rad = 1e-8;
    for (std::size_t v = 0; v < decoded.mesh.vertexCount(); ++v) {
      const double gx = decoded.mesh.translation[0] + decoded.mesh.positions[3 * v];
      const double gy = decoded.mesh.translation[1] + decoded.mesh.positions[3 * v + 1];
      const double gz = decoded.mesh.translation[2] + decoded.mesh.positions[3 * v + 2];
      double lat, lon, h;
      earth.Reverse(gx, -gz, gy, lat, lon, h);  // glTF y-up back to ECEF z-up
      REQUIRE(lon / kRadToDeg >= region[0].get<double>() - tolerance_rad);
      REQUIRE(lon / kRadToDeg <= region[2].get<double>() + tolerance_rad);
      REQUIRE(lat / kRadToDeg >= region[1].get<double>() - tolerance_rad);
      REQUIRE(lat / kRadToDeg <= region[3].get<double>() + tolerance_rad);
      REQUIRE(h >= min_h - tolerance_m);
      REQUIRE(h <= max_h + tolerance_m);
    }
  }
  if (tile.contains("children")) {
    for (const json& child : tile["children"]) {
      checkTile(child, root_dir, error, depth + 1, &region, stats, min_h, max_h);
    }
  }
}

struct BuiltTileset {
  json tileset;
  TreeStats stats;
};

BuiltTileset buildAndCheck(const std::vector<std::string>& inputs, const fs::path& out) {
  std::vector<std::string> args{"build"};
  args.insert(args.end(), inputs.begin(), inputs.end());
  args.insert(args.end(), {"-o", out.string(), "--progress", "none"});
  const auto result = test::runTerratiles(args);
  CAPTURE(result.err);
  REQUIRE(result.exit_code == 0);
  CHECK(result.err.find("terratiles: built") != std::string::npos);

  BuiltTileset built;
  std::ifstream in(out / "tileset.json");
  built.tileset = json::parse(in);
  CHECK(built.tileset["asset"]["version"] == "1.1");
  CHECK(built.tileset["root"]["refine"] == "REPLACE");
  const DemGrid dem = readDem(inputs);
  const DemStatistics dem_stats = computeStatistics(dem);
  checkTile(built.tileset["root"], out, built.tileset["geometricError"].get<double>(), 0, nullptr,
            built.stats, dem_stats.min_height_m, dem_stats.max_height_m);
  // Every GLB on disk is referenced, and no temporary file is left.
  std::size_t glb_files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(out)) {
    CHECK(entry.path().extension() != ".tmp");
    if (entry.path().extension() == ".glb") ++glb_files;
  }
  CHECK(glb_files == built.stats.contents);

  const test::GltfValidation validation = test::validateGltfTree(out.string());
  CAPTURE(validation.report);
  REQUIRE_MESSAGE(validation.ran, "the glTF validator did not run: run the README test set-up");
  CHECK(validation.files == static_cast<int>(glb_files));
  CHECK(validation.errors == 0);
  return built;
}

void checkRootCentre(const json& tileset, double lat_deg, double lon_deg, double tolerance_deg) {
  const json& region = tileset["root"]["boundingVolume"]["region"];
  const double lon = (region[0].get<double>() + region[2].get<double>()) / 2 * kRadToDeg;
  const double lat = (region[1].get<double>() + region[3].get<double>()) / 2 * kRadToDeg;
  CHECK(std::fabs(lat - lat_deg) < tolerance_deg);
  CHECK(std::fabs(lon - lon_deg) < tolerance_deg);
}

}  // namespace

TEST_SUITE("integration") {
  TEST_CASE("the Interlaken DHM25 tile becomes a valid tileset at its place in Switzerland") {
    test::TempDir dir;
    const BuiltTileset built =
        buildAndCheck({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")}, dir.path() / "out");
    checkRootCentre(built.tileset, 46.707, 7.872, 0.01);
    CHECK(built.stats.depth == 2);  // 349 cells, 128 per tile: zooms 0..2
    CHECK(built.stats.contents >= 1 + 2 + 6);
  }

  TEST_CASE("the two Delft AHN3 tiles become one tileset as a mosaic") {
    test::TempDir dir;
    const BuiltTileset built = buildAndCheck(
        {test::sharedData("nl_ahn3_delft_tiles/delft_west_0.5m_28992.tif"),
         test::sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif")},
        dir.path() / "out");
    checkRootCentre(built.tileset, 52.0, 4.36, 0.05);
  }

  TEST_CASE("the SRTM N57E011 tile in EPSG 4326 becomes a valid tileset near Gothenburg") {
    test::TempDir dir;
    const BuiltTileset built =
        buildAndCheck({test::sharedData("srtm3_N57E011_4326.tif")}, dir.path() / "out");
    checkRootCentre(built.tileset, 57.5, 11.5, 0.01);
  }

  TEST_CASE("force replaces a previous output and the result is the same") {
    test::TempDir dir;
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    const std::string out = dir / "out";
    REQUIRE(test::runTerratiles({"build", input, "-o", out, "-q"}).exit_code == 0);
    std::ifstream first_in(out + "/tileset.json");
    const std::string first((std::istreambuf_iterator<char>(first_in)), std::istreambuf_iterator<char>());
    const auto again = test::runTerratiles({"build", input, "-o", out, "-q"});
    CHECK(again.exit_code == 4);
    const auto forced = test::runTerratiles({"build", input, "-o", out, "-q", "--force"});
    CHECK(forced.exit_code == 0);
    CHECK(forced.err.empty());  // -q: nothing on stderr
    std::ifstream second_in(out + "/tileset.json");
    const std::string second((std::istreambuf_iterator<char>(second_in)), std::istreambuf_iterator<char>());
    CHECK(first == second);  // deterministic
  }
}
