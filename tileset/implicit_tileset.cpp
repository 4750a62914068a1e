#include "tileset/implicit_tileset.h"

#include <algorithm>
#include <cstdio>
#include <bit>
#include <map>
#include <numbers>
#include <span>
#include <tuple>
#include <utility>

#include <nlohmann/json.hpp>

#include "src/base/error.h"
#include "src/tiling/tile_scheme.h"

namespace terratiles {

namespace {

constexpr const char* kHemisphereNames[2] = {"west", "east"};
// The metadata class of implicit tiles and its two properties (tileset.json "schema").
constexpr const char* kTileClass = "tile";
constexpr const char* kErrorProperty = "geometricError";
constexpr const char* kRegionProperty = "boundingRegion";

bool insideGeographicGrid(const TileKey& key) {
  if (key.zoom < 0 || key.zoom > kMaxTileZoom) return false;
  const std::int64_t rows = std::int64_t{1} << key.zoom;
  return key.x >= 0 && key.x < 2 * rows && key.y >= 0 && key.y < rows;
}

std::string gridText(std::int32_t zoom) {
  if (zoom < 0 || zoom > kMaxTileZoom) {
    return "zooms are 0.." + std::to_string(kMaxTileZoom);
  }
  const std::int64_t rows = std::int64_t{1} << zoom;
  return "zoom " + std::to_string(zoom) + " has " + std::to_string(2 * rows) + " x " +
         std::to_string(rows) + " tiles";
}

}  // namespace

std::string implicitFilePath(const char* folder, const ImplicitTileCoordinates& c, const char* extension) {
  return std::string(folder) + "/" + kHemisphereNames[c.hemisphere] + "/" +
         std::to_string(c.level) + "/" + std::to_string(c.x) + "/" + std::to_string(c.y) + "." +
         extension;
}

namespace {

// One available tile of an implicit tree, with the values its tile metadata carries.
struct ImplicitTile {
  ImplicitTileCoordinates coordinates;
  double geometric_error_m = 0;
  Region region;
  bool has_content = false;
};

// The tiles under one zoom-0 tile.
struct ImplicitTree {
  std::int32_t hemisphere = 0;
  std::vector<ImplicitTile> tiles;  // sorted by (level, y, x) once collected
  double min_height_m = 0;
  double max_height_m = 0;
  std::int32_t deepest_level = 0;
  bool has_content = false;
};

[[noreturn]] void throwNotQuadtree(const std::string& what) {
  throw Error(ErrorCode::Input,
              "implicit tiling: " + what +
                  "; implicit output needs a finished tree in the geographic scheme "
                  "(--scheme geographic), every child one zoom below its parent");
}

ImplicitTile implicitTile(const TileNode& node) {
  if (node.region.empty) {
    throwNotQuadtree("tile " + node.key.path() + " has an empty region");
  }
  return {implicitTileCoordinates(node.key), node.geometric_error_m, node.region,
          !node.content_uri.empty()};
}

void collectTiles(const TileNode& node, ImplicitTree& tree) {
  tree.tiles.push_back(implicitTile(node));
  for (const TileNode& child : node.children) {
    if (!insideGeographicGrid(child.key)) {
      throwNotQuadtree("tile " + child.key.path() + " is outside the geographic grid (" +
                       gridText(child.key.zoom) + ")");
    }
    if (!(child.key.parent() == node.key)) {
      throwNotQuadtree("tile " + child.key.path() + " is a child of " + node.key.path() +
                       ", whose children are at zoom " + std::to_string(node.key.zoom + 1) +
                       " columns " + std::to_string(2 * node.key.x) + ".." +
                       std::to_string(2 * node.key.x + 1) + " rows " +
                       std::to_string(2 * node.key.y) + ".." + std::to_string(2 * node.key.y + 1));
    }
    collectTiles(child, tree);
  }
}

// Sorts the tiles, refuses duplicates and gathers what the implicit root tile states.
void finishTree(ImplicitTree& tree) {
  auto order = [](const ImplicitTile& a, const ImplicitTile& b) {
    return std::tie(a.coordinates.level, a.coordinates.y, a.coordinates.x) <
           std::tie(b.coordinates.level, b.coordinates.y, b.coordinates.x);
  };
  std::sort(tree.tiles.begin(), tree.tiles.end(), order);
  for (std::size_t i = 1; i < tree.tiles.size(); ++i) {
    if (tree.tiles[i].coordinates == tree.tiles[i - 1].coordinates) {
      const ImplicitTileCoordinates& c = tree.tiles[i].coordinates;
      throwNotQuadtree("the " + std::string(kHemisphereNames[c.hemisphere]) +
                       " tile at level " + std::to_string(c.level) + " x " +
                       std::to_string(c.x) + " y " + std::to_string(c.y) +
                       " (from the south) appears twice");
    }
  }
  TERRATILES_ASSERT(!tree.tiles.empty() && tree.tiles.front().coordinates.level == 0);
  tree.min_height_m = tree.tiles.front().region.min_height_m;
  tree.max_height_m = tree.tiles.front().region.max_height_m;
  for (const ImplicitTile& tile : tree.tiles) {
    tree.min_height_m = std::min(tree.min_height_m, tile.region.min_height_m);
    tree.max_height_m = std::max(tree.max_height_m, tile.region.max_height_m);
    tree.deepest_level = std::max(tree.deepest_level, tile.coordinates.level);
    tree.has_content = tree.has_content || tile.has_content;
  }
}

std::vector<ImplicitTree> collectTrees(const Tileset& tileset) {
  const TileNode& root = tileset.root;
  std::vector<ImplicitTree> trees;
  if (root.key.zoom == -1) {
    // The content-less root above the two zoom-0 tiles (data on both sides of the prime
    // meridian): it has no square, so each zoom-0 child is an implicit root.
    if (!root.content_uri.empty()) {
      throwNotQuadtree("the zoom -1 root has content " + root.content_uri +
                       "; it stands above the two zoom-0 tiles and has no square of its own");
    }
    if (root.children.empty() || root.children.size() > 2) {
      throwNotQuadtree("the zoom -1 root has " + std::to_string(root.children.size()) +
                       " children; expected the zoom-0 tiles holding data, 1 or 2");
    }
    for (const TileNode& child : root.children) {
      if (child.key.zoom != 0 || !insideGeographicGrid(child.key)) {
        throwNotQuadtree("the zoom -1 root has the child " + child.key.path() +
                         "; expected zoom-0 tiles 0/0/0 and 0/1/0");
      }
      ImplicitTree tree;
      tree.hemisphere = child.key.x;
      collectTiles(child, tree);
      trees.push_back(std::move(tree));
    }
    if (trees.size() == 2 && trees[0].hemisphere == trees[1].hemisphere) {
      throwNotQuadtree("the zoom -1 root has the child " + root.children[1].key.path() +
                       " twice");
    }
  } else {
    if (!insideGeographicGrid(root.key)) {
      throwNotQuadtree("the root " + root.key.path() + " is outside the geographic grid (" +
                       gridText(root.key.zoom) + ")");
    }
    ImplicitTree tree;
    tree.hemisphere = implicitTileCoordinates(root.key).hemisphere;
    // The ancestors between the zoom-0 tile and the root hold no content: they draw nothing,
    // so their error is that of drawing nothing, as the pipeline gives content-less tiles.
    for (TileKey key = root.key; key.zoom > 0;) {
      key = key.parent();
      tree.tiles.push_back({implicitTileCoordinates(key),
                            std::max(tileset.geometric_error_m, root.geometric_error_m),
                            root.region, false});
    }
    collectTiles(root, tree);
    trees.push_back(std::move(tree));
  }
  for (ImplicitTree& tree : trees) finishTree(tree);
  std::sort(trees.begin(), trees.end(), [](const ImplicitTree& a, const ImplicitTree& b) {
    return a.hemisphere < b.hemisphere;
  });
  return trees;
}

// ---- Subtrees (spec "Availability", "Subtree Binary Format") ------------------------------

// (4^level - 1) / 3: the tiles of a subtree above `level` (spec "Availability Indexing").
std::uint64_t levelOffset(std::int32_t level) {
  return ((std::uint64_t{1} << (2 * level)) - 1) / 3;
}

// interleaveBits(x, y): bit i of x goes to bit 2i, bit i of y to bit 2i + 1.
std::uint64_t mortonIndex(std::int64_t x, std::int64_t y) {
  std::uint64_t index = 0;
  for (int bit = 0; bit < 31; ++bit) {
    index |= ((static_cast<std::uint64_t>(x) >> bit) & 1u) << (2 * bit);
    index |= ((static_cast<std::uint64_t>(y) >> bit) & 1u) << (2 * bit + 1);
  }
  return index;
}

std::size_t roundUpTo8(std::size_t size) { return (size + 7) / 8 * 8; }

void appendUint32(std::vector<std::uint8_t>& out, std::uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(value >> (8 * i)));
}
void appendUint64(std::vector<std::uint8_t>& out, std::uint64_t value) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<std::uint8_t>(value >> (8 * i)));
}
void appendFloat64(std::vector<std::uint8_t>& out, double value) {
  appendUint64(out, std::bit_cast<std::uint64_t>(value));
}

