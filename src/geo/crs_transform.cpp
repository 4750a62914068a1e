#include "src/geo/crs_transform.h"

#include <GeographicLib/Geocentric.hpp>
#include <cpl_error.h>
#include <ogr_spatialref.h>
#include <proj.h>

#include <algorithm>
#include <vector>

#include "src/base/error.h"
#include "src/geo/swiss_lv95.h"

namespace terratiles {

namespace {

// What PROJ's list of CRS -> WGS84 operations says about grids, with grid availability
// ignored (so operations needing a missing grid are listed too), in PROJ's order of
// preference: the missing grids of non-ballpark operations, and whether the preferred one
// is among those that cannot run (then PROJ silently falls back to a less accurate one).
struct GridDiagnosis {
  std::vector<std::string> missing_grids;
  std::string preferred_name;   // the most accurate operation, when it lacks a grid
  double preferred_accuracy_m = -1;
};

GridDiagnosis diagnoseGrids(const std::string& source_wkt) {
  GridDiagnosis diagnosis;
  PJ_CONTEXT* ctx = proj_context_create();
  proj_log_level(ctx, PJ_LOG_NONE);
  PJ* source = proj_create(ctx, source_wkt.c_str());
  PJ* target = proj_create(ctx, "EPSG:4326");
  PJ_OPERATION_FACTORY_CONTEXT* factory = proj_create_operation_factory_context(ctx, nullptr);
  if (source && target && factory) {
    proj_operation_factory_context_set_grid_availability_use(ctx, factory,
                                                             PROJ_GRID_AVAILABILITY_IGNORED);
    proj_operation_factory_context_set_spatial_criterion(
        ctx, factory, PROJ_SPATIAL_CRITERION_PARTIAL_INTERSECTION);
    PJ_OBJ_LIST* operations = proj_create_operations(ctx, source, target, factory);
    const int count = operations ? proj_list_get_count(operations) : 0;
    for (int i = 0; i < count; ++i) {
      PJ* operation = proj_list_get(ctx, operations, i);
      if (!operation) continue;
      if (!proj_coordoperation_has_ballpark_transformation(ctx, operation)) {
        bool lacks_grid = false;
        const int grids = proj_coordoperation_get_grid_used_count(ctx, operation);
        for (int g = 0; g < grids; ++g) {
          const char* short_name = nullptr;
          int available = 0;
          if (proj_coordoperation_get_grid_used(ctx, operation, g, &short_name, nullptr, nullptr,
                                                nullptr, nullptr, nullptr, &available) &&
              !available && short_name) {
            lacks_grid = true;
            if (std::find(diagnosis.missing_grids.begin(), diagnosis.missing_grids.end(),
                          short_name) == diagnosis.missing_grids.end()) {
              diagnosis.missing_grids.emplace_back(short_name);
            }
          }
        }
        if (i == 0 && lacks_grid) {
          const char* name = proj_get_name(operation);
          diagnosis.preferred_name = name ? name : "";
          diagnosis.preferred_accuracy_m = proj_coordoperation_get_accuracy(ctx, operation);
        }
      }
      proj_destroy(operation);
    }
    proj_list_destroy(operations);
  }
  proj_operation_factory_context_destroy(factory);
  proj_destroy(target);
  proj_destroy(source);
  proj_context_destroy(ctx);
  return diagnosis;
}

std::string joined(const std::vector<std::string>& names) {
  std::string text;
  for (const auto& name : names) text += (text.empty() ? "" : ", ") + name;
  return text;
}

}  // namespace

struct CrsToWgs84::Impl {
  OGRSpatialReference source;
  OGRSpatialReference target;
  std::unique_ptr<OGRCoordinateTransformation> transform;
  std::string source_name;
  bool rigorous_lv95 = false;
  bool is_wgs84 = false;  // the source is WGS84 longitude and latitude in degrees: nothing to do
  std::vector<std::string> warnings;
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

