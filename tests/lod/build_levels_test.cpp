// The cluster LoD loop on real rasters: enough levels, each about half the edges of the one
// before (or stopped by its budget), locked edges never lost, every level a valid height
// field over exactly the finest TIN's footprint.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>

#include <tbb/global_control.h>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/lod/build_levels.h"
#include "src/partition/face_graph.h"
#include "src/partition/partition_faces.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tin/build_tin.h"
#include "tests/test_support.h"

using namespace terratiles;
using namespace terratiles::test;

namespace {

std::uint64_t key(std::uint32_t a, std::uint32_t b) {
  return (static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
}

// Twice the signed area in the (col, row) plane; < 0 is counter-clockwise seen from above.
double crossColRow(const TinMesh& mesh, std::size_t t) {
  const GridPoint& a = mesh.vertices[mesh.triangle_indices[3 * t]];
  const GridPoint& b = mesh.vertices[mesh.triangle_indices[3 * t + 1]];
  const GridPoint& c = mesh.vertices[mesh.triangle_indices[3 * t + 2]];
  return (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
}

// The undirected edges that have one triangle (the outline) or two triangles of different
// clusters (cluster borders).
std::vector<std::uint64_t> lockedEdges(const TinMesh& mesh, const FaceGraph& graph,
                                       const std::vector<std::int32_t>& cluster_of_face) {
  std::vector<std::uint64_t> locked;
  const auto& idx = mesh.triangle_indices;
  for (std::size_t s = 0; s < idx.size(); ++s) {
    const std::int32_t other = graph.across[s];
    if (other == kNoFace || cluster_of_face[static_cast<std::size_t>(other)] != cluster_of_face[s / 3]) {
      locked.push_back(key(idx[s], idx[s % 3 == 2 ? s - 2 : s + 1]));
    }
  }
  std::sort(locked.begin(), locked.end());
  locked.erase(std::unique(locked.begin(), locked.end()), locked.end());
  return locked;
}


void checkLevels(const std::string& raster, double tin_max_error_m, bool with_budget, std::int32_t region_clusters = 0) {
  CAPTURE(raster);
  const DemGrid dem = readDem({sharedData(raster)});
  Progress quiet(ProgressMode::Quiet);
  TinMesh finest = buildTin(dem, TinOptions{tin_max_error_m}, quiet);
  // Constraints: 200 random interior edges of the finest TIN (the paper's random features).
  const std::vector<std::uint64_t> finest_edges = meshEdgeKeys(finest);
  std::mt19937 random(42);
  std::vector<std::array<std::uint32_t, 2>> constraints;
  for (int i = 0; i < 200; ++i) {
    const std::uint64_t e = finest_edges[std::uniform_int_distribution<std::size_t>(0, finest_edges.size() - 1)(random)];
    constraints.push_back({static_cast<std::uint32_t>(e >> 32), static_cast<std::uint32_t>(e & 0xffffffffu)});
  }
  LevelOptions options;
  options.cluster_triangles = 1024;
  options.region_clusters = region_clusters;
  if (with_budget) options.first_budget_m = 2 * tin_max_error_m;
  const std::vector<Level> levels = buildLevels(dem, finest, options, constraints, quiet);
  MESSAGE(raster << ": " << levels.size() << " levels");
  CHECK(meshEdgeCount(finest) == finest_edges.size());
  for (const Level& level : levels) CHECK(level.edge_count == meshEdgeKeys(level.mesh).size());
  CHECK(levels.size() >= 5);  // the finest and at least 4 coarser
  const TinErrorStatistics& finest_error = levels[0].error;
  double finest_area = 0;
  for (std::size_t t = 0; t < levels[0].mesh.triangleCount(); ++t) finest_area -= crossColRow(levels[0].mesh, t);

  for (std::size_t l = 0; l < levels.size(); ++l) {
    CAPTURE(l);
    const Level& level = levels[l];
    MESSAGE("level " << l << ": " << level.mesh.triangleCount() << " triangles, " << level.edge_count
                     << " edges, max error " << level.error.max_error_m << " m, rms " << level.error.rms_error_m
                     << " m, budget " << level.budget_m << " m, clusters " << level.partition.cluster_count);
    // A valid height field: manifold, consistently oriented, nothing flipped or flat seen
    // from above, the same ground as the finest TIN (area, and no valid pixel uncovered that
    // was covered before, no nodata covered).
    const FaceGraph graph = buildFaceGraph(level.mesh);
    if (!level.partition.cluster_of_face.empty()) CHECK(clustersAreContiguous(graph, level.partition));
    double area = 0;
    std::size_t flipped = 0;
    for (std::size_t t = 0; t < level.mesh.triangleCount(); ++t) {
      const double cross = crossColRow(level.mesh, t);
      flipped += cross >= 0;
      area -= cross;
    }
    CHECK(flipped == 0);
    CHECK(std::fabs(area - finest_area) <= 1e-9 * finest_area);
    CHECK(level.error.uncovered_valid_pixels == finest_error.uncovered_valid_pixels);
    CHECK(level.error.covered_nodata_pixels == 0);
    CHECK(level.error.degenerate_triangles == 0);
    if (l > 0) {
      // About half the edges of the finer level, unless the budget stopped it.
      const double ratio = static_cast<double>(level.edge_count) / static_cast<double>(levels[l - 1].edge_count);
      if (level.refused_for_error == 0) CHECK(ratio <= 0.62);
      CHECK(ratio < 0.95);
      if (with_budget) CHECK(level.error.max_error_m <= std::max(level.budget_m, levels[l - 1].error.max_error_m) + 1e-6);
    }
    if (l + 1 == levels.size()) break;
    // Every locked edge (cluster borders and the outline) survives into the next level with
    // its two vertices at the same positions; so do the constraints.
    const Level& coarser = levels[l + 1];
    const std::vector<std::uint64_t> coarser_edges = meshEdgeKeys(coarser.mesh);
    std::size_t lost = 0, moved = 0;
    for (const std::uint64_t e : lockedEdges(level.mesh, graph, level.partition.cluster_of_face)) {
      const auto a = static_cast<std::uint32_t>(e >> 32), b = static_cast<std::uint32_t>(e & 0xffffffffu);
      const std::uint32_t na = level.index_in_coarser[a], nb = level.index_in_coarser[b];
      if (na == kRemovedVertex || nb == kRemovedVertex ||
          !std::binary_search(coarser_edges.begin(), coarser_edges.end(), key(na, nb))) {
        ++lost;
        continue;
      }
      for (const auto& [from, to] : {std::pair{a, na}, std::pair{b, nb}}) {
        const GridPoint& p = level.mesh.vertices[from];
        const GridPoint& q = coarser.mesh.vertices[to];
        moved += p.col != q.col || p.row != q.row || p.height_m != q.height_m;
      }
    }
    CHECK(lost == 0);
    CHECK(moved == 0);
  }
  // The constraints, followed from the finest level through every index map.
  std::size_t constraints_lost = 0;
  for (auto edge : constraints) {
    for (std::size_t l = 0; l + 1 < levels.size(); ++l) {
      edge = {levels[l].index_in_coarser[edge[0]], levels[l].index_in_coarser[edge[1]]};
    }
    const std::vector<std::uint64_t> edges = meshEdgeKeys(levels.back().mesh);
    constraints_lost += edge[0] == kRemovedVertex || edge[1] == kRemovedVertex ||
                        !std::binary_search(edges.begin(), edges.end(), key(edge[0], edge[1]));
  }
  CHECK(constraints_lost == 0);
}

}  // namespace

TEST_SUITE("lod") {

TEST_CASE("meshEdgeCount counts the edges meshEdgeKeys lists, also of meshes that are not manifold") {
  // A fan of two triangles, the same two again (every edge twice in one direction), one
  // reversed, a degenerate one and an isolated one.
  TinMesh mesh;
  mesh.vertices.resize(8);
  mesh.triangle_indices = {0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 2, 3, 2, 1, 0, 4, 4, 5, 5, 6, 7};
  CHECK(meshEdgeCount(mesh) == meshEdgeKeys(mesh).size());
  CHECK(meshEdgeCount(mesh) == 5 + 2 + 3);  // 01 12 20 23 30; 44 45; 56 67 75
  mesh.triangle_indices.resize(6);
  CHECK(meshEdgeCount(mesh) == 5);
}

TEST_CASE("cluster levels on the Interlaken DHM25 tile") {
  checkLevels("ch_dhm25_interlaken_25m_2056.tif", 0.5, false);
}

TEST_CASE("cluster levels on the Minnesota lidar raster, with an error budget") {
  checkLevels("us_mn_lidar_dtm_1m_26915.tif", 0.1, true);
}

TEST_CASE("cluster levels on the Ontario lidar raster (nodata)") {
  checkLevels("ca_on_lidar_dtm_1m_26917.tif", 0.1, false);
}

TEST_CASE("cluster levels on the SRTM N57E011 tile (geographic)") {
  checkLevels("srtm3_N57E011_4326.tif", 2.0, false);
}

TEST_CASE("cluster levels partitioned by grid cells on the SRTM N57E011 tile") {
  checkLevels("srtm3_N57E011_4326.tif", 2.0, false, 64);
}

TEST_CASE("cluster levels partitioned by grid cells on the Ontario lidar raster (nodata) with a budget") {
  checkLevels("ca_on_lidar_dtm_1m_26917.tif", 0.1, true, 64);
}

TEST_CASE("cluster levels partitioned by grid cells do not depend on the thread count") {
  const DemGrid dem = readDem({sharedData("srtm3_N57E011_4326.tif")});
  Progress quiet(ProgressMode::Quiet);
  const TinMesh finest = buildTin(dem, TinOptions{5.0}, quiet);
  LevelOptions options;
  options.cluster_triangles = 512;
  options.region_clusters = 64;
  options.coarser_levels = 3;
  options.simplifier = Simplifier::Native;
  const auto build = [&](std::size_t threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return buildLevels(dem, finest, options, {}, quiet);
  };
  const std::vector<Level> one = build(1), two = build(2);
  REQUIRE(one.size() == two.size());
  REQUIRE(one.size() == 4);
  CHECK(one[0].partition.cluster_count > 64);  // more than one cell
  for (std::size_t l = 0; l < one.size(); ++l) {
    CAPTURE(l);
    CHECK(one[l].partition.cluster_of_face == two[l].partition.cluster_of_face);
    CHECK(one[l].mesh.triangle_indices == two[l].mesh.triangle_indices);
  }
}

TEST_CASE("ground metres per pixel: projected and geographic") {
  const DemGrid swiss = readDem({sharedData("ch_dhm25_interlaken_25m_2056.tif")});
  const auto swiss_m = groundMetresPerPixel(swiss);
  CHECK(swiss_m[0] == doctest::Approx(25.0));
  CHECK(swiss_m[1] == doctest::Approx(25.0));
  const DemGrid srtm = readDem({sharedData("srtm3_N57E011_4326.tif")});
  const auto srtm_m = groundMetresPerPixel(srtm);
  // 3 arc seconds at 57.5 N: 92.8 m north-south, 92.8 * cos(57.5) = 49.9 m east-west.
  CHECK(srtm_m[1] == doctest::Approx(92.8).epsilon(0.01));
  CHECK(srtm_m[0] == doctest::Approx(49.9).epsilon(0.01));
}

TEST_CASE("level options out of range are usage errors") {
  const DemGrid dem = readDem({sharedData("ch_dhm25_interlaken_25m_2056.tif")});
  Progress quiet(ProgressMode::Quiet);
  const TinMesh tin = buildTin(dem, TinOptions{5.0}, quiet);
  LevelOptions options;
  options.level_ratio = 1.5;
  CHECK_THROWS_AS(buildLevels(dem, tin, options, {}, quiet), Error);
  options = {};
  options.cluster_triangles = 0;
  CHECK_THROWS_AS(buildLevels(dem, tin, options, {}, quiet), Error);
  options = {};
  options.region_clusters = -1;
  CHECK_THROWS_WITH_AS(buildLevels(dem, tin, options, {}, quiet),
                       doctest::Contains("the clusters per partition region must be >= 0 (0: global), found -1"), Error);
}

}  // TEST_SUITE
