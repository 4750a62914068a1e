#pragma once
// encodeQuantizedMesh: one terrain tile as quantized-mesh-1.0, the format CesiumJS's
// CesiumTerrainProvider, cesium-native and loaders.gl read (the spec:
// github.com/CesiumGS/quantized-mesh). Little-endian throughout:
//
//   header      center (ECEF, 3 doubles), minimum and maximum height (2 floats), bounding
//               sphere (centre, 3 doubles, and radius), horizon occlusion point (3 doubles,
//               in the ellipsoid-scaled frame: x / a, y / a, z / b)           88 bytes
//   vertices    count (uint32), then u, v and height (uint16 each, 0 .. 32767 across the
//               tile's rectangle and its [minimum, maximum] height), each array as zig-zag
//               deltas of the previous value
//   triangles   (padded to 4 bytes when indices are 32-bit) count (uint32), then 3 indices
//               per triangle, high-water-mark coded; indices are 16-bit up to 65536 vertices
//   edges       west, south, east, north: count (uint32) and the indices (not coded) of the
//               vertices on that side (u = 0, v = 0, u = 32767, v = 32767), each list in
//               order along its side (south to north, west to east)
//   extensions  id (uint8), length (uint32), data: 1 = octvertexnormals (2 bytes per vertex,
//               the unit ECEF normal oct-encoded as CesiumJS's AttributeCompression.octEncode),
//               4 = metadata (uint32 length and JSON)
//
// Vertices are written in the order the triangles first use them (which the high-water mark
// needs); vertices no triangle uses are left out. Quantisation: u = round((lon - west) /
// (east - west) * 32767), v likewise with latitude, height against the header's minimum and
// maximum, which are the vertices' least and greatest ellipsoidal heights rounded outwards to
// float, or the range the options give. The bounding sphere and the horizon occlusion point are computed from the positions
// the tile decodes to (DecodedTerrainTile), so they hold for what a client draws.
//
// Throws Error(Input) for a rectangle that is empty or outside [-180, 180] x [-90, 90], a
// vertex outside the rectangle or not finite, a triangle index out of range, normals given
// for some vertices only, a height outside the given range, or more than 2^32 - 1 of anything.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "src/geo/crs_transform.h"
#include "src/tiling/clip_to_tile.h"

namespace terratiles {

struct QuantizedMeshOptions {
  bool vertex_normals = true;  // write the octvertexnormals extension (when normals are given)
  std::string metadata_json;   // the metadata extension's JSON (empty: none)
  // The header's minimum and maximum height (metres, low <= high), shared by every tile of a
  // zoom, so that a vertex two tiles share decodes to the same height in both (a client
  // interpolates between the two); every vertex must lie in it. Unset: the tile's own range.
  std::optional<std::array<float, 2>> height_range;
};

inline constexpr std::uint16_t kQuantizedMax = 32767;

// What a client decodes: the header, and per written vertex its quantised u, v and height and
// the position they stand for.
struct DecodedTerrainTile {
  EcefPoint center;
  float minimum_height_m = 0;
  float maximum_height_m = 0;
  EcefPoint sphere_center;
  double sphere_radius_m = 0;
  EcefPoint horizon_occlusion_point;  // ellipsoid-scaled
  std::vector<std::array<std::uint16_t, 3>> quantized;  // u, v, height per written vertex
  std::vector<GeodeticPoint> positions;                 // as decoded (see decodedPosition)
  std::vector<std::uint32_t> source_vertex;             // written vertex -> mesh vertex
  std::vector<std::uint32_t> triangles;                 // in written vertex indices
  std::array<std::vector<std::uint32_t>, 4> edges;      // west, south, east, north
};

// The tile's bytes (not compressed). `decoded`, when not null, receives what they decode to.
std::vector<std::uint8_t> encodeQuantizedMesh(const TerrainTileMesh& mesh, const QuantizedMeshOptions& options,
                                              DecodedTerrainTile* decoded = nullptr);

// The position a client decodes from quantised values: lon = west + u / 32767 * (east - west),
// likewise latitude and height, in doubles.
GeodeticPoint decodedPosition(const TileBounds& rectangle, float minimum_height_m, float maximum_height_m,
                              const std::array<std::uint16_t, 3>& quantized);

// CesiumJS's horizon culling point (EllipsoidalOccluder.computeHorizonCullingPointFromVertices)
// for points seen in the direction of `direction` (ECEF), in the ellipsoid-scaled frame:
// every point is above the horizon seen from wherever this point is. False when there is
// none (the points span too much of the globe, or `direction` is the origin).
bool horizonOcclusionPoint(const EcefPoint& direction, std::span<const EcefPoint> points, EcefPoint& result);

// What a client culls a terrain tile with, from the positions it decodes (ECEF): their
// bounding sphere (the centre of their box, a millimetre beyond the farthest) and the horizon
// occlusion point seen from its centre (ellipsoid-scaled; for a tile spanning a quarter of
// the globe or more, which has none, a point far out over the centre). Both terrain formats
// carry these (quantized-mesh in its header, 3D Tiles terrain as tile metadata).
struct TerrainTileCulling {
  EcefPoint sphere_center;
  double sphere_radius_m = 0;
  EcefPoint horizon_occlusion_point;
};
TerrainTileCulling terrainTileCulling(std::span<const EcefPoint> ecef);

// [low, high] rounded outwards to floats, as a header holds a height range.
std::array<float, 2> floatRangeAround(double low, double high);

// CesiumJS's AttributeCompression.octEncodeInRange(normal, 255): two bytes.
std::array<std::uint8_t, 2> octEncodeNormal(const std::array<float, 3>& normal);

// gzip (RFC 1952), as quantized-mesh tiles are served: Error(Internal) when zlib fails.
std::vector<std::uint8_t> gzipBytes(std::span<const std::uint8_t> bytes);

}  // namespace terratiles
