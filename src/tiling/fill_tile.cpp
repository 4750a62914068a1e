#include "src/tiling/fill_tile.h"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <unordered_set>

#include "src/base/error.h"

namespace terratiles {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

struct VertexInfo {
  std::uint32_t index = kNone;  // in the output tile; kNone: a point CGAL made (none expected)
};
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using VertexBase = CGAL::Triangulation_vertex_base_with_info_2<VertexInfo, Kernel>;
using FaceBase = CGAL::Constrained_triangulation_face_base_2<Kernel>;
using Structure = CGAL::Triangulation_data_structure_2<VertexBase, FaceBase>;
using Triangulation = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Structure, CGAL::Exact_predicates_tag>;

double area2(double ax, double ay, double bx, double by, double cx, double cy) {
  return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
}

// Whether a point is on or inside one of the data triangles, through buckets of them.
class DataCover {
 public:
  explicit DataCover(const TerrainTileMesh& data) : data_(data), r_(data.rectangle) {
    buckets_.resize(kCells * kCells);
    for (std::size_t t = 0; t < data.triangles.size(); t += 3) {
      double w = r_.east, e = r_.west, s = r_.north, n = r_.south;
      for (std::size_t k = 0; k < 3; ++k) {
        const GeodeticPoint& p = data.vertices[data.triangles[t + k]];
        w = std::min(w, p.lon_deg), e = std::max(e, p.lon_deg), s = std::min(s, p.lat_deg), n = std::max(n, p.lat_deg);
      }
      for (int y = row(s); y <= row(n); ++y) {
        for (int x = column(w); x <= column(e); ++x) buckets_[static_cast<std::size_t>(y * kCells + x)].push_back(t);
      }
    }
  }
  bool covers(double lon, double lat) const {
    for (const std::size_t t : buckets_[static_cast<std::size_t>(row(lat) * kCells + column(lon))]) {
      const GeodeticPoint& a = data_.vertices[data_.triangles[t]];
      const GeodeticPoint& b = data_.vertices[data_.triangles[t + 1]];
      const GeodeticPoint& c = data_.vertices[data_.triangles[t + 2]];
      if (area2(a.lon_deg, a.lat_deg, b.lon_deg, b.lat_deg, lon, lat) >= 0 &&
          area2(b.lon_deg, b.lat_deg, c.lon_deg, c.lat_deg, lon, lat) >= 0 &&
          area2(c.lon_deg, c.lat_deg, a.lon_deg, a.lat_deg, lon, lat) >= 0) {
        return true;
      }
    }
    return false;
  }

 private:
  static constexpr int kCells = 64;
  int column(double lon) const {
    return std::clamp(static_cast<int>((lon - r_.west) / (r_.east - r_.west) * kCells), 0, kCells - 1);
  }
  int row(double lat) const {
    return std::clamp(static_cast<int>((lat - r_.south) / (r_.north - r_.south) * kCells), 0, kCells - 1);
  }
  const TerrainTileMesh& data_;
  const TileBounds r_;
  std::vector<std::vector<std::size_t>> buckets_;
};

std::array<float, 3> ellipsoidNormal(double lon_deg, double lat_deg) {
  const double lon = lon_deg * std::numbers::pi / 180, lat = lat_deg * std::numbers::pi / 180;
  return {static_cast<float>(std::cos(lat) * std::cos(lon)), static_cast<float>(std::cos(lat) * std::sin(lon)),
          static_cast<float>(std::sin(lat))};
}

// Grid coordinate i of n between low and high, exactly low and high at the ends.
double gridAt(double low, double high, std::int32_t i, std::int32_t n) {
  if (i == n) return high;
  return low + (high - low) * static_cast<double>(i) / static_cast<double>(n);
}

}  // namespace