// The binary chunk: buffer views at offsets that are multiples of 8 (spec "Buffers and
// Buffer Views"), in the order they are added.
class BinaryChunk {
 public:
  std::size_t addView(const std::vector<std::uint8_t>& data) {
    bytes_.resize(roundUpTo8(bytes_.size()), 0);
    nlohmann::json view;
    view["buffer"] = 0;
    view["byteOffset"] = bytes_.size();
    view["byteLength"] = data.size();
    views_.push_back(std::move(view));
    bytes_.insert(bytes_.end(), data.begin(), data.end());
    return views_.size() - 1;
  }
  const nlohmann::json& views() const { return views_; }
  // The chunk padded with zeros to a multiple of 8 bytes.
  std::vector<std::uint8_t> finish() {
    bytes_.resize(roundUpTo8(bytes_.size()), 0);
    return std::move(bytes_);
  }

 private:
  std::vector<std::uint8_t> bytes_;
  nlohmann::json views_ = nlohmann::json::array();
};

// `set_bits` (sorted, distinct) of `length_bits` as availability: a constant when all bits
// are equal, otherwise a bitstream (metadata "Booleans": bit i is bit i % 8 of byte i / 8,
// trailing bits 0) of exactly ceil(length_bits / 8) bytes, as CesiumJS checks.
nlohmann::json availabilityJson(std::uint64_t length_bits,
                                const std::vector<std::uint64_t>& set_bits, BinaryChunk& chunk) {
  nlohmann::json json;
  if (set_bits.empty()) {
    json["constant"] = 0;
  } else if (set_bits.size() == length_bits) {
    json["constant"] = 1;
  } else {
    std::vector<std::uint8_t> bytes((length_bits + 7) / 8, 0);
    for (const std::uint64_t bit : set_bits) {
      bytes[bit / 8] |= static_cast<std::uint8_t>(1u << (bit % 8));
    }
    json["bitstream"] = chunk.addView(bytes);
    json["availableCount"] = set_bits.size();
  }
  return json;
}

