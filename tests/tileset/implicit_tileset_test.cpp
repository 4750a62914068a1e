#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <map>
#include <numbers>
#include <set>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>

#include "src/base/error.h"
#include "tests/test_support.h"
#include "tileset/implicit_tileset.h"

using namespace terratiles;
using test::decodeSubtree;
using test::float64At;
using test::Subtree;
using test::viewBytes;

namespace {

constexpr double kPi = std::numbers::pi;

// ---- Building explicit trees ---------------------------------------------------------------

// A node of the geographic tile `key`: its square in radians grown by 3 % on every side (as
// content regions overlap their neighbours), heights and error distinct per tile.
TileNode makeNode(TileKey key, bool with_content) {
  const double size_deg = 180.0 / (1 << key.zoom);
  const double west_deg = -180.0 + key.x * size_deg;
  const double north_deg = 90.0 - key.y * size_deg;
  const double grow_deg = 0.03 * size_deg;
  constexpr double kRad = kPi / 180;
  TileNode node;
  node.key = key;
  node.region.include((west_deg - grow_deg) * kRad, (north_deg - size_deg - grow_deg) * kRad,
                      -20.0 - key.zoom - 0.5 * key.x);
  node.region.include((west_deg + size_deg + grow_deg) * kRad, (north_deg + grow_deg) * kRad,
                      900.0 + 3 * key.zoom + 0.25 * key.y);
  node.geometric_error_m = 640.0 / (1 << key.zoom) + 0.01 * key.x + 0.001 * key.y;
  if (with_content) node.content_uri = "tiles/" + key.path() + ".glb";
  return node;
}

// Content-less tiles get the tileset's error, as the pipeline gives them.
void setContentlessErrors(TileNode& node, double tileset_error_m) {
  if (node.content_uri.empty()) node.geometric_error_m = tileset_error_m;
  for (TileNode& child : node.children) setContentlessErrors(child, tileset_error_m);
}

Tileset finish(TileNode root) {
  Tileset tileset;
  tileset.generator = "terratiles test";
  tileset.geometric_error_m = 5000;
  tileset.root = std::move(root);
  finalizeTree(tileset.root);
  setContentlessErrors(tileset.root, tileset.geometric_error_m);
  return tileset;
}

// East hemisphere, around N57 E11 (the SRTM sample): a content-less root 1/2/0, content at
// zooms 2-4 with a sparse zoom 4.
Tileset eastTileset() {
  TileNode z3a = makeNode({3, 8, 0}, true);
  TileNode z3b = makeNode({3, 8, 1}, true);
  for (const TileKey key : {TileKey{4, 16, 2}, TileKey{4, 17, 2}, TileKey{4, 16, 3},
                            TileKey{4, 17, 3}}) {
    z3b.children.push_back(makeNode(key, true));
  }
  TileNode z3c = makeNode({3, 9, 1}, true);
  z3c.children.push_back(makeNode({4, 18, 3}, true));
  TileNode z2 = makeNode({2, 4, 0}, true);
  z2.children = {z3a, z3b, z3c};
  TileNode root = makeNode({1, 2, 0}, false);
  root.children = {z2};
  return finish(root);
}

// Both zoom-0 tiles: a content-less zoom -1 root over a content-less west tile (content
// from zoom 1) and an east tile with content.
Tileset bothHemispheresTileset() {
  TileNode west_z1 = makeNode({1, 1, 0}, true);
  west_z1.children = {makeNode({2, 2, 0}, true), makeNode({2, 3, 1}, true)};
  TileNode west = makeNode({0, 0, 0}, false);
  west.children = {west_z1};
  TileNode east_z1 = makeNode({1, 2, 1}, true);
  east_z1.children = {makeNode({2, 5, 2}, true)};
  TileNode east = makeNode({0, 1, 0}, true);
  east.children = {east_z1};
  TileNode root;
  root.key = {-1, 0, 0};
  root.children = {west, east};
  return finish(root);
}

// ---- What the explicit tree says, in implicit coordinates ---------------------------------

struct TileValues {
  bool content = false;
  double geometric_error_m = 0;
  std::array<double, 6> region{};
  friend bool operator==(const TileValues&, const TileValues&) = default;
};
// (hemisphere name, level, x from the west in the hemisphere, y from the south)
using TileCoordinates = std::tuple<std::string, int, std::int64_t, std::int64_t>;
using TileMap = std::map<TileCoordinates, TileValues>;

std::array<double, 6> regionArray(const Region& r) {
  return {r.west_rad, r.south_rad, r.east_rad, r.north_rad, r.min_height_m, r.max_height_m};
}

TileCoordinates coordinatesOf(TileKey key) {
  const std::int64_t rows = std::int64_t{1} << key.zoom;
  const int hemisphere = key.x >= rows ? 1 : 0;
  return {hemisphere == 0 ? "west" : "east", key.zoom, key.x - hemisphere * rows,
          rows - 1 - key.y};
}

void expectedTiles(const TileNode& node, TileMap& out) {
  if (node.key.zoom >= 0) {
    out[coordinatesOf(node.key)] = {!node.content_uri.empty(), node.geometric_error_m,
                                    regionArray(node.region)};
  }
  for (const TileNode& child : node.children) expectedTiles(child, out);
}

// ---- Reading the output back, independently of the writer ----------------------------------

const std::vector<std::uint8_t>& fileBytes(const std::vector<ImplicitFile>& files,
                                           const std::string& path) {
  for (const ImplicitFile& file : files) {
    if (file.path == path) return file.bytes;
  }
  FAIL("no file " << path);
  static const std::vector<std::uint8_t> kNone;
  return kNone;
}

bool hasFile(const std::vector<ImplicitFile>& files, const std::string& path) {
  for (const ImplicitFile& file : files) {
    if (file.path == path) return true;
  }
  return false;
}

nlohmann::json tilesetJson(const std::vector<ImplicitFile>& files) {
  REQUIRE(!files.empty());
  REQUIRE(files[0].path == "tileset.json");
  return nlohmann::json::parse(std::string(files[0].bytes.begin(), files[0].bytes.end()));
}

// Every tile of one hemisphere, read by walking its subtrees (test::readImplicitTiles).
TileMap decodeHemisphere(const std::vector<ImplicitFile>& files, const std::string& hemisphere,
                         int subtree_levels, std::set<std::string>& read) {
  const std::map<std::string, std::size_t> components{{"geometricError", 1}, {"boundingRegion", 6}};
  const test::ImplicitTiles decoded = test::readImplicitTiles(
      [&](const std::string& path) {
        REQUIRE(hasFile(files, path));
        return fileBytes(files, path);
      },
      hemisphere, subtree_levels, components, read);
  TileMap tiles;
  for (const auto& [c, tile] : decoded) {
    TileValues values;
    values.content = tile.content;
    values.geometric_error_m = tile.properties.at("geometricError").at(0);
    for (std::size_t i = 0; i < 6; ++i) values.region[i] = tile.properties.at("boundingRegion").at(i);
    tiles.emplace(TileCoordinates{hemisphere, c.level, c.x, c.y}, values);
  }
  return tiles;
}

void checkTileMaps(const TileMap& decoded, const TileMap& expected) {
  CHECK(decoded.size() == expected.size());
  for (const auto& [coordinates, values] : expected) {
    const auto& [hemisphere, level, x, y] = coordinates;
    INFO(hemisphere << " level " << level << " x " << x << " y " << y);
    const auto found = decoded.find(coordinates);
    REQUIRE(found != decoded.end());
    CHECK(found->second.content == values.content);
    CHECK(found->second.geometric_error_m == values.geometric_error_m);
    CHECK(found->second.region == values.region);
  }
  for (const auto& [coordinates, values] : decoded) {
    const auto& [hemisphere, level, x, y] = coordinates;
    INFO(hemisphere << " level " << level << " x " << x << " y " << y);
    CHECK(expected.count(coordinates) == 1);
  }
}

void checkImplicitRoot(const nlohmann::json& tile, const std::string& hemisphere,
                       int subtree_levels, int available_levels, double west_rad,
                       const TileValues& root_values, const TileMap& tiles) {
  double min_height_m = root_values.region[4];
  double max_height_m = root_values.region[5];
  for (const auto& [coordinates, values] : tiles) {
    if (std::get<0>(coordinates) != hemisphere) continue;
    min_height_m = std::min(min_height_m, values.region[4]);
    max_height_m = std::max(max_height_m, values.region[5]);
  }
  CHECK(tile["boundingVolume"]["region"] ==
        nlohmann::json::array({west_rad, -kPi / 2, west_rad + kPi, kPi / 2, min_height_m,
                               max_height_m}));
  CHECK(tile["geometricError"] == root_values.geometric_error_m);
  CHECK_FALSE(tile.contains("children"));
  CHECK_FALSE(tile.contains("metadata"));
  CHECK(tile["content"]["uri"] == "tiles/" + hemisphere + "/{level}/{x}/{y}.glb");
  const nlohmann::json& implicit = tile["implicitTiling"];
  CHECK(implicit["subdivisionScheme"] == "QUADTREE");
  CHECK(implicit["subtreeLevels"] == subtree_levels);
  CHECK(implicit["availableLevels"] == available_levels);
  CHECK(implicit["subtrees"]["uri"] == "subtrees/" + hemisphere + "/{level}/{x}/{y}.subtree");
}

void checkSchema(const nlohmann::json& tileset) {
  CHECK(tileset["asset"]["version"] == "1.1");
  const nlohmann::json& properties = tileset["schema"]["classes"]["tile"]["properties"];
  CHECK(properties["geometricError"]["semantic"] == "TILE_GEOMETRIC_ERROR");
  CHECK(properties["geometricError"]["type"] == "SCALAR");
  CHECK(properties["geometricError"]["componentType"] == "FLOAT64");
  CHECK(properties["boundingRegion"]["semantic"] == "TILE_BOUNDING_REGION");
  CHECK(properties["boundingRegion"]["type"] == "SCALAR");
  CHECK(properties["boundingRegion"]["componentType"] == "FLOAT64");
  CHECK(properties["boundingRegion"]["array"] == true);
  CHECK(properties["boundingRegion"]["count"] == 6);
}

std::set<std::string> subtreePaths(const std::vector<ImplicitFile>& files) {
  std::set<std::string> paths;
  for (std::size_t i = 1; i < files.size(); ++i) paths.insert(files[i].path);
  CHECK(paths.size() == files.size() - 1);
  return paths;
}

}  // namespace

