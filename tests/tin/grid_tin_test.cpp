#include <doctest/doctest.h>

#include <cmath>

#include "src/tin/grid_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {
// Signed doubled area in the CRS frame (x east = col, y north = -row); > 0 means
// counter-clockwise seen from above.
double signedArea(const TinMesh& mesh, std::size_t t) {
  const auto& a = mesh.vertices[mesh.triangle_indices[t]];
  const auto& b = mesh.vertices[mesh.triangle_indices[t + 1]];
  const auto& c = mesh.vertices[mesh.triangle_indices[t + 2]];
  return (b.col - a.col) * (-(c.row - a.row)) - (-(b.row - a.row)) * (c.col - a.col);
}
}  // namespace

TEST_SUITE("tin") {
  TEST_CASE("sample positions include the last pixel whatever the step") {
    CHECK(gridSamplePositions(10, 1).size() == 10);
    CHECK(gridSamplePositions(10, 4) == std::vector<std::int32_t>{0, 4, 8, 9});
    CHECK(gridSamplePositions(9, 4) == std::vector<std::int32_t>{0, 4, 8});
    CHECK(gridSamplePositions(2, 64) == std::vector<std::int32_t>{0, 1});
  }

  TEST_CASE("a full grid mesh has two counter-clockwise triangles per cell") {
    const DemGrid dem = test::makeDem(7, 5, 1.0, [](int c, int r) { return 10.0 * c - r; });
    const TinMesh mesh = triangulateGrid(dem, 1);
    CHECK(mesh.vertices.size() == 35);
    CHECK(mesh.triangleCount() == 6 * 4 * 2);
    for (std::size_t t = 0; t < mesh.triangle_indices.size(); t += 3) {
      REQUIRE(signedArea(mesh, t) > 0);
    }
    // Step 1 passes through every pixel centre: heights equal the DEM.
    for (const GridPoint& v : mesh.vertices) {
      REQUIRE(v.height_m == dem.heightAt(static_cast<int>(v.col), static_cast<int>(v.row)));
    }
  }

  TEST_CASE("a decimated mesh keeps the footprint and interpolates a plane exactly") {
    const DemGrid dem = test::makeDem(11, 10, 1.0, [](int c, int r) { return 3.0 * c - 2.0 * r; });
    const TinMesh mesh = triangulateGrid(dem, 4);
    // Columns 0 4 8 10, rows 0 4 8 9.
    CHECK(mesh.vertices.size() == 16);
    CHECK(mesh.triangleCount() == 3 * 3 * 2);
    for (int row = 0; row <= 8; ++row) {
      for (int col = 0; col <= 8; ++col) {
        const int c0 = col / 4 * 4, r0 = row / 4 * 4;
        const int c1 = std::min(c0 + 4, 10), r1 = std::min(r0 + 4, 9);
        REQUIRE(interpolateCell(dem, c0, r0, c1, r1, col, row) ==
                doctest::Approx(dem.heightAt(col, row)));
      }
    }
  }

  TEST_CASE("triangles never use a nodata pixel") {
    const DemGrid dem = test::makeDem(6, 6, 1.0, [](int c, int r) {
      return (c == 2 && r == 3) ? std::nan("") : 100.0 + c;
    });
    const TinMesh mesh = triangulateGrid(dem, 1);
    CHECK(mesh.vertices.size() == 35);
    // The hole's pixel touches 6 triangles of the diagonal split.
    CHECK(mesh.triangleCount() == 5 * 5 * 2 - 6);
    for (std::uint32_t v : mesh.triangle_indices) {
      REQUIRE(!std::isnan(mesh.vertices[v].height_m));
    }
  }
}
