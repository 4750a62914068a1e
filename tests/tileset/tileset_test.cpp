#include <doctest/doctest.h>

#include <functional>
#include <nlohmann/json.hpp>

#include "tests/test_support.h"
#include "tileset/read_tileset.h"
#include "tileset/tileset.h"

#include <filesystem>
#include <fstream>

using namespace terratiles;

TEST_SUITE("tileset") {
  TEST_CASE("finalizeTree grows regions and errors so parents bound their children") {
    TileNode root;
    root.region.include(0.10, 0.80, 500);
    root.region.include(0.11, 0.81, 600);
    root.geometric_error_m = 3.0;
    TileNode child;
    child.key = {1, 0, 0};
    child.region.include(0.105, 0.79, 450);
    child.region.include(0.12, 0.805, 580);
    child.geometric_error_m = 5.0;  // larger than the parent's measured error
    root.children.push_back(child);
    finalizeTree(root);
    CHECK(root.region.south_rad == 0.79);
    CHECK(root.region.east_rad == 0.12);
    CHECK(root.region.min_height_m == 450);
    CHECK(root.region.max_height_m == 600);
    CHECK(root.geometric_error_m == 5.0);
  }

  TEST_CASE("tileset json is 3D Tiles 1.1 with REPLACE refinement and region volumes") {
    Tileset tileset;
    tileset.generator = "terratiles test";
    tileset.geometric_error_m = 100;
    tileset.root.region.include(0.1, 0.8, 10);
    tileset.root.region.include(0.2, 0.9, 20);
    tileset.root.geometric_error_m = 12.5;
    tileset.root.content_uri = "tiles/0/0/0.glb";
    TileNode child;
    child.region = tileset.root.region;
    child.content_uri = "tiles/1/0/0.glb";
    tileset.root.children.push_back(child);
    const auto json = nlohmann::json::parse(tilesetToJson(tileset));
    CHECK(json["asset"]["version"] == "1.1");
    CHECK(json["asset"]["generator"] == "terratiles test");
    CHECK(json["geometricError"] == 100.0);
    CHECK(json["root"]["refine"] == "REPLACE");
    CHECK(json["root"]["geometricError"] == 12.5);
    CHECK(json["root"]["boundingVolume"]["region"] ==
          nlohmann::json::array({0.1, 0.8, 0.2, 0.9, 10.0, 20.0}));
    CHECK(json["root"]["content"]["uri"] == "tiles/0/0/0.glb");
    CHECK(json["root"]["children"][0]["content"]["uri"] == "tiles/1/0/0.glb");
    CHECK_FALSE(json["root"]["children"][0].contains("refine"));
  }

  TEST_CASE("a deep tree is split into external tilesets that read back as the same tree") {
    // A full quadtree of zooms 0-7 (21,845 tiles), every tile with content.
    const std::function<TileNode(TileKey)> make = [&](TileKey key) {
      TileNode node;
      node.key = key;
      node.content_uri = "tiles/" + std::to_string(key.zoom) + "/" + std::to_string(key.x) + "/" +
                         std::to_string(key.y) + ".glb";
      node.region.include(0.001 * key.x, 0.001 * key.y, key.zoom);
      node.geometric_error_m = 100.0 / (1 << key.zoom);
      if (key.zoom < 7) {
        for (int k = 0; k < 4; ++k) node.children.push_back(make({key.zoom + 1, 2 * key.x + k % 2, 2 * key.y + k / 2}));
      }
      return node;
    };
    Tileset tileset;
    tileset.generator = "terratiles test";
    tileset.geometric_error_m = 1000;
    tileset.root = make({0, 0, 0});
    finalizeTree(tileset.root);
    REQUIRE(tileCount(tileset.root) == 21845);

    // Small trees stay one file, as tilesetToJson writes it.
    Tileset small = tileset;
    small.root.children.resize(1);
    small.root.children[0].children.clear();
    const std::vector<TilesetFile> one = tilesetFiles(small);
    REQUIRE(one.size() == 1);
    CHECK(one[0].text == tilesetToJson(small));

    // 21,845 tiles are more than one file takes: 6 levels per file, zooms 0-5 in tileset.json
    // and one external tileset per zoom 6 tile (4096), each with its 4 children.
    const std::vector<TilesetFile> files = tilesetFiles(tileset);
    REQUIRE(files.size() == 1 + 4096);
    CHECK(files[0].path == "tileset.json");
    CHECK(files[1].path.rfind("tilesets/6/", 0) == 0);
    std::size_t largest = 0;
    for (const TilesetFile& file : files) largest = std::max(largest, file.text.size());
    CHECK(largest < 4'000'000);  // 1,365 tiles, indented JSON
    const nlohmann::json external = nlohmann::json::parse(files[1].text);
    CHECK(external["root"]["refine"] == "REPLACE");
    CHECK(external["root"]["content"]["uri"].get<std::string>().rfind("../../../tiles/6/", 0) == 0);
    CHECK(external["root"]["children"].size() == 4);

    // Written out and read back, the tree is the single file's, tile for tile (an external
    // root says refine REPLACE, as every root must, which its parent file inherits anyway).
    test::TempDir dir;
    for (const TilesetFile& file : files) {
      const std::filesystem::path path = dir.path() / file.path;
      std::filesystem::create_directories(path.parent_path());
      std::ofstream(path) << file.text;
    }
    const nlohmann::json read = test::withoutInnerRefine(readTilesetTree(dir.path() / "tileset.json"));
    CHECK(read == nlohmann::json::parse(tilesetToJson(tileset)));
  }
}

