#include "src/tiling/clip_to_tile.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <unordered_map>

#include "src/base/error.h"

namespace terratiles {
namespace {

enum Side : std::uint8_t { kWest, kSouth, kEast, kNorth };

// What a polygon edge runs along: a triangle edge (the mesh vertices a < b), or a side.
struct Support {
  bool on_side = false;
  Side side = kWest;
  std::uint32_t a = 0, b = 0;
};

struct PolygonVertex {
  GeodeticPoint point;
  std::array<double, 3> normal{};
  // Who the vertex is, so that a tile makes it once: a mesh vertex (a), where the triangle
  // edge (a, b) crosses `side`, or the rectangle's corner between `side` and the next side.
  enum Kind : std::uint8_t { kMeshVertex, kCrossing, kCorner } kind = kMeshVertex;
  std::uint32_t a = 0, b = 0;
  Side side = kWest;
  Support next;  // the polygon edge from this vertex to the next
};

struct VertexKey {
  std::uint64_t first = 0, second = 0;
  bool operator==(const VertexKey&) const = default;
};
struct VertexKeyHash {
  std::size_t operator()(const VertexKey& key) const {
    return std::hash<std::uint64_t>()(key.first * 0x9E3779B97F4A7C15ull ^ key.second);
  }
};

VertexKey keyOf(const PolygonVertex& v) {
  const std::uint64_t kind = v.kind, side = v.side;
  return {(kind << 40) | (side << 32) | v.a, v.b};
}

double along(const GeodeticPoint& p, Side side) {
  return side == kWest || side == kEast ? p.lon_deg : p.lat_deg;
}

// Signed distance inside: >= 0 inside the rectangle's half-plane of `side`.
double inside(const GeodeticPoint& p, Side side, const TileBounds& r) {
  switch (side) {
    case kWest: return p.lon_deg - r.west;
    case kEast: return r.east - p.lon_deg;
    case kSouth: return p.lat_deg - r.south;
    case kNorth: return r.north - p.lat_deg;
  }
  return 0;
}

double sideLine(Side side, const TileBounds& r) {
  switch (side) {
    case kWest: return r.west;
    case kEast: return r.east;
    case kSouth: return r.south;
    case kNorth: return r.north;
  }
  return 0;
}

std::array<double, 3> normalOf(const GeodeticMesh& mesh, std::uint32_t v) {
  if (mesh.normals.empty()) return {0, 0, 0};
  const auto& n = mesh.normals[v];
  return {n[0], n[1], n[2]};
}

class TriangleClipper {
 public:
  TriangleClipper(const GeodeticMesh& mesh, const TileBounds& rectangle) : mesh_(mesh), r_(rectangle) {}

  // The polygon of triangle t inside the rectangle (empty when none).
  const std::vector<PolygonVertex>& clip(std::uint32_t t) {
    const std::uint32_t* corners = &mesh_.triangles[3 * static_cast<std::size_t>(t)];
    polygon_.clear();
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = corners[k], w = corners[(k + 1) % 3];
      PolygonVertex vertex;
      vertex.point = mesh_.vertices[v];
      vertex.normal = normalOf(mesh_, v);
      vertex.kind = PolygonVertex::kMeshVertex;
      vertex.a = v;
      vertex.next = {false, kWest, std::min(v, w), std::max(v, w)};
      polygon_.push_back(vertex);
    }
    for (const Side side : {kWest, kSouth, kEast, kNorth}) {
      clipAgainst(side);
      if (polygon_.size() < 3) {
        polygon_.clear();
        break;
      }
    }
    return polygon_;
  }

