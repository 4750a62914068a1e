// Real rasters in other CRSs are placed where PROJ puts them: every stage of placeOnGlobe
// (CRS -> lon/lat, EGM96 undulation, ECEF) compared with PROJ's own C API on sampled pixels.
#include <doctest/doctest.h>
#include <proj.h>

#include <cmath>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "src/geo/place_on_globe.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

struct ProjContext {
  PJ_CONTEXT* context = proj_context_create();
  ~ProjContext() { proj_context_destroy(context); }
};

struct ProjOperation {
  PJ* pj;
  explicit ProjOperation(PJ* p) : pj(p) { REQUIRE(pj != nullptr); }
  ~ProjOperation() { proj_destroy(pj); }
};

// Max 3D distance between our ECEF placement and PROJ's, over 400 valid pixels.
double worstPlacementDifference_m(const std::vector<std::string>& inputs) {
  const DemGrid dem = readDem(inputs);
  const GeoidGrid egm96 = readGeoidGrid(kDefaultGeoidPath);
  std::vector<GridPoint> points;
  for (int j = 0; j < 20; ++j) {
    for (int i = 0; i < 20; ++i) {
      const int col = i * (dem.width - 1) / 19, row = j * (dem.height - 1) / 19;
      if (dem.isValid(col, row)) points.push_back({double(col), double(row), dem.heightAt(col, row)});
    }
  }
  REQUIRE(points.size() > 100);
  std::vector<GeodeticPoint> geodetic(points.size());
  std::vector<EcefPoint> ecef(points.size());
  placeOnGlobe(dem, points, CrsToWgs84(dem.crs_wkt), &egm96, geodetic, ecef);

  ProjContext ctx;
  ProjOperation raw(proj_create_crs_to_crs(ctx.context, dem.crs_name.c_str(), "EPSG:4326", nullptr));
  ProjOperation to_lonlat(proj_normalize_for_visualization(ctx.context, raw.pj));
  ProjOperation geoid(proj_create(ctx.context,
                                  "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
                                  "+step +proj=vgridshift +grids=egm96_15.gtx +multiplier=1 "
                                  "+step +proj=cart +ellps=WGS84"));
  double worst = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const CrsPoint crs = dem.pixelCentre(points[i].col, points[i].row);
    PJ_COORD c = proj_coord(crs.x, crs.y, points[i].height_m, 0);
    c = proj_trans(to_lonlat.pj, PJ_FWD, c);  // lon, lat in degrees, height kept
    c.xyzt.z = points[i].height_m;
    c = proj_trans(geoid.pj, PJ_FWD, c);      // + N(EGM96), then ECEF
    REQUIRE(std::isfinite(c.xyz.x));
    worst = std::max(worst, std::hypot(ecef[i].x - c.xyz.x, ecef[i].y - c.xyz.y, ecef[i].z - c.xyz.z));
  }
  return worst;
}

}  // namespace

TEST_SUITE("geo") {
  TEST_CASE("rasters in EPSG 26915 28992 and 4326 are placed within a millimetre of PROJ") {
    const double minnesota = worstPlacementDifference_m({test::sharedData("us_mn_lidar_dtm_1m_26915.tif")});
    const double delft = worstPlacementDifference_m(
        {test::sharedData("nl_ahn3_delft_tiles/delft_west_0.5m_28992.tif"),
         test::sharedData("nl_ahn3_delft_tiles/delft_east_0.5m_28992.tif")});
    const double srtm = worstPlacementDifference_m({test::sharedData("srtm3_N57E011_4326.tif")});
    MESSAGE("placement vs PROJ (ECEF, with EGM96): EPSG:26915 " << minnesota * 1000 << " mm, EPSG:28992 "
            << delft * 1000 << " mm, EPSG:4326 " << srtm * 1000 << " mm");
    CHECK(minnesota < 1e-3);
    CHECK(delft < 1e-3);
    CHECK(srtm < 1e-3);
  }

  TEST_CASE("a latitude past a pole takes the geoid's undulation at the point across it") {
    // A DEM overview's last row over a pole has its centres half an overview pixel past it.
    const GeoidGrid egm96 = readGeoidGrid(kDefaultGeoidPath);
    for (const double lon : {-179.958333, -30.0, 0.0, 45.5, 179.9}) {
      for (const double past : {0.041667, 0.125, 1.0}) {
        const std::optional<double> south = egm96.undulationAt(lon, -90.0 - past);
        const std::optional<double> north = egm96.undulationAt(lon, 90.0 + past);
        const double across = lon < 0 ? lon + 180.0 : lon - 180.0;
        REQUIRE(south.has_value());
        REQUIRE(north.has_value());
        CHECK(*south == *egm96.undulationAt(across, -90.0 + past));
        CHECK(*north == *egm96.undulationAt(across, 90.0 - past));
      }
      // At the poles themselves every longitude gives one value (EGM96: -29.5 m and 13.6 m).
      CHECK(*egm96.undulationAt(lon, -90.0) == doctest::Approx(-29.53).epsilon(1e-3));
      CHECK(*egm96.undulationAt(lon, 90.0) == doctest::Approx(13.61).epsilon(1e-3));
    }
    CHECK_FALSE(egm96.undulationAt(0.0, 180.5).has_value());  // not a latitude at all
  }
}
