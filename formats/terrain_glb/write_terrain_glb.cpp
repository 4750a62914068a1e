#include "formats/terrain_glb/write_terrain_glb.h"

#include <GeographicLib/Geocentric.hpp>
#include <meshoptimizer.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>

#include <nlohmann/json.hpp>

#include "src/base/error.h"

namespace terratiles {
namespace {

constexpr std::uint32_t kPositionMax = 65535;
constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;
constexpr int kByte = 5120;
constexpr int kUnsignedShort = 5123;
constexpr int kUnsignedInt = 5125;

[[noreturn]] void refuse(const std::string& what) {
  throw Error(ErrorCode::Input, "3D Tiles terrain tile: " + what);
}

void validate(const TerrainTileMesh& mesh) {
  const TileBounds& r = mesh.rectangle;
  if (mesh.triangles.empty() || mesh.triangles.size() % 3 != 0) {
    refuse(std::to_string(mesh.triangles.size()) + " triangle indices; expected a positive multiple of 3");
  }
  for (const std::uint32_t v : mesh.triangles) {
    if (v >= mesh.vertices.size()) {
      refuse("triangle index " + std::to_string(v) + " for " + std::to_string(mesh.vertices.size()) + " vertices");
    }
  }
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.vertices.size()) {
    refuse(std::to_string(mesh.normals.size()) + " normals for " + std::to_string(mesh.vertices.size()) +
           " vertices; expected one per vertex or none");
  }
  for (const GeodeticPoint& p : mesh.vertices) {
    if (!(p.lon_deg >= r.west && p.lon_deg <= r.east && p.lat_deg >= r.south && p.lat_deg <= r.north) ||
        !std::isfinite(p.height_m)) {
      refuse("vertex (" + std::to_string(p.lon_deg) + ", " + std::to_string(p.lat_deg) + ", " +
             std::to_string(p.height_m) + ") outside the rectangle or not finite");
    }
  }
}

struct Vector3 {
  double x = 0, y = 0, z = 0;
};
double dot(const Vector3& a, const Vector3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

// The GLB's binary chunk (the compressed views) and the fallback buffer's layout (the views'
// uncompressed sizes), both with views at multiples of 4 bytes.
class MeshoptViews {
 public:
  // Adds one view; `stride` is the element size, `count` the elements.
  int add(std::vector<std::uint8_t> compressed, std::size_t count, std::size_t stride, const char* mode,
          int target, const char* filter) {
    nlohmann::json view;
    view["buffer"] = 1;
    view["byteOffset"] = fallback_length_;
    view["byteLength"] = count * stride;
    if (std::strcmp(mode, "ATTRIBUTES") == 0) view["byteStride"] = stride;
    if (target) view["target"] = target;
    nlohmann::json& meshopt = view["extensions"]["EXT_meshopt_compression"];
    meshopt["buffer"] = 0;
    meshopt["byteOffset"] = binary_.size();
    meshopt["byteLength"] = compressed.size();
    meshopt["byteStride"] = stride;
    meshopt["count"] = count;
    meshopt["mode"] = mode;
    if (filter) meshopt["filter"] = filter;
    views_.push_back(std::move(view));
    fallback_length_ += (count * stride + 3) / 4 * 4;
    binary_.insert(binary_.end(), compressed.begin(), compressed.end());
    binary_.resize((binary_.size() + 3) / 4 * 4, 0);
    return static_cast<int>(views_.size()) - 1;
  }
  nlohmann::json views() const { return views_; }
  std::size_t fallbackLength() const { return fallback_length_; }
  const std::vector<std::uint8_t>& binary() const { return binary_; }

 private:
  nlohmann::json views_ = nlohmann::json::array();
  std::vector<std::uint8_t> binary_;
  std::size_t fallback_length_ = 0;
};

std::vector<std::uint8_t> encodeIndices(const std::vector<std::uint32_t>& indices, std::size_t vertex_count,
                                        bool sequence) {
  std::vector<std::uint8_t> out(sequence ? meshopt_encodeIndexSequenceBound(indices.size(), vertex_count)
                                         : meshopt_encodeIndexBufferBound(indices.size(), vertex_count));
  const std::size_t size = sequence ? meshopt_encodeIndexSequence(out.data(), out.size(), indices.data(), indices.size())
                                    : meshopt_encodeIndexBuffer(out.data(), out.size(), indices.data(), indices.size());
  if (size == 0) throw Error(ErrorCode::Internal, "3D Tiles terrain tile: meshoptimizer could not code the indices");
  out.resize(size);
  return out;
}

template <typename T>
std::vector<std::uint8_t> encodeVertices(const std::vector<T>& values, std::size_t count) {
  const std::size_t stride = values.size() / count * sizeof(T);
  std::vector<std::uint8_t> out(meshopt_encodeVertexBufferBound(count, stride));
  const std::size_t size = meshopt_encodeVertexBuffer(out.data(), out.size(), values.data(), count, stride);
  if (size == 0) throw Error(ErrorCode::Internal, "3D Tiles terrain tile: meshoptimizer could not code the vertices");
  out.resize(size);
  return out;
}

void appendUint32(std::vector<std::uint8_t>& out, std::uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(value >> (8 * i)));
}

}  // namespace

