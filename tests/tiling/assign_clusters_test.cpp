// TileFrame and assignClusters at the edge of the Web Mercator scheme: polar data is clamped
// into the first and last rows, and whatever is computed from clamped points (cluster
// centroids, boxes) must stay inside the scheme, however it rounds.
#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include <algorithm>
#include <map>
#include <set>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/lod/build_levels.h"
#include "src/partition/face_graph.h"
#include "src/partition/partition_faces.h"
#include "src/tin/build_tin.h"
#include "tests/test_support.h"
#include "src/tiling/assign_clusters.h"
#include "src/tiling/tile_scheme.h"

using namespace terratiles;

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr double kLimitDeg = kWebMercatorMaxLatitudeDeg;

// The whole Earth in EPSG:4326 at 1 deg: pixel centres at lon -179.5 .. 179.5 and lat
// 89.5 .. -89.5, so rows 0-4 and 175-179 are beyond the Web Mercator limit.
DemGrid globalDem() {
  DemGrid dem;
  dem.width = 360;
  dem.height = 180;
  dem.origin_x = -180.0;
  dem.origin_y = 90.0;
  dem.pixel_size_x = 1.0;
  dem.pixel_size_y = 1.0;
  dem.crs_wkt = "EPSG:4326";
  dem.crs_name = "EPSG:4326";
  dem.heights_m.assign(dem.pixelCount(), 0.0f);
  return dem;
}

// Appends a strip of 2 * columns triangles between grid rows row_a and row_b, from grid column
// first_col eastwards, to `mesh`; returns the number of triangles added.
std::size_t addStrip(TinMesh& mesh, double row_a, double row_b, double first_col, int columns) {
  const auto base = static_cast<std::uint32_t>(mesh.vertices.size());
  for (int c = 0; c <= columns; ++c) {
    mesh.vertices.push_back({first_col + c, row_a, 0.0});
    mesh.vertices.push_back({first_col + c, row_b, 0.0});
  }
  for (std::uint32_t c = 0; c < static_cast<std::uint32_t>(columns); ++c) {
    const std::uint32_t a0 = base + 2 * c, b0 = a0 + 1, a1 = a0 + 2, b1 = a0 + 3;
    mesh.triangle_indices.insert(mesh.triangle_indices.end(), {a0, b0, a1, a1, b0, b1});
  }
  return 2 * static_cast<std::size_t>(columns);
}

template <class F>
std::optional<Error> thrownError(F&& f) {
  try {
    f();
  } catch (const Error& error) {
    return error;
  }
  return std::nullopt;
}

}  // namespace