TerrainTileMesh fillTile(const TerrainTileMesh& data, std::int32_t grid_cells,
                         const std::function<double(double lon_deg, double lat_deg)>& height_at) {
  if (grid_cells < 1 || grid_cells > 4096) {
    throw Error(ErrorCode::Usage, "fill grid of " + std::to_string(grid_cells) + " cells a side; expected 1 to 4096");
  }
  TerrainTileMesh tile = data;
  const TileBounds& r = data.rectangle;
  // A tile the data covers whole (its triangles' area is the rectangle's; a level cut to a
  // tile has no overlaps) needs no fill: most tiles of a DEM's interior, all of a global one.
  long double covered = 0;
  for (std::size_t t = 0; t < data.triangles.size(); t += 3) {
    const GeodeticPoint& a = data.vertices[data.triangles[t]];
    const GeodeticPoint& b = data.vertices[data.triangles[t + 1]];
    const GeodeticPoint& c = data.vertices[data.triangles[t + 2]];
    covered += std::fabs(area2(a.lon_deg, a.lat_deg, b.lon_deg, b.lat_deg, c.lon_deg, c.lat_deg));
  }
  const long double rectangle = 2.0L * (r.east - r.west) * (r.north - r.south);
  if (std::fabs(covered - rectangle) <= 1e-12L * rectangle) return tile;
  const bool with_normals = !data.normals.empty() || data.vertices.empty();
  const DataCover cover(data);

  Triangulation triangulation;
  // The data's outline: its edges that only one of its triangles runs along (either way).
  std::unordered_set<std::uint64_t> directed;
  const auto key = [](std::uint32_t from, std::uint32_t to) { return (std::uint64_t{from} << 32) | to; };
  for (std::size_t t = 0; t < data.triangles.size(); t += 3) {
    for (std::size_t k = 0; k < 3; ++k) directed.insert(key(data.triangles[t + k], data.triangles[t + (k + 1) % 3]));
  }
  std::vector<Triangulation::Vertex_handle> handle(data.vertices.size());
  const auto place = [&](std::uint32_t v) {
    if (handle[v] == Triangulation::Vertex_handle()) {
      handle[v] = triangulation.insert(Triangulation::Point(data.vertices[v].lon_deg, data.vertices[v].lat_deg));
      handle[v]->info().index = v;
    }
    return handle[v];
  };
  for (std::size_t t = 0; t < data.triangles.size(); t += 3) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t a = data.triangles[t + k], b = data.triangles[t + (k + 1) % 3];
      if (!directed.count(key(b, a))) triangulation.insert_constraint(place(a), place(b));
    }
  }
  // The grid, where the data is not.
  for (std::int32_t j = 0; j <= grid_cells; ++j) {
    const double lat = gridAt(r.south, r.north, j, grid_cells);
    for (std::int32_t i = 0; i <= grid_cells; ++i) {
      const double lon = gridAt(r.west, r.east, i, grid_cells);
      if (cover.covers(lon, lat)) continue;
      const auto vertex = triangulation.insert(Triangulation::Point(lon, lat));
      if (vertex->info().index != kNone) continue;  // a data vertex already there
      vertex->info().index = static_cast<std::uint32_t>(tile.vertices.size());
      tile.vertices.push_back({lon, lat, height_at(lon, lat)});
      if (with_normals) tile.normals.push_back(ellipsoidNormal(lon, lat));
    }
  }
  // Every face outside the data is fill (the outline's constraints split the two).
  for (auto face = triangulation.finite_faces_begin(); face != triangulation.finite_faces_end(); ++face) {
    std::array<std::uint32_t, 3> corners{};
    double cx = 0, cy = 0;
    for (int k = 0; k < 3; ++k) {
      const auto vertex = face->vertex(k);
      cx += vertex->point().x() / 3;
      cy += vertex->point().y() / 3;
      if (vertex->info().index == kNone) {  // where two outline edges cross: not expected
        const double lon = vertex->point().x(), lat = vertex->point().y();
        vertex->info().index = static_cast<std::uint32_t>(tile.vertices.size());
        tile.vertices.push_back({lon, lat, height_at(lon, lat)});
        if (with_normals) tile.normals.push_back(ellipsoidNormal(lon, lat));
      }
      corners[static_cast<std::size_t>(k)] = vertex->info().index;
    }
    if (cover.covers(cx, cy)) continue;
    const auto& p0 = face->vertex(0)->point();
    const auto& p1 = face->vertex(1)->point();
    const auto& p2 = face->vertex(2)->point();
    if (!(area2(p0.x(), p0.y(), p1.x(), p1.y(), p2.x(), p2.y()) > 0)) continue;
    tile.triangles.insert(tile.triangles.end(), corners.begin(), corners.end());
  }
  return tile;
}

}  // namespace terratiles