struct SubtreeTiles {
  std::vector<std::pair<std::uint64_t, const ImplicitTileRecord*>> tiles;  // (availability bit, tile)
  std::vector<std::uint64_t> child_subtree_bits;
};

ImplicitFile subtreeFile(const ImplicitTileCoordinates& root, SubtreeTiles& subtree,
                         std::span<const ImplicitTileProperty> properties, std::int32_t subtree_levels,
                         bool has_content) {
  std::sort(subtree.tiles.begin(), subtree.tiles.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  std::sort(subtree.child_subtree_bits.begin(), subtree.child_subtree_bits.end());
  const std::uint64_t tile_bits = levelOffset(subtree_levels);
  const std::uint64_t child_bits = std::uint64_t{1} << (2 * subtree_levels);

  std::vector<std::uint64_t> available;
  std::vector<std::uint64_t> with_content;
  // Tile metadata is packed by increasing availability index (spec "Tile Metadata"), one
  // buffer view per property.
  std::vector<std::vector<std::uint8_t>> columns(properties.size());
  for (const auto& [bit, tile] : subtree.tiles) {
    available.push_back(bit);
    if (tile->has_content) with_content.push_back(bit);
    std::size_t value = 0;
    for (std::size_t p = 0; p < properties.size(); ++p) {
      for (std::size_t i = 0; i < properties[p].valuesPerTile(); ++i) appendFloat64(columns[p], tile->metadata.at(value++));
    }
    TERRATILES_ASSERT(value == tile->metadata.size());
  }

  BinaryChunk chunk;
  nlohmann::json json;
  json["tileAvailability"] = availabilityJson(tile_bits, available, chunk);
  if (has_content) {
    json["contentAvailability"] =
        nlohmann::json::array({availabilityJson(tile_bits, with_content, chunk)});
  }
  json["childSubtreeAvailability"] =
      availabilityJson(child_bits, subtree.child_subtree_bits, chunk);
  nlohmann::json table;
  table["class"] = kTileClass;
  table["count"] = subtree.tiles.size();
  for (std::size_t p = 0; p < properties.size(); ++p) {
    table["properties"][properties[p].name]["values"] = chunk.addView(columns[p]);
  }
  json["propertyTables"] = nlohmann::json::array({table});
  json["tileMetadata"] = 0;
  json["bufferViews"] = chunk.views();
  std::vector<std::uint8_t> binary = chunk.finish();
  nlohmann::json buffer;
  buffer["byteLength"] = binary.size();  // the internal buffer: the binary chunk
  json["buffers"] = nlohmann::json::array({buffer});

  // Header: magic "subt", version 1, JSON and binary chunk lengths, each chunk padded to
  // 8 bytes (JSON with spaces, binary with zeros).
  std::string text = json.dump();
  text.resize(roundUpTo8(text.size()), ' ');
  ImplicitFile file;
  file.path = implicitFilePath("subtrees", root, "subtree");
  file.bytes.reserve(24 + text.size() + binary.size());
  appendUint32(file.bytes, 0x74627573u);
  appendUint32(file.bytes, 1);
  appendUint64(file.bytes, text.size());
  appendUint64(file.bytes, binary.size());
  file.bytes.insert(file.bytes.end(), text.begin(), text.end());
  file.bytes.insert(file.bytes.end(), binary.begin(), binary.end());
  return file;
}

// The tile properties of a tileset's implicit tiles: its measured error and region.
const std::vector<ImplicitTileProperty>& tilesetProperties() {
  static const std::vector<ImplicitTileProperty> properties = {
      {kErrorProperty, "TILE_GEOMETRIC_ERROR",
       "geometricError of the tile in metres, as measured (it does not halve per level)", "SCALAR", 0},
      {kRegionProperty, "TILE_BOUNDING_REGION",
       "bounding region of the tile and its descendants' content: west, south, east, north "
       "in radians, minimum and maximum height in metres above the WGS84 ellipsoid",
       "SCALAR", 6}};
  return properties;
}

// ---- tileset.json ------------------------------------------------------------------------

nlohmann::json regionJson(double west_rad, double south_rad, double east_rad, double north_rad,
                          double min_height_m, double max_height_m) {
  return nlohmann::json::array(
      {west_rad, south_rad, east_rad, north_rad, min_height_m, max_height_m});
}

nlohmann::json implicitRootJson(const ImplicitTree& tree, std::int32_t subtree_levels,
                                bool is_tileset_root) {
  constexpr double kPi = std::numbers::pi;
  const ImplicitTile& root = tree.tiles.front();
  nlohmann::json tile;
  // Exactly the zoom-0 square: the spec subdivides it at its midpoints, which are the
  // scheme's tile edges. The heights span every tile below.
  const double west_rad = tree.hemisphere == 0 ? -kPi : 0.0;
  tile["boundingVolume"]["region"] = regionJson(west_rad, -kPi / 2, west_rad + kPi, kPi / 2,
                                                tree.min_height_m, tree.max_height_m);
  tile["geometricError"] = root.geometric_error_m;
  if (is_tileset_root) tile["refine"] = "REPLACE";
  if (tree.has_content) {
    tile["content"]["uri"] = implicitTemplatePath("tiles", tree.hemisphere, "glb");
  }
  nlohmann::json& implicit = tile["implicitTiling"];
  implicit["subdivisionScheme"] = "QUADTREE";
  implicit["subtreeLevels"] = subtree_levels;
  implicit["availableLevels"] = tree.deepest_level + 1;
  implicit["subtrees"]["uri"] = implicitTemplatePath("subtrees", tree.hemisphere, "subtree");
  return tile;
}

}  // namespace

