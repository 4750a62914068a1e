// `terratiles transform` against the 16 LV95 reference points that PROJ 9.1.1 computed
// (../shared/data/reference/lv95_reference_points.csv), through the CLI as a user runs it.
#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "tests/test_support.h"

using terratiles::test::runTerratiles;
using terratiles::test::sharedData;

namespace {

struct Row {
  std::vector<double> v;  // test::lv95ReferenceRows()'s columns
};

std::vector<Row> referenceRows() {
  std::vector<Row> rows;
  for (auto& values : terratiles::test::lv95ReferenceRows()) rows.push_back({std::move(values)});
  return rows;
}

// Runs the transform on "E N H" of every row and returns the output triples.
std::vector<std::array<double, 3>> transformRows(const std::vector<Row>& rows,
                                                 const std::vector<std::string>& options) {
  std::ostringstream input;
  input.precision(17);
  input << "# E N H_LN02\n";
  for (const Row& r : rows) input << r.v[0] << " " << r.v[1] << " " << r.v[2] << "\n";
  std::vector<std::string> args{"transform"};
  args.insert(args.end(), options.begin(), options.end());
  const auto result = runTerratiles(args, input.str());
  CAPTURE(result.err);
  REQUIRE(result.exit_code == 0);
  std::istringstream out(result.out);
  std::string line;
  std::getline(out, line);
  CHECK(line == "# E N H_LN02");  // comments pass through
  std::vector<std::array<double, 3>> values;
  while (std::getline(out, line)) {
    std::array<double, 3> p{};
    std::istringstream fields(line);
    fields >> p[0] >> p[1] >> p[2];
    values.push_back(p);
  }
  REQUIRE(values.size() == rows.size());
  return values;
}

}  // namespace

TEST_SUITE("cli") {
  TEST_CASE("transform reproduces PROJ's LV95 reference points in every frame") {
    const std::vector<Row> rows = referenceRows();
    REQUIRE(rows.size() == 16);
    const std::string chgeo = sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif");
    // Columns: 0 E, 1 N, 2 H, 3 lon, 4 lat, 5 merc_x, 6 merc_y, 7-9 ECEF no geoid,
    // 10 N_chgeo2004, 11 h_wgs84_geoid, 12-14 ECEF with geoid, 15 N_egm96.
    const auto lonlat = transformRows(rows, {"--from", "EPSG:2056", "--to", "EPSG:4326"});
    const auto mercator = transformRows(rows, {"--from", "EPSG:2056", "--to", "EPSG:3857"});
    const auto ecef = transformRows(rows, {"--from", "EPSG:2056", "--to", "EPSG:4978"});
    const auto ecef_geoid =
        transformRows(rows, {"--from", "EPSG:2056+5728", "--to", "EPSG:4978", "--geoid", chgeo});
    const auto height_geoid =
        transformRows(rows, {"--from", "EPSG:2056+5728", "--to", "EPSG:4979", "--geoid", chgeo});
    double worst_deg = 0, worst_mercator_m = 0, worst_ecef_m = 0, worst_ecef_geoid_m = 0,
           worst_height_m = 0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const auto& r = rows[i].v;
      worst_deg = std::max({worst_deg, std::fabs(lonlat[i][0] - r[3]), std::fabs(lonlat[i][1] - r[4])});
      worst_mercator_m = std::max({worst_mercator_m, std::fabs(mercator[i][0] - r[5]), std::fabs(mercator[i][1] - r[6])});
      for (int k = 0; k < 3; ++k) {
        worst_ecef_m = std::max(worst_ecef_m, std::fabs(ecef[i][k] - r[7 + k]));
        worst_ecef_geoid_m = std::max(worst_ecef_geoid_m, std::fabs(ecef_geoid[i][k] - r[12 + k]));
      }
      worst_height_m = std::max(worst_height_m, std::fabs(height_geoid[i][2] - r[11]));
    }
    MESSAGE("vs PROJ 9.1.1: lon/lat " << worst_deg << " deg, web mercator " << worst_mercator_m * 1000
            << " mm, ECEF " << worst_ecef_m * 1000 << " mm, ECEF with CHGeo2004 "
            << worst_ecef_geoid_m * 1000 << " mm, ellipsoidal height " << worst_height_m * 1000 << " mm");
    CHECK(worst_deg < 1e-9);
    CHECK(worst_mercator_m < 1e-3);
    CHECK(worst_ecef_m < 1e-3);
    CHECK(worst_ecef_geoid_m < 5e-3);
    CHECK(worst_height_m < 5e-3);
  }

  TEST_CASE("transform goes back from WGS84 to LV95 and refuses what it cannot do accurately") {
    const auto back = runTerratiles({"transform", "--from", "EPSG:4326", "--to", "EPSG:2056"},
                                    "7.4386325026 46.9510828859 549\n");
    REQUIRE(back.exit_code == 0);
    double e = 0, n = 0, h = 0;
    std::istringstream(back.out) >> e >> n >> h;
    CHECK(std::fabs(e - 2600000.0) < 2e-3);
    CHECK(std::fabs(n - 1200000.0) < 2e-3);
    CHECK(h == 549.0);

    // A vertical CRS without a geoid: PROJ would silently go ballpark (144-189 m off).
    const auto ballpark = runTerratiles({"transform", "--from", "EPSG:2056+5728", "--to", "EPSG:4978"},
                                        "2600000 1200000 549\n");
    CHECK(ballpark.exit_code == 3);
    CHECK(ballpark.err.find("pass --geoid FILE") != std::string::npos);

    const auto outside = runTerratiles({"transform", "--from", "EPSG:4326", "--to", "EPSG:3857"},
                                       "10 89 0\n");
    CHECK(outside.exit_code == 3);
    CHECK(outside.err.find("85.05") != std::string::npos);

    const auto garbage = runTerratiles({"transform", "--from", "EPSG:2056", "--to", "EPSG:4326"},
                                       "2600000 1200000\nnot a point\n");
    CHECK(garbage.exit_code == 3);
    CHECK(garbage.err == "terratiles: error: standard input line 2: expected 'x y [z]' numbers, found 'not a point'\n");

    const auto unknown = runTerratiles({"transform", "--from", "EPSG:999999", "--to", "EPSG:4326"}, "");
    CHECK(unknown.exit_code == 2);
    CHECK(unknown.err.find("unknown coordinate reference system 'EPSG:999999'") != std::string::npos);
  }
}
