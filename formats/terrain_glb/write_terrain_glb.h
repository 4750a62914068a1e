#pragma once
// encodeTerrainGlb: one terrain tile as the glTF content of 3D Tiles terrain, the format
// CesiumJS's Cesium3DTilesTerrainProvider reads (Cesium3DTilesTerrainGeometryProcessor in
// @cesium/engine, since CesiumJS 1.126; issue 17). One GLB, one mesh, one primitive:
//
//   POSITION   UNSIGNED_SHORT normalised VEC3 (KHR_mesh_quantization), stride 8: the
//              vertex's place on a lattice in glTF's axes (ECEF x, z, -y) of `lattice_step_m`
//              (a zoom's tiles share one: a vertex two tiles share is on the same lattice
//              point in both, and decodes the same up to the client's float32 rounding of
//              q / 65535, 0.4 % of a step), 0 .. 65535 steps from the tile's cube corner, a
//              lattice point; the node matrix takes the unit cube (side 65535 steps) to ECEF
//              (Y up, as glTF: the client turns Y-up into Z-up): the side times the identity
//              and a translation, which the glTF validator's float32 TRS check recomposes
//              exactly. One scale for all axes also because CesiumJS turns normals with the
//              matrix, scale included: a flatter box would flatten them.
//   NORMAL     BYTE normalised VEC3, stride 4, EXT_meshopt_compression's OCTAHEDRAL filter
//              (8 bits), the level's normal in glTF's axes.
//   indices    triangles, counter-clockwise seen from above; UNSIGNED_SHORT up to 65535
//              vertices, else UNSIGNED_INT
//   CESIUM_tile_edges  a primitive extension naming four index accessors: the vertices on
//              the rectangle's sides, "left" (west) south to north, "bottom" (south) east to
//              west, "right" (east) north to south, "top" (north) west to east, the order
//              CesiumJS builds skirts in; corners in both their sides' lists.
//
// Every buffer view is EXT_meshopt_compression-coded (vertex codec for attributes, index
// codec for the triangles, index sequence codec for the edges) in the GLB's binary chunk,
// with a fallback buffer of no bytes (required extension). Vertices are in the order
// meshoptimizer's vertex cache and fetch optimisations give, which makes them compress best.
//
// Throws Error(Input) for a tile without triangles, an index out of range, normals for some
// vertices only, a vertex outside the rectangle, or no vertex on a side.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/quantized_mesh/write_quantized_mesh.h"
#include "src/geo/crs_transform.h"
#include "src/tiling/clip_to_tile.h"

namespace terratiles {

// What the tile decodes to, as a client computes it (the unit box times the node matrix).
struct DecodedTerrainGlb {
  std::vector<EcefPoint> positions;                 // per written vertex
  std::vector<std::uint32_t> source_vertex;         // written vertex -> mesh vertex
  std::vector<std::uint32_t> triangles;             // in written vertex indices
  std::array<std::vector<std::uint32_t>, 4> edges;  // west S->N, south E->W, east N->S, north W->E
};

struct TerrainGlb {
  std::vector<std::uint8_t> bytes;
  // The least and greatest ellipsoidal height of the decoded positions, and what a client
  // culls the tile with (3D Tiles terrain's tile metadata carries both).
  double minimum_height_m = 0;
  double maximum_height_m = 0;
  TerrainTileCulling culling;
  double position_step_m = 0;  // the quantisation step along each axis
  std::size_t vertices = 0;
  std::size_t triangles = 0;
};

// The longest extent of the tile's vertices along ECEF's axes: a lattice step of at least
// extent / 65534 holds the tile.
double terrainTileExtent(const TerrainTileMesh& mesh);

// `lattice_step_m` 0: the tile's own, terrainTileExtent / 65534. Throws Error(Internal) for a
// step the tile does not fit in.
TerrainGlb encodeTerrainGlb(const TerrainTileMesh& mesh, const std::string& generator, double lattice_step_m = 0,
                            DecodedTerrainGlb* decoded = nullptr);

}  // namespace terratiles
