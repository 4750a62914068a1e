#include "tileset/tileset.h"

#include <algorithm>
#include <nlohmann/json.hpp>

namespace terratiles {

void Region::include(double lon_rad, double lat_rad, double height_m) {
  if (empty) {
    west_rad = east_rad = lon_rad;
    south_rad = north_rad = lat_rad;
    min_height_m = max_height_m = height_m;
    empty = false;
    return;
  }
  west_rad = std::min(west_rad, lon_rad);
  east_rad = std::max(east_rad, lon_rad);
  south_rad = std::min(south_rad, lat_rad);
  north_rad = std::max(north_rad, lat_rad);
  min_height_m = std::min(min_height_m, height_m);
  max_height_m = std::max(max_height_m, height_m);
}

void Region::include(const Region& other) {
  if (other.empty) return;
  include(other.west_rad, other.south_rad, other.min_height_m);
  include(other.east_rad, other.north_rad, other.max_height_m);
}

void finalizeTree(TileNode& node) {
  for (TileNode& child : node.children) {
    finalizeTree(child);
    node.region.include(child.region);
    node.geometric_error_m = std::max(node.geometric_error_m, child.geometric_error_m);
  }
}

namespace {

nlohmann::json tileJson(const TileNode& node, bool is_root) {
  nlohmann::json tile;
  tile["boundingVolume"]["region"] = {node.region.west_rad,     node.region.south_rad,
                                      node.region.east_rad,     node.region.north_rad,
                                      node.region.min_height_m, node.region.max_height_m};
  tile["geometricError"] = node.geometric_error_m;
  if (is_root) tile["refine"] = "REPLACE";
  if (!node.content_uri.empty()) tile["content"]["uri"] = node.content_uri;
  if (!node.children.empty()) {
    nlohmann::json children = nlohmann::json::array();
    for (const TileNode& child : node.children) children.push_back(tileJson(child, false));
    tile["children"] = std::move(children);
  }
  return tile;
}

}  // namespace

std::string tilesetToJson(const Tileset& tileset) {
  nlohmann::json json;
  json["asset"] = {{"version", "1.1"}, {"generator", tileset.generator}};
  json["geometricError"] = tileset.geometric_error_m;
  json["root"] = tileJson(tileset.root, true);
  return json.dump(1, '\t') + "\n";
}

}  // namespace terratiles