TEST_SUITE("tileset") {
  TEST_CASE("implicit coordinates count columns within the hemisphere and rows from the south") {
    CHECK(implicitTileCoordinates({0, 0, 0}) == ImplicitTileCoordinates{0, 0, 0, 0});
    CHECK(implicitTileCoordinates({0, 1, 0}) == ImplicitTileCoordinates{1, 0, 0, 0});
    // Zoom 2 has 8 x 4 tiles: column 5 is the east hemisphere's second, row 1 from the north
    // is row 2 from the south.
    CHECK(implicitTileCoordinates({2, 5, 1}) == ImplicitTileCoordinates{1, 2, 1, 2});
    CHECK(implicitTileCoordinates({3, 3, 0}) == ImplicitTileCoordinates{0, 3, 3, 7});
    CHECK(implicitTileCoordinates({3, 15, 7}) == ImplicitTileCoordinates{1, 3, 7, 0});
    CHECK(implicitContentUri({2, 5, 1}) == "tiles/east/2/1/2.glb");
    CHECK(implicitContentUri({3, 3, 0}) == "tiles/west/3/3/7.glb");
    for (const TileKey key : {TileKey{1, 4, 0}, TileKey{1, 0, 2}, TileKey{-1, 0, 0},
                              TileKey{2, -1, 0}}) {
      INFO(key.path());
      try {
        (void)implicitContentUri(key);
        FAIL("no error");
      } catch (const Error& error) {
        CHECK(error.code() == ErrorCode::Usage);
        CHECK(std::string(error.what()).find("outside the geographic grid") != std::string::npos);
      }
    }
  }

  TEST_CASE("implicit subtree bits and metadata sit where the spec puts them") {
    // 0/1/0 (content) -> 1/3/0 (none) -> 2/6/1 (content), one subtree of 3 levels (21 bits).
    // 1/3/0 is (x 1, y 1): Morton 3, bit 1 + 3 = 4. 2/6/1 is (x 2, y 2): Morton 0b1100 = 12,
    // bit 5 + 12 = 17.
    TileNode z2 = makeNode({2, 6, 1}, true);
    TileNode z1 = makeNode({1, 3, 0}, false);
    z1.children = {z2};
    TileNode z0 = makeNode({0, 1, 0}, true);
    z0.children = {z1};
    const Tileset tileset = finish(z0);
    const std::vector<ImplicitFile> files = writeImplicitTileset(tileset, 3);
    REQUIRE(files.size() == 2);
    CHECK(files[1].path == "subtrees/east/0/0/0.subtree");
    const Subtree subtree = decodeSubtree(files[1].bytes);
    const nlohmann::json& json = subtree.json;
    const auto tiles = viewBytes(subtree, json["tileAvailability"]["bitstream"]);
    CHECK(std::vector<std::uint8_t>(tiles.begin(), tiles.end()) ==
          std::vector<std::uint8_t>{0x11, 0x00, 0x02});
    CHECK(json["tileAvailability"]["availableCount"] == 3);
    const auto contents = viewBytes(subtree, json["contentAvailability"][0]["bitstream"]);
    CHECK(std::vector<std::uint8_t>(contents.begin(), contents.end()) ==
          std::vector<std::uint8_t>{0x01, 0x00, 0x02});
    CHECK(json["childSubtreeAvailability"] == nlohmann::json{{"constant", 0}});
    const std::size_t errors = json["propertyTables"][0]["properties"]["geometricError"]["values"];
    CHECK(float64At(subtree, errors, 0) == tileset.root.geometric_error_m);
    CHECK(float64At(subtree, errors, 1) == 5000.0);  // content-less: the tileset's error
    CHECK(float64At(subtree, errors, 2) == tileset.root.children[0].children[0].geometric_error_m);
    const std::size_t regions = json["propertyTables"][0]["properties"]["boundingRegion"]["values"];
    CHECK(float64At(subtree, regions, 12) ==
          tileset.root.children[0].children[0].region.west_rad);
    CHECK(float64At(subtree, regions, 17) ==
          tileset.root.children[0].children[0].region.max_height_m);
  }

  TEST_CASE("implicit east hemisphere tree keeps every tile with its error and region") {
    const Tileset tileset = eastTileset();
    TileMap expected;
    expectedTiles(tileset.root, expected);
    // The zoom-0 ancestor the explicit tree lacks: available, content-less, the root's region.
    const TileValues zoom0{false, 5000.0, regionArray(tileset.root.region)};
    expected[{"east", 0, 0, 0}] = zoom0;
    REQUIRE(expected.size() == 11);
    // Subtree files for 1, 2, 3 and 6 levels: every tile; 0-1, 2-3 and each zoom-4 tile;
    // 0-2 and each zoom-3 tile; one.
    const std::map<int, std::size_t> subtree_counts{{1, 11}, {2, 7}, {3, 4}, {6, 1}};
    for (const auto& [levels, count] : subtree_counts) {
      INFO("subtree levels " << levels);
      const std::vector<ImplicitFile> files = writeImplicitTileset(tileset, levels);
      const nlohmann::json json = tilesetJson(files);
      checkSchema(json);
      CHECK(json["geometricError"] == 5000.0);
      // An explicit root framing the data (what viewers zoom to) above the implicit root.
      CHECK(json["root"]["refine"] == "REPLACE");
      CHECK_FALSE(json["root"].contains("implicitTiling"));
      CHECK(json["root"]["boundingVolume"]["region"] == regionArray(tileset.root.region));
      CHECK(json["root"]["geometricError"] == 5000.0);
      REQUIRE(json["root"]["children"].size() == 1);
      checkImplicitRoot(json["root"]["children"][0], "east", levels, 5, 0.0, zoom0, expected);
      std::set<std::string> read;
      checkTileMaps(decodeHemisphere(files, "east", levels, read), expected);
      CHECK(read == subtreePaths(files));
      CHECK(read.size() == count);
    }
  }

  TEST_CASE("implicit ancestors above a root with content draw nothing at the tileset's error") {
    Tileset tileset = eastTileset();
    tileset.root = TileNode(tileset.root.children[0]);  // 2/4/0, with content
    // A zoom-4 tile reaching lower than its parent's region: the implicit root's heights
    // still span it.
    tileset.root.children[1].children[2].region.min_height_m = -500;
    TileMap expected;
    expectedTiles(tileset.root, expected);
    const TileValues ancestor{false, 5000.0, regionArray(tileset.root.region)};
    expected[{"east", 0, 0, 0}] = ancestor;
    expected[{"east", 1, 0, 1}] = ancestor;
    REQUIRE(expected.size() == 11);
    REQUIRE(tileset.root.geometric_error_m < 5000.0);
    const std::vector<ImplicitFile> files = writeImplicitTileset(tileset, 2);
    const nlohmann::json json = tilesetJson(files);
    REQUIRE(json["root"]["children"].size() == 1);
    checkImplicitRoot(json["root"]["children"][0], "east", 2, 5, 0.0, ancestor, expected);
    CHECK(json["root"]["children"][0]["boundingVolume"]["region"][4] == -500.0);
    std::set<std::string> read;
    checkTileMaps(decodeHemisphere(files, "east", 2, read), expected);
    CHECK(read == subtreePaths(files));
  }

  TEST_CASE("implicit output with data in both hemispheres has an explicit root over two") {
    const Tileset tileset = bothHemispheresTileset();
    TileMap expected;
    expectedTiles(tileset.root, expected);
    REQUIRE(expected.size() == 7);
    for (const int levels : {1, 2, 6}) {
      INFO("subtree levels " << levels);
      const std::vector<ImplicitFile> files = writeImplicitTileset(tileset, levels);
      const nlohmann::json json = tilesetJson(files);
      checkSchema(json);
      const nlohmann::json& root = json["root"];
      CHECK_FALSE(root.contains("implicitTiling"));
      CHECK_FALSE(root.contains("content"));
      CHECK(root["refine"] == "REPLACE");
      CHECK(root["geometricError"] == std::max(tileset.geometric_error_m, tileset.root.geometric_error_m));
      CHECK(root["boundingVolume"]["region"] == regionArray(tileset.root.region));
      REQUIRE(root["children"].size() == 2);
      checkImplicitRoot(root["children"][0], "west", levels, 3, -kPi,
                        expected.at({"west", 0, 0, 0}), expected);
      checkImplicitRoot(root["children"][1], "east", levels, 3, 0.0,
                        expected.at({"east", 0, 0, 0}), expected);
      std::set<std::string> read;
      TileMap decoded = decodeHemisphere(files, "west", levels, read);
      decoded.merge(decodeHemisphere(files, "east", levels, read));
      checkTileMaps(decoded, expected);
      CHECK(read == subtreePaths(files));
    }
  }

  TEST_CASE("implicit output does not depend on the order of children") {
    const Tileset tileset = eastTileset();
    Tileset reversed = tileset;
    std::vector<TileNode*> open{&reversed.root};
    while (!open.empty()) {
      TileNode* node = open.back();
      open.pop_back();
      std::reverse(node->children.begin(), node->children.end());
      for (TileNode& child : node->children) open.push_back(&child);
    }
    const Tileset both = bothHemispheresTileset();
    Tileset both_reversed = both;
    std::reverse(both_reversed.root.children.begin(), both_reversed.root.children.end());
    for (const int levels : {2, 6}) {
      const std::vector<ImplicitFile> a = writeImplicitTileset(tileset, levels);
      const std::vector<ImplicitFile> b = writeImplicitTileset(reversed, levels);
      REQUIRE(a.size() == b.size());
      for (std::size_t i = 0; i < a.size(); ++i) {
        CHECK(a[i].path == b[i].path);
        CHECK(a[i].bytes == b[i].bytes);
      }
      const std::vector<ImplicitFile> c = writeImplicitTileset(both, levels);
      const std::vector<ImplicitFile> d = writeImplicitTileset(both_reversed, levels);
      REQUIRE(c.size() == d.size());
      for (std::size_t i = 0; i < c.size(); ++i) {
        CHECK(c[i].path == d[i].path);
        CHECK(c[i].bytes == d[i].bytes);
      }
    }
  }

  TEST_CASE("implicit output refuses subtree levels out of range and trees off the quadtree") {
    const Tileset good = eastTileset();
    for (const int levels : {0, 13}) {
      try {
        (void)writeImplicitTileset(good, levels);
        FAIL("no error for " << levels);
      } catch (const Error& error) {
        CHECK(error.code() == ErrorCode::Usage);
        CHECK(std::string(error.what()) ==
              "implicit tiling: " + std::to_string(levels) +
                  " levels per subtree; expected 1..12");
      }
    }

    auto expectInputError = [](const Tileset& tileset, const std::string& part) {
      INFO(part);
      try {
        (void)writeImplicitTileset(tileset);
        FAIL("no error");
      } catch (const Error& error) {
        CHECK(error.code() == ErrorCode::Input);
        const std::string message = error.what();
        CHECK(message.find(part) != std::string::npos);
        CHECK(message.find("--scheme geographic") != std::string::npos);
      }
    };
    Tileset skipped = good;
    skipped.root.children[0].key = {3, 8, 1};  // two zooms below 1/2/0
    expectInputError(skipped, "tile 3/8/1 is a child of 1/2/0, whose children are at zoom 2 "
                              "columns 4..5 rows 0..1");
    Tileset wrong_parent = good;
    wrong_parent.root.children[0].key = {2, 6, 0};  // zoom 2 but under 1/3/0
    expectInputError(wrong_parent, "tile 2/6/0 is a child of 1/2/0");
    Tileset outside = good;
    outside.root.key = {1, 4, 0};
    expectInputError(outside,
                     "the root 1/4/0 is outside the geographic grid (zoom 1 has 4 x 2 tiles)");
    Tileset twice = good;
    twice.root.children.push_back(twice.root.children[0]);
    expectInputError(twice, "the east tile at level 2 x 0 y 3 (from the south) appears twice");
    Tileset empty_region = good;
    empty_region.root.children[0].children[1].region = Region{};
    expectInputError(empty_region, "tile 3/8/1 has an empty region");
    Tileset root_content = bothHemispheresTileset();
    root_content.root.content_uri = "tiles/root.glb";
    expectInputError(root_content, "the zoom -1 root has content tiles/root.glb");
    Tileset root_child = bothHemispheresTileset();
    root_child.root.children[1].key = {1, 2, 0};
    expectInputError(root_child, "the zoom -1 root has the child 1/2/0");
  }
}
