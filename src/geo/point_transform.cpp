#include "src/geo/point_transform.h"

#include <GeographicLib/Geocentric.hpp>
#include <cpl_error.h>
#include <ogr_spatialref.h>

#include <vector>

#include "src/base/error.h"
#include "src/geo/crs_transform.h"
#include "src/geo/swiss_lv95.h"
#include "src/tiling/tile_scheme.h"

namespace terratiles {
namespace {

enum class Frame { Geographic, Ecef, WebMercator, Lv95, Proj };

struct CrsInfo {
  std::string name;        // "EPSG:2056", or the CRS name
  std::string horizontal;  // WKT of the horizontal part
  bool has_vertical = false;
  Frame frame = Frame::Proj;
};

CrsInfo identify(const std::string& text) {
  OGRSpatialReference srs;
  CPLPushErrorHandler(CPLQuietErrorHandler);
  const OGRErr status = srs.SetFromUserInput(text.c_str());
  CPLPopErrorHandler();
  if (status != OGRERR_NONE || srs.IsEmpty()) {
    throw Error(ErrorCode::Usage, "unknown coordinate reference system '" + text +
                                      "'; expected an EPSG code such as EPSG:2056, a WKT or a "
                                      "PROJ string");
  }
  CrsInfo info;
  info.has_vertical = srs.IsCompound() || srs.IsVertical();
  if (srs.IsCompound()) srs.StripVertical();
  if (!srs.GetAuthorityCode(nullptr)) srs.AutoIdentifyEPSG();
  const char* authority = srs.GetAuthorityName(nullptr);
  const char* code = srs.GetAuthorityCode(nullptr);
  info.name = authority && code ? std::string(authority) + ":" + code
                                : std::string(srs.GetName() ? srs.GetName() : text);
  char* wkt = nullptr;
  srs.exportToWkt(&wkt);
  info.horizontal = wkt ? wkt : "";
  CPLFree(wkt);
  if (info.name == "EPSG:4326" || info.name == "EPSG:4979") info.frame = Frame::Geographic;
  else if (info.name == "EPSG:4978") info.frame = Frame::Ecef;
  else if (info.name == "EPSG:3857") info.frame = Frame::WebMercator;
  else if (info.name == "EPSG:2056") info.frame = Frame::Lv95;
  return info;
}

std::string frameDescription(const CrsInfo& crs) {
  switch (crs.frame) {
    case Frame::Geographic: return crs.name;
    case Frame::Ecef: return crs.name + " (GeographicLib)";
    case Frame::WebMercator: return crs.name + " (sphere a=6378137)";
    case Frame::Lv95: return crs.name + " (rigorous swisstopo)";
    case Frame::Proj: return crs.name + " (PROJ)";
  }
  return crs.name;
}

}  // namespace

struct PointTransform::Impl {
  CrsInfo from, to;
  const GeoidGrid* geoid = nullptr;
  std::unique_ptr<CrsToWgs84> from_proj;                       // Frame::Proj source
  std::unique_ptr<OGRCoordinateTransformation> to_proj;        // Frame::Proj target
};

PointTransform::PointTransform(const std::string& from, const std::string& to, const GeoidGrid* geoid)
    : impl_(std::make_unique<Impl>()) {
  impl_->from = identify(from);
  impl_->to = identify(to);
  impl_->geoid = geoid;
  for (const CrsInfo* crs : {&impl_->from, &impl_->to}) {
    if (crs->has_vertical && !geoid) {
      throw Error(ErrorCode::Input,
                  crs->name + " with a vertical CRS has orthometric heights, and PROJ knows no "
                              "accurate path for them without a geoid grid (PROJ 9.1 would fall "
                              "back to a ballpark transformation); pass --geoid FILE (e.g. "
                              "CHGeo2004 for LN02 heights) or give the horizontal CRS " +
                      crs->name + " alone");
    }
  }
  if (impl_->from.frame == Frame::Proj) {
    impl_->from_proj = std::make_unique<CrsToWgs84>(impl_->from.horizontal, TransformEngine::Proj);
  }
  if (impl_->to.frame == Frame::Proj) {
    OGRSpatialReference wgs84, target;
    wgs84.importFromEPSG(4326);
    target.SetFromUserInput(impl_->to.horizontal.c_str());
    wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    target.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    OGRCoordinateTransformationOptions options;
    options.SetBallparkAllowed(false);
    CPLPushErrorHandler(CPLQuietErrorHandler);
    impl_->to_proj.reset(OGRCreateCoordinateTransformation(&wgs84, &target, options));
    CPLPopErrorHandler();
    if (!impl_->to_proj) {
      throw Error(ErrorCode::Input, "no accurate transformation from WGS84 to " + impl_->to.name +
                                        " is known (PROJ offers only a ballpark one); install "
                                        "the datum grids (apt-get install proj-data)");
    }
  }
}

PointTransform::~PointTransform() = default;

bool PointTransform::targetIsGeographic() const {
  if (impl_->to.frame == Frame::Geographic) return true;
  if (impl_->to.frame != Frame::Proj) return false;
  OGRSpatialReference srs;
  srs.SetFromUserInput(impl_->to.horizontal.c_str());
  return srs.IsGeographic();
}

std::string PointTransform::description() const {
  std::string text = frameDescription(impl_->from) + " -> WGS84";
  if (impl_->geoid) text += " -> geoid " + impl_->geoid->name;
  return text + " -> " + frameDescription(impl_->to);
}

void PointTransform::transform(std::span<Point3> points) const {
  const Impl& impl = *impl_;
  const auto& wgs84 = GeographicLib::Geocentric::WGS84();
  std::vector<GeodeticPoint> geodetic(points.size());
  // Source -> WGS84 lon/lat (heights unchanged).
  switch (impl.from.frame) {
    case Frame::Geographic:
      for (std::size_t i = 0; i < points.size(); ++i) geodetic[i] = {points[i].x, points[i].y, points[i].z};
      break;
    case Frame::Ecef:
      for (std::size_t i = 0; i < points.size(); ++i) {
        wgs84.Reverse(points[i].x, points[i].y, points[i].z, geodetic[i].lat_deg, geodetic[i].lon_deg,
                      geodetic[i].height_m);
      }
      break;
    case Frame::WebMercator:
      for (std::size_t i = 0; i < points.size(); ++i) {
        const LonLat ll = webMercatorToLonLat({points[i].x, points[i].y});
        geodetic[i] = {ll.lon_deg, ll.lat_deg, points[i].z};
      }
      break;
    case Frame::Lv95:
    case Frame::Proj: {
      std::vector<CrsPoint> crs(points.size());
      for (std::size_t i = 0; i < points.size(); ++i) {
        crs[i] = {points[i].x, points[i].y};
        geodetic[i].height_m = points[i].z;
      }
      if (impl.from.frame == Frame::Lv95) lv95ToWgs84(crs, geodetic);
      else impl.from_proj->transform(crs, geodetic);
      break;
    }
  }
  // Geoid: orthometric on the non-WGS84 side, ellipsoidal on the WGS84 side.
  const bool from_wgs84 = impl.from.frame == Frame::Geographic || impl.from.frame == Frame::Ecef;
  const bool to_wgs84 = impl.to.frame == Frame::Geographic || impl.to.frame == Frame::Ecef;
  if (impl.geoid && from_wgs84 != to_wgs84) {
    for (std::size_t i = 0; i < points.size(); ++i) {
      const auto undulation = impl.geoid->undulationAt(geodetic[i].lon_deg, geodetic[i].lat_deg);
      if (!undulation) {
        throw Error(ErrorCode::Input, "point " + std::to_string(i + 1) + " (" +
                                          std::to_string(geodetic[i].lon_deg) + " E " +
                                          std::to_string(geodetic[i].lat_deg) +
                                          " N) is outside the geoid grid " + impl.geoid->name);
      }
      geodetic[i].height_m += to_wgs84 ? *undulation : -*undulation;
    }
  }
  // WGS84 -> target.
  switch (impl.to.frame) {
    case Frame::Geographic:
      for (std::size_t i = 0; i < points.size(); ++i) {
        points[i] = {geodetic[i].lon_deg, geodetic[i].lat_deg, geodetic[i].height_m};
      }
      break;
    case Frame::Ecef:
      for (std::size_t i = 0; i < points.size(); ++i) {
        wgs84.Forward(geodetic[i].lat_deg, geodetic[i].lon_deg, geodetic[i].height_m, points[i].x,
                      points[i].y, points[i].z);
      }
      break;
    case Frame::WebMercator:
      for (std::size_t i = 0; i < points.size(); ++i) {
        const WebMercatorPoint m = lonLatToWebMercator(geodetic[i].lon_deg, geodetic[i].lat_deg);
        points[i] = {m.x_m, m.y_m, geodetic[i].height_m};
      }
      break;
    case Frame::Lv95: {
      std::vector<CrsPoint> lv95(points.size());
      wgs84ToLv95(geodetic, lv95);
      for (std::size_t i = 0; i < points.size(); ++i) points[i] = {lv95[i].x, lv95[i].y, geodetic[i].height_m};
      break;
    }
    case Frame::Proj:
      for (std::size_t i = 0; i < points.size(); ++i) {
        double x = geodetic[i].lon_deg, y = geodetic[i].lat_deg, z = geodetic[i].height_m;
        if (!impl.to_proj->Transform(1, &x, &y, &z)) {
          throw Error(ErrorCode::Input, "PROJ cannot transform point " + std::to_string(i + 1) +
                                            " to " + impl.to.name +
                                            "; expected a point inside the CRS's area of use");
        }
        points[i] = {x, y, geodetic[i].height_m};
      }
      break;
  }
}

}  // namespace terratiles
