#include <doctest/doctest.h>

#include <cmath>
#include <iomanip>
#include <map>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <sstream>

#include "formats/dem/read_dem.h"
#include "src/base/progress.h"
#include "src/tiling/clip_to_tile.h"
#include "src/tin/build_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

// SRTM N57E011's TIN at `max_error_m` in longitude, latitude and the DEM's heights, with the
// ellipsoid's normals.
GeodeticMesh realMesh(double max_error_m) {
  const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
  Progress progress;
  TinOptions options;
  options.max_error_m = max_error_m;
  const TinMesh tin = buildTin(dem, options, progress);
  GeodeticMesh mesh;
  for (const GridPoint& p : tin.vertices) {
    const CrsPoint at = dem.pixelCentre(p.col, p.row);
    mesh.vertices.push_back({at.x, at.y, p.height_m});
    const double lon = at.x * std::numbers::pi / 180, lat = at.y * std::numbers::pi / 180;
    mesh.normals.push_back({static_cast<float>(std::cos(lat) * std::cos(lon)),
                            static_cast<float>(std::cos(lat) * std::sin(lon)), static_cast<float>(std::sin(lat))});
  }
  mesh.triangles = tin.triangle_indices;
  return mesh;
}

double area2(const GeodeticPoint& a, const GeodeticPoint& b, const GeodeticPoint& c) {
  return (b.lon_deg - a.lon_deg) * (c.lat_deg - a.lat_deg) - (b.lat_deg - a.lat_deg) * (c.lon_deg - a.lon_deg);
}

// The height of a mesh at (lon, lat), from a triangle holding the point (linear in degrees),
// through buckets of triangles by their boxes.
class HeightLookup {
 public:
  HeightLookup(const std::vector<GeodeticPoint>& vertices, const std::vector<std::uint32_t>& triangles)
      : vertices_(vertices), triangles_(triangles) {
    for (const GeodeticPoint& p : vertices) {
      west_ = std::min(west_, p.lon_deg);
      east_ = std::max(east_, p.lon_deg);
      south_ = std::min(south_, p.lat_deg);
      north_ = std::max(north_, p.lat_deg);
    }
    buckets_.resize(kCells * kCells);
    for (std::size_t t = 0; t < triangles.size(); t += 3) {
      double w = 180, e = -180, s = 90, n = -90;
      for (int k = 0; k < 3; ++k) {
        const GeodeticPoint& p = vertices[triangles[t + static_cast<std::size_t>(k)]];
        w = std::min(w, p.lon_deg), e = std::max(e, p.lon_deg), s = std::min(s, p.lat_deg), n = std::max(n, p.lat_deg);
      }
      for (int y = cell(s, south_, north_); y <= cell(n, south_, north_); ++y) {
        for (int x = cell(w, west_, east_); x <= cell(e, west_, east_); ++x) buckets_[y * kCells + x].push_back(t);
      }
    }
  }
  std::optional<double> at(double lon, double lat) const {
    const GeodeticPoint p{lon, lat, 0};
    for (const std::size_t t : buckets_[cell(lat, south_, north_) * kCells + cell(lon, west_, east_)]) {
      const GeodeticPoint& a = vertices_[triangles_[t]];
      const GeodeticPoint& b = vertices_[triangles_[t + 1]];
      const GeodeticPoint& c = vertices_[triangles_[t + 2]];
      const double whole = area2(a, b, c);
      const double l1 = area2(a, p, c) / whole, l2 = area2(a, b, p) / whole;
      if (l1 < -1e-12 || l2 < -1e-12 || l1 + l2 > 1 + 1e-12) continue;
      return a.height_m + l1 * (b.height_m - a.height_m) + l2 * (c.height_m - a.height_m);
    }
    return std::nullopt;
  }

 private:
  static constexpr int kCells = 128;
  static int cell(double value, double low, double high) {
    return std::clamp(static_cast<int>((value - low) / (high - low) * kCells), 0, kCells - 1);
  }
  const std::vector<GeodeticPoint>& vertices_;
  const std::vector<std::uint32_t>& triangles_;
  double west_ = 180, east_ = -180, south_ = 90, north_ = -90;
  std::vector<std::vector<std::size_t>> buckets_;
};

}  // namespace

