#include "src/geo/dem_on_globe.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <GeographicLib/Geocentric.hpp>
#include <GeographicLib/Math.hpp>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <cmath>
#include <limits>
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
  width_ = static_cast<std::size_t>(dem.width);
  pole_rows_.assign(static_cast<std::size_t>(dem.height), 0);
  if (progress) progress->beginStage("placing the DEM's pixels on the globe", static_cast<std::uint64_t>(dem.height));
  // A WGS84 longitude and latitude DEM: the factors per column from the first row (a column's
  // longitude is the same on every row; the comparison below holds each pixel to it).
  if (transforms_->local().isWgs84LonLat() && dem.width > 0 && dem.height > 0) {
    Factors& factors = factors_.emplace();
    std::vector<CrsPoint> first_row(width_);
    std::vector<GeodeticPoint> lon_lat(width_);
    for (std::int32_t col = 0; col < dem.width; ++col) first_row[static_cast<std::size_t>(col)] = dem.pixelCentre(col, 0);
    transforms_->local().transform(first_row, lon_lat);
    for (auto* v : {&factors.slam, &factors.clam, &factors.cos_lon, &factors.sin_lon}) v->assign(width_ + kDemOnGlobePadding, 0.0);
    constexpr double kDegToRad = std::numbers::pi / 180.0;
    for (std::size_t col = 0; col < width_; ++col) {
      GeographicLib::Math::sincosd(lon_lat[col].lon_deg, factors.slam[col], factors.clam[col]);
      const double lon = lon_lat[col].lon_deg * kDegToRad;
      factors.cos_lon[col] = std::cos(lon);
      factors.sin_lon[col] = std::sin(lon);
    }
    factors.rows.resize(static_cast<std::size_t>(dem.height));
    factors.height.assign(pixels + kDemOnGlobePadding, 0.0);
  }
  // Columns at most 360 degrees apart, no two of them on one meridian (a seam column
  // repeated is half a column or less from the first).
  if (transforms_->local().isWgs84LonLat() && dem.width > 0 &&
      (static_cast<double>(dem.width) - 0.5) * dem.pixel_size_x < 360.0) {
    degrees_per_column_ = dem.pixel_size_x;
  }
  std::atomic<bool> factors_hold = true;
  const auto placeRows = [&](const tbb::blocked_range<std::int32_t>& rows, bool with_factors) {
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
    if (with_factors) {
      const GeographicLib::Geocentric& earth = GeographicLib::Geocentric::WGS84();
      const double f = earth.Flattening(), e2 = f * (2 - f), e2m = (1 - f) * (1 - f);
      constexpr double kDegToRad = std::numbers::pi / 180.0;
      for (std::int32_t row = rows.begin(); row < rows.end() && factors_hold; ++row) {
        RowFactors& r = factors_->rows[static_cast<std::size_t>(row)];
        const double lat_deg = geodetic[dem.index(0, row) - first].lat_deg;
        GeographicLib::Math::sincosd(GeographicLib::Math::LatFix(lat_deg), r.sphi, r.cphi);
        r.n = earth.EquatorialRadius() / std::sqrt(1 - e2 * (r.sphi * r.sphi));
        r.e2m_n = e2m * r.n;
        r.cos_lat = std::cos(lat_deg * kDegToRad);
        r.sin_lat = std::sin(lat_deg * kDegToRad);
        for (std::int32_t col = 0; col < dem.width; ++col) {
          const std::size_t i = dem.index(col, row) - first;
          factors_->height[first + i] = geodetic[i].height_m;
          const EcefPoint p = point(col, row);
          const UnitVector u = up(col, row), normal = ellipsoidNormal(geodetic[i]);
          if (std::memcmp(&p, &ecef[i], sizeof p) != 0 || std::memcmp(&u, &normal, sizeof u) != 0) {
            factors_hold = false;
            break;
          }
        }
      }
    } else {
      for (std::size_t i = 0; i < count; ++i) {
        x_[first + i] = ecef[i].x;
        y_[first + i] = ecef[i].y;
        z_[first + i] = ecef[i].z;
        const UnitVector up = ellipsoidNormal(geodetic[i]);
        up_x_[first + i] = up[0];
        up_y_[first + i] = up[1];
        up_z_[first + i] = up[2];
      }
    }
    constexpr double kPoleDeg = 90 - 1e-9;
    for (std::int32_t row = rows.begin(); row < rows.end(); ++row) {
      bool at_pole = true;
      for (std::int32_t col = 0; col < dem.width && at_pole; ++col) {
        at_pole = std::fabs(geodetic[dem.index(col, row) - first].lat_deg) >= kPoleDeg;
      }
      pole_rows_[static_cast<std::size_t>(row)] = at_pole ? 1 : 0;
    }
  };
  constexpr std::int32_t kRows = 16;
  if (factors_) {
    tbb::parallel_for(tbb::blocked_range<std::int32_t>(0, dem.height, kRows),
                      [&](const tbb::blocked_range<std::int32_t>& rows) { placeRows(rows, true); });
    if (!factors_hold) factors_.reset();  // a pixel the factors do not give bit for bit: store them all
  }
  if (!factors_) {
    for (auto* v : {&x_, &y_, &z_, &up_x_, &up_y_}) v->assign(pixels + kDemOnGlobePadding, 0.0);
    up_z_.assign(pixels + kDemOnGlobePadding, 1.0);
    tbb::parallel_for(tbb::blocked_range<std::int32_t>(0, dem.height, kRows),
                      [&](const tbb::blocked_range<std::int32_t>& rows) { placeRows(rows, false); });
  }
  has_pole_rows_ = std::find(pole_rows_.begin(), pole_rows_.end(), 1) != pole_rows_.end();
  // Spacing of neighbouring points, without their heights (the part along the vertical).
  const auto horizontal = [&](std::int32_t col, std::int32_t row, std::int32_t next_col, std::int32_t next_row) {
    const EcefPoint p = point(col, row), q = point(next_col, next_row);
    const UnitVector u = up(col, row);
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
      sin_latitude = std::max(sin_latitude, std::fabs(sinLatitude(col, row)));
      if (col + 1 < dem.width) columns = std::min(columns, horizontal(col, row, col + 1, row));
      if (row + 1 < dem.height) rows = std::min(rows, horizontal(col, row, col, row + 1));
    }
    column_spacing_m_[static_cast<std::size_t>(row)] = pole_rows_[static_cast<std::size_t>(row)] ? 0.0 : columns;
    row_spacing_m_[static_cast<std::size_t>(row)] = rows;
    max_sin_latitude_[static_cast<std::size_t>(row)] = pole_rows_[static_cast<std::size_t>(row)] ? 0.0 : sin_latitude;
  });
  double least = std::numeric_limits<double>::infinity();
  for (std::int32_t row = 0; row < dem.height; ++row) {
    if (!pole_rows_[static_cast<std::size_t>(row)]) least = std::min(least, column_spacing_m_[static_cast<std::size_t>(row)]);
  }
  least_column_spacing_m_ = std::isfinite(least) ? least : 0.0;
  if (dem.width > 2) {
    const std::int32_t middle = dem.height / 2;
    const double seam = horizontal(dem.width - 1, middle, 0, middle);
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
  if (!geodetic.empty()) {
    placeOnGlobe(dem_, points, transforms_->local(), geoid_, geodetic, ecef);
    return;
  }
  // A point at a valid pixel's centre with that pixel's height is that pixel's point (the
  // constructor placed it with placeOnGlobe's steps): every vertex of a TIN but its virtual
  // ones. The others are placed in batches; all in parallel.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 16384), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<GridPoint> rest;
    std::vector<std::size_t> rest_index;
    for (std::size_t i = range.begin(); i < range.end(); ++i) {
      const GridPoint& g = points[i];
      if (g.col >= 0 && g.row >= 0 && g.col < dem_.width && g.row < dem_.height) {
        const auto col = static_cast<std::int32_t>(g.col), row = static_cast<std::int32_t>(g.row);
        if (col == g.col && row == g.row && static_cast<double>(dem_.heightAt(col, row)) == g.height_m) {
          ecef[i] = point(col, row);
          continue;
        }
      }
      rest.push_back(g);
      rest_index.push_back(i);
    }
    if (rest.empty()) return;
    std::vector<GeodeticPoint> rest_geodetic(rest.size());
    std::vector<EcefPoint> rest_ecef(rest.size());
    placeOnGlobe(dem_, rest, transforms_->local(), geoid_, rest_geodetic, rest_ecef);
    for (std::size_t k = 0; k < rest.size(); ++k) ecef[rest_index[k]] = rest_ecef[k];
  });
}

EcefPoint DemOnGlobe::place(const GridPoint& point) const {
  GeodeticPoint geodetic;
  EcefPoint ecef;
  placeOnGlobe(dem_, std::span<const GridPoint>(&point, 1), transforms_->local(), geoid_,
               std::span<GeodeticPoint>(&geodetic, 1), std::span<EcefPoint>(&ecef, 1));
  return ecef;
}

}  // namespace terratiles