ImplicitTileCoordinates implicitTileCoordinates(const TileKey& key) {
  if (!insideGeographicGrid(key)) {
    throw Error(ErrorCode::Usage, "implicit tiling: tile " + key.path() +
                                      " is outside the geographic grid (" +
                                      gridText(key.zoom) + ")");
  }
  const std::int64_t rows = std::int64_t{1} << key.zoom;
  ImplicitTileCoordinates c;
  c.hemisphere = static_cast<std::int32_t>(key.x / rows);
  c.level = key.zoom;
  c.x = key.x - c.hemisphere * rows;
  c.y = rows - 1 - key.y;
  return c;
}

std::string implicitContentUri(const TileKey& key) {
  return implicitFilePath("tiles", implicitTileCoordinates(key), "glb");
}

bool tileKeyFromImplicitUri(const std::string& uri, TileKey& key) {
  char hemisphere[8] = {0}, tail[8] = {0};
  int level = 0;
  long long x = 0, y = 0;
  if (std::sscanf(uri.c_str(), "tiles/%4[a-z]/%d/%lld/%lld.%4s", hemisphere, &level, &x, &y, tail) != 5) return false;
  const std::string h = hemisphere;
  if ((h != "west" && h != "east") || std::string(tail) != "glb" || level < 0 || level > kMaxTileZoom) return false;
  const long long side = 1LL << level;
  if (x < 0 || y < 0 || x >= side || y >= side) return false;
  key = {level, static_cast<std::int32_t>(x + (h == "east" ? side : 0)), static_cast<std::int32_t>(side - 1 - y)};
  return implicitContentUri(key) == uri;
}

