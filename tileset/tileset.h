#pragma once
// The 3D Tiles 1.1 model we write (explicit tiling) and its tileset.json writer.
//
// Bounding volumes are regions (3D Tiles spec 1.1, "Region": west, south, east, north in
// radians on WGS84, min and max height in metres above the ellipsoid). finalizeTree grows
// every region to contain its children's and raises every geometricError to at least its
// children's, so the tree is consistent whatever order tiles were added in.

#include <cstddef>
#include <string>
#include <vector>

#include "src/tiling/tile_key.h"

namespace terratiles {

struct Region {
  double west_rad = 0;
  double south_rad = 0;
  double east_rad = 0;
  double north_rad = 0;
  double min_height_m = 0;
  double max_height_m = 0;
  bool empty = true;

  void include(double lon_rad, double lat_rad, double height_m);
  void include(const Region& other);
};

struct TileNode {
  TileKey key;
  std::string content_uri;      // relative to tileset.json; empty for a tile without content
  Region region;                // of the content, grown by finalizeTree to the children's
  double geometric_error_m = 0; // measured content error, raised by finalizeTree
  std::vector<TileNode> children;
};

struct Tileset {
  TileNode root;
  double geometric_error_m = 0;  // error of drawing nothing at all (>= root's)
  std::string generator;         // asset.generator, e.g. "terratiles 0.1.0"
};

void finalizeTree(TileNode& node);

// tileset.json text: asset.version "1.1", refine REPLACE on the root (inherited).
std::string tilesetToJson(const Tileset& tileset);

// A JSON file of a tileset: its path relative to the output directory, and its text.
struct TilesetFile {
  std::string path;
  std::string text;
};

// Trees of more than this many tiles are split into external tilesets by default (about
// 3 MB of JSON in one file).
constexpr std::size_t kSingleFileTiles = 10000;
constexpr int kDefaultLevelsPerFile = 6;

// The tileset as JSON files that each hold at most `levels_per_file` levels of the tree
// (0: one file while the tree holds at most kSingleFileTiles tiles, else kDefaultLevelsPerFile),
// so no file grows with the data: tileset.json holds the root's levels; a tile
// levels_per_file levels below a file's root becomes, in that file, a tile without children
// whose content is the external tileset tilesets/{z}/{x}/{y}.json (3D Tiles 1.1, "External
// tilesets"; viewers always descend into it), and that file's root is the tile itself, with
// its content (uri relative to that file, ../../../tiles/...) and the next levels. Bounding
// volumes and geometric errors are the tile's in both files. With one file, the text is
// tilesetToJson's.
std::vector<TilesetFile> tilesetFiles(const Tileset& tileset, int levels_per_file = 0);

// The number of tiles in the tree below and including `node`.
std::size_t tileCount(const TileNode& node);

}  // namespace terratiles
