#include "formats/quantized_mesh/write_quantized_mesh.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#include "src/base/error.h"

namespace terratiles {
namespace {

// WGS84's semi-axes, for the ellipsoid-scaled frame.
constexpr double kEquatorialRadius = 6378137.0;
constexpr double kPolarRadius = 6356752.3142451793;

class ByteWriter {
 public:
  template <typename T>
  void put(T value) {
    static_assert(std::is_arithmetic_v<T>);
    const auto at = bytes_.size();
    bytes_.resize(at + sizeof(T));
    std::memcpy(bytes_.data() + at, &value, sizeof(T));  // little-endian hosts only (x86-64, arm64)
  }
  void padTo(std::size_t alignment) {
    while (bytes_.size() % alignment != 0) bytes_.push_back(0);
  }
  void putIndex(std::uint32_t index, bool wide) {
    if (wide) {
      put(index);
    } else {
      put(static_cast<std::uint16_t>(index));
    }
  }
  void append(std::span<const std::uint8_t> more) { bytes_.insert(bytes_.end(), more.begin(), more.end()); }
  std::size_t size() const { return bytes_.size(); }
  std::vector<std::uint8_t> take() { return std::move(bytes_); }

 private:
  std::vector<std::uint8_t> bytes_;
};

std::uint16_t zigZag(std::int32_t delta) {
  return static_cast<std::uint16_t>((static_cast<std::uint32_t>(delta) << 1) ^ static_cast<std::uint32_t>(delta >> 31));
}

std::uint16_t quantize(double value, double low, double high) {
  if (!(high > low)) return 0;
  const double q = std::round((value - low) / (high - low) * kQuantizedMax);
  return static_cast<std::uint16_t>(std::clamp(q, 0.0, static_cast<double>(kQuantizedMax)));
}

double lerp(double a, double b, double t) { return (1.0 - t) * a + t * b; }

std::string describe(const TileBounds& r) {
  std::ostringstream text;
  text.precision(12);
  text << "[" << r.west << ", " << r.south << ", " << r.east << ", " << r.north << "]";
  return text.str();
}

void validate(const TerrainTileMesh& mesh) {
  const TileBounds& r = mesh.rectangle;
  if (!(r.west >= -180 && r.west < r.east && r.east <= 180 && r.south >= -90 &&
        r.south < r.north && r.north <= 90)) {
    throw Error(ErrorCode::Input, "quantized-mesh tile: rectangle " + describe(r) +
                                      " (west, south, east, north degrees) is empty or outside the globe; expected "
                                      "-180 <= west < east <= 180 and -90 <= south < north <= 90");
  }
  if (mesh.vertices.size() > std::numeric_limits<std::uint32_t>::max() ||
      mesh.triangles.size() / 3 > std::numeric_limits<std::uint32_t>::max()) {
    throw Error(ErrorCode::Input, "quantized-mesh tile: more than 2^32 - 1 vertices or triangles");
  }
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const GeodeticPoint& p = mesh.vertices[i];
    if (!(p.lon_deg >= r.west && p.lon_deg <= r.east && p.lat_deg >= r.south &&
          p.lat_deg <= r.north && std::isfinite(p.height_m))) {
      std::ostringstream text;
      text.precision(15);
      text << "quantized-mesh tile: vertex " << i << " at (" << p.lon_deg << ", " << p.lat_deg << ", " << p.height_m
           << ") is outside the tile's rectangle " << describe(r)
           << " or not finite; expected every vertex inside it (clip the mesh to the tile first)";
      throw Error(ErrorCode::Input, text.str());
    }
  }
  if (mesh.triangles.size() % 3 != 0) {
    throw Error(ErrorCode::Input, "quantized-mesh tile: " + std::to_string(mesh.triangles.size()) +
                                      " triangle indices; expected 3 per triangle");
  }
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    if (mesh.triangles[i] >= mesh.vertices.size()) {
      throw Error(ErrorCode::Input, "quantized-mesh tile: triangle " + std::to_string(i / 3) + " uses vertex " +
                                        std::to_string(mesh.triangles[i]) + "; expected below the vertex count " +
                                        std::to_string(mesh.vertices.size()));
    }
  }
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.vertices.size()) {
    throw Error(ErrorCode::Input, "quantized-mesh tile: " + std::to_string(mesh.normals.size()) + " normals for " +
                                      std::to_string(mesh.vertices.size()) +
                                      " vertices; expected one per vertex or none");
  }
}

