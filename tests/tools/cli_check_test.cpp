// `terratiles check` on real builds: the default (boundaries merge) leaves no hole in any cut
// whose neighbours are at most one zoom apart, no T-junction where tiles of two zooms meet,
// contents agree where they overlap, every geometricError is honest; duplicate passes too;
// centroid (holes) and the grid pyramid (T-junctions) fail: the checker is not blind.
#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "src/pipeline/check_output.h"
#include "tests/test_support.h"
#include "tileset/implicit_tileset.h"

using namespace terratiles;

namespace {

CheckReport buildAndCheck(const std::string& raster, const std::vector<std::string>& options, const test::TempDir& dir,
                          const std::string& name) {
  std::vector<std::string> args{"build", test::sharedData(raster), "-o", dir / name, "-q"};
  args.insert(args.end(), options.begin(), options.end());
  const auto built = test::runTerratiles(args);
  CAPTURE(built.err);
  REQUIRE(built.exit_code == 0);
  Progress quiet(ProgressMode::Quiet);
  CheckOptions check;
  check.cuts = 300;
  const CheckReport report = checkOutput(dir / name, check, quiet);
  MESSAGE(raster << " " << name << ":\n" << describeCheck(report));
  return report;
}

// The check has no tolerance: these are exact.
void checkSeamless(const CheckReport& report) {
  CHECK(report.zooms >= 2);
  CHECK(report.cuts >= 300);
  CHECK(report.cuts_with_holes == 0);
  CHECK(report.left_out_pixels == 0);
  CHECK(report.neighbour_pairs > 0);
  CHECK(report.missing_border_vertices == 0);
  // Outline vertices touching tiles share decode to exactly one position, whatever grid
  // each zoom uses.
  CHECK(report.shared_border_vertices > 0);
  CHECK(report.shared_vertex_gaps == 0);
  CHECK(report.worst_shared_vertex_gap_m == 0);
  CHECK(report.measured_pixels > 0);
  CHECK(report.overlap_pixels > 0);
  CHECK(report.overlap_disagreements == 0);
  CHECK(report.dishonest_errors == 0);
  CHECK(report.worst_error_ratio <= 1);
  CHECK(report.error_order_violations == 0);
  CHECK(report.region_violations == 0);
  CHECK(report.content_region_violations == 0);
  CHECK(report.ok());
}

}  // namespace

TEST_SUITE("check") {
  TEST_CASE("merge tiles of four real rasters in the three schemes pass the check") {
    test::TempDir dir;
    checkSeamless(buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {}, dir, "interlaken_webmercator"));
    checkSeamless(buildAndCheck("srtm3_N57E011_4326.tif", {"--scheme", "geographic", "--tin-max-error", "5"}, dir,
                                "srtm_geographic"));
    checkSeamless(buildAndCheck("ca_on_lidar_dtm_1m_26917.tif", {"--scheme", "local", "--tin-max-error", "0.1", "--tile-triangles", "4096"}, dir,
                                "ontario_local"));
    checkSeamless(buildAndCheck("us_mn_lidar_dtm_1m_26915.tif", {"--tin-max-error", "0.1", "--tile-triangles", "4096"},
                                dir, "minnesota_webmercator"));
  }

  TEST_CASE("duplicate passes the check, centroid leaves holes, the grid pyramid has T-junctions") {
    test::TempDir dir;
    checkSeamless(buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--assign", "duplicate"}, dir, "duplicate"));
    const CheckReport centroid = buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--assign", "centroid"}, dir, "centroid");
    CHECK(centroid.cuts_with_holes > 0);
    CHECK_FALSE(centroid.ok());
    // The CLI says so with exit code 5.
    const auto cli = test::runTerratiles({"check", dir / "centroid", "--cuts", "50"});
    CHECK(cli.exit_code == 5);
    CHECK(cli.out.find("terratiles check: FAILED") != std::string::npos);
    // The grid pyramid's T-junctions between zooms are missing border vertices.
    const CheckReport grid = buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--lod", "grid"}, dir, "grid");
    CHECK(grid.neighbour_pairs > 0);
    CHECK(grid.missing_border_vertices > 0);
    CHECK_FALSE(grid.ok());
    const auto not_an_output = test::runTerratiles({"check", dir.path().string()});
    CHECK(not_an_output.exit_code == 3);
    CHECK(not_an_output.err.find("tileset.json cannot be read") != std::string::npos);
  }
}

