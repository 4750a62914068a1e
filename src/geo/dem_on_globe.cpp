#include "src/geo/dem_on_globe.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "src/base/error.h"
#include "src/geo/place_on_globe.h"

namespace terratiles {

// One CRS transformation per thread: GDAL's and PROJ's objects are not thread-safe.
struct DemOnGlobe::Transforms {
  explicit Transforms(const std::string& wkt) : crs_wkt(wkt) {}
  const CrsToWgs84& local() {
    std::unique_ptr<CrsToWgs84>& transform = per_thread.local();
    if (!transform) transform = std::make_unique<CrsToWgs84>(crs_wkt);
    return *transform;
  }
  std::string crs_wkt;
  tbb::enumerable_thread_specific<std::unique_ptr<CrsToWgs84>> per_thread;
};

UnitVector ellipsoidNormal(const GeodeticPoint& point) {
  constexpr double kDegToRad = std::numbers::pi / 180.0;
  const double lat = point.lat_deg * kDegToRad, lon = point.lon_deg * kDegToRad;
  return {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
}

DemOnGlobe::DemOnGlobe(const DemGrid& dem, const GeoidGrid* geoid, Progress* progress)
    : dem_(dem), geoid_(geoid), transforms_(std::make_unique<Transforms>(dem.crs_wkt)) {
  transforms_->local();  // refuses a CRS without a transformation to WGS84 here, up front
  double sum = 0;
  std::size_t valid = 0;
  for (const float h : dem.heights_m) {
    if (std::isnan(h)) continue;
    sum += h;
    ++valid;
  }
  nodata_height_m_ = valid ? sum / static_cast<double>(valid) : 0.0;
  if (geoid) {
    GeodeticPoint centre;
    const CrsPoint c = dem.pixelCentre((dem.width - 1) / 2.0, (dem.height - 1) / 2.0);
    transforms_->local().transform(std::span<const CrsPoint>(&c, 1), std::span<GeodeticPoint>(&centre, 1));
    centre_undulation_m_ = geoid->undulationAt(centre.lon_deg, centre.lat_deg).value_or(0.0);
  }

  const std::size_t pixels = dem.pixelCount();
  for (auto* v : {&x_, &y_, &z_, &up_x_, &up_y_}) v->assign(pixels + kDemOnGlobePadding, 0.0);
  up_z_.assign(pixels + kDemOnGlobePadding, 1.0);
  pole_rows_.assign(static_cast<std::size_t>(dem.height), 0);
  if (progress) progress->beginStage("placing the DEM's pixels on the globe", static_cast<std::uint64_t>(dem.height));
  constexpr std::int32_t kRows = 16;
  tbb::parallel_for(tbb::blocked_range<std::int32_t>(0, dem.height, kRows), [&](const tbb::blocked_range<std::int32_t>& rows) {
    const std::size_t first = dem.index(0, rows.begin());
    const std::size_t count = static_cast<std::size_t>(rows.size()) * static_cast<std::size_t>(dem.width);
    std::vector<GridPoint> grid(count);
    std::vector<GeodeticPoint> geodetic(count);
    for (std::int32_t row = rows.begin(); row < rows.end(); ++row) {
      for (std::int32_t col = 0; col < dem.width; ++col) {
        const float h = dem.heightAt(col, row);
        grid[dem.index(col, row) - first] = {static_cast<double>(col), static_cast<double>(row),
                                             std::isnan(h) ? nodata_height_m_ : static_cast<double>(h)};
      }
    }
    std::vector<EcefPoint> ecef(count);
    placePixels(grid, geodetic, ecef);
    for (std::size_t i = 0; i < count; ++i) {
      x_[first + i] = ecef[i].x;
      y_[first + i] = ecef[i].y;
      z_[first + i] = ecef[i].z;
      const UnitVector up = ellipsoidNormal(geodetic[i]);
      up_x_[first + i] = up[0];
      up_y_[first + i] = up[1];
      up_z_[first + i] = up[2];
    }
    constexpr double kPoleDeg = 90 - 1e-9;
    for (std::int32_t row = rows.begin(); row < rows.end(); ++row) {
      bool at_pole = true;
      for (std::int32_t col = 0; col < dem.width && at_pole; ++col) {
        at_pole = std::fabs(geodetic[dem.index(col, row) - first].lat_deg) >= kPoleDeg;
      }
      pole_rows_[static_cast<std::size_t>(row)] = at_pole ? 1 : 0;
    }
  });
  has_pole_rows_ = std::find(pole_rows_.begin(), pole_rows_.end(), 1) != pole_rows_.end();
  // Spacing of neighbouring points, without their heights (the part along the vertical).
  const auto horizontal = [&](std::size_t i, std::size_t j) {
    const EcefPoint p = point(i), q = point(j);
    const UnitVector u = up(i);
    const double d[3] = {q.x - p.x, q.y - p.y, q.z - p.z};
    const double along = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
    return std::sqrt(std::max(0.0, d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - along * along));
  };
  column_spacing_m_.assign(static_cast<std::size_t>(dem.height), 0.0);
  row_spacing_m_.assign(static_cast<std::size_t>(dem.height), 0.0);
  max_sin_latitude_.assign(static_cast<std::size_t>(dem.height), 0.0);
  tbb::parallel_for(std::int32_t{0}, dem.height, [&](std::int32_t row) {
    double columns = dem.width > 1 ? 1e300 : 0.0, rows = row + 1 < dem.height ? 1e300 : 0.0, sin_latitude = 0;
    for (std::int32_t col = 0; col < dem.width; ++col) {
      sin_latitude = std::max(sin_latitude, std::fabs(up_z_[dem.index(col, row)]));
      if (col + 1 < dem.width) columns = std::min(columns, horizontal(dem.index(col, row), dem.index(col + 1, row)));
      if (row + 1 < dem.height) rows = std::min(rows, horizontal(dem.index(col, row), dem.index(col, row + 1)));
    }
    column_spacing_m_[static_cast<std::size_t>(row)] = pole_rows_[static_cast<std::size_t>(row)] ? 0.0 : columns;
    row_spacing_m_[static_cast<std::size_t>(row)] = rows;
    max_sin_latitude_[static_cast<std::size_t>(row)] = pole_rows_[static_cast<std::size_t>(row)] ? 0.0 : sin_latitude;
  });
  if (dem.width > 2) {
    const std::int32_t middle = dem.height / 2;
    const double seam = horizontal(dem.index(dem.width - 1, middle), dem.index(0, middle));
    wraps_longitude_ = seam < 1.5 * column_spacing_m_[static_cast<std::size_t>(middle)];
  }
  if (progress) {
    progress->advance(static_cast<std::uint64_t>(dem.height));
    progress->endStage();
  }
}

// placeOnGlobe's steps in its order (so a valid pixel's point is bit for bit what
// placeOnGlobe gives a vertex there), except that a nodata pixel outside the geoid grid takes
// the undulation at the DEM's centre: only its vertical is ever used.
void DemOnGlobe::placePixels(std::span<const GridPoint> grid, std::span<GeodeticPoint> geodetic,
                             std::span<EcefPoint> ecef) const {
  std::vector<CrsPoint> crs(grid.size());
  for (std::size_t i = 0; i < grid.size(); ++i) {
    crs[i] = dem_.pixelCentre(grid[i].col, grid[i].row);
    geodetic[i].height_m = grid[i].height_m;
  }
  transforms_->local().transform(crs, geodetic);
  if (geoid_) {
    for (std::size_t i = 0; i < grid.size(); ++i) {
      GeodeticPoint& p = geodetic[i];
      const std::optional<double> undulation = geoid_->undulationAt(p.lon_deg, p.lat_deg);
      const auto col = static_cast<std::int32_t>(grid[i].col), row = static_cast<std::int32_t>(grid[i].row);
      if (!undulation && dem_.isValid(col, row)) {
        throw Error(ErrorCode::Input,
                    "the point at " + std::to_string(p.lon_deg) + " E " + std::to_string(p.lat_deg) +
                        " N is outside the geoid grid " + geoid_->name +
                        "; pass a grid that covers the data with --geoid FILE, or "
                        "--heights ellipsoidal when the DEM heights are ellipsoidal");
      }
      p.height_m += undulation ? *undulation : centre_undulation_m_;
    }
  }
  geodeticToEcef(geodetic, ecef);
}

DemOnGlobe::~DemOnGlobe() = default;


void DemOnGlobe::place(std::span<const GridPoint> points, std::span<GeodeticPoint> geodetic,
                       std::span<EcefPoint> ecef) const {
  TERRATILES_ASSERT(points.size() == ecef.size() && (geodetic.empty() || geodetic.size() == points.size()));
  std::vector<GeodeticPoint> scratch;
  if (geodetic.empty()) {
    scratch.resize(points.size());
    geodetic = scratch;
  }
  placeOnGlobe(dem_, points, transforms_->local(), geoid_, geodetic, ecef);
}

EcefPoint DemOnGlobe::place(const GridPoint& point) const {
  GeodeticPoint geodetic;
  EcefPoint ecef;
  placeOnGlobe(dem_, std::span<const GridPoint>(&point, 1), transforms_->local(), geoid_,
               std::span<GeodeticPoint>(&geodetic, 1), std::span<EcefPoint>(&ecef, 1));
  return ecef;
}

}  // namespace terratiles
