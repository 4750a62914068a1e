#pragma once
// placeOnGlobe: DEM grid points -> WGS84 geodetic and ECEF, the one placement every output
// vertex goes through: pixel position -> CRS (x, y) -> WGS84 lon/lat (CrsToWgs84: rigorous
// for EPSG:2056, PROJ otherwise) -> ellipsoidal height (h = H + N with a geoid, H as it is
// without) -> ECEF (GeographicLib, WGS84).

#include <span>

#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/geo/geoid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

// Sizes of points, geodetic and ecef must match. geoid null: heights are ellipsoidal.
// Throws Error(Input) for a point PROJ cannot transform or outside the geoid grid.
void placeOnGlobe(const DemGrid& dem, std::span<const GridPoint> points, const CrsToWgs84& to_wgs84,
                  const GeoidGrid* geoid, std::span<GeodeticPoint> geodetic, std::span<EcefPoint> ecef);

}  // namespace terratiles
