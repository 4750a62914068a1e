#include "src/geo/crs_transform.h"

#include <GeographicLib/Geocentric.hpp>
#include <cpl_error.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <vector>

#include "src/base/error.h"
#include "src/geo/swiss_lv95.h"

namespace terratiles {

struct CrsToWgs84::Impl {
  OGRSpatialReference source;
  OGRSpatialReference target;
  std::unique_ptr<OGRCoordinateTransformation> transform;
  std::string source_name;
  bool rigorous_lv95 = false;
};

CrsToWgs84::CrsToWgs84(const std::string& crs_wkt, TransformEngine engine)
    : impl_(std::make_unique<Impl>()) {
  CPLPushErrorHandler(CPLQuietErrorHandler);
  CPLErrorReset();
  const OGRErr source_status = impl_->source.SetFromUserInput(crs_wkt.c_str());
  impl_->target.importFromEPSG(4326);
  CPLPopErrorHandler();
  if (source_status != OGRERR_NONE) {
    throw Error(ErrorCode::Input, "unknown coordinate reference system '" + crs_wkt.substr(0, 80) +
                                      "'; expected an EPSG code such as EPSG:2056 or a WKT");
  }
  impl_->source.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  impl_->target.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  const char* authority = impl_->source.GetAuthorityName(nullptr);
  const char* code = impl_->source.GetAuthorityCode(nullptr);
  impl_->source_name = authority && code ? std::string(authority) + ":" + code
                                         : std::string(impl_->source.GetName() ? impl_->source.GetName() : "CRS");
  if (engine == TransformEngine::Auto && impl_->source_name == "EPSG:2056") {
    impl_->rigorous_lv95 = true;
    return;
  }

  OGRCoordinateTransformationOptions options;
  options.SetBallparkAllowed(false);
  CPLPushErrorHandler(CPLQuietErrorHandler);
  CPLErrorReset();
  impl_->transform.reset(
      OGRCreateCoordinateTransformation(&impl_->source, &impl_->target, options));
  std::string gdal_message = CPLGetLastErrorMsg();
  CPLPopErrorHandler();
  if (!impl_->transform) {
    throw Error(ErrorCode::Input,
                "no accurate transformation from " + impl_->source_name +
                    " to WGS84 is known (PROJ offers only a ballpark one" +
                    (gdal_message.empty() ? std::string() : ": " + gdal_message) +
                    "); install the datum grids (apt-get install proj-data) or reproject the "
                    "input with gdalwarp");
  }
}

CrsToWgs84::~CrsToWgs84() = default;

const std::string& CrsToWgs84::sourceName() const { return impl_->source_name; }

std::string CrsToWgs84::pathDescription() const {
  return impl_->rigorous_lv95 ? impl_->source_name + " -> WGS84 by the rigorous swisstopo formulas"
                              : impl_->source_name + " -> WGS84 by PROJ";
}

void CrsToWgs84::transform(std::span<const CrsPoint> in, std::span<GeodeticPoint> out) const {
  TERRATILES_ASSERT(in.size() == out.size());
  if (impl_->rigorous_lv95) {
    lv95ToWgs84(in, out);
    return;
  }
  constexpr std::size_t kBatch = 65536;
  std::vector<double> x(kBatch), y(kBatch), z(kBatch);
  std::vector<int> success(kBatch);
  for (std::size_t begin = 0; begin < in.size(); begin += kBatch) {
    const std::size_t count = std::min(kBatch, in.size() - begin);
    for (std::size_t i = 0; i < count; ++i) {
      x[i] = in[begin + i].x;
      y[i] = in[begin + i].y;
      z[i] = out[begin + i].height_m;
    }
    const bool all_ok = impl_->transform->Transform(count, x.data(), y.data(), z.data(),
                                                     success.data()) != 0;
    for (std::size_t i = 0; i < count; ++i) {
      if (!all_ok && !success[i]) {
        throw Error(ErrorCode::Input,
                    "PROJ cannot transform the point (" + std::to_string(in[begin + i].x) + ", " +
                        std::to_string(in[begin + i].y) + ") of " + impl_->source_name +
                        " to WGS84; expected coordinates inside the CRS's area of use");
      }
      out[begin + i].lon_deg = x[i];
      out[begin + i].lat_deg = y[i];
    }
  }
}

void geodeticToEcef(std::span<const GeodeticPoint> in, std::span<EcefPoint> out) {
  TERRATILES_ASSERT(in.size() == out.size());
  const GeographicLib::Geocentric& earth = GeographicLib::Geocentric::WGS84();
  for (std::size_t i = 0; i < in.size(); ++i) {
    earth.Forward(in[i].lat_deg, in[i].lon_deg, in[i].height_m, out[i].x, out[i].y, out[i].z);
  }
}

}  // namespace terratiles
