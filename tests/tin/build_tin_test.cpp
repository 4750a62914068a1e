#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

struct TopologyReport {
  std::size_t boundary_edges = 0;
  std::size_t interior_edges = 0;
  std::size_t non_manifold_edges = 0;    // an undirected edge in more than two triangles
  std::size_t inconsistent_edges = 0;    // the same directed edge twice (flipped triangle)
  std::size_t boundary_off_border = 0;   // boundary edges not on the raster's border
  std::size_t clockwise_triangles = 0;   // not counter-clockwise seen from above
  std::size_t unused_vertices = 0;
  std::size_t non_delaunay_edges = 0;    // opposite vertex strictly inside the circumcircle
  long euler = 0;                        // V - E + F, 1 for a disk
};

// Checks that `mesh` is a valid manifold triangulation of the full raster rectangle.
// block_pixels: edges lying on a window border of a windowed build are constrained and
// exempt from the Delaunay check (0: none are).
TopologyReport checkTopology(const TinMesh& mesh, int width, int height, int block_pixels) {
  TopologyReport report;
  struct Edge {
    std::uint64_t key;     // min << 32 | max
    std::uint32_t opposite;
    bool forward;          // min -> max in the triangle's order
  };
  std::vector<Edge> edges;
  const auto& idx = mesh.triangle_indices;
  edges.reserve(idx.size());
  std::vector<std::uint8_t> used(mesh.vertices.size(), 0);
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    const GridPoint& a = mesh.vertices[idx[t]];
    const GridPoint& b = mesh.vertices[idx[t + 1]];
    const GridPoint& c = mesh.vertices[idx[t + 2]];
    // Counter-clockwise in the CRS frame (x = col, y = -row).
    if ((b.col - a.col) * (-(c.row - a.row)) - (-(b.row - a.row)) * (c.col - a.col) <= 0) {
      ++report.clockwise_triangles;
    }
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t u = idx[t + k], v = idx[t + (k + 1) % 3], w = idx[t + (k + 2) % 3];
      used[u] = 1;
      edges.push_back({(std::uint64_t{std::min(u, v)} << 32) | std::max(u, v), w, u < v});
    }
  }
  std::sort(edges.begin(), edges.end(), [](const Edge& l, const Edge& r) { return l.key < r.key; });
  auto on_border = [&](const GridPoint& p, const GridPoint& q) {
    return (p.col == 0 && q.col == 0) || (p.row == 0 && q.row == 0) ||
           (p.col == width - 1 && q.col == width - 1) || (p.row == height - 1 && q.row == height - 1);
  };
  std::size_t undirected = 0;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    ++undirected;
    const auto u = static_cast<std::uint32_t>(edges[i].key >> 32);
    const auto v = static_cast<std::uint32_t>(edges[i].key & 0xffffffffu);
    if (j - i == 1) {
      ++report.boundary_edges;
      if (!on_border(mesh.vertices[u], mesh.vertices[v])) ++report.boundary_off_border;
    } else if (j - i == 2) {
      ++report.interior_edges;
      if (edges[i].forward == edges[i + 1].forward) ++report.inconsistent_edges;
      // Delaunay: the opposite vertex of one side is not strictly inside the circumcircle of
      // the other side's triangle (exact in 128-bit integers on pixel coordinates).
      const GridPoint& p = mesh.vertices[u];
      const GridPoint& q = mesh.vertices[v];
      const GridPoint& l = mesh.vertices[edges[i].opposite];
      const GridPoint& r = mesh.vertices[edges[i + 1].opposite];
      auto lifted = [&](const GridPoint& s) {
        return std::array<std::int64_t, 3>{std::int64_t(s.col - r.col), std::int64_t(s.row - r.row),
                                           std::int64_t((s.col - r.col) * (s.col - r.col) + (s.row - r.row) * (s.row - r.row))};
      };
      const auto A = lifted(p), B = lifted(q), C = lifted(l);
      __extension__ typedef __int128 I;
      const I det = I{A[0]} * (I{B[1]} * C[2] - I{B[2]} * C[1]) - I{A[1]} * (I{B[0]} * C[2] - I{B[2]} * C[0]) +
                    I{A[2]} * (I{B[0]} * C[1] - I{B[1]} * C[0]);
      const std::int64_t orientation = std::int64_t(q.col - p.col) * std::int64_t(l.row - p.row) -
                                       std::int64_t(q.row - p.row) * std::int64_t(l.col - p.col);
      const bool on_window_border =
          block_pixels > 0 && ((p.col == q.col && int(p.col) % block_pixels == 0) ||
                               (p.row == q.row && int(p.row) % block_pixels == 0));
      if (!on_window_border && ((orientation > 0 && det > 0) || (orientation < 0 && det < 0))) {
        ++report.non_delaunay_edges;
      }
    } else {
      ++report.non_manifold_edges;
    }
    i = j;
  }
  report.unused_vertices = static_cast<std::size_t>(std::count(used.begin(), used.end(), 0));
  report.euler = static_cast<long>(mesh.vertices.size()) - static_cast<long>(undirected) +
                 static_cast<long>(mesh.triangleCount());
  return report;
}

