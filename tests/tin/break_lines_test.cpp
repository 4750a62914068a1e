// Break lines (--constraints): real feature lines read through OGR in another CRS, inserted
// into the TIN as constrained edges, kept at every level of detail; the TIN still holds its
// error bound on every pixel and stays a valid surface.
#include <doctest/doctest.h>

#include <gdal_priv.h>
#include <gdal_alg.h>
#include <gdal_utils.h>
#include <ogrsf_frmts.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <unordered_map>
#include <unordered_set>

#include <nlohmann/json.hpp>

#include <fstream>

#include "formats/dem/read_dem.h"
#include "formats/vector/read_break_lines.h"
#include "src/base/error.h"
#include "src/lod/build_levels.h"
#include "src/partition/face_graph.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

// Contour lines of a real raster (GDAL's contour generator, every `interval` metres),
// written as `driver` to `path` in `crs` (e.g. GeoJSON in EPSG:4326): real lines that follow
// the terrain, in a CRS other than the DEM's.
void writeContours(const std::string& raster, double interval, const std::string& driver, const std::string& crs,
                   const std::string& path) {
  GDALAllRegister();
  GDALDatasetH source = GDALOpen(raster.c_str(), GA_ReadOnly);
  REQUIRE(source != nullptr);
  GDALRasterBandH band = GDALGetRasterBand(source, 1);
  int has_nodata = 0;
  const double nodata = GDALGetRasterNoDataValue(band, &has_nodata);
  GDALDriverH memory = GDALGetDriverByName("Memory");
  GDALDatasetH lines = GDALCreate(memory, "contours", 0, 0, 0, GDT_Unknown, nullptr);
  OGRSpatialReferenceH srs = OSRClone(GDALGetSpatialRef(source));
  OGRLayerH layer = GDALDatasetCreateLayer(lines, "contours", srs, wkbLineString, nullptr);
  OGRFieldDefnH field = OGR_Fld_Create("elevation", OFTReal);
  OGR_L_CreateField(layer, field, TRUE);
  OGR_Fld_Destroy(field);
  REQUIRE(GDALContourGenerate(band, interval, 0, 0, nullptr, has_nodata, nodata, layer, -1, 0, nullptr,
                              nullptr) == CE_None);
  const char* args[] = {"-f", driver.c_str(), "-t_srs", crs.c_str(), nullptr};
  GDALVectorTranslateOptions* options = GDALVectorTranslateOptionsNew(const_cast<char**>(args), nullptr);
  int usage_error = 0;
  GDALDatasetH written = GDALVectorTranslate(path.c_str(), nullptr, 1, &lines, options, &usage_error);
  GDALVectorTranslateOptionsFree(options);
  REQUIRE(written != nullptr);
  GDALClose(written);
  GDALClose(lines);
  OSRDestroySpatialReference(srs);
  GDALClose(source);
}

std::uint64_t pixelKey(double col, double row) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(row)) << 32) | static_cast<std::uint32_t>(col);
}

struct UnionFind {
  std::vector<std::uint32_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t find(std::uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  }
  void join(std::uint32_t a, std::uint32_t b) { parent[find(a)] = find(b); }
};

double distanceToSegment(double x, double y, const PixelSegment& s) {
  const double dx = s.col1 - s.col0, dy = s.row1 - s.row0;
  const double length2 = dx * dx + dy * dy;
  const double t = length2 > 0 ? std::clamp(((x - s.col0) * dx + (y - s.row0) * dy) / length2, 0.0, 1.0) : 0.0;
  return std::hypot(x - (s.col0 + t * dx), y - (s.row0 + t * dy));
}

