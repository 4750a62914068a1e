#pragma once
// DemOnGlobe: where a DEM's pixels, and any point of its grid, lie on the WGS84 globe, and
// the vertical along which every error of terratiles is measured (DESIGN.md 5).
//
// A renderer draws each triangle as the straight triangle between its three corners in ECEF.
// So the vertical error of a triangle at a DEM pixel is measured between the pixel's DEM
// point (the pixel centre at its DEM height, placed by placeOnGlobe exactly as a vertex
// there is placed) and the triangle's plane, along the pixel's vertical: the WGS84 ellipsoid
// normal at that point (src/geo/drawn_triangle.h). Long edges over flat ground sag below the
// surface by about L^2 / (8 R): 0.5 m at 5 km, 240 m at 110 km.
//
// Every pixel is placed once, in parallel (one CRS transformation per thread). A nodata pixel
// is placed at the DEM's mean valid height, so that its vertical exists too (the TIN's
// virtual vertices sit there). Memory: 48 bytes per pixel (doubles: a vertical rounded to
// float would tilt by 6e-8 rad, and move a steep triangle's error by a ten-millionth), or 8
// for a DEM in WGS84 longitude and latitude (SRTM, ETOPO5): there a pixel's latitude is its
// row's and its longitude its column's, so its point and vertical are products of factors
// per row and per column and its ellipsoidal height (DemOnGlobe::Factors), the same
// operations GeographicLib's Geocentric::Forward and ellipsoidNormal do. The constructor
// compares every pixel's product with the placed point bit for bit and keeps the 48 bytes
// when one differs. Placing is deterministic: the same DEM and geoid give the same points
// bit for bit, in the build and in `terratiles check`.

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/geo/geoid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

using UnitVector = std::array<double, 3>;

// DemOnGlobe's per-pixel arrays hold this many entries past the last pixel (points at the
// origin, verticals (0, 0, 1)), so a vectorised scan may read a few lanes past the raster.
inline constexpr std::size_t kDemOnGlobePadding = 8;

class DemOnGlobe {
 public:
  // geoid: the DEM's heights are orthometric and become ellipsoidal as h = H + N; nullptr:
  // they are ellipsoidal already. Both must outlive this object. Throws Error(Input) as
  // placeOnGlobe does (no transformation to WGS84, a pixel outside the geoid grid).
  DemOnGlobe(const DemGrid& dem, const GeoidGrid* geoid, Progress* progress = nullptr);
  ~DemOnGlobe();
  DemOnGlobe(const DemOnGlobe&) = delete;
  DemOnGlobe& operator=(const DemOnGlobe&) = delete;

  const DemGrid& dem() const { return dem_; }
  const GeoidGrid* geoid() const { return geoid_; }
  // The height a nodata pixel (and a TIN's virtual vertex) is placed at: the mean valid height.
  double nodataHeight() const { return nodata_height_m_; }

  // A WGS84 longitude and latitude DEM's pixels (see above): pixel (col, row) with
  // ellipsoidal height h lies at {X * clam[col], X * slam[col], (e2m_n + h) * sphi} with
  // X = (n + h) * cphi (the row's factors), and its vertical is {cos_lat * cos_lon[col],
  // cos_lat * sin_lon[col], sin_lat}. The column arrays and `height` hold
  // kDemOnGlobePadding entries more (zeros), for vectorised scans.
  struct RowFactors {
    double n, e2m_n, sphi, cphi;  // Geocentric::Forward's prime vertical radius and sincosd
    double cos_lat, sin_lat;      // ellipsoidNormal's
  };
  struct Factors {
    std::vector<RowFactors> rows;
    std::vector<double> slam, clam, cos_lon, sin_lon;  // per column
    std::vector<double> height;                        // per pixel: ellipsoidal, metres
  };
  // The factors, or nullptr when the points and verticals are stored (pointX() ... upZ()).
  const Factors* factors() const { return factors_ ? &*factors_ : nullptr; }

