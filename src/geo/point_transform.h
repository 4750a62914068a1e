#pragma once
// PointTransform: points from one CRS to another through WGS84, for
// `terratiles transform` (a cs2cs-like check of where terratiles puts things).
//
// Path: source -> WGS84 lon/lat -> [geoid] -> target. Special-cased, without PROJ:
// EPSG:4326/4979 (lon, lat, h), EPSG:4978 (ECEF, GeographicLib), EPSG:3857 (Web Mercator
// on the sphere) and EPSG:2056 (the rigorous swisstopo formulas, both directions). Any other
// CRS goes through PROJ (GDAL), refusing ballpark transformations.
//
// Heights: every path keeps the height as it is, except the geoid: with a geoid, heights on
// the non-WGS84 side are orthometric and become ellipsoidal (h = H + N) going to WGS84, and
// orthometric again (H = h - N) coming from it. A source CRS with a vertical part (such as
// EPSG:2056+5728, LN02 heights) needs a geoid: PROJ 9.1 would otherwise fall back silently to
// a ballpark transformation 144-189 m off.

#include <memory>
#include <span>
#include <string>

#include "src/geo/geoid.h"

namespace terratiles {

struct Point3 {
  double x = 0;
  double y = 0;
  double z = 0;
};

class PointTransform {
 public:
  // from, to: "EPSG:2056", "EPSG:2056+5728", WKT or a PROJ string. geoid may be null; the
  // grid must outlive this object. Throws Error(Usage) for an unknown CRS and Error(Input)
  // when no accurate path exists.
  PointTransform(const std::string& from, const std::string& to, const GeoidGrid* geoid);
  ~PointTransform();
  PointTransform(const PointTransform&) = delete;
  PointTransform& operator=(const PointTransform&) = delete;

  // Transforms the points in place. Throws Error(Input) naming the first point that cannot
  // be transformed (outside the CRS, the geoid grid, or the Web Mercator latitude limit).
  void transform(std::span<Point3> points) const;

  // Whether target coordinates are degrees (for printing).
  bool targetIsGeographic() const;
  // One line: the path taken, e.g. "EPSG:2056 -> WGS84 (rigorous swisstopo) -> EPSG:4978".
  std::string description() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace terratiles
