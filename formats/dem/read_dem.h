#pragma once
// readDem: reads one or several adjacent DEM rasters (GeoTIFF or anything GDAL reads) into
// one DemGrid mosaic.
//
// Every input must be north-up with square pixels, carry a CRS, and share the CRS and pixel
// size of the first input; inputs must sit on the same pixel lattice (offsets a whole number
// of pixels). The mosaic spans the union of the inputs; where inputs overlap the first valid
// value wins; pixels no input covers, nodata values and non-finite values become NaN.
// Throws Error(Input) with a one-line message naming the file, what was found and what was
// expected, and how to fix it.

#include <string>
#include <vector>

#include "src/dem/dem_grid.h"

namespace terratiles {

struct ReadDemOptions {
  // Refuse mosaics larger than this many pixels (the in-memory path); 0 = no limit.
  std::size_t max_pixels = 400'000'000;
};

DemGrid readDem(const std::vector<std::string>& paths, const ReadDemOptions& options = {});

}  // namespace terratiles
