#include <doctest/doctest.h>

#include <nlohmann/json.hpp>

#include "tileset/tileset.h"

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
}