// The invariants of a TIN built with break lines: the error bound on every pixel, no nodata
// covered, a manifold surface; every constrained edge an edge of the mesh, near a break
// line; every segment's two ends vertices of the TIN joined by constrained edges.
void checkConstrainedTin(const DemGrid& dem, const ConstrainedTin& tin, const std::vector<PixelSegment>& segments,
                         double max_error_m, double max_distance_px) {
  const TinErrorStatistics errors = measureTin(dem, tin.mesh);
  CHECK(errors.max_error_m <= max_error_m + 1e-9);
  CHECK(errors.covered_nodata_pixels == 0);
  CHECK(errors.degenerate_triangles == 0);
  CHECK_NOTHROW(buildFaceGraph(tin.mesh));  // throws for a non-manifold or folded mesh
  const std::vector<std::uint64_t> edges = meshEdgeKeys(tin.mesh);
  const std::unordered_set<std::uint64_t> edge_set(edges.begin(), edges.end());
  REQUIRE(!tin.constrained_edges.empty());
  // Segments by 16-pixel cell of their bounding box grown by max_distance_px.
  constexpr int kCell = 16;
  std::unordered_map<std::uint64_t, std::vector<std::size_t>> segments_near;
  for (std::size_t i = 0; i < segments.size(); ++i) {
    const PixelSegment& s = segments[i];
    const int c0 = static_cast<int>(std::floor((std::min(s.col0, s.col1) - max_distance_px) / kCell));
    const int c1 = static_cast<int>(std::floor((std::max(s.col0, s.col1) + max_distance_px) / kCell));
    const int r0 = static_cast<int>(std::floor((std::min(s.row0, s.row1) - max_distance_px) / kCell));
    const int r1 = static_cast<int>(std::floor((std::max(s.row0, s.row1) + max_distance_px) / kCell));
    for (int r = r0; r <= r1; ++r) {
      for (int c = c0; c <= c1; ++c) segments_near[pixelKey(c + 1, r + 1)].push_back(i);
    }
  }
  UnionFind chains(tin.mesh.vertices.size());
  double worst_distance = 0;
  for (const auto& edge : tin.constrained_edges) {
    REQUIRE(edge_set.count((static_cast<std::uint64_t>(std::min(edge[0], edge[1])) << 32) | std::max(edge[0], edge[1])));
    chains.join(edge[0], edge[1]);
    for (const std::uint32_t v : edge) {
      const GridPoint& p = tin.mesh.vertices[v];
      double nearest = 1e300;  // farther than max_distance_px when no segment's cell holds it
      const auto cell = segments_near.find(pixelKey(std::floor(p.col / kCell) + 1, std::floor(p.row / kCell) + 1));
      if (cell != segments_near.end()) {
        for (const std::size_t i : cell->second) nearest = std::min(nearest, distanceToSegment(p.col, p.row, segments[i]));
      }
      worst_distance = std::max(worst_distance, nearest);
    }
  }
  CHECK(worst_distance <= max_distance_px);
  std::unordered_map<std::uint64_t, std::uint32_t> vertex_at;
  for (std::uint32_t v = 0; v < tin.mesh.vertices.size(); ++v) {
    vertex_at[pixelKey(tin.mesh.vertices[v].col, tin.mesh.vertices[v].row)] = v;
  }
  std::size_t unjoined = 0, missing = 0;
  for (const PixelSegment& s : segments) {
    const auto from = vertex_at.find(pixelKey(s.col0, s.row0)), to = vertex_at.find(pixelKey(s.col1, s.row1));
    if (from == vertex_at.end() || to == vertex_at.end()) {
      ++missing;
      continue;
    }
    if (chains.find(from->second) != chains.find(to->second)) ++unjoined;
  }
  CHECK(missing == 0);
  CHECK(unjoined == 0);
  MESSAGE(segments.size() << " segments -> " << tin.constrained_edges.size() << " constrained edges, "
          << tin.segments_bent << " bent, " << tin.edges_dropped << " dropped; " << tin.mesh.triangleCount()
          << " triangles, max error " << errors.max_error_m << " m, farthest constrained vertex "
          << worst_distance << " px from its line");
}

}  // namespace

