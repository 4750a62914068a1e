// Integration tests: `terratiles build` in-process on the real rasters in ../shared/data,
// then everything asserted on the written output: tileset.json structure, decoded GLBs,
// placement on the globe, and the Khronos glTF validator.
#include <doctest/doctest.h>

#include <GeographicLib/Geocentric.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
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
// The DEM's orthometric height range, and the geoid the build used (nullptr: heights were
// written as ellipsoidal).
struct HeightCheck {
  double min_m = 0;
  double max_m = 0;
  const GeoidGrid* geoid = nullptr;
};

void checkTile(const json& tile, const fs::path& root_dir, double parent_error, int depth,
               const json* parent_region, TreeStats& stats, const HeightCheck& heights) {
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
    // 3D Tiles, but our region is computed from this very content) and, once the geoid
    // undulation is taken off again, within the DEM's height range, to the quantisation step.
    const auto& earth = GeographicLib::Geocentric::WGS84();
    // Regions are grown by the quantisation step, so decoded content lies inside them; the
    // tolerance only absorbs the float arithmetic of this check.
    const double tolerance_m = 1e-3, tolerance_rad = 1e-10;
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
      REQUIRE(h >= region[4].get<double>() - tolerance_m);
      REQUIRE(h <= region[5].get<double>() + tolerance_m);
      if (heights.geoid) h -= heights.geoid->undulationAt(lon, lat).value();
      // Within the DEM's heights to the quantisation error (sqrt(3)/2 of the widest step used
      // here, 1/8 m for SRTM's 100 km root tile, wider than 2^20 steps of 1/128 m) and to the
      // tile's error: simplification may place a vertex off the DEM's pixels, within budget.
      REQUIRE(h >= heights.min_m - 0.11 - error);
      REQUIRE(h <= heights.max_m + 0.11 + error);
    }
  }
  if (tile.contains("children")) {
    for (const json& child : tile["children"]) {
      checkTile(child, root_dir, error, depth + 1, &region, stats, heights);
    }
  }
}

struct BuiltTileset {
  json tileset;
  TreeStats stats;
};

BuiltTileset buildAndCheck(const std::vector<std::string>& inputs, const fs::path& out,
                          const std::vector<std::string>& options = {}) {
  std::vector<std::string> args{"build"};
  args.insert(args.end(), inputs.begin(), inputs.end());
  args.insert(args.end(), {"-o", out.string(), "--progress", "none"});
  args.insert(args.end(), options.begin(), options.end());
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
  const bool ellipsoidal = std::find(options.begin(), options.end(), "ellipsoidal") != options.end();
  const auto geoid_option = std::find(options.begin(), options.end(), "--geoid");
  const GeoidGrid geoid = readGeoidGrid(geoid_option != options.end() ? *(geoid_option + 1)
                                                                      : std::string(kDefaultGeoidPath));
  const HeightCheck heights{dem_stats.min_height_m, dem_stats.max_height_m,
                            ellipsoidal ? nullptr : &geoid};
  checkTile(built.tileset["root"], out, built.tileset["geometricError"].get<double>(), 0, nullptr,
            built.stats, heights);
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
    // 95,099 triangles at 0.5 m, about 16,384 per finest tile: webmercator zoom 13 (8 tiles)
    // and zoom 12 (3 tiles), under a content-less common ancestor.
    CHECK(built.stats.depth >= 2);
    CHECK(built.stats.contents >= 3 + 8);
  }

  TEST_CASE("the native simplifier builds Interlaken into a valid tileset that terratiles check passes") {
    test::TempDir dir;
    const std::string chgeo = test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif");
    const fs::path out = dir.path() / "native";
    const BuiltTileset built = buildAndCheck({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")}, out,
                                             {"--simplifier", "native", "--geoid", chgeo});
    CHECK(built.stats.contents >= 3 + 8);
    // The independent check: every tile within its geometricError of the DEM as drawn, no
    // cracks, shared vertices bit for bit.
    const auto check = test::runTerratiles({"check", out.string(), "--progress", "none"});
    CAPTURE(check.err);
    CHECK(check.exit_code == 0);
  }

  TEST_CASE("the geoid lifts Swiss LN02 heights by the undulation and CHGeo2004 can replace EGM96") {
    test::TempDir dir;
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    const std::string chgeo = test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif");
    const BuiltTileset plain = buildAndCheck({input}, dir.path() / "ellipsoidal", {"--heights", "ellipsoidal"});
    const BuiltTileset egm96 = buildAndCheck({input}, dir.path() / "egm96");
    const BuiltTileset swiss = buildAndCheck({input}, dir.path() / "chgeo", {"--geoid", chgeo});
    auto lowest = [](const BuiltTileset& b) { return b.tileset["root"]["boundingVolume"]["region"][4].get<double>(); };
    // Geoid undulation near Interlaken: CHGeo2004 about 49.5-50.5 m, EGM96 within 3 m of it.
    CHECK(lowest(swiss) - lowest(plain) > 49.0);
    CHECK(lowest(swiss) - lowest(plain) < 51.5);
    CHECK(std::fabs(lowest(egm96) - lowest(swiss)) < 3.0);
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

  TEST_CASE("build writes byte-identical tiles and tileset.json with one and two threads") {
    test::TempDir dir;
    const std::string input = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    // The report holds stage times, so it is left out; 2 m keeps the builds short.
    auto build = [&](const std::string& threads) {
      const std::string out = dir / ("threads_" + threads);
      const auto result = test::runTerratiles(
          {"build", input, "-o", out, "-q", "--no-report", "--tin-max-error", "2", "--threads", threads});
      CAPTURE(result.err);
      REQUIRE(result.exit_code == 0);
      std::map<std::string, std::string> files;  // relative path -> bytes
      for (const auto& entry : fs::recursive_directory_iterator(out)) {
        if (!entry.is_regular_file()) continue;
        std::ifstream in(entry.path(), std::ios::binary);
        files[fs::relative(entry.path(), out).string()] =
            std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      }
      return files;
    };
    const auto one = build("1");
    const auto two = build("2");
    CHECK(one.count("tileset.json") == 1);
    CHECK(one.size() > 3);
    REQUIRE(one.size() == two.size());
    for (const auto& [path, bytes] : one) {
      CAPTURE(path);
      REQUIRE(two.count(path) == 1);
      CHECK(two.at(path) == bytes);
    }
  }
}