 private:
  void clipAgainst(Side side) {
    next_polygon_.clear();
    const std::size_t n = polygon_.size();
    for (std::size_t i = 0; i < n; ++i) {
      const PolygonVertex& p = polygon_[i];
      const PolygonVertex& q = polygon_[(i + 1) % n];
      const double dp = inside(p.point, side, r_), dq = inside(q.point, side, r_);
      if (dp >= 0) {
        PolygonVertex kept = p;
        if (dp == 0 && dq < 0) kept.next = {true, side, 0, 0};
        next_polygon_.push_back(kept);
      }
      if ((dp > 0 && dq < 0) || (dp < 0 && dq > 0)) {
        PolygonVertex crossing = cross(p.next, side);
        crossing.next = dp > 0 ? Support{true, side, 0, 0} : p.next;
        next_polygon_.push_back(crossing);
      }
    }
    polygon_.swap(next_polygon_);
  }

  // Where the polygon edge along `support` crosses `side`.
  PolygonVertex cross(const Support& support, Side side) const {
    const bool side_is_meridian = side == kWest || side == kEast;
    const double line = sideLine(side, r_);
    if (support.on_side) return corner(side_is_meridian ? line : sideLine(support.side, r_),
                                       side_is_meridian ? sideLine(support.side, r_) : line);
    // The triangle edge (a, b), a < b, from a: the same numbers in every tile.
    const GeodeticPoint& a = mesh_.vertices[support.a];
    const GeodeticPoint& b = mesh_.vertices[support.b];
    const double t = (line - along(a, side)) / (along(b, side) - along(a, side));
    const double other =
        side_is_meridian ? a.lat_deg + t * (b.lat_deg - a.lat_deg) : a.lon_deg + t * (b.lon_deg - a.lon_deg);
    // An edge through a corner of the rectangle (within rounding) meets both its sides there:
    // the corner, which each of the four tiles around it computes alike, whichever side it
    // crosses first.
    const std::array<Side, 2> across_sides =
        side_is_meridian ? std::array<Side, 2>{kSouth, kNorth} : std::array<Side, 2>{kWest, kEast};
    for (const Side across : across_sides) {
      const double other_line = sideLine(across, r_);
      if (std::fabs(other - other_line) <= 1e-12 * std::max(1.0, std::fabs(other_line))) {
        return corner(side_is_meridian ? line : other_line, side_is_meridian ? other_line : line);
      }
    }
    PolygonVertex v;
    v.kind = PolygonVertex::kCrossing;
    v.side = side;
    v.a = support.a;
    v.b = support.b;
    const double height = a.height_m + t * (b.height_m - a.height_m);
    v.point = side_is_meridian ? GeodeticPoint{line, other, height} : GeodeticPoint{other, line, height};
    const auto na = normalOf(mesh_, support.a), nb = normalOf(mesh_, support.b);
    for (std::size_t k = 0; k < 3; ++k) v.normal[k] = na[k] + t * (nb[k] - na[k]);
    return v;
  }

  // The rectangle's corner at (lon, lat). Its height and normal come later, from the one
  // triangle every tile around the corner takes (cornerOnSurface).
  PolygonVertex corner(double lon, double lat) const {
    PolygonVertex v;
    v.kind = PolygonVertex::kCorner;
    v.a = static_cast<std::uint32_t>((lon == r_.east ? 1 : 0) + (lat == r_.north ? 2 : 0));
    v.point = {lon, lat, 0};
    return v;
  }

