#pragma once
// GeoidGrid: geoid undulation N (metres; WGS84 ellipsoidal height = orthometric height + N)
// on a regular longitude/latitude grid, sampled bilinearly between grid nodes as PROJ's
// vgridshift does. Grids that span 360 degrees of longitude wrap around the antimeridian.
// Reading a grid file is formats/geoid/read_geoid.h.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace terratiles {

struct GeoidGrid {
  std::string name;            // for reports and logs, e.g. "EGM96 (egm96_15.gtx)"
  double first_lon_deg = 0;    // longitude of node column 0
  double first_lat_deg = 0;    // latitude of node row 0 (the northernmost row)
  double step_deg = 0.25;      // node spacing in longitude
  double step_lat_deg = 0.25;  // node spacing in latitude
  std::int32_t width = 0;
  std::int32_t height = 0;
  bool wraps_longitude = false;
  std::vector<float> undulation_m;  // row-major, NaN where the grid has no value

  // N at (lon, lat) by bilinear interpolation; nullopt outside the grid or next to a
  // node without value. A latitude past a pole (|lat| in (90, 180]) is the point across it.
  std::optional<double> undulationAt(double lon_deg, double lat_deg) const;
};

}  // namespace terratiles
