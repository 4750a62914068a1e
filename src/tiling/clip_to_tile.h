#pragma once
// clipToTile: the part of a level mesh inside one terrain tile's rectangle of longitude and
// latitude, as a mesh of its own (issue 17: terrain tiles cover exactly their rectangle).
//
// The level mesh is taken in (longitude, latitude) with heights linear over each triangle:
// every triangle is clipped against the rectangle's four sides (Sutherland-Hodgman), and the
// convex polygon left is cut into triangles from the corner that leaves the fewest flat ones
// (none, unless three of its corners are collinear from every corner). The new vertices are
// where a triangle edge crosses a side, with the height interpolated along that edge, and the
// rectangle's corners inside a triangle, with the height of its plane. A crossing is computed
// from the edge's two vertices in the order of their indices and the side's coordinate alone,
// so two tiles that share a side compute the same vertex bit for bit: neighbours of one zoom
// meet vertex for vertex along their common side, with no T-junction. Vertices exactly on a
// side belong to the tiles on both sides of it.
//
// Normals (when the mesh has them) are interpolated the same way and normalised.

#include <array>
#include <cstdint>
#include <map>
#include <span>
#include <utility>
#include <vector>

#include "src/geo/crs_transform.h"
#include "src/tiling/tile_scheme.h"

namespace terratiles {

// A level mesh in longitude and latitude (degrees) and ellipsoidal height.
struct GeodeticMesh {
  std::vector<GeodeticPoint> vertices;
  std::vector<std::uint32_t> triangles;       // 3 per triangle, counter-clockwise seen from above
  std::vector<std::array<float, 3>> normals;  // empty, or a unit ECEF normal per vertex
};

// One terrain tile's mesh.
struct TerrainTileMesh {
  TileBounds rectangle;                       // degrees of longitude and latitude
  std::vector<GeodeticPoint> vertices;        // inside the rectangle or on its sides
  std::vector<std::uint32_t> triangles;       // 3 per triangle, counter-clockwise seen from above
  std::vector<std::array<float, 3>> normals;  // empty, or a unit ECEF normal per vertex
};

// The part of `mesh` inside `rectangle` (degrees), from the triangles listed in `candidates`
// (any superset of those that meet it; each once).
TerrainTileMesh clipToTile(const GeodeticMesh& mesh, std::span<const std::uint32_t> candidates,
                           const TileBounds& rectangle);

// The geographic quadtree of terrain tiles (quantized-mesh's TMS layout, EPSG:4326): zoom z
// has 2^(z+1) x 2^z tiles of 180 / 2^z degrees, x counted east from -180, y north from -90.
struct TerrainTileKey {
  std::int32_t zoom = 0;
  std::int64_t x = 0;
  std::int64_t y = 0;
  auto operator<=>(const TerrainTileKey&) const = default;
};
TileBounds terrainTileBounds(const TerrainTileKey& key);

// Moves every vertex that lies within half a step of a tile side at `zoom` onto that side,
// a step being the tile's size over `steps_per_tile` (quantized-mesh's 32767): such a vertex
// would be quantised onto the side in one tile and have no counterpart in its neighbour; on
// the side, it belongs to both (clipToTile). Returns how many moved.
std::size_t snapToTileSides(std::vector<GeodeticPoint>& vertices, std::int32_t zoom, double steps_per_tile);

// Per tile at `zoom` that a triangle's box of longitude and latitude meets (sides included):
// those triangles, in mesh order.
std::map<TerrainTileKey, std::vector<std::uint32_t>> trianglesPerTerrainTile(const GeodeticMesh& mesh,
                                                                              std::int32_t zoom);

}  // namespace terratiles
