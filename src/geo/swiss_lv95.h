#pragma once
// The rigorous swisstopo path between CH1903+/LV95 (EPSG:2056) and WGS84, after swisstopo's
// "Formulas and constants for the calculation of the Swiss conformal cylindrical projection
// and for the transformation between coordinate systems":
//   LV95 (E, N) --oblique Mercator inverse through the Gauss sphere (Bessel 1841)--> CH1903+
//   geodetic --Bessel geocentric--> + (674.374, 15.056, 405.346) m --> WGS84 geodetic.
// The ellipsoid parts use GeographicLib::Geocentric.
//
// Heights: each point's height goes through the 3D datum shift as a Bessel ellipsoidal
// height and comes back unchanged, exactly as PROJ's EPSG:2056 -> EPSG:4326 pipeline does
// ("push v_3 ... pop v_3"): the datum shift moves lon/lat by up to ~1e-6 deg per 1000 m of
// height, so pass the real heights (LN02 heights are what swisstopo and PROJ use).
// The forward direction inverts PROJ's pipeline the same way (heights taken as WGS84), so
// both directions agree with PROJ to the micrometre; a round trip LV95 -> WGS84 -> LV95 with
// the height unchanged is off by up to ~1.3 mm at 4000 m, as PROJ's own round trip.
//
// Batch functions over caller-owned arrays: no allocation, thread-safe, O(n).

#include <span>

#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"

namespace terratiles {

// LV95 (E, N) in metres -> WGS84 lon/lat. inout[i].height_m is the input height and is left
// unchanged. Sizes must match.
void lv95ToWgs84(std::span<const CrsPoint> lv95, std::span<GeodeticPoint> inout);

// WGS84 lon/lat (height as WGS84 ellipsoidal) -> LV95 (E, N) in metres. Sizes must match.
void wgs84ToLv95(std::span<const GeodeticPoint> wgs84, std::span<CrsPoint> lv95);

}  // namespace terratiles