std::string contentUri(const TileKey& key, bool implicit_tiling) {
  return implicit_tiling ? implicitContentUri(key) : "tiles/" + key.path() + ".glb";
}

bool tileKeyFromContentUri(const std::string& uri, TileKey& key) {
  if (tileKeyFromImplicitUri(uri, key)) return true;
  int zoom = 0, x = 0, y = 0;
  char tail[8] = {};
  if (std::sscanf(uri.c_str(), "tiles/%d/%d/%d.%4s", &zoom, &x, &y, tail) != 4 || std::string(tail) != "glb") return false;
  key = {zoom, x, y};
  return true;
}

std::string implicitTemplatePath(const char* folder, std::int32_t hemisphere, const char* extension) {
  return std::string(folder) + "/" + kHemisphereNames[hemisphere] + "/{level}/{x}/{y}." + extension;
}

std::size_t ImplicitTileProperty::valuesPerTile() const {
  return static_cast<std::size_t>(type == "VEC3" ? 3 : 1) * static_cast<std::size_t>(std::max(array_count, 1));
}

nlohmann::json implicitTileSchema(std::span<const ImplicitTileProperty> properties, const std::string& class_description) {
  nlohmann::json schema;
  schema["id"] = "terratiles";
  nlohmann::json& tile = schema["classes"][kTileClass];
  tile["description"] = class_description;
  for (const ImplicitTileProperty& property : properties) {
    nlohmann::json json;
    json["description"] = property.description;
    json["type"] = property.type;
    json["componentType"] = "FLOAT64";
    if (property.array_count > 0) {
      json["array"] = true;
      json["count"] = property.array_count;
    }
    json["semantic"] = property.semantic;
    json["required"] = true;
    tile["properties"][property.name] = std::move(json);
  }
  return schema;
}

