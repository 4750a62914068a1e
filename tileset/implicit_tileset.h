#pragma once
// 3D Tiles 1.1 implicit tiling (spec "Implicit Tiling") for trees in the geographic scheme
// (OGC WorldCRS84Quad, src/tiling/tile_scheme.h): the explicit tree of tileset.h rewritten
// as one QUADTREE per zoom-0 tile that holds data, with binary subtree files, and every
// tile's own geometricError and bounding region kept exactly as tile metadata (semantics
// TILE_GEOMETRIC_ERROR and TILE_BOUNDING_REGION, 3D Metadata Semantic Reference), since
// our errors are measured per tile (they do not halve per level) and our regions are those
// of the content (they overlap the neighbouring squares).
//
// Output layout, paths relative to tileset.json. H is the hemisphere, the zoom-0 tile:
// "west" (x = 0, lon -180..0) or "east" (x = 1, lon 0..180).
//   tileset.json                         asset 1.1, schema, a root framing the data above
//                                        the implicit root tile(s)
//   subtrees/H/{level}/{x}/{y}.subtree   one per subtree that holds available tiles
//   tiles/H/{level}/{x}/{y}.glb          tile content: written by the caller, at
//                                        implicitContentUri(key)
// The implicit coordinates are those of the spec's region subdivision: level = zoom,
// x = column from the west within the hemisphere (global x - H * 2^zoom), y = row FROM THE
// SOUTH (2^zoom - 1 - TileKey.y; TileKey counts rows from the north).

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "src/tiling/tile_key.h"
#include "tileset/tileset.h"

namespace terratiles {

// Levels per subtree file. 6 keeps a subtree's three availability bitstreams under 1 KB
// (1365 tile bits, 4096 child-subtree bits) while a 1-degree DEM (zooms ~7-10 below six
// content-less ancestors) needs only two or three subtree requests per hemisphere.
inline constexpr std::int32_t kDefaultSubtreeLevels = 6;
// Beyond this a subtree's bitstreams (4^levels bits) and CesiumJS's per-subtree index
// arrays grow past megabytes.
inline constexpr std::int32_t kMaxSubtreeLevels = 12;

struct ImplicitTileCoordinates {
  std::int32_t hemisphere = 0;  // the zoom-0 tile's x: 0 west, 1 east
  std::int32_t level = 0;       // = zoom
  std::int64_t x = 0;           // column from the west within the hemisphere
  std::int64_t y = 0;           // row from the south
  friend bool operator==(const ImplicitTileCoordinates&,
                         const ImplicitTileCoordinates&) = default;
};

// The implicit coordinates of a geographic tile. Throws Error(Usage) for a key outside the
// geographic grid (zoom 0..kMaxTileZoom, x < 2^(zoom+1), y < 2^zoom).
ImplicitTileCoordinates implicitTileCoordinates(const TileKey& key);

// The content URI a tile gets in implicit output, "tiles/H/{level}/{x}/{y}.glb": the content
// template of its hemisphere's implicit root, filled in. Throws as implicitTileCoordinates.
std::string implicitContentUri(const TileKey& key);

// The tile whose content implicitContentUri names; false when `uri` is not such a name.
bool tileKeyFromImplicitUri(const std::string& uri, TileKey& key);

// The content name of a tile in an output: implicitContentUri with implicit tiling, else
// "tiles/z/x/y.glb".
std::string contentUri(const TileKey& key, bool implicit_tiling);

// The tile a content name of either kind names (for readers of an output: `terratiles
// check`, `terratiles report`); false for any other name.
bool tileKeyFromContentUri(const std::string& uri, TileKey& key);

struct ImplicitFile {
  std::string path;  // relative to the output directory, '/'-separated
  std::vector<std::uint8_t> bytes;
};

// "folder/H/{level}/{x}/{y}.extension": the URI template of an implicit root's content
// ("tiles", "glb") or subtrees ("subtrees", "subtree"), H its hemisphere's name.
std::string implicitTemplatePath(const char* folder, std::int32_t hemisphere, const char* extension);
// The same filled in for one tile.
std::string implicitFilePath(const char* folder, const ImplicitTileCoordinates& c, const char* extension);

// One property of the tile metadata class ("tile"): FLOAT64 components, a SCALAR or VEC3,
// or a fixed-length array of them (array_count > 0), carrying a semantic of the 3D Metadata
// Semantic Reference.
struct ImplicitTileProperty {
  std::string name;
  std::string semantic;
  std::string description;
  std::string type = "SCALAR";  // "SCALAR" or "VEC3"
  std::int32_t array_count = 0;
  std::size_t valuesPerTile() const;
};

// An available tile and its metadata: the properties' values one after the other.
struct ImplicitTileRecord {
  ImplicitTileCoordinates coordinates;
  bool has_content = false;
  std::vector<double> metadata;
};

// tileset.json's "schema": the class "tile" with `properties`.
nlohmann::json implicitTileSchema(std::span<const ImplicitTileProperty> properties,
                                  const std::string& class_description);

// The binary subtree files (subtrees/H/{level}/{x}/{y}.subtree) of one hemisphere's available
// tiles, `subtree_levels` levels each, with the tiles' metadata as the subtrees' property
// table: tile, content and child-subtree availability. `tiles` must be closed under parents
// (every available tile's parent is available); any order. Throws Error(Internal) otherwise.
std::vector<ImplicitFile> implicitSubtreeFiles(std::int32_t hemisphere, const std::vector<ImplicitTileRecord>& tiles,
                                               std::span<const ImplicitTileProperty> properties,
                                               std::int32_t subtree_levels);

// tileset.json (first) and every subtree file of `tileset` as implicit tiling; the caller
// writes them, and each content at implicitContentUri(key).
//
// `tileset` is a finished geographic tree (after finalizeTree): a root at zoom >= 0, or a
// content-less root at zoom -1 whose children are zoom-0 tiles, every other child exactly
// one zoom below its parent, every region non-empty. Each zoom-0 tile that holds data
// becomes an implicit root whose boundingVolume is exactly its square (so the quadtree
// subdivision is the scheme's), heights spanning all its tiles, and whose geometricError is
// its own. Zoom-0 tiles and ancestors the tree lacks (root above zoom 0) are available and
// content-less, with the root's region and the larger of the root's and the tileset's
// error. tileset.json's root is an explicit content-less tile with the data's region (the
// tree root's), so viewers frame the data and not a hemisphere, above the implicit root or
// the two (an implicitTiling object may be on any tile, spec "Implicit Root Tile"; the
// 3d-tiles-validator accepts the squares reaching beyond it). Tile metadata repeats every
// tile's error and region.
//
// Deterministic: the same tileset gives the same bytes. Throws Error(Usage) for
// subtree_levels outside 1..kMaxSubtreeLevels and Error(Input) naming the tile for a tree
// that is not a geographic quadtree as above. O(tiles log tiles + subtrees * 4^levels).
std::vector<ImplicitFile> writeImplicitTileset(
    const Tileset& tileset, std::int32_t subtree_levels = kDefaultSubtreeLevels);

}  // namespace terratiles