TEST_CASE("clipToTile: a real TIN cut into terrain tiles keeps its surface and meets along every side") {
  const GeodeticMesh mesh = realMesh(5);
  double mesh_area = 0;
  for (std::size_t t = 0; t < mesh.triangles.size(); t += 3) {
    mesh_area += area2(mesh.vertices[mesh.triangles[t]], mesh.vertices[mesh.triangles[t + 1]],
                       mesh.vertices[mesh.triangles[t + 2]]);
  }
  const HeightLookup original(mesh.vertices, mesh.triangles);
  for (const std::int32_t zoom : {7, 9, 10}) {
    INFO("zoom " << zoom);
    std::map<TerrainTileKey, TerrainTileMesh> tiles;
    for (const auto& [key, candidates] : trianglesPerTerrainTile(mesh, zoom)) {
      tiles[key] = clipToTile(mesh, candidates, terrainTileBounds(key));
    }
    CHECK(tiles.size() >= (zoom == 7 ? 2u : 9u));
    double tiles_area = 0;
    std::size_t outside = 0, not_counter_clockwise = 0, not_unit = 0;
    for (const auto& [key, tile] : tiles) {
      const TileBounds& r = tile.rectangle;
      for (const GeodeticPoint& p : tile.vertices) {
        outside += !(p.lon_deg >= r.west && p.lon_deg <= r.east && p.lat_deg >= r.south && p.lat_deg <= r.north);
      }
      for (std::size_t t = 0; t < tile.triangles.size(); t += 3) {
        const double a = area2(tile.vertices[tile.triangles[t]], tile.vertices[tile.triangles[t + 1]],
                               tile.vertices[tile.triangles[t + 2]]);
        not_counter_clockwise += !(a > 0);
        tiles_area += a;
      }
      REQUIRE(tile.normals.size() == tile.vertices.size());
      for (const auto& n : tile.normals) not_unit += std::fabs(std::hypot(n[0], n[1], n[2]) - 1) > 1e-6;
    }
    CHECK(outside == 0);
    CHECK(not_counter_clockwise == 0);
    CHECK(not_unit == 0);
    // The tiles cover exactly what the mesh covers.
    CHECK(tiles_area == doctest::Approx(mesh_area).epsilon(1e-12));
    // Two tiles that share a side hold the same vertices on it, bit for bit.
    std::size_t sides = 0, side_vertices = 0;
    for (const auto& [key, tile] : tiles) {
      for (const bool east : {true, false}) {
        const TerrainTileKey other_key{zoom, key.x + (east ? 1 : 0), key.y + (east ? 0 : 1)};
        const auto other = tiles.find(other_key);
        if (other == tiles.end()) continue;
        const auto mine = test::verticesOnSide(tile, east, false);
        const auto theirs = test::verticesOnSide(other->second, east, true);
        CHECK(mine == theirs);
        const auto describe = [](const TerrainTileKey& k, const std::array<double, 3>& m) {
          std::ostringstream text;
          text << std::setprecision(17) << "only in tile " << k.x << "," << k.y << ": " << m[0] << " " << m[1] << " "
               << m[2];
          return text.str();
        };
        for (const auto& m : mine) {
          if (!theirs.count(m)) MESSAGE(describe(key, m));
        }
        for (const auto& m : theirs) {
          if (!mine.count(m)) MESSAGE(describe(other_key, m));
        }
        ++sides;
        side_vertices += mine.size();
      }
    }
    CHECK(sides >= (zoom == 7 ? 1u : 12u));
    CHECK(side_vertices > sides * 10);
    // The surface is the mesh's: at random points, the tile holding the point has the
    // mesh's height there.
    std::mt19937 random(static_cast<unsigned>(zoom));
    std::uniform_real_distribution<double> lon(11.0, 12.0), lat(57.0, 58.0);
    std::size_t compared = 0;
    double worst = 0;
    std::map<TerrainTileKey, HeightLookup> lookups;
    for (int i = 0; i < 400; ++i) {
      const double x = lon(random), y = lat(random);
      const auto expected = original.at(x, y);
      if (!expected) continue;
      const double size = std::ldexp(180.0, -zoom);
      const TerrainTileKey key{zoom, static_cast<std::int64_t>(std::floor((x + 180) / size)),
                               static_cast<std::int64_t>(std::floor((y + 90) / size))};
      REQUIRE(tiles.count(key) == 1);
      const TerrainTileMesh& tile = tiles.at(key);
      const auto got = lookups.try_emplace(key, tile.vertices, tile.triangles).first->second.at(x, y);
      REQUIRE(got.has_value());
      worst = std::max(worst, std::fabs(*got - *expected));
      ++compared;
    }
    CHECK(compared > 300);
    CHECK(worst < 1e-6);
  }
}