double terrainTileExtent(const TerrainTileMesh& mesh) {
  std::vector<EcefPoint> ecef(mesh.vertices.size());
  geodeticToEcef(mesh.vertices, ecef);
  if (ecef.empty()) return 0;
  EcefPoint lo = ecef[0], hi = ecef[0];
  for (const EcefPoint& p : ecef) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  return std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
}

TerrainGlb encodeTerrainGlb(const TerrainTileMesh& mesh, const std::string& generator, double lattice_step_m,
                            DecodedTerrainGlb* decoded) {
  validate(mesh);
  const TileBounds& r = mesh.rectangle;

  // Triangle order for the vertex cache, then vertices in the order the triangles use them.
  std::vector<std::uint32_t> triangles(mesh.triangles.size());
  meshopt_optimizeVertexCache(triangles.data(), mesh.triangles.data(), mesh.triangles.size(), mesh.vertices.size());
  std::vector<std::uint32_t> remap(mesh.vertices.size());
  const std::size_t count =
      meshopt_optimizeVertexFetchRemap(remap.data(), triangles.data(), triangles.size(), mesh.vertices.size());
  std::vector<std::uint32_t> source_vertex(count);
  for (std::uint32_t v = 0; v < remap.size(); ++v) {
    if (remap[v] != ~0u) source_vertex[remap[v]] = v;
  }
  for (std::uint32_t& v : triangles) v = remap[v];

  std::vector<GeodeticPoint> used(count);
  for (std::size_t i = 0; i < count; ++i) used[i] = mesh.vertices[source_vertex[i]];
  std::vector<EcefPoint> ecef(count);
  geodeticToEcef(used, ecef);

  // The cube in glTF's axes (x, y, z = ECEF x, z, -y): its corner on a multiple of the step,
  // so that every tile quantising on the same step puts a vertex on the same lattice point.
  std::vector<Vector3> local(count);
  for (std::size_t i = 0; i < count; ++i) local[i] = {ecef[i].x, ecef[i].z, -ecef[i].y};
  const double extent = terrainTileExtent(mesh);
  const double step = lattice_step_m > 0 ? lattice_step_m : std::max(extent, 1e-3) / (kPositionMax - 1);
  if (!(extent <= step * (kPositionMax - 1))) {
    throw Error(ErrorCode::Internal, "3D Tiles terrain tile: extent " + std::to_string(extent) + " m exceeds " +
                                         std::to_string(kPositionMax - 1) + " steps of " + std::to_string(step) + " m");
  }
  Vector3 low{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
              std::numeric_limits<double>::infinity()};
  for (const Vector3& v : local) low = {std::min(low.x, v.x), std::min(low.y, v.y), std::min(low.z, v.z)};
  // Lattice indices: of the corner, and of each vertex (from its coordinates alone, so two
  // tiles give a shared vertex the same one).
  const Vector3 low_index{std::floor(low.x / step), std::floor(low.y / step), std::floor(low.z / step)};
  low = {low_index.x * step, low_index.y * step, low_index.z * step};
  const double cube_side = step * kPositionMax;
  // The unit cube to ECEF: M = [R side | R low], R's columns the glTF axes in ECEF (1, 0, 0),
  // (0, 0, 1), (0, -1, 0). In glTF's frame the node matrix is side times the identity plus a
  // translation: the glTF validator's TRS check (a float32 decomposition) recomposes it exactly.
  const double m[3][4] = {{cube_side, 0, 0, low.x}, {0, 0, -cube_side, -low.z}, {0, cube_side, 0, low.y}};

  // Positions: 16 bits per axis of the box, the fourth component unused.
  std::vector<std::uint16_t> positions(count * 4, 0);
  std::array<std::uint32_t, 3> q_min{kPositionMax, kPositionMax, kPositionMax}, q_max{0, 0, 0};
  std::vector<EcefPoint> decoded_positions(count);
  const auto quantise = [step](double value, double corner_index) {
    return static_cast<std::uint16_t>(
        std::clamp(std::nearbyint(value / step) - corner_index, 0.0, static_cast<double>(kPositionMax)));
  };
  for (std::size_t i = 0; i < count; ++i) {
    const std::array<std::uint16_t, 3> q{quantise(local[i].x, low_index.x), quantise(local[i].y, low_index.y),
                                         quantise(local[i].z, low_index.z)};
    double f[3];
    for (int a = 0; a < 3; ++a) {
      positions[i * 4 + a] = q[a];
      q_min[a] = std::min<std::uint32_t>(q_min[a], q[a]);
      q_max[a] = std::max<std::uint32_t>(q_max[a], q[a]);
      // As CesiumJS decodes: value / 65535 as a float, then the matrix in doubles.
      f[a] = static_cast<float>(q[a] / static_cast<double>(kPositionMax));
    }
    decoded_positions[i] = {m[0][0] * f[0] + m[0][1] * f[1] + m[0][2] * f[2] + m[0][3],
                            m[1][0] * f[0] + m[1][1] * f[1] + m[1][2] * f[2] + m[1][3],
                            m[2][0] * f[0] + m[2][1] * f[1] + m[2][2] * f[2] + m[2][3]};
  }

  TerrainGlb result;
  result.vertices = count;
  result.position_step_m = step;
  result.triangles = triangles.size() / 3;
  result.culling = terrainTileCulling(decoded_positions);
  result.minimum_height_m = std::numeric_limits<double>::infinity();
  result.maximum_height_m = -result.minimum_height_m;
  const GeographicLib::Geocentric& earth = GeographicLib::Geocentric::WGS84();
  for (const EcefPoint& p : decoded_positions) {
    double lat = 0, lon = 0, h = 0;
    earth.Reverse(p.x, p.y, p.z, lat, lon, h);
    result.minimum_height_m = std::min(result.minimum_height_m, h);
    result.maximum_height_m = std::max(result.maximum_height_m, h);
  }

  // The sides' vertices, in the order CesiumJS's skirts take them.
  std::array<std::vector<std::uint32_t>, 4> edges;
  for (std::uint32_t i = 0; i < count; ++i) {
    if (used[i].lon_deg == r.west) edges[0].push_back(i);
    if (used[i].lat_deg == r.south) edges[1].push_back(i);
    if (used[i].lon_deg == r.east) edges[2].push_back(i);
    if (used[i].lat_deg == r.north) edges[3].push_back(i);
  }
  const char* side_names[4] = {"west", "south", "east", "north"};
  for (int side = 0; side < 4; ++side) {
    if (edges[side].empty()) refuse(std::string("no vertex on the tile's ") + side_names[side] + " side");
    // West south to north, south east to west, east north to south, north west to east.
    const bool by_latitude = side % 2 == 0;
    const bool increasing = side == 0 || side == 3;
    std::sort(edges[side].begin(), edges[side].end(), [&](std::uint32_t a, std::uint32_t b) {
      const double ka = by_latitude ? used[a].lat_deg : used[a].lon_deg;
      const double kb = by_latitude ? used[b].lat_deg : used[b].lon_deg;
      return increasing ? std::tie(ka, a) < std::tie(kb, b) : std::tie(kb, a) < std::tie(ka, b);
    });
  }

  const bool short_indices = count <= 65535;
  const std::size_t index_size = short_indices ? 2 : 4;
  MeshoptViews views;
  nlohmann::json accessors = nlohmann::json::array();
  nlohmann::json attributes;
  {
    nlohmann::json accessor;
    accessor["bufferView"] = views.add(encodeVertices(positions, count), count, 8, "ATTRIBUTES", kArrayBuffer, nullptr);
    accessor["componentType"] = kUnsignedShort;
    accessor["normalized"] = true;
    accessor["count"] = count;
    accessor["type"] = "VEC3";
    accessor["min"] = q_min;
    accessor["max"] = q_max;
    attributes["POSITION"] = accessors.size();
    accessors.push_back(std::move(accessor));
  }
  if (!mesh.normals.empty()) {
    // n_stored = R^T n: CesiumJS applies M's linear part (R times the side) and normalises.
    std::vector<float> normals(count * 4, 0.0f);
    for (std::size_t i = 0; i < count; ++i) {
      const auto& n = mesh.normals[source_vertex[i]];
      const Vector3 e{n[0], n[1], n[2]};
      Vector3 v{e.x, e.z, -e.y};  // R^T n: glTF's axes
      const double length = std::sqrt(dot(v, v));
      if (length > 0) v = {v.x / length, v.y / length, v.z / length};
      normals[i * 4 + 0] = static_cast<float>(v.x);
      normals[i * 4 + 1] = static_cast<float>(v.y);
      normals[i * 4 + 2] = static_cast<float>(v.z);
    }
    std::vector<std::int8_t> octahedral(count * 4);
    meshopt_encodeFilterOct(octahedral.data(), count, 4, 8, normals.data());
    nlohmann::json accessor;
    accessor["bufferView"] =
        views.add(encodeVertices(octahedral, count), count, 4, "ATTRIBUTES", kArrayBuffer, "OCTAHEDRAL");
    accessor["componentType"] = kByte;
    accessor["normalized"] = true;
    accessor["count"] = count;
    accessor["type"] = "VEC3";
    attributes["NORMAL"] = accessors.size();
    accessors.push_back(std::move(accessor));
  }
  const auto index_accessor = [&](const std::vector<std::uint32_t>& indices, bool sequence) {
    nlohmann::json accessor;
    accessor["bufferView"] = views.add(encodeIndices(indices, count, sequence), indices.size(), index_size,
                                       sequence ? "INDICES" : "TRIANGLES", sequence ? 0 : kElementArrayBuffer, nullptr);
    accessor["componentType"] = short_indices ? kUnsignedShort : kUnsignedInt;
    accessor["count"] = indices.size();
    accessor["type"] = "SCALAR";
    accessors.push_back(std::move(accessor));
    return accessors.size() - 1;
  };
  nlohmann::json primitive;
  primitive["attributes"] = std::move(attributes);
  primitive["indices"] = index_accessor(triangles, false);
  primitive["mode"] = 4;
  nlohmann::json& tile_edges = primitive["extensions"]["CESIUM_tile_edges"];
  tile_edges["left"] = index_accessor(edges[0], true);
  tile_edges["bottom"] = index_accessor(edges[1], true);
  tile_edges["right"] = index_accessor(edges[2], true);
  tile_edges["top"] = index_accessor(edges[3], true);

  nlohmann::json gltf;
  gltf["asset"] = {{"version", "2.0"}, {"generator", generator}};
  gltf["extensionsUsed"] = {"CESIUM_tile_edges", "EXT_meshopt_compression", "KHR_mesh_quantization"};
  gltf["extensionsRequired"] = {"EXT_meshopt_compression", "KHR_mesh_quantization"};
  gltf["scene"] = 0;
  gltf["scenes"] = nlohmann::json::array({{{"nodes", {0}}}});
  // glTF is Y-up, 3D Tiles Z-up: the node holds (x, y, z) -> (x, z, -y) after M.
  nlohmann::json matrix = nlohmann::json::array();
  for (int column = 0; column < 4; ++column) {
    matrix.push_back(m[0][column]);
    matrix.push_back(m[2][column]);
    matrix.push_back(-m[1][column]);
    matrix.push_back(column == 3 ? 1.0 : 0.0);
  }
  gltf["nodes"] = nlohmann::json::array({{{"mesh", 0}, {"matrix", std::move(matrix)}}});
  gltf["meshes"] = nlohmann::json::array({{{"primitives", nlohmann::json::array({std::move(primitive)})}}});
  gltf["accessors"] = std::move(accessors);
  gltf["bufferViews"] = views.views();
  nlohmann::json fallback;
  fallback["byteLength"] = views.fallbackLength();
  fallback["extensions"]["EXT_meshopt_compression"]["fallback"] = true;
  gltf["buffers"] = nlohmann::json::array({{{"byteLength", views.binary().size()}}, std::move(fallback)});

  // GLB: header, JSON chunk (padded with spaces), binary chunk (padded with zeros).
  std::string text = gltf.dump();
  text.resize((text.size() + 3) / 4 * 4, ' ');
  const std::vector<std::uint8_t>& binary = views.binary();
  std::vector<std::uint8_t>& out = result.bytes;
  out.reserve(28 + text.size() + binary.size());
  appendUint32(out, 0x46546C67u);  // "glTF"
  appendUint32(out, 2);
  appendUint32(out, static_cast<std::uint32_t>(28 + text.size() + binary.size()));
  appendUint32(out, static_cast<std::uint32_t>(text.size()));
  appendUint32(out, 0x4E4F534Au);  // "JSON"
  out.insert(out.end(), text.begin(), text.end());
  appendUint32(out, static_cast<std::uint32_t>(binary.size()));
  appendUint32(out, 0x004E4942u);  // "BIN"
  out.insert(out.end(), binary.begin(), binary.end());

  if (decoded) {
    decoded->positions = std::move(decoded_positions);
    decoded->source_vertex = std::move(source_vertex);
    decoded->triangles = std::move(triangles);
    decoded->edges = std::move(edges);
  }
  return result;
}

}  // namespace terratiles