TEST_SUITE("tin") {
  TEST_CASE("contours in EPSG:4326 become TIN edges of the Interlaken tile and survive every level") {
    test::TempDir dir;
    const std::string raster = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    writeContours(raster, 100, "GeoJSON", "EPSG:4326", dir / "contours.geojson");
    const DemGrid dem = readDem({raster});
    const BreakLines lines = readBreakLines(dir / "contours.geojson", dem);
    CHECK(lines.features > 20);
    REQUIRE(lines.segments.size() > 1000);
    Progress quiet(ProgressMode::Quiet);
    for (const std::int32_t block : {128, 0}) {  // windowed (the default) and one triangulation
      CAPTURE(block);
      TinOptions options;
      options.max_error_m = 0.5;
      options.block_pixels = block;
      const ConstrainedTin tin = buildConstrainedTin(dem, options, lines.segments, quiet);
      // Contours never cross, so nothing is bent; window borders move a crossing half a pixel.
      CHECK(tin.segments_bent == 0);
      checkConstrainedTin(dem, tin, lines.segments, 0.5, 0.5 + 1e-9);
      if (block == 0) continue;
      // The level loop locks them at every level (paper algorithm 2 throws if one is lost).
      LevelOptions level_options;
      level_options.first_budget_m = 1.0;
      const std::vector<Level> levels = buildLevels(dem, tin.mesh, level_options, tin.constrained_edges, quiet);
      CHECK(levels.size() >= 4);
    }
  }

  TEST_CASE("random crossing break lines on a raster with nodata keep the bound and join their ends") {
    // Ontario lidar (nodata margins): contours in the DEM's own CRS as a GeoPackage, plus 300
    // random segments between valid pixels that cross each other and the window borders.
    test::TempDir dir;
    const std::string raster = test::sharedData("ca_on_lidar_dtm_1m_26917.tif");
    writeContours(raster, 2, "GPKG", "EPSG:26917", dir / "contours.gpkg");
    const DemGrid dem = readDem({raster});
    const BreakLines contours = readBreakLines(dir / "contours.gpkg", dem);
    REQUIRE(contours.segments.size() > 100);
    Progress quiet(ProgressMode::Quiet);
    const ConstrainedTin with_contours = buildConstrainedTin(dem, TinOptions{0.5}, contours.segments, quiet);
    checkConstrainedTin(dem, with_contours, contours.segments, 0.5, 0.5 + 1e-9);

    std::mt19937 random(7);
    std::uniform_int_distribution<std::int32_t> col(0, dem.width - 1), row(0, dem.height - 1);
    const auto validPixel = [&] {
      while (true) {
        const std::int32_t c = col(random), r = row(random);
        if (dem.isValid(c, r)) return std::array<std::int32_t, 2>{c, r};
      }
    };
    std::vector<PixelSegment> crossing;
    while (crossing.size() < 300) {
      const auto a = validPixel(), b = validPixel();
      // Only segments over valid pixels (as readBreakLines makes them): sample every pixel.
      const std::int32_t steps = std::max(std::abs(b[0] - a[0]), std::abs(b[1] - a[1]));
      bool valid = steps > 0 && steps < 120;
      for (std::int32_t k = 0; valid && k <= steps; ++k) {
        valid = dem.isValid(a[0] + static_cast<std::int32_t>(std::lround(double(k) / steps * (b[0] - a[0]))),
                            a[1] + static_cast<std::int32_t>(std::lround(double(k) / steps * (b[1] - a[1]))));
      }
      if (valid) crossing.push_back({a[0], a[1], b[0], b[1]});
    }
    for (const std::int32_t block : {128, 37}) {
      CAPTURE(block);
      TinOptions options;
      options.max_error_m = 0.5;
      options.block_pixels = block;
      const ConstrainedTin tin = buildConstrainedTin(dem, options, crossing, quiet);
      CHECK(tin.segments_bent > 0);  // random segments cross away from pixel centres
      CHECK(tin.edges_dropped == 0);
      MESSAGE(tin.segments_bent_to_end << " bent to an end");
      // Crossing lines meet at the pixel nearest their crossing: under a pixel and a half off.
      checkConstrainedTin(dem, tin, crossing, 0.5, 1.5);
    }
  }

  TEST_CASE("break line files that cannot be used are refused with a clear error") {
    const DemGrid dem = readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    CHECK_THROWS_WITH(readBreakLines("/nonexistent/roads.geojson", dem), doctest::Contains("does not exist"));
    CHECK_THROWS_WITH(readBreakLines(test::sharedData("ch_dhm25_interlaken_25m_2056.tif"), dem),
                      doctest::Contains("cannot read it as vector data"));
  }
}

TEST_SUITE("cli") {
  TEST_CASE("levels --constraints keeps contour lines as edges of every level") {
    test::TempDir dir;
    const std::string raster = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    writeContours(raster, 200, "GeoJSON", "EPSG:4326", dir / "contours.geojson");
    const auto result = test::runTerratiles(
        {"levels", raster, "-o", dir / "levels", "--constraints", dir / "contours.geojson", "--levels", "3"});
    REQUIRE(result.exit_code == 0);
    std::ifstream file(dir / "levels/levels.json");
    const nlohmann::json summary = nlohmann::json::parse(file);
    CHECK(summary["break_lines"]["constrained_edges"].get<int>() > 100);
    CHECK(summary["levels"].size() == 4);
    const auto missing = test::runTerratiles({"levels", raster, "-o", dir / "x", "--constraints", dir / "no.geojson"});
    CHECK(missing.exit_code == 3);
    CHECK(missing.err.find("does not exist") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path() / "x"));
  }
}
