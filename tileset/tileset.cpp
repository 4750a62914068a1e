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

// How tiles are written into the files of a split tileset (levels_per_file 0: one file).
struct FileSplit {
  int levels_per_file = 0;
  std::vector<TilesetFile>* files = nullptr;
  std::string generator;
};

std::string externalTilesetPath(const TileKey& key) {
  return "tilesets/" + std::to_string(key.zoom) + "/" + std::to_string(key.x) + "/" + std::to_string(key.y) + ".json";
}

nlohmann::json fileJson(const TileNode& root, double geometric_error_m, const FileSplit& split,
                        const std::string& to_output_root);

// `depth`: levels below the root of the file the tile is written into; `to_output_root`: the
// path from that file's directory to the output directory ("" or "../../../").
nlohmann::json tileJson(const TileNode& node, bool is_root, int depth, const FileSplit& split,
                        const std::string& to_output_root) {
  nlohmann::json tile;
  tile["boundingVolume"]["region"] = {node.region.west_rad,     node.region.south_rad,
                                      node.region.east_rad,     node.region.north_rad,
                                      node.region.min_height_m, node.region.max_height_m};
  tile["geometricError"] = node.geometric_error_m;
  if (is_root) tile["refine"] = "REPLACE";
  if (split.levels_per_file > 0 && depth == split.levels_per_file) {
    const std::string path = externalTilesetPath(node.key);
    tile["content"]["uri"] = to_output_root + path;
    split.files->push_back({path, ""});
    const std::size_t at = split.files->size() - 1;
    (*split.files)[at].text = fileJson(node, node.geometric_error_m, split, "../../../").dump(1, '\t') + "\n";
    return tile;
  }
  if (!node.content_uri.empty()) tile["content"]["uri"] = to_output_root + node.content_uri;
  if (!node.children.empty()) {
    nlohmann::json children = nlohmann::json::array();
    for (const TileNode& child : node.children) {
      children.push_back(tileJson(child, false, depth + 1, split, to_output_root));
    }
    tile["children"] = std::move(children);
  }
  return tile;
}

nlohmann::json fileJson(const TileNode& root, double geometric_error_m, const FileSplit& split,
                        const std::string& to_output_root) {
  nlohmann::json json;
  json["asset"] = {{"version", "1.1"}, {"generator", split.generator}};
  json["geometricError"] = geometric_error_m;
  json["root"] = tileJson(root, true, 0, split, to_output_root);
  return json;
}

}  // namespace

std::size_t tileCount(const TileNode& node) {
  std::size_t count = 1;
  for (const TileNode& child : node.children) count += tileCount(child);
  return count;
}

std::string tilesetToJson(const Tileset& tileset) {
  const FileSplit one_file{0, nullptr, tileset.generator};
  return fileJson(tileset.root, tileset.geometric_error_m, one_file, "").dump(1, '\t') + "\n";
}

std::vector<TilesetFile> tilesetFiles(const Tileset& tileset, int levels_per_file) {
  if (levels_per_file <= 0) {
    levels_per_file = tileCount(tileset.root) <= kSingleFileTiles ? 0 : kDefaultLevelsPerFile;
  }
  std::vector<TilesetFile> files(1);
  const FileSplit split{levels_per_file, &files, tileset.generator};
  files[0] = {"tileset.json", fileJson(tileset.root, tileset.geometric_error_m, split, "").dump(1, '\t') + "\n"};
  return files;
}

}  // namespace terratiles