  const GeodeticMesh& mesh_;
  const TileBounds r_;
  std::vector<PolygonVertex> polygon_, next_polygon_;
};

double area2(const GeodeticPoint& a, const GeodeticPoint& b, const GeodeticPoint& c) {
  return (b.lon_deg - a.lon_deg) * (c.lat_deg - a.lat_deg) - (b.lat_deg - a.lat_deg) * (c.lon_deg - a.lon_deg);
}

// A rectangle corner's height and normal on the mesh: from the lowest-numbered candidate
// triangle that holds it (sides included), or where rounding leaves it in none, the one it is
// least outside of. Every tile around the corner has those triangles among its candidates, so
// all of them compute the same bits, also where the corner is on a mesh edge or vertex. False
// when there is no candidate.
bool cornerOnSurface(const GeodeticMesh& mesh, std::span<const std::uint32_t> candidates, GeodeticPoint& corner,
                     std::array<double, 3>& normal) {
  std::uint32_t holder = 0xffffffff;
  double least_outside = std::numeric_limits<double>::infinity();
  for (const std::uint32_t t : candidates) {
    const std::uint32_t* v = &mesh.triangles[3 * static_cast<std::size_t>(t)];
    const GeodeticPoint &a = mesh.vertices[v[0]], &b = mesh.vertices[v[1]], &c = mesh.vertices[v[2]];
    const double whole = area2(a, b, c);
    if (!(whole > 0)) continue;
    const double outside =
        std::max(0.0, -std::min({area2(a, b, corner), area2(b, c, corner), area2(c, a, corner)}) / whole);
    if (outside < least_outside || (outside == least_outside && t < holder)) {
      least_outside = outside;
      holder = t;
    }
  }
  if (holder == 0xffffffff) return false;
  const std::uint32_t* v = &mesh.triangles[3 * static_cast<std::size_t>(holder)];
  const GeodeticPoint &a = mesh.vertices[v[0]], &b = mesh.vertices[v[1]], &c = mesh.vertices[v[2]];
  const double whole = area2(a, b, c);
  const double l1 = area2(a, corner, c) / whole, l2 = area2(a, b, corner) / whole;
  corner.height_m = a.height_m + l1 * (b.height_m - a.height_m) + l2 * (c.height_m - a.height_m);
  const auto na = normalOf(mesh, v[0]), nb = normalOf(mesh, v[1]), nc = normalOf(mesh, v[2]);
  for (std::size_t k = 0; k < 3; ++k) normal[k] = na[k] + l1 * (nb[k] - na[k]) + l2 * (nc[k] - na[k]);
  return true;
}

std::array<float, 3> unitNormal(const std::array<double, 3>& v) {
  const double length = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (!(length > 0)) return {0, 0, 1};
  return {static_cast<float>(v[0] / length), static_cast<float>(v[1] / length), static_cast<float>(v[2] / length)};
}

}  // namespace

TerrainTileMesh clipToTile(const GeodeticMesh& mesh, std::span<const std::uint32_t> candidates,
                           const TileBounds& rectangle) {
  TerrainTileMesh tile;
  tile.rectangle = rectangle;
  const bool with_normals = !mesh.normals.empty();
  std::unordered_map<VertexKey, std::uint32_t, VertexKeyHash> index_of;
  TriangleClipper clipper(mesh, rectangle);
  std::vector<std::uint32_t> polygon_index, corners;
  for (const std::uint32_t t : candidates) {
    if (3 * static_cast<std::size_t>(t) + 2 >= mesh.triangles.size()) {
      throw Error(ErrorCode::Internal, "clipToTile: candidate triangle " + std::to_string(t) + " beyond the mesh's " +
                                           std::to_string(mesh.triangles.size() / 3));
    }
    const std::vector<PolygonVertex>& polygon = clipper.clip(t);
    const std::size_t n = polygon.size();
    if (n < 3) continue;
    // The fan from the corner that leaves the fewest flat triangles.
    std::size_t apex = 0, best = 0;
    for (std::size_t i = 0; i < n; ++i) {
      std::size_t solid = 0;
      for (std::size_t k = 1; k + 1 < n; ++k) {
        solid += area2(polygon[i].point, polygon[(i + k) % n].point, polygon[(i + k + 1) % n].point) > 0;
      }
      if (solid > best) {
        best = solid;
        apex = i;
      }
    }
    if (best == 0) continue;
    polygon_index.assign(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      const auto next_index = static_cast<std::uint32_t>(tile.vertices.size());
      const auto [at, added] = index_of.try_emplace(keyOf(polygon[i]), next_index);
      if (added) {
        tile.vertices.push_back(polygon[i].point);
        if (with_normals) tile.normals.push_back(unitNormal(polygon[i].normal));
        if (polygon[i].kind == PolygonVertex::kCorner) corners.push_back(at->second);
      }
      polygon_index[i] = at->second;
    }
    for (std::size_t k = 1; k + 1 < n; ++k) {
      const std::size_t j = (apex + k) % n, l = (apex + k + 1) % n;
      if (!(area2(polygon[apex].point, polygon[j].point, polygon[l].point) > 0)) continue;
      tile.triangles.insert(tile.triangles.end(), {polygon_index[apex], polygon_index[j], polygon_index[l]});
    }
  }
  for (const std::uint32_t c : corners) {
    std::array<double, 3> normal{};
    if (!cornerOnSurface(mesh, candidates, tile.vertices[c], normal)) {
      throw Error(ErrorCode::Internal, "clipToTile: a corner of the tile has no candidate triangle");
    }
    if (with_normals) tile.normals[c] = unitNormal(normal);
  }
  return tile;
}

