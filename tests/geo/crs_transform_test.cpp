#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "src/base/error.h"
#include "src/geo/crs_transform.h"
#include "tests/test_support.h"

using namespace terratiles;


TEST_SUITE("geo") {
  TEST_CASE("EPSG 2056 goes to WGS84 and ECEF as PROJ computes the reference points") {
    const auto points = test::lv95ReferenceRows();
    REQUIRE(points.size() == 16);
    const CrsToWgs84 to_wgs84("EPSG:2056");
    std::vector<CrsPoint> in;
    for (const auto& p : points) in.push_back({p[0], p[1]});
    std::vector<GeodeticPoint> geodetic(in.size());
    for (std::size_t i = 0; i < points.size(); ++i) geodetic[i].height_m = points[i][2];
    to_wgs84.transform(in, geodetic);
    for (std::size_t i = 0; i < points.size(); ++i) CHECK(geodetic[i].height_m == points[i][2]);
    std::vector<EcefPoint> ecef(in.size());
    geodeticToEcef(geodetic, ecef);
    double worst_deg = 0, worst_m = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      CAPTURE(i);
      worst_deg = std::max({worst_deg, std::fabs(geodetic[i].lon_deg - points[i][3]),
                            std::fabs(geodetic[i].lat_deg - points[i][4])});
      worst_m = std::max({worst_m, std::fabs(ecef[i].x - points[i][7]),
                          std::fabs(ecef[i].y - points[i][8]), std::fabs(ecef[i].z - points[i][9])});
    }
    MESSAGE("worst lon/lat difference " << worst_deg << " deg, ECEF " << worst_m << " m");
    CHECK(worst_deg < 1e-9);   // the CSV prints 1e-10 deg
    CHECK(worst_m < 1e-3);
  }

  TEST_CASE("a projected CRS without an accurate path to WGS84 is refused") {
    // A CRS on an unknown datum: PROJ could only offer a ballpark transformation.
    const std::string custom =
        "+proj=tmerc +lat_0=0 +lon_0=9 +k=1 +x_0=500000 +y_0=0 +a=6378000 +b=6357000 +units=m "
        "+no_defs +type=crs";
    try {
      CrsToWgs84 transform(custom);
      FAIL("a ballpark transformation was accepted");
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::Input);
      CHECK(std::string(e.what()).find("no accurate transformation") != std::string::npos);
    }
  }

  TEST_CASE("a CRS whose most accurate path needs a missing grid is reported with that grid") {
    // British National Grid: PROJ prefers the OSTN15 grid, which Debian's proj-data does not
    // ship, and falls back to a 2 m Helmert; we say so.
    const CrsToWgs84 british("EPSG:27700");
    REQUIRE(british.warnings().size() == 1);
    CHECK(british.warnings()[0].find("needs the grid uk_os_OSTN15_NTv2_OSGBtoETRS.tif") != std::string::npos);
    CHECK(british.warnings()[0].find("projsync --file uk_os_OSTN15_NTv2_OSGBtoETRS.tif") != std::string::npos);
    // Paths that have what they need say nothing.
    CHECK(CrsToWgs84("EPSG:2056").warnings().empty());
    CHECK(CrsToWgs84("EPSG:26915").warnings().empty());
  }

  TEST_CASE("geodetic to ECEF puts the equator and the pole on the WGS84 axes") {
    std::vector<GeodeticPoint> in{{0, 0, 0}, {90, 0, 100}, {0, 90, 0}};
    std::vector<EcefPoint> out(3);
    geodeticToEcef(in, out);
    CHECK(out[0].x == doctest::Approx(6378137.0));
    CHECK(out[1].y == doctest::Approx(6378237.0));
    CHECK(out[2].z == doctest::Approx(6356752.314245));
  }
}

#include "formats/geoid/read_geoid.h"

TEST_SUITE("geo") {
  TEST_CASE("EGM96 and CHGeo2004 undulations match PROJ at the reference points") {
    const GeoidGrid egm96 = readGeoidGrid(kDefaultGeoidPath);
    const GeoidGrid chgeo = readGeoidGrid(test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif"));
    CHECK(egm96.wraps_longitude);
    CHECK_FALSE(chgeo.wraps_longitude);
    int points = 0;
    double worst_egm96 = 0, worst_chgeo = 0;
    for (const auto& row : test::lv95ReferenceRows()) {
      const double lon = row[3], lat = row[4];
      worst_egm96 = std::max(worst_egm96, std::fabs(egm96.undulationAt(lon, lat).value() - row[15]));
      worst_chgeo = std::max(worst_chgeo, std::fabs(chgeo.undulationAt(lon, lat).value() - row[10]));
      ++points;
    }
    CHECK(points == 16);
    MESSAGE("worst undulation difference to PROJ: EGM96 " << worst_egm96 << " m, CHGeo2004 " << worst_chgeo << " m");
    CHECK(worst_egm96 < 1e-3);
    CHECK(worst_chgeo < 1e-3);
    // CHGeo2004 covers Switzerland only.
    CHECK_FALSE(chgeo.undulationAt(4.36, 52.0).has_value());
    // EGM96 wraps at the antimeridian.
    CHECK(egm96.undulationAt(179.99, 0.0).value() == doctest::Approx(egm96.undulationAt(-180.01, 0.0).value()));
  }

  TEST_CASE("a missing or unreadable geoid grid is an input error with the fix") {
    CHECK_THROWS_WITH(readGeoidGrid("/nonexistent/geoid.gtx"), doctest::Contains("install proj-data"));
    CHECK_THROWS_WITH(readGeoidGrid(test::sharedData("README.md")), doctest::Contains("not a geoid grid GDAL can read"));
  }
}