// A valid pixel no triangle covers must touch nodata (8-neighbourhood): the TIN follows the
// valid data's edge to within one pixel.
std::size_t uncoveredAwayFromNodata(const DemGrid& dem, const TinMesh& mesh) {
  // Rasterise coverage with measureTin's rule (closed triangles).
  std::vector<std::uint8_t> covered(dem.pixelCount(), 0);
  const auto& idx = mesh.triangle_indices;
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    const GridPoint& a = mesh.vertices[idx[t]];
    const GridPoint& b = mesh.vertices[idx[t + 1]];
    const GridPoint& c = mesh.vertices[idx[t + 2]];
    const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
    for (int row = int(std::min({a.row, b.row, c.row})); row <= int(std::max({a.row, b.row, c.row})); ++row) {
      for (int col = int(std::min({a.col, b.col, c.col})); col <= int(std::max({a.col, b.col, c.col})); ++col) {
        const double wa = ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col)) / area2;
        const double wb = ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col)) / area2;
        if (wa >= -1e-12 && wb >= -1e-12 && 1 - wa - wb >= -1e-12) covered[dem.index(col, row)] = 1;
      }
    }
  }
  std::size_t away = 0;
  for (int row = 0; row < dem.height; ++row) {
    for (int col = 0; col < dem.width; ++col) {
      if (!dem.isValid(col, row) || covered[dem.index(col, row)]) continue;
      bool touches_nodata = false;
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int r = row + dr, c = col + dc;
          if (r >= 0 && c >= 0 && r < dem.height && c < dem.width && !dem.isValid(c, r)) touches_nodata = true;
        }
      }
      if (!touches_nodata) ++away;
    }
  }
  return away;
}

void checkTin(const DemGrid& dem, double max_error_m, int block_pixels = TinOptions{}.block_pixels) {
  CAPTURE(max_error_m);
  CAPTURE(block_pixels);
  const bool has_nodata = computeStatistics(dem).valid_pixels < dem.pixelCount();
  Progress progress;
  TinOptions options;
  options.max_error_m = max_error_m;
  options.block_pixels = block_pixels;
  const TinMesh mesh = buildTin(dem, options, progress);
  // Every pixel of the raster, not a sample.
  const TinErrorStatistics errors = measureTin(dem, mesh);
  // The builder decides in exact pixel arithmetic plus one plane evaluation; measureTin
  // interpolates with barycentric weights: integer heights (SRTM) hit the bound exactly and
  // the two evaluations differ by rounding only, so allow a nanometre.
  CHECK(errors.max_error_m <= max_error_m + 1e-9);
  CHECK(errors.covered_nodata_pixels == 0);
  CHECK(errors.degenerate_triangles == 0);
  if (has_nodata) {
    CHECK(uncoveredAwayFromNodata(dem, mesh) == 0);
  } else {
    CHECK(errors.uncovered_valid_pixels == 0);
    CHECK(errors.measured_pixels == dem.pixelCount());
  }
  const TopologyReport topology = checkTopology(mesh, dem.width, dem.height, block_pixels);
  CHECK(topology.non_manifold_edges == 0);
  CHECK(topology.inconsistent_edges == 0);
  CHECK(topology.clockwise_triangles == 0);
  CHECK(topology.unused_vertices == 0);
  CHECK(topology.non_delaunay_edges == 0);
  if (!has_nodata) {  // the full rectangle: a disk whose border is the raster's
    CHECK(topology.boundary_off_border == 0);
    CHECK(topology.euler == 1);
  }
  // Vertices are pixels carrying the DEM's own height.
  for (const GridPoint& v : mesh.vertices) {
    REQUIRE(v.col == std::floor(v.col));
    REQUIRE(v.height_m == dem.heightAt(static_cast<int>(v.col), static_cast<int>(v.row)));
  }
  MESSAGE(dem.width << " x " << dem.height << " at " << max_error_m << " m: " << mesh.vertices.size()
          << " vertices " << mesh.triangleCount() << " triangles, max " << errors.max_error_m
          << " m rms " << errors.rms_error_m << " m");
}

}  // namespace