EcefPoint scaled(const EcefPoint& p) {
  return {p.x / kEquatorialRadius, p.y / kEquatorialRadius, p.z / kPolarRadius};
}

double dot(const EcefPoint& a, const EcefPoint& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

EcefPoint cross(const EcefPoint& a, const EcefPoint& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

}  // namespace

GeodeticPoint decodedPosition(const TileBounds& rectangle, float minimum_height_m, float maximum_height_m,
                              const std::array<std::uint16_t, 3>& quantized) {
  const double u = quantized[0] / static_cast<double>(kQuantizedMax);
  const double v = quantized[1] / static_cast<double>(kQuantizedMax);
  const double h = quantized[2] / static_cast<double>(kQuantizedMax);
  return {lerp(rectangle.west, rectangle.east, u), lerp(rectangle.south, rectangle.north, v),
          lerp(minimum_height_m, maximum_height_m, h)};
}

bool horizonOcclusionPoint(const EcefPoint& direction, std::span<const EcefPoint> points, EcefPoint& result) {
  EcefPoint toward = scaled(direction);
  const double length = std::sqrt(dot(toward, toward));
  if (!(length > 0)) return false;
  toward = {toward.x / length, toward.y / length, toward.z / length};
  double largest = 0;
  for (const EcefPoint& point : points) {
    const EcefPoint s = scaled(point);
    double magnitude_squared = dot(s, s);
    double magnitude = std::sqrt(magnitude_squared);
    const EcefPoint unit{s.x / magnitude, s.y / magnitude, s.z / magnitude};
    // A point below the ellipsoid counts as on it.
    magnitude_squared = std::max(1.0, magnitude_squared);
    magnitude = std::max(1.0, magnitude);
    const double cos_alpha = dot(unit, toward);
    const EcefPoint c = cross(unit, toward);
    const double sin_alpha = std::sqrt(dot(c, c));
    const double cos_beta = 1.0 / magnitude;
    const double sin_beta = std::sqrt(magnitude_squared - 1.0) * cos_beta;
    const double candidate = 1.0 / (cos_alpha * cos_beta - sin_alpha * sin_beta);
    if (!(candidate >= 0)) return false;  // this point faces away (or NaN)
    largest = std::max(largest, candidate);
  }
  if (!(largest > 0) || !std::isfinite(largest)) return false;
  result = {toward.x * largest, toward.y * largest, toward.z * largest};
  return true;
}

TerrainTileCulling terrainTileCulling(std::span<const EcefPoint> ecef) {
  TerrainTileCulling culling;
  // The bounding sphere: the centre of the points' box, the farthest point's distance.
  if (!ecef.empty()) {
    EcefPoint lo = ecef[0], hi = ecef[0];
    for (const EcefPoint& p : ecef) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    culling.sphere_center = {(lo.x + hi.x) / 2, (lo.y + hi.y) / 2, (lo.z + hi.z) / 2};
    double radius_squared = 0;
    for (const EcefPoint& p : ecef) {
      const EcefPoint d{p.x - culling.sphere_center.x, p.y - culling.sphere_center.y, p.z - culling.sphere_center.z};
      radius_squared = std::max(radius_squared, dot(d, d));
    }
    // A millimetre more than the farthest vertex: a client's float arithmetic stays inside.
    culling.sphere_radius_m = std::sqrt(radius_squared) + 1e-3;
  }
  if (!horizonOcclusionPoint(culling.sphere_center, ecef, culling.horizon_occlusion_point)) {
    // The tile spans too much of the globe for a point every vertex is in front of (a quarter
    // of it and more): a point far out over its centre, which only a view from the far side
    // of the Earth puts behind the horizon.
    EcefPoint toward = scaled(culling.sphere_center);
    const double length = std::sqrt(dot(toward, toward));
    culling.horizon_occlusion_point =
        length > 0 ? EcefPoint{toward.x / length * 1e3, toward.y / length * 1e3, toward.z / length * 1e3}
                   : EcefPoint{0, 0, 1e3};
  }
  return culling;
}

std::array<float, 2> floatRangeAround(double low, double high) {
  float low_f = static_cast<float>(low), high_f = static_cast<float>(high);
  if (low_f > low) low_f = std::nextafter(low_f, -std::numeric_limits<float>::infinity());
  if (high_f < high) high_f = std::nextafter(high_f, std::numeric_limits<float>::infinity());
  return {low_f, high_f};
}

std::array<std::uint8_t, 2> octEncodeNormal(const std::array<float, 3>& normal) {
  const double x = normal[0], y = normal[1], z = normal[2];
  const double sum = std::fabs(x) + std::fabs(y) + std::fabs(z);
  double ox = sum > 0 ? x / sum : 0, oy = sum > 0 ? y / sum : 0;
  if (z < 0) {
    const double px = ox, py = oy;
    ox = (1.0 - std::fabs(py)) * (px < 0 ? -1.0 : 1.0);
    oy = (1.0 - std::fabs(px)) * (py < 0 ? -1.0 : 1.0);
  }
  const auto snorm = [](double value) {
    // CesiumMath.toSNorm: Math.round, which rounds halves up (the value is never negative).
    return static_cast<std::uint8_t>(std::floor((std::clamp(value, -1.0, 1.0) * 0.5 + 0.5) * 255.0 + 0.5));
  };
  return {snorm(ox), snorm(oy)};
}

std::vector<std::uint8_t> encodeQuantizedMesh(const TerrainTileMesh& mesh, const QuantizedMeshOptions& options,
                                              DecodedTerrainTile* decoded) {
  validate(mesh);
  DecodedTerrainTile tile;
  // Vertices in the order the triangles first use them.
  constexpr std::uint32_t kUnused = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> written_index(mesh.vertices.size(), kUnused);
  tile.triangles.reserve(mesh.triangles.size());
  for (const std::uint32_t v : mesh.triangles) {
    if (written_index[v] == kUnused) {
      written_index[v] = static_cast<std::uint32_t>(tile.source_vertex.size());
      tile.source_vertex.push_back(v);
    }
    tile.triangles.push_back(written_index[v]);
  }
  const std::size_t count = tile.source_vertex.size();

  // Heights: the range rounded outwards to float, so every height quantises inside it.
  double low = 0, high = 0;
  if (count > 0) {
    low = std::numeric_limits<double>::infinity();
    high = -low;
    for (const std::uint32_t v : tile.source_vertex) {
      low = std::min(low, mesh.vertices[v].height_m);
      high = std::max(high, mesh.vertices[v].height_m);
    }
  }
  auto [low_f, high_f] = floatRangeAround(low, high);
  if (options.height_range) {
    const auto [range_low, range_high] = *options.height_range;
    if (count > 0 && !(range_low <= low && high <= range_high)) {
      throw Error(ErrorCode::Internal, "quantized-mesh tile: heights " + std::to_string(low) + " .. " +
                                           std::to_string(high) + " m outside the shared range " +
                                           std::to_string(range_low) + " .. " + std::to_string(range_high) + " m");
    }
    low_f = range_low;
    high_f = range_high;
  }
  tile.minimum_height_m = low_f;
  tile.maximum_height_m = high_f;

  const TileBounds& r = mesh.rectangle;
  tile.quantized.resize(count);
  tile.positions.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    const GeodeticPoint& p = mesh.vertices[tile.source_vertex[i]];
    tile.quantized[i] = {quantize(p.lon_deg, r.west, r.east), quantize(p.lat_deg, r.south, r.north),
                         quantize(p.height_m, low_f, high_f)};
    tile.positions[i] = decodedPosition(r, low_f, high_f, tile.quantized[i]);
  }

  // The bounding sphere of the decoded positions and the horizon occlusion point seen from
  // its centre; the tile's centre is the sphere's.
  std::vector<EcefPoint> ecef(count);
  geodeticToEcef(tile.positions, ecef);
  const TerrainTileCulling culling = terrainTileCulling(ecef);
  tile.sphere_center = culling.sphere_center;
  tile.sphere_radius_m = culling.sphere_radius_m;
  tile.horizon_occlusion_point = culling.horizon_occlusion_point;
  tile.center = tile.sphere_center;

  // The vertices on each side, in order along it.
  for (std::uint32_t i = 0; i < count; ++i) {
    const auto& q = tile.quantized[i];
    if (q[0] == 0) tile.edges[0].push_back(i);
    if (q[1] == 0) tile.edges[1].push_back(i);
    if (q[0] == kQuantizedMax) tile.edges[2].push_back(i);
    if (q[1] == kQuantizedMax) tile.edges[3].push_back(i);
  }
  for (int side = 0; side < 4; ++side) {
    const int along = side % 2 == 0 ? 1 : 0;  // west and east run along v, south and north along u
    std::stable_sort(tile.edges[side].begin(), tile.edges[side].end(), [&](std::uint32_t a, std::uint32_t b) {
      return tile.quantized[a][along] < tile.quantized[b][along];
    });
  }

  ByteWriter out;
  out.put(tile.center.x);
  out.put(tile.center.y);
  out.put(tile.center.z);
  out.put(tile.minimum_height_m);
  out.put(tile.maximum_height_m);
  out.put(tile.sphere_center.x);
  out.put(tile.sphere_center.y);
  out.put(tile.sphere_center.z);
  out.put(tile.sphere_radius_m);
  out.put(tile.horizon_occlusion_point.x);
  out.put(tile.horizon_occlusion_point.y);
  out.put(tile.horizon_occlusion_point.z);

  out.put(static_cast<std::uint32_t>(count));
  for (int component = 0; component < 3; ++component) {
    std::int32_t previous = 0;
    for (std::size_t i = 0; i < count; ++i) {
      const std::int32_t value = tile.quantized[i][static_cast<std::size_t>(component)];
      out.put(zigZag(value - previous));
      previous = value;
    }
  }

  const bool wide = count > 65536;
  if (wide) out.padTo(4);
  out.put(static_cast<std::uint32_t>(tile.triangles.size() / 3));
  std::uint32_t highest = 0;
  for (const std::uint32_t index : tile.triangles) {
    out.putIndex(highest - index, wide);
    if (index == highest) ++highest;
  }
  for (const auto& edge : tile.edges) {
    out.put(static_cast<std::uint32_t>(edge.size()));
    for (const std::uint32_t index : edge) out.putIndex(index, wide);
  }

  if (options.vertex_normals && !mesh.normals.empty()) {
    out.put(std::uint8_t{1});
    out.put(static_cast<std::uint32_t>(2 * count));
    for (const std::uint32_t v : tile.source_vertex) {
      const auto oct = octEncodeNormal(mesh.normals[v]);
      out.put(oct[0]);
      out.put(oct[1]);
    }
  }
  if (!options.metadata_json.empty()) {
    out.put(std::uint8_t{4});
    out.put(static_cast<std::uint32_t>(4 + options.metadata_json.size()));
    out.put(static_cast<std::uint32_t>(options.metadata_json.size()));
    out.append({reinterpret_cast<const std::uint8_t*>(options.metadata_json.data()), options.metadata_json.size()});
  }
  if (decoded) *decoded = std::move(tile);
  return out.take();
}

std::vector<std::uint8_t> gzipBytes(std::span<const std::uint8_t> bytes) {
  if (bytes.size() > std::numeric_limits<uInt>::max() / 2) {
    throw Error(ErrorCode::Internal, "gzip: " + std::to_string(bytes.size()) + " bytes; expected below 2 GB");
  }
  z_stream stream{};
  // 15 + 16: a gzip header and trailer around the deflate stream.
  if (deflateInit2(&stream, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
    throw Error(ErrorCode::Internal, "gzip: zlib's deflateInit2 failed");
  }
  std::vector<std::uint8_t> out(deflateBound(&stream, static_cast<uLong>(bytes.size())) + 32);
  stream.next_in = const_cast<Bytef*>(bytes.data());
  stream.avail_in = static_cast<uInt>(bytes.size());
  stream.next_out = out.data();
  stream.avail_out = static_cast<uInt>(out.size());
  const int status = deflate(&stream, Z_FINISH);
  const std::size_t written = out.size() - stream.avail_out;
  deflateEnd(&stream);
  if (status != Z_STREAM_END) throw Error(ErrorCode::Internal, "gzip: zlib's deflate did not finish");
  out.resize(written);
  return out;
}

}  // namespace terratiles
