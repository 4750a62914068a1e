#pragma once
// encodeTerrainGlb: one terrain tile as the glTF content of 3D Tiles terrain, the format
// CesiumJS's Cesium3DTilesTerrainProvider reads (Cesium3DTilesTerrainGeometryProcessor in
// @cesium/engine, since CesiumJS 1.126; issue 17). One GLB, one mesh, one primitive:
//
//   POSITION   UNSIGNED_SHORT normalised VEC3 (KHR_mesh_quantization), stride 8: the
//              vertex's place in a cube in the tile's east-north-up frame (ENU at the centre
//              of its rectangle on the ellipsoid), 0 .. 65535 along each side, the cube's side
//              the longest extent of the tile's vertices; the node's matrix takes the unit
//              cube to ECEF (Y up, as glTF: the client turns Y-up into Z-up). The step, the
//              side over 65535, is the position quantisation: 0.6 m for a zoom-9 tile (0.35
//              degrees), 7.5 cm at zoom 12. One scale for all axes because CesiumJS turns
//              normals with the matrix, scale included: a flatter box would flatten them.
//              Tiles of a sixth of the globe and more (zooms 0-2) use a cube aligned with
//              glTF's axes whose side is a power of two instead, so that the glTF validator's
//              float32 TRS decomposition check of the node matrix holds.
//   NORMAL     BYTE normalised VEC3, stride 4, EXT_meshopt_compression's OCTAHEDRAL filter
//              (8 bits), the level's normal in the tile's ENU frame.
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

TerrainGlb encodeTerrainGlb(const TerrainTileMesh& mesh, const std::string& generator,
                            DecodedTerrainGlb* decoded = nullptr);

}  // namespace terratiles
