#pragma once
// CRS -> WGS84 geodetic -> ECEF.
//
// CrsToWgs84 takes a horizontal CRS to WGS84 longitude/latitude (EPSG:4326, lon/lat order):
// EPSG:2056 (CH1903+/LV95) through the rigorous swisstopo formulas (src/geo/swiss_lv95.h),
// any other CRS through GDAL's OGRCoordinateTransformation (PROJ). It refuses a
// "ballpark" transformation (one PROJ would use when it knows no real datum shift) with
// Error(Input), because silently placing terrain hundreds of metres off is worse than failing.
// Heights pass through unchanged (the caller decides what they are relative to).
//
// geodeticToEcef uses GeographicLib::Geocentric::WGS84().

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "src/dem/dem_grid.h"

namespace terratiles {

struct GeodeticPoint {
  double lon_deg = 0;
  double lat_deg = 0;
  double height_m = 0;  // above the WGS84 ellipsoid
};

struct EcefPoint {
  double x = 0;
  double y = 0;
  double z = 0;
};

enum class TransformEngine {
  Auto,  // the rigorous swisstopo formulas for EPSG:2056, PROJ for every other CRS
  Proj,  // PROJ through GDAL for every CRS (for comparisons and benchmarks)
};

class CrsToWgs84 {
 public:
  // crs_wkt: any horizontal CRS GDAL understands (WKT, "EPSG:2056", PROJ string).
  explicit CrsToWgs84(const std::string& crs_wkt, TransformEngine engine = TransformEngine::Auto);
  ~CrsToWgs84();
  CrsToWgs84(const CrsToWgs84&) = delete;
  CrsToWgs84& operator=(const CrsToWgs84&) = delete;

  // Transforms in[i] to out[i]. out[i].height_m must hold the point's height on input: PROJ
  // runs 3D datum shifts with it (EPSG:2056's Helmert moves lon/lat by up to 1e-6 deg per
  // 1000 m of height), and it is left unchanged on output. Sizes must match.
  // Throws Error(Input) naming the first point PROJ cannot transform.
  void transform(std::span<const CrsPoint> in, std::span<GeodeticPoint> out) const;

  // Lines for the log and the report, e.g. that PROJ's most accurate operation lacks a grid
  // and a less accurate one is used (EPSG:27700 without the OSTN15 grid: 2 m instead of cm).
  const std::vector<std::string>& warnings() const;

  // "EPSG:2056", or the CRS name; and which path transforms it, for logs and reports.
  const std::string& sourceName() const;
  std::string pathDescription() const;
  // Whether the source is WGS84 longitude and latitude itself (transform copies x and y).
  bool isWgs84LonLat() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

void geodeticToEcef(std::span<const GeodeticPoint> in, std::span<EcefPoint> out);

}  // namespace terratiles
