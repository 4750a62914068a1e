#pragma once
// measureTin: the vertical error of a TIN against its DEM, on every pixel.
//
// Rasterises every triangle of `mesh` (GridPoint frame: col, row in pixels) onto the DEM grid
// and compares the linearly interpolated height with the DEM at each pixel centre the
// triangle covers (a pixel on a shared edge is measured once per triangle touching it). Also
// counts pixels no triangle covers and nodata pixels a triangle covers, so tests can assert
// "every valid pixel is within E" and "no triangle covers nodata" from one pass. O(pixels
// covered). Does not modify anything.

#include <cstddef>

#include "src/dem/dem_grid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

struct TinErrorStatistics {
  double max_error_m = 0;          // over valid pixels covered by the TIN
  double rms_error_m = 0;
  std::size_t measured_pixels = 0;      // valid pixels covered (each counted once)
  std::size_t uncovered_valid_pixels = 0;  // valid pixels no triangle covers
  std::size_t covered_nodata_pixels = 0;   // nodata pixels inside some triangle
  std::size_t degenerate_triangles = 0;    // zero area in the grid plane
};

TinErrorStatistics measureTin(const DemGrid& dem, const TinMesh& mesh);

}  // namespace terratiles
