#pragma once
// readGeoidGrid: a geoid undulation grid from any raster GDAL reads in a geographic CRS
// (PROJ's .gtx and GeoTIFF grids, e.g. /usr/share/proj/egm96_15.gtx from Debian's proj-data
// or swisstopo's CHGeo2004 grid). Nodes are GDAL pixel centres. Throws Error(Input).

#include <string>

#include "src/geo/geoid.h"

namespace terratiles {

// Debian's proj-data EGM96 grid, the default geoid.
inline constexpr const char* kDefaultGeoidPath = "/usr/share/proj/egm96_15.gtx";

GeoidGrid readGeoidGrid(const std::string& path);

}  // namespace terratiles