TileBounds terrainTileBounds(const TerrainTileKey& key) {
  const double size = std::ldexp(180.0, -key.zoom);
  return {-180.0 + static_cast<double>(key.x) * size, -90.0 + static_cast<double>(key.y) * size,
          -180.0 + static_cast<double>(key.x + 1) * size, -90.0 + static_cast<double>(key.y + 1) * size};
}

std::size_t snapToTileSides(std::vector<GeodeticPoint>& vertices, std::int32_t zoom, double steps_per_tile) {
  const double size = std::ldexp(180.0, -zoom);
  const auto snap = [&](double& value, double origin, std::int64_t count) {
    const double at = (value - origin) / size;
    const double index = std::clamp(std::round(at), 0.0, static_cast<double>(count));
    if (std::fabs(at - index) * steps_per_tile >= 0.5) return false;
    const double side = origin + index * size;  // as terrainTileBounds computes it
    if (value == side) return false;
    value = side;
    return true;
  };
  std::size_t moved = 0;
  for (GeodeticPoint& p : vertices) {
    bool changed = snap(p.lon_deg, -180.0, std::int64_t{2} << zoom);
    changed = snap(p.lat_deg, -90.0, std::int64_t{1} << zoom) || changed;
    moved += changed;
  }
  return moved;
}

std::map<TerrainTileKey, std::vector<std::uint32_t>> trianglesPerTerrainTile(const GeodeticMesh& mesh,
                                                                              std::int32_t zoom) {
  const double size = std::ldexp(180.0, -zoom);
  const std::int64_t columns = std::int64_t{2} << zoom, rows = std::int64_t{1} << zoom;
  // The tiles a coordinate range [low, high] meets, sides included: a low exactly on a tile
  // side also meets the tile before it.
  const auto range = [&](double low, double high, double origin, std::int64_t count) {
    const std::int64_t first = static_cast<std::int64_t>(std::ceil((low - origin) / size)) - 1;
    const std::int64_t last = static_cast<std::int64_t>(std::floor((high - origin) / size));
    return std::pair{std::clamp<std::int64_t>(first, 0, count - 1), std::clamp<std::int64_t>(last, 0, count - 1)};
  };
  std::map<TerrainTileKey, std::vector<std::uint32_t>> tiles;
  for (std::size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
    double west = 180, east = -180, south = 90, north = -90;
    for (int k = 0; k < 3; ++k) {
      const GeodeticPoint& p = mesh.vertices[mesh.triangles[t + static_cast<std::size_t>(k)]];
      west = std::min(west, p.lon_deg);
      east = std::max(east, p.lon_deg);
      south = std::min(south, p.lat_deg);
      north = std::max(north, p.lat_deg);
    }
    const auto [x0, x1] = range(west, east, -180.0, columns);
    const auto [y0, y1] = range(south, north, -90.0, rows);
    for (std::int64_t y = y0; y <= y1; ++y) {
      for (std::int64_t x = x0; x <= x1; ++x) tiles[{zoom, x, y}].push_back(static_cast<std::uint32_t>(t / 3));
    }
  }
  return tiles;
}

}  // namespace terratiles