TEST_SUITE("tiling") {
  TEST_CASE("a cluster of polar faces clamped to the Web Mercator edge goes to the first or last row") {
    const DemGrid dem = globalDem();
    const TileFrame frame(TileSchemeKind::WebMercator, dem);
    // Two clusters of 128 faces, one in the Arctic (grid rows 0-1, lat 89.5 and 88.5) and one
    // in the Antarctic (rows 178-179), between lon -79.5 and -15.5: every corner is clamped to
    // +-kLimitDeg, so every face has zero area in scheme coordinates.
    Level level;
    const std::size_t north_faces = addStrip(level.mesh, 0, 1, 100, 64);
    const std::size_t south_faces = addStrip(level.mesh, 178, 179, 100, 64);
    level.partition.cluster_count = 2;
    level.partition.cluster_of_face.assign(north_faces, 0);
    level.partition.cluster_of_face.insert(level.partition.cluster_of_face.end(), south_faces, 1);

    const std::vector<std::array<double, 2>> scheme = frame.toScheme(level.mesh.vertices);
    REQUIRE(scheme.front()[0] == doctest::Approx(-79.5));
    for (std::size_t v = 0; v < scheme.size(); ++v) {
      CHECK(std::fabs(scheme[v][1]) == kLimitDeg);
    }
    // The rounding this is about: the area-weighted mean latitude assignClusters takes (face
    // weight = area + 1e-30, here 1e-30 for every face; face latitude = the mean of its three
    // corners) lands past the limit: 85.05112877980706, 33 ulps, for these 128 faces (the
    // 6000 x 3000 ETOPO5 build stopped at 85.05112877980692).
    for (const double edge_deg : {kLimitDeg, -kLimitDeg}) {
      double weighted_sum = 0, weight_sum = 0;
      for (std::size_t f = 0; f < north_faces; ++f) {
        weighted_sum += 1e-30 * (edge_deg + edge_deg + edge_deg) / 3;
        weight_sum += 1e-30;
      }
      REQUIRE(std::fabs(weighted_sum / weight_sum) > kLimitDeg);
    }

    for (const Assignment assignment : {Assignment::Merge, Assignment::Duplicate, Assignment::Centroid}) {
      CAPTURE(assignmentName(assignment));
      std::vector<TileKey> own_cluster_tiles;
      std::vector<TileFaces> tiles;
      // Without TileFrame keeping derived latitudes inside, this threw Error(Input): "latitude
      // 85.05112877980706 deg (at lon -47.50000000000015 deg) is beyond the Web Mercator limit".
      REQUIRE_NOTHROW(tiles = assignClusters(frame, level, 3, assignment, {}, own_cluster_tiles));
      // The centroid, lon -47.5, is in column 2 of zoom 3 (lon -90 .. -45).
      REQUIRE(own_cluster_tiles.size() == 2);
      CHECK(own_cluster_tiles[0] == TileKey{3, 2, 0});
      CHECK(own_cluster_tiles[1] == TileKey{3, 2, 7});
      // Every face is in the first or last row, in the columns its box crosses (lon -79.5 ..
      // -15.5: columns 2 and 3) or, for centroid, in its cluster's tile.
      std::size_t faces = 0;
      for (const TileFaces& tile : tiles) {
        CHECK((tile.key.y == 0 || tile.key.y == 7));
        CHECK((tile.key.x == 2 || tile.key.x == 3));
        faces += tile.faces.size();
      }
      CHECK(faces >= north_faces + south_faces);
    }
  }

  TEST_CASE("TileFrame takes points and boxes rounded past the clamped edge back into the scheme") {
    const DemGrid dem = globalDem();
    const double north_deg = std::nextafter(kLimitDeg, kInfinity);
    const double south_deg = std::nextafter(-kLimitDeg, -kInfinity);
    const double far_north_deg = kLimitDeg + 3.3e-13;  // the 6000 x 3000 ETOPO5 centroid
    // The scheme's own contract is kept: raw latitudes beyond the limit are refused.
    CHECK(thrownError([&] { tileAt(TileSchemeKind::WebMercator, 0.0, north_deg, 3); }).value().code() ==
          ErrorCode::Input);

    const TileFrame mercator(TileSchemeKind::WebMercator, dem);
    for (const std::int32_t zoom : {0, 3, 12}) {
      const std::int32_t last = (1 << zoom) - 1;
      CHECK(mercator.tileAt({157.08405646359694, far_north_deg}, zoom) ==
            tileAt(TileSchemeKind::WebMercator, 157.08405646359694, kLimitDeg, zoom));
      CHECK(mercator.tileAt({10.0, north_deg}, zoom).y == 0);
      CHECK(mercator.tileAt({10.0, south_deg}, zoom).y == last);
      // Boxes: the same tiles as the box clamped to the edge.
      CHECK(mercator.tilesIntersecting({-10.0, 80.0, 10.0, far_north_deg}, zoom) ==
            tilesIntersecting(TileSchemeKind::WebMercator, {-10.0, 80.0, 10.0, kLimitDeg}, zoom));
      CHECK(mercator.tilesIntersecting({-10.0, south_deg, 10.0, south_deg}, zoom) ==
            tilesIntersecting(TileSchemeKind::WebMercator, {-10.0, -kLimitDeg, 10.0, -kLimitDeg}, zoom));
      CHECK(mercator.tilesIntersecting({-180.0, south_deg, 180.0, north_deg}, zoom).size() ==
            static_cast<std::size_t>(1) << (2 * zoom));
      // Points inside the range are not moved.
      const double inside_deg = std::nextafter(kLimitDeg, 0.0);
      CHECK(mercator.tileAt({10.0, inside_deg}, zoom) == tileAt(TileSchemeKind::WebMercator, 10.0, inside_deg, zoom));
    }

    const TileFrame geographic(TileSchemeKind::Geographic, dem);
    CHECK(geographic.tileAt({10.0, std::nextafter(90.0, kInfinity)}, 2) == TileKey{2, 4, 0});
    CHECK(geographic.tileAt({10.0, std::nextafter(-90.0, -kInfinity)}, 2) == TileKey{2, 4, 3});
    CHECK(geographic.tilesIntersecting({0.0, 89.0, 1.0, std::nextafter(90.0, kInfinity)}, 2) ==
          std::vector<TileKey>{{2, 4, 0}});

    // Not finite is not rounding: still refused by the scheme.
    const double nan = std::numeric_limits<double>::quiet_NaN();
    CHECK(thrownError([&] { mercator.tileAt({10.0, nan}, 3); }).value().code() == ErrorCode::Input);
    CHECK(thrownError([&] { mercator.tileAt({10.0, kInfinity}, 3); }).value().code() == ErrorCode::Input);
    CHECK(thrownError([&] { geographic.tilesIntersecting({0.0, 0.0, 1.0, nan}, 3); }).value().code() ==
          ErrorCode::Input);
  }

  TEST_CASE("toScheme in parallel gives every point the coordinates it gets alone") {
    const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
    Progress quiet(ProgressMode::Quiet);
    const TinMesh tin = buildTin(dem, TinOptions{0.5}, quiet);
    REQUIRE(tin.vertices.size() > 100000);  // large enough for the parallel path
    for (const TileSchemeKind kind : {TileSchemeKind::WebMercator, TileSchemeKind::Geographic}) {
      const TileFrame frame(kind, dem);
      const std::vector<std::array<double, 2>> all = frame.toScheme(tin.vertices);
      for (std::size_t v = 0; v < tin.vertices.size(); v += 997) {
        const std::vector<std::array<double, 2>> one = frame.toScheme(std::span<const GridPoint>(&tin.vertices[v], 1));
        CHECK(one[0] == all[v]);
      }
    }
  }

  TEST_CASE("approximate tile coordinates stay within a hundredth of a finest tile of the exact ones") {
    for (const auto& [raster, kind] : {std::pair<const char*, TileSchemeKind>{"srtm3_N57E011_4326.tif", TileSchemeKind::WebMercator},
                                       {"ch_dhm25_interlaken_25m_2056.tif", TileSchemeKind::WebMercator},
                                       {"ch_dhm25_interlaken_25m_2056.tif", TileSchemeKind::Geographic},
                                       {"ch_dhm25_interlaken_25m_2056.tif", TileSchemeKind::Local}}) {
      CAPTURE(std::string(raster));
      const DemGrid dem = readDem({test::sharedData(raster)});
      Progress quiet(ProgressMode::Quiet);
      const TinMesh tin = buildTin(dem, TinOptions{0.5}, quiet);
      const TileFrame frame(kind, dem);
      const ZoomPlan plan = planZooms(frame, tin, 16384, -1, 16);
      const double tiles = std::ldexp(1.0, plan.max_zoom);
      const std::vector<std::array<double, 2>> scheme = frame.toScheme(tin.vertices);
      double worst = 0;
      for (std::size_t v = 0; v < tin.vertices.size(); ++v) {
        const std::array<double, 2> approximate = frame.approximateTileCoordinates(tin.vertices[v].col, tin.vertices[v].row);
        const TileKey tile = frame.tileAt(scheme[v], plan.max_zoom);
        // The exact point lies in `tile`; the approximate one within 0.01 of a tile of it.
        const double x = approximate[0] * tiles - tile.x, y = approximate[1] * tiles - tile.y;
        worst = std::max({worst, -x, x - 1, -y, y - 1});
      }
      MESSAGE(std::string(raster) << " zoom " << plan.max_zoom << ": approximate coordinates at most " << worst << " tiles outside the exact tile");
      CHECK(worst < 0.01);
    }
  }

  TEST_CASE("tile neighbourhood regions are blocks of 2 x 2 tiles offset by one tile") {
    const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
    Progress quiet(ProgressMode::Quiet);
    const TinMesh tin = buildTin(dem, TinOptions{0.5}, quiet);
    const TileFrame frame(TileSchemeKind::WebMercator, dem);
    const ZoomPlan plan = planZooms(frame, tin, 16384, -1, 16);
    const std::int32_t zoom = plan.max_zoom;
    const std::vector<std::int32_t> regions = tileNeighbourhoodRegions(frame, tin, zoom);
    REQUIRE(regions.size() == tin.triangleCount());
    const std::vector<std::array<double, 2>> scheme = frame.toScheme(tin.vertices);
    // Faces well inside a tile (centroid tile the same for the exact and the approximate
    // centroid): the region is the block ((x + 1) / 2, (y + 1) / 2) of that tile, one region
    // per block, and no region holds two blocks.
    std::map<std::pair<std::int32_t, std::int32_t>, std::set<std::int32_t>> regions_of_block;
    std::map<std::int32_t, std::set<std::pair<std::int32_t, std::int32_t>>> blocks_of_region;
    std::size_t checked = 0;
    for (std::size_t t = 0; t < tin.triangleCount(); ++t) {
      std::array<double, 2> centroid{0, 0};
      for (std::size_t k = 0; k < 3; ++k) {
        centroid[0] += scheme[tin.triangle_indices[3 * t + k]][0] / 3;
        centroid[1] += scheme[tin.triangle_indices[3 * t + k]][1] / 3;
      }
      const TileKey tile = frame.tileAt(centroid, zoom);
      const TileKey a = frame.tileAt({centroid[0] + 0.001, centroid[1] + 0.001}, zoom);
      const TileKey b = frame.tileAt({centroid[0] - 0.001, centroid[1] - 0.001}, zoom);
      if (!(a == tile && b == tile)) continue;  // near a tile edge
      const std::pair block{(tile.x + 1) / 2, (tile.y + 1) / 2};
      regions_of_block[block].insert(regions[t]);
      blocks_of_region[regions[t]].insert(block);
      ++checked;
    }
    CHECK(checked > tin.triangleCount() * 9 / 10);
    CHECK(regions_of_block.size() > 4);
    for (const auto& [block, set] : regions_of_block) CHECK(set.size() == 1);
    for (const auto& [region, set] : blocks_of_region) CHECK(set.size() == 1);
  }

  TEST_CASE("groupClustersByTiles joins exactly the clusters whose faces cross the same tiles") {
    const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
    Progress quiet(ProgressMode::Quiet);
    const TinMesh tin = buildTin(dem, TinOptions{5.0}, quiet);
    const TileFrame frame(TileSchemeKind::WebMercator, dem);
    const ZoomPlan plan = planZooms(frame, tin, 16384, -1, 16);
    const std::int32_t zoom = plan.max_zoom - 1;
    const FaceGraph graph = buildFaceGraph(tin);
    const FacePartition partition = partitionFaces(graph, {Partitioner::Metis, plan.clusters_per_level[0], 1},
                                                   tileNeighbourhoodRegions(frame, tin, plan.max_zoom));
    const FacePartition grouped = groupClustersByTiles(frame, tin, partition, zoom);
    // Every face's tiles by tilesIntersecting of its box.
    const std::vector<std::array<double, 2>> scheme = frame.toScheme(tin.vertices);
    std::vector<std::set<std::pair<std::int32_t, std::int32_t>>> sets(static_cast<std::size_t>(partition.cluster_count));
    for (std::size_t t = 0; t < tin.triangleCount(); ++t) {
      TileBounds box{1e300, 1e300, -1e300, -1e300};
      for (std::size_t k = 0; k < 3; ++k) {
        const auto& p = scheme[tin.triangle_indices[3 * t + k]];
        box = {std::min(box.west, p[0]), std::min(box.south, p[1]), std::max(box.east, p[0]), std::max(box.north, p[1])};
      }
      for (const TileKey& key : frame.tilesIntersecting(box, zoom)) {
        sets[static_cast<std::size_t>(partition.cluster_of_face[t])].insert({key.y, key.x});
      }
    }
    std::map<std::set<std::pair<std::int32_t, std::int32_t>>, std::int32_t> group_of_set;
    std::vector<std::int32_t> expected(tin.triangleCount());
    for (std::size_t t = 0; t < tin.triangleCount(); ++t) {
      const auto& set = sets[static_cast<std::size_t>(partition.cluster_of_face[t])];
      expected[t] = group_of_set.try_emplace(set, static_cast<std::int32_t>(group_of_set.size())).first->second;
    }
    CHECK(grouped.cluster_count == static_cast<std::int32_t>(group_of_set.size()));
    CHECK(grouped.cluster_of_face == expected);
    CHECK(grouped.cluster_count < partition.cluster_count);
  }
}
