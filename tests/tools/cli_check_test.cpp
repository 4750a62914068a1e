// `terratiles check` on real builds: the default (boundaries merge) leaves no hole in any cut
// whose neighbours are at most one zoom apart, no T-junction where tiles of two zooms meet,
// contents agree where they overlap, every geometricError is honest; duplicate passes too;
// centroid (holes) and the grid pyramid (T-junctions) fail: the checker is not blind.
#include <doctest/doctest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "src/pipeline/check_output.h"
#include "tests/test_support.h"

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

void checkSeamless(const CheckReport& report) {
  CHECK(report.zooms >= 2);
  CHECK(report.cuts >= 300);
  CHECK(report.cuts_with_holes == 0);
  CHECK(report.neighbour_pairs > 0);
  CHECK(report.missing_border_vertices == 0);
  // Outline vertices touching tiles share decode to one position (both on one grid).
  CHECK(report.shared_border_vertices > 0);
  CHECK(report.shared_vertex_gaps == 0);
  CHECK(report.worst_shared_vertex_gap_m <= 1e-3);
  CHECK(report.overlap_pixels > 0);
  CHECK(report.overlap_disagreements == 0);
  CHECK(report.dishonest_errors == 0);
  CHECK(report.error_order_violations == 0);
  CHECK(report.region_violations == 0);
  CHECK(report.ok());
}

}  // namespace

TEST_SUITE("check") {
  TEST_CASE("merge tiles of four real rasters in the three schemes pass the check") {
    test::TempDir dir;
    checkSeamless(buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {}, dir, "interlaken_webmercator"));
    checkSeamless(buildAndCheck("srtm3_N57E011_4326.tif", {"--scheme", "geographic", "--tin-max-error", "5"}, dir,
                                "srtm_geographic"));
    checkSeamless(buildAndCheck("ca_on_lidar_dtm_1m_26917.tif", {"--scheme", "local", "--tin-max-error", "0.1", "--tile-triangles", "4096"}, dir,
                                "ontario_local"));
    checkSeamless(buildAndCheck("us_mn_lidar_dtm_1m_26915.tif", {"--tin-max-error", "0.1", "--tile-triangles", "4096"},
                                dir, "minnesota_webmercator"));
  }

  TEST_CASE("duplicate passes the check, centroid leaves holes, the grid pyramid has T-junctions") {
    test::TempDir dir;
    checkSeamless(buildAndCheck("ch_dhm25_interlaken_25m_2056.tif", {"--assign", "duplicate"}, dir, "duplicate"));
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
}
