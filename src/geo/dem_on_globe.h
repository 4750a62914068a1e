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
// float would tilt by 6e-8 rad, and move a steep triangle's error by a ten-millionth). Placing is deterministic: the same
// DEM and geoid give the same points bit for bit, in the build and in `terratiles check`.

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

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

  // Per pixel (DemGrid::index): the DEM point in ECEF and the unit vertical there.
  EcefPoint point(std::size_t pixel) const { return {x_[pixel], y_[pixel], z_[pixel]}; }
  UnitVector up(std::size_t pixel) const { return {up_x_[pixel], up_y_[pixel], up_z_[pixel]}; }
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
  // The largest |sin latitude| of the verticals of row `row`'s pixels (0 on a pole row, whose
  // pixels have no column to stray by).
  double maxSinLatitude(std::int32_t row) const { return max_sin_latitude_[static_cast<std::size_t>(row)]; }
  // Whether the DEM spans the whole circle of longitude (its last column is next to its first).
  bool wrapsLongitude() const { return wraps_longitude_; }
  // The same as arrays (structure of arrays, for vectorised scans).
  const double* pointX() const { return x_.data(); }
  const double* pointY() const { return y_.data(); }
  const double* pointZ() const { return z_.data(); }
  const double* upX() const { return up_x_.data(); }
  const double* upY() const { return up_y_.data(); }
  const double* upZ() const { return up_z_.data(); }

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
  std::vector<double> x_, y_, z_;
  std::vector<double> up_x_, up_y_, up_z_;
  std::vector<std::uint8_t> pole_rows_;
  std::vector<double> column_spacing_m_, row_spacing_m_, max_sin_latitude_;
  bool wraps_longitude_ = false;
  bool has_pole_rows_ = false;
};

// The WGS84 ellipsoid normal at a geodetic position.
UnitVector ellipsoidNormal(const GeodeticPoint& point);

}  // namespace terratiles