  // WGS84 itself (EPSG:4326, as SRTM and ETOPO5 come): PROJ's transformation is a no-op, and
  // one call per point (a vertex a collapse moves) costs more than the rest of its placing.
  const char* const same_options[] = {"IGNORE_DATA_AXIS_TO_SRS_AXIS_MAPPING=NO", "CRITERION=EQUIVALENT", nullptr};
  if (engine == TransformEngine::Auto && impl_->source.IsGeographic() && !impl_->source.IsDerivedGeographic() &&
      impl_->source.IsSame(&impl_->target, same_options)) {
    impl_->is_wgs84 = true;
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
    const GridDiagnosis diagnosis = diagnoseGrids(crs_wkt);
    if (!diagnosis.missing_grids.empty()) {
      throw Error(ErrorCode::Input,
                  "no accurate transformation from " + impl_->source_name +
                      " to WGS84 is installed: PROJ needs the grid " +
                      joined(diagnosis.missing_grids) +
                      " (without it only a ballpark offset, metres off, is possible); install "
                      "it into PROJ's data directory with 'projsync --file " +
                      diagnosis.missing_grids.front() + "' or reproject the input with gdalwarp");
    }
    throw Error(ErrorCode::Input,
                "no accurate transformation from " + impl_->source_name +
                    " to WGS84 is known (PROJ offers only a ballpark one" +
                    (gdal_message.empty() ? std::string() : ": " + gdal_message) +
                    "); install the datum grids (apt-get install proj-data) or reproject the "
                    "input with gdalwarp");
  }
  const GridDiagnosis diagnosis = diagnoseGrids(crs_wkt);
  if (!diagnosis.preferred_name.empty()) {
    impl_->warnings.push_back(
        "PROJ's most accurate path from " + impl_->source_name + " to WGS84 ('" +
        diagnosis.preferred_name + "', " +
        (diagnosis.preferred_accuracy_m >= 0 ? std::to_string(diagnosis.preferred_accuracy_m) + " m"
                                             : std::string("unknown accuracy")) +
        ") needs the grid " + joined(diagnosis.missing_grids) +
        ", which is not installed, so a less accurate one is used; install it with 'projsync "
        "--file " + diagnosis.missing_grids.front() + "'");
  }
}

CrsToWgs84::~CrsToWgs84() = default;

const std::vector<std::string>& CrsToWgs84::warnings() const { return impl_->warnings; }

const std::string& CrsToWgs84::sourceName() const { return impl_->source_name; }

bool CrsToWgs84::isWgs84LonLat() const { return impl_->is_wgs84; }

std::string CrsToWgs84::pathDescription() const {
  if (impl_->is_wgs84) return impl_->source_name + " is WGS84 longitude and latitude (no transformation)";
  return impl_->rigorous_lv95 ? impl_->source_name + " -> WGS84 by the rigorous swisstopo formulas"
                              : impl_->source_name + " -> WGS84 by PROJ";
}

void CrsToWgs84::transform(std::span<const CrsPoint> in, std::span<GeodeticPoint> out) const {
  TERRATILES_ASSERT(in.size() == out.size());
  if (impl_->rigorous_lv95) {
    lv95ToWgs84(in, out);
    return;
  }
  if (impl_->is_wgs84) {
    for (std::size_t i = 0; i < in.size(); ++i) {
      out[i].lon_deg = in[i].x;
      out[i].lat_deg = in[i].y;
    }
    return;
  }
  // Batches of at most 65536 points; a short call (one vertex a collapse moves) allocates only
  // what it needs.
  const std::size_t batch = std::min<std::size_t>(65536, in.size());
  std::vector<double> x(batch), y(batch), z(batch);
  std::vector<int> success(batch);
  for (std::size_t begin = 0; begin < in.size(); begin += batch) {
    const std::size_t count = std::min(batch, in.size() - begin);
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
