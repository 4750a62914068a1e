#include "tileset/read_tileset.h"

#include <fstream>
#include <set>
#include <string>

#include "src/base/error.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json readJsonFile(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(ErrorCode::Input, path.string() + " cannot be read; expected a tileset written by terratiles build");
  json value = json::parse(in, nullptr, false);
  if (value.is_discarded() || !value.is_object() || !value.contains("root")) {
    throw Error(ErrorCode::Input, path.string() + " is not a 3D Tiles tileset (JSON with a root tile)");
  }
  return value;
}

bool isExternalTileset(const std::string& uri) {
  return uri.size() > 5 && uri.compare(uri.size() - 5, 5, ".json") == 0;
}

// Rewrites `tile`'s subtree, read from the file in `file_dir`, as seen from `top_dir`.
void inlineTree(json& tile, const fs::path& file_dir, const fs::path& top_dir, std::set<fs::path>& open_files) {
  if (tile.contains("content") && tile["content"].contains("uri")) {
    const std::string uri = tile["content"]["uri"].get<std::string>();
    const fs::path target = (file_dir / uri).lexically_normal();
    if (isExternalTileset(uri)) {
      if (!open_files.insert(target).second) {
        throw Error(ErrorCode::Input, target.string() + " refers to itself through its external tilesets");
      }
      json external = readJsonFile(target);
      json root = std::move(external["root"]);
      inlineTree(root, target.parent_path(), top_dir, open_files);
      open_files.erase(target);
      tile = std::move(root);
      return;
    }
    tile["content"]["uri"] = target.lexically_relative(top_dir).generic_string();
  }
  if (tile.contains("children")) {
    for (json& child : tile["children"]) inlineTree(child, file_dir, top_dir, open_files);
  }
}

}  // namespace

json readTilesetTree(const fs::path& tileset_path) {
  json tileset = readJsonFile(tileset_path);
  const fs::path dir = tileset_path.parent_path().lexically_normal();
  std::set<fs::path> open_files{tileset_path.lexically_normal()};
  inlineTree(tileset["root"], dir, dir, open_files);
  return tileset;
}

}  // namespace terratiles