TEST_SUITE("tin") {
  TEST_CASE("a plane needs only the two corner triangles") {
    const DemGrid plane = test::makeDem(50, 30, 1.0, [](int c, int r) { return 100.0 + 0.5 * c - 0.25 * r; });
    Progress progress;
    const TinMesh mesh = buildTin(plane, TinOptions{0.01, 0}, progress);
    CHECK(mesh.vertices.size() == 4);
    CHECK(mesh.triangleCount() == 2);
    checkTin(plane, 0.01, 0);
  }

  TEST_CASE("a cone is refined until every pixel is within the bound") {
    const DemGrid cone = test::makeDem(61, 47, 1.0, [](int c, int r) {
      return 500.0 - 3.0 * std::hypot(c - 30.3, r - 20.7);
    });
    for (double e : {5.0, 1.0, 0.1}) checkTin(cone, e, 0);
  }

  TEST_CASE("small windows stitch into one seamless TIN with and without nodata") {
    const DemGrid cone = test::makeDem(97, 70, 1.0, [](int c, int r) {
      return 500.0 - 3.0 * std::hypot(c - 40.3, r - 30.7);
    });
    const DemGrid holes = test::makeDem(97, 70, 1.0, [](int c, int r) {
      if (std::hypot(c - 32.0, r - 32.0) < 7.5 || c + r < 9) return std::nan("");
      return 500.0 - 3.0 * std::hypot(c - 40.3, r - 30.7);
    });
    for (int block : {8, 16, 32}) {
      checkTin(cone, 1.0, block);
      checkTin(holes, 1.0, block);
    }
  }

  TEST_CASE("the windowed and the single triangulation make about as many triangles") {
    const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
    Progress progress;
    TinOptions single{10.0, 0}, windowed{10.0, 256};
    const double ratio = static_cast<double>(buildTin(dem, windowed, progress).triangleCount()) /
                         static_cast<double>(buildTin(dem, single, progress).triangleCount());
    MESSAGE("windowed / single triangles: " << ratio);
    CHECK(ratio < 1.02);
  }

  TEST_CASE("tighter bounds give more triangles") {
    const DemGrid dem = readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    Progress progress;
    const std::size_t coarse = buildTin(dem, TinOptions{2.0, 0}, progress).triangleCount();
    const std::size_t fine = buildTin(dem, TinOptions{0.5, 0}, progress).triangleCount();
    CHECK(fine > coarse);
  }

  TEST_CASE("bad options are refused with a clear error") {
    const DemGrid dem = test::makeDem(8, 8, 1.0, [](int c, int) { return c; });
    Progress progress;
    CHECK_THROWS_WITH(buildTin(dem, TinOptions{0.0}, progress), doctest::Contains("expected a positive number of metres"));
    const DemGrid specks = test::makeDem(8, 8, 1.0, [](int c, int r) { return (c + r) % 3 == 0 ? 1.0 : std::nan(""); });
    CHECK_THROWS_WITH(buildTin(specks, TinOptions{1.0}, progress), doctest::Contains("no triangle can be built"));
  }

  TEST_CASE("holes nodata corners and ragged borders are followed without covering nodata") {
    // A cone with a round hole, a nodata corner and a ragged nodata margin on one side.
    const DemGrid dem = test::makeDem(80, 64, 1.0, [](int c, int r) {
      if (std::hypot(c - 50.0, r - 30.0) < 9.5) return std::nan("");
      if (c + r < 12) return std::nan("");
      if (c > 70 + (r * 7) % 5) return std::nan("");
      return 400.0 - 2.0 * std::hypot(c - 30.3, r - 25.7);
    });
    for (double e : {2.0, 0.5, 0.1}) checkTin(dem, e, 0);
  }
}