TEST_SUITE("check") {
  TEST_CASE("implicit tiling keeps the explicit tree's tiles, errors and contents, and passes the check") {
    test::TempDir dir;
    const std::string input = test::sharedData("srtm3_N57E011_4326.tif");
    const std::vector<std::string> common{"--scheme", "geographic", "--tin-max-error", "5", "-q"};
    std::vector<std::string> explicit_args{"build", input, "-o", dir / "explicit"};
    explicit_args.insert(explicit_args.end(), common.begin(), common.end());
    REQUIRE(test::runTerratiles(explicit_args).exit_code == 0);
    std::vector<std::string> implicit_args{"build", input, "-o", dir / "implicit", "--implicit"};
    implicit_args.insert(implicit_args.end(), common.begin(), common.end());
    const auto built = test::runTerratiles(implicit_args);
    CAPTURE(built.err);
    REQUIRE(built.exit_code == 0);

    const auto readJson = [](const std::string& path) {
      std::ifstream in(path);
      return nlohmann::json::parse(in);
    };
    const nlohmann::json tileset = readJson(dir / "implicit/tileset.json");
    CHECK(tileset["asset"]["version"] == "1.1");
    // The root frames the data (what a viewer zooms to), the implicit root below it is the
    // east zoom-0 square (N57E011 lies in it only).
    const nlohmann::json build_facts = readJson(dir / "implicit/build.json");
    CHECK_FALSE(tileset["root"].contains("implicitTiling"));
    CHECK(tileset["root"]["boundingVolume"] == build_facts["explicit_tileset"]["root"]["boundingVolume"]);
    REQUIRE(tileset["root"]["children"].size() == 1);
    const nlohmann::json& root = tileset["root"]["children"][0];
    REQUIRE(root.contains("implicitTiling"));
    CHECK(root["boundingVolume"]["region"][0] == 0.0);
    CHECK(root["boundingVolume"]["region"][2] == std::numbers::pi);
    CHECK(root["implicitTiling"]["subdivisionScheme"] == "QUADTREE");
    CHECK(root["content"]["uri"] == "tiles/east/{level}/{x}/{y}.glb");
    // Every tile's measured error travels as tile metadata (CesiumJS would halve the root's).
    bool has_error_semantic = false;
    for (const auto& [name, property] : tileset["schema"]["classes"]["tile"]["properties"].items()) {
      has_error_semantic |= property.value("semantic", "") == "TILE_GEOMETRIC_ERROR";
    }
    CHECK(has_error_semantic);
    CHECK(std::filesystem::exists(dir / "implicit/subtrees/east/0/0/0.subtree"));

    // The same tiles with the same errors as the explicit build, each content on disk under
    // its implicit name and byte for byte the explicit one.
    std::map<std::string, std::pair<double, std::string>> explicit_tiles, implicit_tiles;
    std::function<void(const nlohmann::json&, std::map<std::string, std::pair<double, std::string>>&)> collect =
        [&](const nlohmann::json& node, std::map<std::string, std::pair<double, std::string>>& out) {
          if (node.contains("content")) {
            const std::string uri = node["content"]["uri"];
            TileKey key;
            REQUIRE(tileKeyFromContentUri(uri, key));
            out[key.path()] = {node["geometricError"].get<double>(), uri};
          }
          for (const auto& child : node.value("children", nlohmann::json::array())) collect(child, out);
        };
    collect(readJson(dir / "explicit/tileset.json")["root"], explicit_tiles);
    collect(readJson(dir / "implicit/build.json")["explicit_tileset"]["root"], implicit_tiles);
    REQUIRE(explicit_tiles.size() >= 4);
    REQUIRE(implicit_tiles.size() == explicit_tiles.size());
    for (const auto& [key, value] : explicit_tiles) {
      CAPTURE(key);
      REQUIRE(implicit_tiles.count(key) == 1);
      CHECK(implicit_tiles[key].first == value.first);
      const auto bytes = [](const std::string& path) {
        std::ifstream in(path, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), {});
      };
      CHECK(bytes(dir / ("implicit/" + implicit_tiles[key].second)) == bytes(dir / ("explicit/" + value.second)));
    }

    Progress quiet(ProgressMode::Quiet);
    CheckOptions check;
    check.cuts = 100;
    const CheckReport report = checkOutput(dir / "implicit", check, quiet);
    MESSAGE(describeCheck(report));
    CHECK(report.tiles == explicit_tiles.size());
    CHECK(report.ok());
    const test::GltfValidation gltf = test::validateGltfTree(dir / "implicit");
    REQUIRE(gltf.ran);
    CHECK(gltf.files == static_cast<int>(explicit_tiles.size()));
    CHECK(gltf.errors == 0);

    // Web mercator's rows do not halve a region: implicit tiling is refused, clearly.
    const auto refused = test::runTerratiles({"build", input, "-o", dir / "refused", "--implicit", "-q"});
    CHECK(refused.exit_code == 2);
    CHECK(refused.err.find("--scheme geographic") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir / "refused"));
  }
}
