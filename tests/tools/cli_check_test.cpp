// `terratiles check` on real builds: the default (boundaries merge) leaves no hole in any cut
// whose neighbours are at most one zoom apart, no T-junction where tiles of two zooms meet,
// contents agree where they overlap, every geometricError is honest; duplicate passes too;
// centroid (holes) and the grid pyramid (T-junctions) fail: the checker is not blind.
#include <doctest/doctest.h>

#include <GeographicLib/Geocentric.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <bit>
#include <string>
#include <vector>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/gltf/read_glb.h"
#include "formats/gltf/write_glb.h"
#include "src/geo/drawn_pixels.h"
#include "src/pipeline/check_output.h"
#include "src/pipeline/drawn_tiles.h"
#include "src/tin/measure_tin.h"
#include "tests/test_support.h"
#include "tileset/implicit_tileset.h"
#include "tileset/read_tileset.h"

using namespace terratiles;

namespace {

CheckReport buildAndCheck(const std::string& raster, const std::vector<std::string>& options, const test::TempDir& dir,
                          const std::string& name) {
  std::vector<std::string> args{"build", test::sharedData(raster), "-o", dir / name, "-q"};
  args.insert(args.end(), options.begin(), options.end());
  const auto built = test::runTerratiles(args);
  CAPTURE(built.err);
  REQUIRE(built.exit_code == 0);
  Progress quiet(ProgressMode::Quiet);
  CheckOptions check;
  check.cuts = 300;
  const CheckReport report = checkOutput(dir / name, check, quiet);
  MESSAGE(raster << " " << name << ":\n" << describeCheck(report));
  return report;
}

nlohmann::json readJsonFile(const std::string& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

// Every tile with content of a tileset.json tree, depth first.
void forEachContent(nlohmann::json& node, const std::function<void(nlohmann::json&)>& visit) {
  if (node.contains("content")) visit(node);
  if (node.contains("children")) {
    for (nlohmann::json& child : node["children"]) forEachContent(child, visit);
  }
}

// A decoded GLB's vertex v in ECEF, as doubles (glTF y-up back to z-up).
std::array<double, 3> ecefOf(const GlbMesh& mesh, std::size_t v) {
  return {mesh.translation[0] + mesh.positions[3 * v], -(mesh.translation[2] + mesh.positions[3 * v + 2]),
          mesh.translation[1] + mesh.positions[3 * v + 1]};
}

// Random triangles over a DEM for the scans' tests: corners at pixel centres (as a TIN's),
// just off them (as decoded), or anywhere, from a pixel across to a hundred.
std::vector<std::array<GridPoint, 3>> randomTriangles(const DemGrid& dem, std::size_t count, std::uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<std::array<GridPoint, 3>> out;
  for (std::size_t i = 0; i < count; ++i) {
    const double size = std::pow(10.0, 2 * unit(random));
    const double col = unit(random) * (dem.width - 1), row = unit(random) * (dem.height - 1);
    const int kind = static_cast<int>(i % 3);
    std::array<GridPoint, 3> corners;
    for (GridPoint& corner : corners) {
      double c = std::clamp(col + (unit(random) - 0.5) * size, 0.0, dem.width - 1.0);
      double r = std::clamp(row + (unit(random) - 0.5) * size, 0.0, dem.height - 1.0);
      if (kind < 2) c = std::round(c), r = std::round(r);
      if (kind == 1) c += (unit(random) - 0.5) * 2e-4, r += (unit(random) - 0.5) * 2e-4;
      const float h = dem.heightAt(static_cast<std::int32_t>(std::round(std::clamp(c, 0.0, dem.width - 1.0))),
                                   static_cast<std::int32_t>(std::round(std::clamp(r, 0.0, dem.height - 1.0))));
      corner = {c, r, std::isnan(h) ? 0.0 : static_cast<double>(h) + (unit(random) - 0.5) * 40};
    }
    out.push_back(corners);
  }
  return out;
}

// The fast scans of drawn_tiles.h against the reference ones they stand for, on a DEM.
void checkScans(const DemGrid& dem, const GeoidGrid* geoid) {
  const DemOnGlobe globe(dem, geoid);
  const PixelBoxes boxes(globe);
  std::size_t met = 0, covered = 0, triangles = 0;
  for (const auto& corners : randomTriangles(dem, 3000, 7)) {
    std::array<EcefPoint, 3> ecef;
    for (std::size_t k = 0; k < 3; ++k) ecef[k] = globe.place(corners[k]);
    const DrawnTriangle triangle(ecef[0], ecef[1], ecef[2]);
    if (triangle.degenerate()) continue;
    ++triangles;
    const auto gridCorner = [&](const GridPoint& p) {
      const bool at_pole = p.row == std::round(p.row) && globe.poleRow(static_cast<std::int32_t>(p.row));
      return GridCorner{p.col, p.row, at_pole};
    };
    const std::array<GridCorner, 3> grid{gridCorner(corners[0]), gridCorner(corners[1]), gridCorner(corners[2])};
    for (const double shift_m : {0.0, 1e-3, 0.0068}) {
      const PixelBox expected = candidatePixels(globe, grid, triangle.longestEdge(), shift_m);
      const PixelBox box = boxes.box(grid, triangle.longestEdge(), shift_m);
      REQUIRE(box.row0 == expected.row0);
      REQUIRE(box.row1 == expected.row1);
      REQUIRE(box.col0 == expected.col0);
      REQUIRE(box.col1 == expected.col1);
      std::vector<PixelOffset> reference, fast;
      forEachPixelMeeting(globe, triangle, expected, [&](std::size_t pixel, double offset_m) {
        reference.push_back({pixel, offset_m});
      });
      pixelsMeeting(globe, triangle, box, fast);
      REQUIRE(fast.size() == reference.size());
      for (std::size_t i = 0; i < fast.size(); ++i) {
        REQUIRE(fast[i].pixel == reference[i].pixel);
        REQUIRE(std::bit_cast<std::uint64_t>(fast[i].offset_m) == std::bit_cast<std::uint64_t>(reference[i].offset_m));
      }
      met += fast.size();
    }
    std::vector<std::uint32_t> reference, fast;
    forEachCoveredPixel(dem, corners[0], corners[1], corners[2], [&](std::size_t pixel, double) {
      if (!std::isnan(dem.heights_m[pixel])) reference.push_back(static_cast<std::uint32_t>(pixel));
      return true;
    });
    coveredValidPixels(dem, corners[0], corners[1], corners[2], fast);
    REQUIRE(fast == reference);
    covered += fast.size();
  }
  MESSAGE(triangles << " triangles: " << met << " pixels met, " << covered << " covered");
  CHECK(met > 10000);
  CHECK(covered > 10000);
}

}  // namespace

TEST_SUITE("check") {
  TEST_CASE("the check's and the build's fast scans find the reference scans' pixels and offsets bit for bit") {
    const GeoidGrid swiss = readGeoidGrid(test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif"));
    checkScans(readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")}), &swiss);
    checkScans(readDem({test::sharedData("srtm3_N57E011_4326.tif")}), nullptr);
    checkScans(readDem({test::sharedData("ca_on_lidar_dtm_1m_26917.tif")}), nullptr);
    // The whole globe (ETOPO5 at every sixth pixel: half a degree; columns wrap, pole rows,
    // long chords) with a patch of nodata.
    const DemGrid etopo = readDem({test::sharedData("etopo5_global_4326.tif")});
    constexpr int kStep = 6;
    DemGrid globe = etopo;
    globe.width = (etopo.width + kStep - 1) / kStep;
    globe.height = (etopo.height + kStep - 1) / kStep;
    globe.pixel_size_x = etopo.pixel_size_x * kStep;
    globe.pixel_size_y = etopo.pixel_size_y * kStep;
    globe.origin_x = etopo.pixelCentre(0, 0).x - globe.pixel_size_x / 2;
    globe.origin_y = etopo.pixelCentre(0, 0).y + globe.pixel_size_y / 2;
    globe.heights_m.assign(globe.pixelCount(), DemGrid::kNoData);
    for (int row = 0; row < globe.height; ++row) {
      for (int col = 0; col < globe.width; ++col) {
        const bool patch = col > 100 && col < 140 && row > 50 && row < 90;
        if (!patch) globe.heights_m[globe.index(col, row)] = etopo.heightAt(col * kStep, row * kStep);
      }
    }
    checkScans(globe, nullptr);
  }

  TEST_CASE("a drawn triangle's lowest height bound is below all of it and within a millimetre of its least") {
    // Chords of 10 to 3,000 km between ETOPO5 pixels at their heights (trenches to peaks, the
    // poles' rows too), against the least height of a dense lattice of each (every L / 300),
    // which lies at most (L / 300)^2 / (6 R) above the triangle's least (the height is convex
    // and curved by at most 1 / R).
    const DemGrid etopo = readDem({test::sharedData("etopo5_global_4326.tif")});
    const DemOnGlobe globe(etopo, nullptr);
    const auto& earth = GeographicLib::Geocentric::WGS84();
    std::mt19937 random(11);
    std::uniform_real_distribution<double> unit(0, 1);
    constexpr int kLattice = 300;
    constexpr double kRadius_m = 6.3e6;
    int triangles = 0, interior_lowest = 0;
    while (triangles < 60) {
      const double size_px = std::pow(10.0, 0.3 + 2.3 * unit(random));  // 2 to 400 pixels of 5'
      const double col = unit(random) * (etopo.width - 1), row = unit(random) * (etopo.height - 1);
      std::array<EcefPoint, 3> corners;
      for (EcefPoint& corner : corners) {
        const auto c = static_cast<std::int32_t>(std::clamp(std::round(col + (unit(random) - 0.5) * size_px), 0.0, etopo.width - 1.0));
        const auto r = static_cast<std::int32_t>(std::clamp(std::round(row + (unit(random) - 0.5) * size_px), 0.0, etopo.height - 1.0));
        corner = globe.point(c, r);
      }
      const DrawnTriangle triangle(corners[0], corners[1], corners[2]);
      if (triangle.degenerate() || triangle.longestEdge() < 10e3) continue;
      ++triangles;
      double least = HUGE_VAL;
      int least_i = 0, least_j = 0;
      for (int i = 0; i <= kLattice; ++i) {
        for (int j = 0; i + j <= kLattice; ++j) {
          const double u = static_cast<double>(i) / kLattice, w = static_cast<double>(j) / kLattice;
          double lat = 0, lon = 0, h = 0;
          earth.Reverse(triangle.a.x + u * triangle.ab[0] + w * triangle.ac[0], triangle.a.y + u * triangle.ab[1] + w * triangle.ac[1],
                        triangle.a.z + u * triangle.ab[2] + w * triangle.ac[2], lat, lon, h);
          if (h < least) least = h, least_i = i, least_j = j;
        }
      }
      if (least_i > 0 && least_j > 0 && least_i + least_j < kLattice) ++interior_lowest;
      const double bound = lowestHeightBound(triangle);
      const double side_m = triangle.longestEdge() / kLattice;
      CAPTURE(triangle.longestEdge());
      CAPTURE(least);
      CHECK(bound <= least);
      CHECK(bound >= least - side_m * side_m / (6 * kRadius_m) - 1e-3);
    }
    MESSAGE(triangles << " triangles, " << interior_lowest << " lowest inside");
    CHECK(interior_lowest >= 5);  // both of the bound's searches are met
    CHECK(triangles - interior_lowest >= 10);
  }

  TEST_CASE("outline edges are the edges exactly one triangle has in ascending order") {
    std::mt19937 random(3);
    OutlineScratch scratch;
    std::vector<std::array<std::uint32_t, 2>> edges;
    for (int round = 0; round < 200; ++round) {
      const std::uint32_t vertices = 3 + random() % 60;
      std::vector<std::uint32_t> indices;
      for (std::uint32_t t = random() % 80; t-- > 0;) {
        for (int k = 0; k < 3; ++k) indices.push_back(static_cast<std::uint32_t>(random() % vertices));
      }
      // Reference: sorted (smaller, larger) keys, those that occur once.
      std::vector<std::uint64_t> keys;
      for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
        for (std::size_t k = 0; k < 3; ++k) {
          const std::uint32_t a = indices[t + k], b = indices[t + (k + 1) % 3];
          keys.push_back((static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b));
        }
      }
      std::sort(keys.begin(), keys.end());
      std::vector<std::array<std::uint32_t, 2>> expected;
      for (std::size_t i = 0; i < keys.size();) {
        std::size_t j = i;
        while (j < keys.size() && keys[j] == keys[i]) ++j;
        if (j - i == 1) expected.push_back({static_cast<std::uint32_t>(keys[i] >> 32), static_cast<std::uint32_t>(keys[i])});
        i = j;
      }
      outlineEdges(indices, vertices, scratch, edges);
      REQUIRE(edges == expected);
    }
  }


  TEST_CASE("merge tiles of four real rasters in the three schemes pass the check") {
    test::TempDir dir;
    test::checkSeamless(buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {}, dir, "interlaken_webmercator"));
    test::checkSeamless(buildAndCheck("srtm3_N57E011_4326.tif", {"--scheme", "geographic", "--tin-max-error", "5"}, dir,
                                "srtm_geographic"));
    test::checkSeamless(buildAndCheck("ca_on_lidar_dtm_1m_26917.tif", {"--scheme", "local", "--tin-max-error", "0.1", "--tile-triangles", "4096"}, dir,
                                "ontario_local"));
    test::checkSeamless(buildAndCheck("us_mn_lidar_dtm_1m_26915.tif", {"--tin-max-error", "0.1", "--tile-triangles", "4096"},
                                dir, "minnesota_webmercator"));
  }

  TEST_CASE("duplicate passes the check, centroid leaves holes, the grid pyramid has T-junctions") {
    test::TempDir dir;
    test::checkSeamless(buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--assign", "duplicate"}, dir, "duplicate"));
    const CheckReport centroid = buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--assign", "centroid"}, dir, "centroid");
    CHECK(centroid.cuts_with_holes > 0);
    CHECK_FALSE(centroid.ok());
    // The CLI says so with exit code 5.
    const auto cli = test::runTerratiles({"check", dir / "centroid", "--cuts", "50"});
    CHECK(cli.exit_code == 5);
    CHECK(cli.out.find("terratiles check: FAILED") != std::string::npos);
    // The grid pyramid's T-junctions between zooms are missing border vertices.
    const CheckReport grid = buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--lod", "grid"}, dir, "grid");
    CHECK(grid.neighbour_pairs > 0);
    CHECK(grid.missing_border_vertices > 0);
    CHECK_FALSE(grid.ok());
    const auto not_an_output = test::runTerratiles({"check", dir.path().string()});
    CHECK(not_an_output.exit_code == 3);
    CHECK(not_an_output.err.find("tileset.json cannot be read") != std::string::npos);
  }

  TEST_CASE("the check gives the same report in strips of 16 rows as in one strip") {
    // The DEM read and measured a strip of rows at a time (each with the rows its tiles'
    // tallest triangle reaches): every pixel counted in its own strip, every tile's error the
    // largest over the strips, the coverage classes summed over them. --strip-pixels 1 makes
    // strips of 16 rows (the least), so each raster below has 15 to 76 strips.
    test::TempDir dir;
    // Interlaken with a hole of nodata and a ragged edge (ragged pixels left out next to it).
    DemGrid dem = readDem({test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
    for (std::int32_t row = 0; row < dem.height; ++row) {
      for (std::int32_t col = 0; col < dem.width; ++col) {
        const bool hole = std::hypot(col - 200.0, row - 100.0) < 30;
        const bool ragged = col < 20 + (row * 7) % 13;
        if (hole || ragged) dem.heights_m[dem.index(col, row)] = DemGrid::kNoData;
      }
    }
    const std::string holed = dir / "interlaken_holed.tif";
    test::writeGeoTiff(dem, holed);
    struct Case {
      std::string input;
      std::vector<std::string> options;
    };
    const std::vector<Case> cases = {
        {holed, {"--tile-triangles", "2048"}},
        {test::sharedData("srtm3_N57E011_4326.tif"), {"--scheme", "geographic", "--tin-max-error", "5"}},
    };
    for (std::size_t c = 0; c < cases.size(); ++c) {
      CAPTURE(cases[c].input);
      const std::string out = dir / ("out" + std::to_string(c));
      std::vector<std::string> args{"build", cases[c].input, "-o", out, "-q", "--no-report"};
      args.insert(args.end(), cases[c].options.begin(), cases[c].options.end());
      const auto built = test::runTerratiles(args);
      CAPTURE(built.err);
      REQUIRE(built.exit_code == 0);
      Progress quiet(ProgressMode::Quiet);
      CheckOptions one;
      one.cuts = 300;
      const CheckReport whole = checkOutput(out, one, quiet);
      MESSAGE(describeCheck(whole));
      CheckOptions many = one;
      many.strip_pixels = 1;
      test::checkSameReport(checkOutput(out, many, quiet), whole);
      test::checkSeamless(whole);
      if (c == 0) CHECK(whole.uncovered_valid_pixels > 0);  // the ragged edge, next to nodata
    }
    // A strip of no pixels is refused.
    CheckOptions none;
    none.strip_pixels = 0;
    Progress quiet(ProgressMode::Quiet);
    try {
      checkOutput(dir / "out0", none, quiet);
      FAIL("a strip of no pixels was accepted");
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::Usage);
      CHECK(std::string(e.what()).find("--strip-pixels is 0, expected a positive number") != std::string::npos);
    }
    const auto cli = test::runTerratiles({"check", dir / "out0", "--strip-pixels", "-5"});
    CHECK(cli.exit_code == 2);
    CHECK(cli.err.find("--strip-pixels is -5") != std::string::npos);
  }

  TEST_CASE("the check fails on geometric errors measured before quantisation") {
    // The same raster twice: the levels and tiles are the same, only the position grid
    // differs (7.8 mm, the default, and 0.5 m). The fine build's errors are the coarse
    // build's errors before (most of) its quantisation: written into the coarse tileset,
    // the check must find decoded contents beyond them.
    test::TempDir dir;
    const CheckReport fine =
        buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--no-report"}, dir, "fine");
    test::checkSeamless(fine);
    const CheckReport coarse =
        buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--no-report", "--position-step", "0.5"}, dir, "coarse");
    test::checkSeamless(coarse);
    std::map<std::string, double> fine_errors;
    nlohmann::json fine_tileset = readJsonFile(dir / "fine/tileset.json");
    forEachContent(fine_tileset["root"], [&](nlohmann::json& tile) {
      fine_errors[tile["content"]["uri"].get<std::string>()] = tile["geometricError"].get<double>();
    });
    nlohmann::json tileset = readJsonFile(dir / "coarse/tileset.json");
    std::size_t replaced = 0;
    forEachContent(tileset["root"], [&](nlohmann::json& tile) {
      const std::string uri = tile["content"]["uri"];
      REQUIRE(fine_errors.count(uri) == 1);
      tile["geometricError"] = fine_errors[uri];
      ++replaced;
    });
    CHECK(replaced == fine_errors.size());
    std::ofstream(dir / "coarse/tileset.json") << tileset.dump(1);
    Progress quiet(ProgressMode::Quiet);
    CheckOptions options;
    options.cuts = 20;
    const CheckReport mutated = checkOutput(dir / "coarse", options, quiet);
    MESSAGE(describeCheck(mutated));
    CHECK(mutated.dishonest_errors > 0);
    CHECK(mutated.worst_error_ratio > 1);
    CHECK_FALSE(mutated.ok());
  }

  TEST_CASE("the check fails on one shared vertex left off the grid of the coarser zoom") {
    // SRTM N57E011 in the geographic scheme: its coarse zooms use coarser grids (tiles over
    // 65 km), and the vertices they share with finer zooms are snapped to those grids in
    // both. One such vertex moved back by a step of its own zoom's grid must be found.
    test::TempDir dir;
    const CheckReport built =
        buildAndCheck("srtm3_N57E011_4326.tif",
                      {"--scheme", "geographic", "--tin-max-error", "5", "--tile-triangles", "2048", "--no-report"}, dir,
                      "srtm");
    test::checkSeamless(built);
    const nlohmann::json facts = readJsonFile(dir / "srtm/build.json");
    const nlohmann::json& steps = facts["position_step_m_by_zoom"];
    // A zoom on a finer grid than the zoom above it.
    std::int32_t fine_zoom = -1;
    for (const auto& [zoom, step] : steps.items()) {
      const std::string coarser = std::to_string(std::stoi(zoom) - 1);
      if (steps.contains(coarser) && steps[coarser].get<double>() > step.get<double>()) fine_zoom = std::stoi(zoom);
    }
    REQUIRE(fine_zoom >= 0);
    const double fine_step = steps[std::to_string(fine_zoom)].get<double>();
    // A vertex a tile of that zoom shares with a tile of the coarser one.
    nlohmann::json tileset = readJsonFile(dir / "srtm/tileset.json");
    std::vector<std::string> fine_uris, coarse_uris;
    forEachContent(tileset["root"], [&](nlohmann::json& tile) {
      const std::string uri = tile["content"]["uri"];
      TileKey key;
      REQUIRE(tileKeyFromContentUri(uri, key));
      if (key.zoom == fine_zoom) fine_uris.push_back(uri);
      if (key.zoom == fine_zoom - 1) coarse_uris.push_back(uri);
    });
    std::map<std::array<double, 3>, int> coarse_points;
    for (const std::string& uri : coarse_uris) {
      const GlbMesh mesh = readGlbFile(dir / ("srtm/" + uri)).mesh;
      for (std::size_t v = 0; v < mesh.vertexCount(); ++v) coarse_points[ecefOf(mesh, v)] = 1;
    }
    // The first such point, moved in every tile of the fine zoom that holds it (as if that
    // zoom had snapped it to its own grid): only the pairs with the coarser zoom see it.
    std::optional<std::array<double, 3>> point;
    for (const std::string& uri : fine_uris) {
      const GlbMesh mesh = readGlbFile(dir / ("srtm/" + uri)).mesh;
      for (std::size_t v = 0; v < mesh.vertexCount() && !point; ++v) {
        if (coarse_points.count(ecefOf(mesh, v))) point = ecefOf(mesh, v);
      }
      if (point) break;
    }
    REQUIRE(point);
    std::size_t moved = 0;
    for (const std::string& uri : fine_uris) {
      GlbMesh mesh = readGlbFile(dir / ("srtm/" + uri)).mesh;
      bool changed = false;
      for (std::size_t v = 0; v < mesh.vertexCount(); ++v) {
        if (ecefOf(mesh, v) != *point) continue;
        mesh.positions[3 * v] += static_cast<float>(fine_step);  // off the coarser grid, on its own
        changed = true;
      }
      if (!changed) continue;
      ++moved;
      GlbOptions glb;
      glb.position_step_m = fine_step;
      const EncodedGlb encoded = encodeGlb(mesh, glb);
      std::ofstream(dir / ("srtm/" + uri), std::ios::binary)
          .write(reinterpret_cast<const char*>(encoded.bytes.data()), static_cast<std::streamsize>(encoded.bytes.size()));
    }
    MESSAGE("moved one vertex in " << moved << " tiles of zoom " << fine_zoom);
    REQUIRE(moved > 0);
    Progress quiet(ProgressMode::Quiet);
    CheckOptions options;
    options.cuts = 20;
    const CheckReport mutated = checkOutput(dir / "srtm", options, quiet);
    MESSAGE(describeCheck(mutated));
    CHECK(mutated.shared_vertex_gaps >= 1);
    CHECK(mutated.worst_shared_vertex_gap_m > 0);
    CHECK_FALSE(mutated.ok());
  }
}

TEST_SUITE("check") {
  TEST_CASE("implicit tiling keeps the explicit tree's tiles, errors and contents, and passes the check") {
    test::TempDir dir;
    const std::string input = test::sharedData("srtm3_N57E011_4326.tif");
    const std::vector<std::string> common{"--scheme", "geographic", "--tin-max-error", "5", "-q"};
    std::vector<std::string> explicit_args{"build", input, "-o", dir / "explicit"};
    explicit_args.insert(explicit_args.end(), common.begin(), common.end());
    REQUIRE(test::runTerratiles(explicit_args).exit_code == 0);
    std::vector<std::string> implicit_args{"build", input, "-o", dir / "implicit", "--implicit"};
    implicit_args.insert(implicit_args.end(), common.begin(), common.end());
    const auto built = test::runTerratiles(implicit_args);
    CAPTURE(built.err);
    REQUIRE(built.exit_code == 0);

    const auto readJson = [](const std::string& path) {
      std::ifstream in(path);
      return nlohmann::json::parse(in);
    };
    const nlohmann::json tileset = readJson(dir / "implicit/tileset.json");
    CHECK(tileset["asset"]["version"] == "1.1");
    // The root frames the data (what a viewer zooms to), the implicit root below it is the
    // east zoom-0 square (N57E011 lies in it only).
    const nlohmann::json build_facts = readJson(dir / "implicit/build.json");
    CHECK_FALSE(tileset["root"].contains("implicitTiling"));
    CHECK(tileset["root"]["boundingVolume"] == build_facts["explicit_tileset"]["root"]["boundingVolume"]);
    REQUIRE(tileset["root"]["children"].size() == 1);
    const nlohmann::json& root = tileset["root"]["children"][0];
    REQUIRE(root.contains("implicitTiling"));
    CHECK(root["boundingVolume"]["region"][0] == 0.0);
    CHECK(root["boundingVolume"]["region"][2] == std::numbers::pi);
    CHECK(root["implicitTiling"]["subdivisionScheme"] == "QUADTREE");
    CHECK(root["content"]["uri"] == "tiles/east/{level}/{x}/{y}.glb");
    // Every tile's measured error travels as tile metadata (CesiumJS would halve the root's).
    bool has_error_semantic = false;
    for (const auto& [name, property] : tileset["schema"]["classes"]["tile"]["properties"].items()) {
      has_error_semantic |= property.value("semantic", "") == "TILE_GEOMETRIC_ERROR";
    }
    CHECK(has_error_semantic);
    CHECK(std::filesystem::exists(dir / "implicit/subtrees/east/0/0/0.subtree"));

    // The same tiles with the same errors as the explicit build, each content on disk under
    // its implicit name and byte for byte the explicit one.
    std::map<std::string, std::pair<double, std::string>> explicit_tiles, implicit_tiles;
    std::function<void(const nlohmann::json&, std::map<std::string, std::pair<double, std::string>>&)> collect =
        [&](const nlohmann::json& node, std::map<std::string, std::pair<double, std::string>>& out) {
          if (node.contains("content")) {
            const std::string uri = node["content"]["uri"];
            TileKey key;
            REQUIRE(tileKeyFromContentUri(uri, key));
            out[key.path()] = {node["geometricError"].get<double>(), uri};
          }
          for (const auto& child : node.value("children", nlohmann::json::array())) collect(child, out);
        };
    collect(readJson(dir / "explicit/tileset.json")["root"], explicit_tiles);
    collect(readJson(dir / "implicit/build.json")["explicit_tileset"]["root"], implicit_tiles);
    REQUIRE(explicit_tiles.size() >= 4);
    REQUIRE(implicit_tiles.size() == explicit_tiles.size());
    for (const auto& [key, value] : explicit_tiles) {
      CAPTURE(key);
      REQUIRE(implicit_tiles.count(key) == 1);
      CHECK(implicit_tiles[key].first == value.first);
      const auto bytes = [](const std::string& path) {
        std::ifstream in(path, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), {});
      };
      CHECK(bytes(dir / ("implicit/" + implicit_tiles[key].second)) == bytes(dir / ("explicit/" + value.second)));
    }

    Progress quiet(ProgressMode::Quiet);
    CheckOptions check;
    check.cuts = 100;
    const CheckReport report = checkOutput(dir / "implicit", check, quiet);
    MESSAGE(describeCheck(report));
    CHECK(report.tiles == explicit_tiles.size());
    CHECK(report.ok());
    const test::GltfValidation gltf = test::validateGltfTree(dir / "implicit");
    REQUIRE(gltf.ran);
    CHECK(gltf.files == static_cast<int>(explicit_tiles.size()));
    CHECK(gltf.errors == 0);

    // Web mercator's rows do not halve a region: implicit tiling is refused, clearly.
    const auto refused = test::runTerratiles({"build", input, "-o", dir / "refused", "--implicit", "-q"});
    CHECK(refused.exit_code == 2);
    CHECK(refused.err.find("--scheme geographic") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir / "refused"));
  }

  TEST_CASE("a tileset split into external tilesets has the same tiles and tree, and passes the check") {
    test::TempDir dir;
    const std::string interlaken = test::sharedData("ch_dhm25_interlaken_25m_2056.tif");
    for (const char* name : {"one", "split"}) {
      std::vector<std::string> args{"build", interlaken, "-o", dir / name, "-q", "--no-report"};
      if (std::string(name) == "split") args.insert(args.end(), {"--tileset-levels", "2"});
      const auto built = test::runTerratiles(args);
      CAPTURE(built.err);
      REQUIRE(built.exit_code == 0);
    }
    const auto one = test::filesUnder(dir.path() / "one", {"tiles/"});
    CHECK(one == test::filesUnder(dir.path() / "split", {"tiles/"}));
    const auto externals = test::filesUnder(dir.path() / "split", {"tilesets/"});
    REQUIRE(externals.size() >= 2);
    // tileset.json holds two levels, the root and its children; their children's contents are
    // the external tilesets.
    const nlohmann::json top = readJsonFile(dir / "split/tileset.json");
    REQUIRE(top["root"].contains("children"));
    std::size_t stubs = 0;
    for (const nlohmann::json& child : top["root"]["children"]) {
      for (const nlohmann::json& grandchild : child.value("children", nlohmann::json::array())) {
        CHECK(!grandchild.contains("children"));
        CHECK(grandchild["content"]["uri"].get<std::string>().rfind("tilesets/", 0) == 0);
        ++stubs;
      }
    }
    CHECK(stubs == externals.size() - (externals.size() - stubs));  // every stub names a file
    for (const auto& [path, text] : externals) CHECK(nlohmann::json::parse(text)["root"]["refine"] == "REPLACE");
    // Read back with the external tilesets in place: the single file's tree, tile for tile
    // (each external root says refine REPLACE, which it inherits anyway).
    const nlohmann::json read = test::withoutInnerRefine(readTilesetTree(dir.path() / "split/tileset.json"));
    CHECK(read == readJsonFile(dir / "one/tileset.json"));
    Progress quiet(ProgressMode::Quiet);
    CheckOptions check;
    check.cuts = 300;
    test::checkSeamless(checkOutput(dir / "split", check, quiet));
  }
}