// Every raster in ../shared/data without nodata, at the bounds; every pixel checked.
TEST_SUITE("tin-real") {
  TEST_CASE("the Interlaken DHM25 TIN holds 0.5 1 and 2 m on every pixel") {
    const DemGrid dem = readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    for (double e : {0.5, 1.0, 2.0}) checkTin(dem, e);
  }
  TEST_CASE("the Delft AHN3 mosaic TIN holds 0.5 1 and 2 m on every pixel") {
    const DemGrid dem = readDem({test::sharedData("nl_ahn3_delft_tiles/delft_west_0.5m_28992.tif"),
                                 test::sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif")});
    for (double e : {0.5, 1.0, 2.0}) checkTin(dem, e);
  }
  TEST_CASE("the two Delft files give one TIN with no seam along their common border") {
    // West tile: columns 0-382 of the mosaic; east tile: 383-526. No TIN edge may be a
    // boundary edge along that line, and triangles must span it.
    const DemGrid dem = readDem({test::sharedData("nl_ahn3_delft_tiles/delft_west_0.5m_28992.tif"),
                                 test::sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif")});
    Progress progress;
    const TinMesh mesh = buildTin(dem, TinOptions{0.5}, progress);
    const TopologyReport topology = checkTopology(mesh, dem.width, dem.height, TinOptions{}.block_pixels);
    CHECK(topology.boundary_off_border == 0);
    std::size_t spanning = 0;
    for (std::size_t t = 0; t < mesh.triangle_indices.size(); t += 3) {
      double lo = 1e9, hi = -1e9;
      for (int k = 0; k < 3; ++k) {
        lo = std::min(lo, mesh.vertices[mesh.triangle_indices[t + k]].col);
        hi = std::max(hi, mesh.vertices[mesh.triangle_indices[t + k]].col);
      }
      if (lo <= 382 && hi >= 383) ++spanning;
    }
    CHECK(spanning > 0);
  }

  TEST_CASE("the Minnesota lidar TIN holds 0.5 1 and 2 m on every pixel") {
    const DemGrid dem = readDem({test::sharedData("us_mn_lidar_dtm_1m_26915.tif")});
    for (double e : {0.5, 1.0, 2.0}) checkTin(dem, e);
  }
  TEST_CASE("the Ontario lidar TIN with nodata holds 0.5 1 and 2 m and covers no nodata") {
    const DemGrid dem = readDem({test::sharedData("ca_on_lidar_dtm_1m_26917.tif")});
    REQUIRE(computeStatistics(dem).valid_pixels < dem.pixelCount());  // it does have nodata
    for (double e : {0.5, 1.0, 2.0}) checkTin(dem, e);
  }
  TEST_CASE("the SRTM and ETOPO5 TINs hold 10 and 20 m on every pixel") {
    for (const char* name : {"srtm3_N57E011_4326.tif", "srtm3_N00E010-E011_4326.tif",
                             "ch_etopo5_1km_2056.tif", "etopo5_global_4326.tif"}) {
      CAPTURE(name);
      const DemGrid dem = readDem({test::sharedData(name)});
      for (double e : {10.0, 20.0}) checkTin(dem, e);
    }
  }
}