std::vector<ImplicitFile> implicitSubtreeFiles(std::int32_t hemisphere, const std::vector<ImplicitTileRecord>& tiles,
                                               std::span<const ImplicitTileProperty> properties,
                                               std::int32_t subtree_levels) {
  std::map<std::tuple<std::int32_t, std::int64_t, std::int64_t>, SubtreeTiles> subtrees;
  const std::int64_t child_mask = (std::int64_t{1} << subtree_levels) - 1;
  bool has_content = false;
  for (const ImplicitTileRecord& tile : tiles) {
    has_content = has_content || tile.has_content;
    const ImplicitTileCoordinates& c = tile.coordinates;
    const std::int32_t depth = c.level % subtree_levels;
    const std::int64_t root_x = c.x >> depth;
    const std::int64_t root_y = c.y >> depth;
    const std::uint64_t bit =
        levelOffset(depth) + mortonIndex(c.x - (root_x << depth), c.y - (root_y << depth));
    subtrees[{c.level - depth, root_y, root_x}].tiles.emplace_back(bit, &tile);
    if (depth == 0 && c.level > 0) {
      // The root of a child subtree: one bit in its parent subtree, indexed by the Morton
      // index one level below that subtree's deepest level.
      subtrees[{c.level - subtree_levels, c.y >> subtree_levels, c.x >> subtree_levels}]
          .child_subtree_bits.push_back(mortonIndex(c.x & child_mask, c.y & child_mask));
    }
  }
  std::vector<ImplicitFile> files;
  for (auto& [key, subtree] : subtrees) {
    if (subtree.tiles.empty()) {
      throw Error(ErrorCode::Internal, "implicit tiling: a subtree at level " + std::to_string(std::get<0>(key)) +
                                           " has child subtrees but no root tile; every tile's parent must be available");
    }
    const ImplicitTileCoordinates root{hemisphere, std::get<0>(key), std::get<2>(key), std::get<1>(key)};
    files.push_back(subtreeFile(root, subtree, properties, subtree_levels, has_content));
  }
  return files;
}

std::vector<ImplicitFile> writeImplicitTileset(const Tileset& tileset,
                                               std::int32_t subtree_levels) {
  if (subtree_levels < 1 || subtree_levels > kMaxSubtreeLevels) {
    throw Error(ErrorCode::Usage, "implicit tiling: " + std::to_string(subtree_levels) +
                                      " levels per subtree; expected 1.." +
                                      std::to_string(kMaxSubtreeLevels));
  }
  const std::vector<ImplicitTree> trees = collectTrees(tileset);

  nlohmann::json json;
  json["asset"] = {{"version", "1.1"}, {"generator", tileset.generator}};
  json["geometricError"] = tileset.geometric_error_m;
  json["schema"] = implicitTileSchema(tilesetProperties(), "Per-tile values of the implicit tiles, overriding the subdivision");
  // An explicit content-less root with the data's region above the implicit root(s) (one
  // per hemisphere with data): the implicit roots' volumes must be the zoom-0 squares for
  // the subdivision, but a viewer frames the tileset by its root, which must be the data.
  nlohmann::json& root = json["root"];
  const Region& data = tileset.root.region;
  root["boundingVolume"]["region"] = regionJson(data.west_rad, data.south_rad, data.east_rad, data.north_rad,
                                                data.min_height_m, data.max_height_m);
  root["geometricError"] = std::max(tileset.geometric_error_m, tileset.root.geometric_error_m);
  root["refine"] = "REPLACE";
  root["children"] = nlohmann::json::array();
  for (const ImplicitTree& tree : trees) root["children"].push_back(implicitRootJson(tree, subtree_levels, false));

  std::vector<ImplicitFile> files;
  const std::string text = json.dump(1, '\t') + "\n";
  files.push_back({"tileset.json", std::vector<std::uint8_t>(text.begin(), text.end())});
  for (const ImplicitTree& tree : trees) {
    std::vector<ImplicitTileRecord> records;
    records.reserve(tree.tiles.size());
    for (const ImplicitTile& tile : tree.tiles) {
      const Region& r = tile.region;
      records.push_back({tile.coordinates, tile.has_content,
                         {tile.geometric_error_m, r.west_rad, r.south_rad, r.east_rad, r.north_rad, r.min_height_m,
                          r.max_height_m}});
    }
    for (ImplicitFile& file : implicitSubtreeFiles(tree.hemisphere, records, tilesetProperties(), subtree_levels)) {
      files.push_back(std::move(file));
    }
  }
  return files;
}

}  // namespace terratiles