  // Per pixel: the DEM point in ECEF and the unit vertical there.
  EcefPoint point(std::int32_t col, std::int32_t row) const {
    const std::size_t pixel = dem_.index(col, row);
    if (!factors_) return {x_[pixel], y_[pixel], z_[pixel]};
    const RowFactors& r = factors_->rows[static_cast<std::size_t>(row)];
    const double h = factors_->height[pixel];
    const double across = (r.n + h) * r.cphi;
    return {across * factors_->clam[static_cast<std::size_t>(col)], across * factors_->slam[static_cast<std::size_t>(col)],
            (r.e2m_n + h) * r.sphi};
  }
  UnitVector up(std::int32_t col, std::int32_t row) const {
    if (!factors_) {
      const std::size_t pixel = dem_.index(col, row);
      return {up_x_[pixel], up_y_[pixel], up_z_[pixel]};
    }
    const RowFactors& r = factors_->rows[static_cast<std::size_t>(row)];
    return {r.cos_lat * factors_->cos_lon[static_cast<std::size_t>(col)],
            r.cos_lat * factors_->sin_lon[static_cast<std::size_t>(col)], r.sin_lat};
  }
  // The same by pixel index (DemGrid::index).
  EcefPoint point(std::size_t pixel) const {
    if (!factors_) return {x_[pixel], y_[pixel], z_[pixel]};
    return point(static_cast<std::int32_t>(pixel % width_), static_cast<std::int32_t>(pixel / width_));
  }
  UnitVector up(std::size_t pixel) const {
    if (!factors_) return {up_x_[pixel], up_y_[pixel], up_z_[pixel]};
    return up(static_cast<std::int32_t>(pixel % width_), static_cast<std::int32_t>(pixel / width_));
  }
  // The sine of the latitude of a pixel's vertical (up()[2]).
  double sinLatitude(std::int32_t col, std::int32_t row) const {
    return factors_ ? factors_->rows[static_cast<std::size_t>(row)].sin_lat : up_z_[dem_.index(col, row)];
  }
  // Whether row `row` lies at a pole (a geographic DEM's first or last row at +-90 degrees):
  // all its pixels are one point, so the grid cannot say which triangle is drawn above them;
  // the TIN and the simplifier measure them in the grid, the tiles and `terratiles check` as
  // drawn (where verticals meet triangles: at the pole, the pole vertex).
  bool poleRow(std::int32_t row) const { return pole_rows_[static_cast<std::size_t>(row)] != 0; }
  // Whether any row is a pole row.
  bool hasPoleRows() const { return has_pole_rows_; }
  // The smallest ground distance between neighbouring pixels' points along row `row`
  // (between columns; 0 on a pole row) and between rows `row` and `row` + 1, metres
  // (horizontal, heights left out).
  double columnSpacing(std::int32_t row) const { return column_spacing_m_[static_cast<std::size_t>(row)]; }
  double rowSpacing(std::int32_t row) const { return row_spacing_m_[static_cast<std::size_t>(row)]; }
  // The least columnSpacing of the rows off the poles (0 if none).
  double leastColumnSpacing() const { return least_column_spacing_m_; }
  // The largest |sin latitude| of the verticals of row `row`'s pixels (0 on a pole row, whose
  // pixels have no column to stray by).
  double maxSinLatitude(std::int32_t row) const { return max_sin_latitude_[static_cast<std::size_t>(row)]; }
  // Whether the DEM spans the whole circle of longitude (its last column is next to its first).
  bool wrapsLongitude() const { return wraps_longitude_; }
  // On a DEM in WGS84 longitude and latitude (no two columns on one meridian): degrees of
  // longitude per column (a pixel's longitude is its column's, and so is that of every grid
  // point placed in that column, at any row and height); 0 on any other DEM.
  double degreesPerColumn() const { return degrees_per_column_; }
  // Without factors(): the same as arrays (structure of arrays, for vectorised scans;
  // pixelLanes in dem_on_globe_lanes.h reads either form).
  const double* pointX() const { return stored(x_); }
  const double* pointY() const { return stored(y_); }
  const double* pointZ() const { return stored(z_); }
  const double* upX() const { return stored(up_x_); }
  const double* upY() const { return stored(up_y_); }
  const double* upZ() const { return stored(up_z_); }

  // Grid points (col, row, orthometric or ellipsoidal height as the DEM's) on the globe,
  // exactly as placeOnGlobe places them: a point at a pixel centre with that pixel's DEM
  // height gets that pixel's point() bit for bit. Thread-safe. geodetic may be empty.
  void place(std::span<const GridPoint> points, std::span<GeodeticPoint> geodetic,
             std::span<EcefPoint> ecef) const;
  EcefPoint place(const GridPoint& point) const;

 private:
  struct Transforms;
  void placePixels(std::span<const GridPoint> grid, std::span<GeodeticPoint> geodetic,
                   std::span<EcefPoint> ecef) const;

  const DemGrid& dem_;
  const GeoidGrid* geoid_;
  double nodata_height_m_ = 0;
  double centre_undulation_m_ = 0;
  std::unique_ptr<Transforms> transforms_;
  const double* stored(const std::vector<double>& array) const {
    TERRATILES_ASSERT(!factors_);  // the factor form has no such arrays: read it with pixelLanes
    return array.data();
  }

  std::size_t width_ = 0;
  std::optional<Factors> factors_;
  std::vector<double> x_, y_, z_;  // without factors_
  std::vector<double> up_x_, up_y_, up_z_;
  std::vector<std::uint8_t> pole_rows_;
  std::vector<double> column_spacing_m_, row_spacing_m_, max_sin_latitude_;
  bool wraps_longitude_ = false;
  double degrees_per_column_ = 0;
  double least_column_spacing_m_ = 0;
  bool has_pole_rows_ = false;
};

// The WGS84 ellipsoid normal at a geodetic position.
UnitVector ellipsoidNormal(const GeodeticPoint& point);

}  // namespace terratiles
