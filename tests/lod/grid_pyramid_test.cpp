#include <doctest/doctest.h>

#include <cmath>
#include <set>

#include "src/lod/grid_pyramid.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {
DemGrid cone() {
  return test::makeDem(41, 33, 10.0, [](int c, int r) {
    return 1000.0 - 5.0 * std::hypot(c - 20.0, r - 16.0);
  });
}
}  // namespace

TEST_SUITE("lod") {
  TEST_CASE("the pyramid has one root tile and quadtree children") {
    Progress progress;
    GridPyramidOptions options;
    options.tile_cells = 8;
    const GridPyramid pyramid = buildGridPyramid(cone(), options, progress);
    // 40 cells / 8 -> zooms 0..3 (8 << 3 = 64 >= 40).
    REQUIRE(pyramid.levels.size() == 4);
    CHECK(pyramid.levels[0].tiles.size() == 1);
    CHECK(pyramid.levels[0].step == 8);
    CHECK(pyramid.levels[3].step == 1);
    for (std::size_t z = 0; z < pyramid.levels.size(); ++z) {
      const PyramidLevel& level = pyramid.levels[z];
      std::size_t triangles = 0;
      std::set<std::pair<int, int>> keys;
      for (const PyramidTile& tile : level.tiles) {
        triangles += tile.faces.size();
        CHECK(tile.key.zoom == static_cast<int>(z));
        CHECK(keys.insert({tile.key.x, tile.key.y}).second);
        // Every tile of zoom z > 0 has a parent at zoom z - 1.
        if (z > 0) {
          const TileKey parent = tile.key.parent();
          bool found = false;
          for (const PyramidTile& p : pyramid.levels[z - 1].tiles) found |= p.key == parent;
          CHECK(found);
        }
        CHECK(tile.faces.size() <= 2u * 8 * 8);
      }
      // Tiles partition the level: each triangle is in exactly one tile.
      CHECK(triangles == level.mesh.triangleCount());
    }
  }

  TEST_CASE("measured errors are zero at the finest zoom and grow towards the root") {
    Progress progress;
    GridPyramidOptions options;
    options.tile_cells = 8;
    const GridPyramid pyramid = buildGridPyramid(cone(), options, progress);
    CHECK(pyramid.levels.back().max_error_m == 0.0);
    for (std::size_t z = 0; z + 1 < pyramid.levels.size(); ++z) {
      CHECK(pyramid.levels[z].max_error_m > 0.0);
      CHECK(pyramid.levels[z].max_error_m >= pyramid.levels[z + 1].max_error_m);
      CHECK(pyramid.levels[z].rms_error_m <= pyramid.levels[z].max_error_m);
    }
    // The cone's apex is on the step-8 lattice? (20, 16): no, so the root cuts it: its error
    // is at least the drop from the apex to the nearest root samples.
    CHECK(pyramid.levels[0].max_error_m > 5.0);
  }

  TEST_CASE("a plane has zero measured error at every zoom") {
    Progress progress;
    GridPyramidOptions options;
    options.tile_cells = 4;
    const DemGrid plane = test::makeDem(30, 20, 5.0, [](int c, int r) { return 0.5 * c + 0.25 * r; });
    const GridPyramid pyramid = buildGridPyramid(plane, options, progress);
    for (const PyramidLevel& level : pyramid.levels) {
      CHECK(level.max_error_m == doctest::Approx(0.0).epsilon(1e-9));
      for (const PyramidTile& tile : level.tiles) CHECK(tile.measured_pixels > 0);
    }
  }
}
