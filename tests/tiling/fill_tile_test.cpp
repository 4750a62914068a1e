#include <doctest/doctest.h>

#include <cmath>
#include <map>
#include <numbers>
#include <set>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "src/base/progress.h"
#include "src/tiling/clip_to_tile.h"
#include "src/tiling/fill_tile.h"
#include "src/tin/build_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

double area2(const GeodeticPoint& a, const GeodeticPoint& b, const GeodeticPoint& c) {
  return (b.lon_deg - a.lon_deg) * (c.lat_deg - a.lat_deg) - (b.lat_deg - a.lat_deg) * (c.lon_deg - a.lon_deg);
}

// The checks of one filled tile: it covers its rectangle exactly once (counter-clockwise
// triangles whose areas sum to the rectangle's, every edge inside it shared by two triangles
// running it both ways, every edge used once on a side of the rectangle), keeps the data mesh
// as it was, and puts every fill vertex at the fill's height.
void checkFilled(const TerrainTileMesh& filled, const TerrainTileMesh& data,
                 const std::function<double(double, double)>& height_at) {
  const TileBounds& r = filled.rectangle;
  REQUIRE(filled.vertices.size() >= data.vertices.size());
  REQUIRE(filled.triangles.size() >= data.triangles.size());
  for (std::size_t i = 0; i < data.vertices.size(); ++i) {
    REQUIRE(filled.vertices[i].lon_deg == data.vertices[i].lon_deg);
    REQUIRE(filled.vertices[i].height_m == data.vertices[i].height_m);
  }
  CHECK(std::equal(data.triangles.begin(), data.triangles.end(), filled.triangles.begin()));
  std::size_t wrong_height = 0;
  for (std::size_t i = data.vertices.size(); i < filled.vertices.size(); ++i) {
    const GeodeticPoint& p = filled.vertices[i];
    wrong_height += p.height_m != height_at(p.lon_deg, p.lat_deg);
  }
  CHECK(wrong_height == 0);
  CHECK(filled.normals.size() == filled.vertices.size());
  double area = 0;
  std::size_t not_counter_clockwise = 0;
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> runs;  // directed edge -> uses
  for (std::size_t t = 0; t < filled.triangles.size(); t += 3) {
    const double a = area2(filled.vertices[filled.triangles[t]], filled.vertices[filled.triangles[t + 1]],
                           filled.vertices[filled.triangles[t + 2]]);
    not_counter_clockwise += !(a > 0);
    area += a;
    for (std::size_t k = 0; k < 3; ++k) ++runs[{filled.triangles[t + k], filled.triangles[t + (k + 1) % 3]}];
  }
  CHECK(not_counter_clockwise == 0);
  CHECK(area / 2 == doctest::Approx((r.east - r.west) * (r.north - r.south)).epsilon(1e-9));
  std::size_t twice_one_way = 0, open_inside = 0;
  for (const auto& [edge, uses] : runs) {
    twice_one_way += uses > 1;
    if (runs.count({edge.second, edge.first})) continue;
    const GeodeticPoint& a = filled.vertices[edge.first];
    const GeodeticPoint& b = filled.vertices[edge.second];
    const bool on_side =
        (a.lon_deg == r.west && b.lon_deg == r.west) || (a.lon_deg == r.east && b.lon_deg == r.east) ||
        (a.lat_deg == r.south && b.lat_deg == r.south) || (a.lat_deg == r.north && b.lat_deg == r.north);
    open_inside += !on_side;
  }
  CHECK(twice_one_way == 0);
  CHECK(open_inside == 0);
}

}  // namespace

TEST_CASE("fillTile: tiles around real data cover their rectangles, the data untouched, and meet along every side") {
  const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
  Progress progress;
  TinOptions options;
  options.max_error_m = 5;
  const TinMesh tin = buildTin(dem, options, progress);
  GeodeticMesh mesh;
  for (const GridPoint& p : tin.vertices) {
    const CrsPoint at = dem.pixelCentre(p.col, p.row);
    mesh.vertices.push_back({at.x, at.y, p.height_m});
    mesh.normals.push_back({0, 0, 1});
  }
  mesh.triangles = tin.triangle_indices;
  const GeoidGrid geoid = readGeoidGrid("/usr/share/proj/egm96_15.gtx");
  const auto geoid_height = [&](double lon, double lat) { return geoid.undulationAt(lon, lat).value_or(0.0); };

  for (const std::int32_t zoom : {5, 8, 9}) {
    INFO("zoom " << zoom);
    // The tiles with data and a ring of tiles around them without.
    const auto with_data = trianglesPerTerrainTile(mesh, zoom);
    std::map<TerrainTileKey, TerrainTileMesh> tiles;
    for (const auto& [key, candidates] : with_data) {
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        for (std::int64_t dx = -1; dx <= 1; ++dx) {
          const TerrainTileKey around{zoom, key.x + dx, key.y + dy};
          if (tiles.count(around)) continue;
          const auto found = with_data.find(around);
          const TerrainTileMesh data = clipToTile(
              mesh, found == with_data.end() ? std::span<const std::uint32_t>() : std::span(found->second),
              terrainTileBounds(around));
          const TerrainTileMesh filled = fillTile(data, 16, geoid_height);
          checkFilled(filled, data, geoid_height);
          tiles[around] = filled;
        }
      }
    }
    CHECK(tiles.size() > with_data.size());
    // Neighbours hold the same vertices on their common side, bit for bit.
    std::size_t sides = 0;
    for (const auto& [key, tile] : tiles) {
      for (const bool east : {true, false}) {
        const auto other = tiles.find({zoom, key.x + (east ? 1 : 0), key.y + (east ? 0 : 1)});
        if (other == tiles.end()) continue;
        CHECK(test::verticesOnSide(tile, east, false) == test::verticesOnSide(other->second, east, true));
        ++sides;
      }
    }
    CHECK(sides >= 12);
  }
}

TEST_CASE("fillTile: a tile without data is the fill's grid") {
  TerrainTileMesh empty;
  empty.rectangle = terrainTileBounds({0, 0, 0});
  const auto flat = [](double, double) { return 0.0; };
  const TerrainTileMesh filled = fillTile(empty, 8, flat);
  checkFilled(filled, empty, flat);
  CHECK(filled.vertices.size() == 81);
  CHECK(filled.triangles.size() == 3 * 128);
  CHECK_THROWS_AS(fillTile(empty, 0, flat), Error);
}
