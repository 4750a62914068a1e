#pragma once
// Reading DEM rasters (GeoTIFF or anything GDAL reads, a GDAL VRT too) as one mosaic.
//
// Every input must be north-up with square pixels, carry a CRS, and share the CRS and pixel
// size of the first input; inputs must sit on the same pixel lattice (offsets a whole number
// of pixels). The mosaic spans the union of the inputs; where inputs overlap the first valid
// value wins; pixels no input covers, nodata values and non-finite values become NaN.
// Throws Error(Input) with a one-line message naming the file, what was found and what was
// expected, and how to fix it.
//
// scanDemMosaic reads only the inputs' headers (each file is opened, checked and closed, so
// tens of thousands of files are fine); readDemWindow then reads any window of the mosaic,
// opening only the files it overlaps. readDem reads the whole mosaic at once.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "src/base/progress.h"
#include "src/dem/dem_grid.h"

namespace terratiles {

// One input raster and where it sits on the mosaic's pixel lattice.
struct MosaicRaster {
  std::string path;
  std::int64_t col0 = 0;  // its north-west pixel, in mosaic pixels
  std::int64_t row0 = 0;
  std::int32_t width = 0;
  std::int32_t height = 0;
};

// A window of the mosaic in its pixels; it may reach past the mosaic (read as nodata).
struct PixelWindow {
  std::int64_t col0 = 0;
  std::int64_t row0 = 0;
  std::int32_t width = 0;
  std::int32_t height = 0;
};

// The inputs as one pixel lattice, without their pixels.
struct DemMosaic {
  std::vector<MosaicRaster> rasters;  // in input order: where they overlap, the first valid value wins
  std::int64_t width = 0;             // pixels of the union of the inputs
  std::int64_t height = 0;
  double origin_x = 0;  // north-west corner, CRS units
  double origin_y = 0;
  double pixel_size = 1;
  std::string crs_wkt;   // WKT2 of the horizontal CRS
  std::string crs_name;  // e.g. "EPSG:2056"
};

// Checks every input against the first and lays them out; with `progress` and more than one
// input, a stage counts the files.
DemMosaic scanDemMosaic(const std::vector<std::string>& paths, Progress* progress = nullptr);

// The heights of `window`, as a DemGrid whose origin is the window's corner and whose pixels
// are placed from the mosaic's corner (DemGrid::col_offset): a pixel two windows share has
// the same coordinates in both.
DemGrid readDemWindow(const DemMosaic& mosaic, const PixelWindow& window);
// The same grid without its heights (heights_m empty): where the window's pixels lie.
DemGrid mosaicWindowGrid(const DemMosaic& mosaic, const PixelWindow& window);
// The whole mosaic's grid, without its heights.
inline DemGrid mosaicGrid(const DemMosaic& mosaic) {
  return mosaicWindowGrid(mosaic, {0, 0, static_cast<std::int32_t>(mosaic.width), static_cast<std::int32_t>(mosaic.height)});
}

struct ReadDemOptions {
  // Refuse mosaics larger than this many pixels (the in-memory path); 0 = no limit.
  std::size_t max_pixels = 400'000'000;
  Progress* progress = nullptr;  // advanced once per input file read
};

// The mosaic at 1/factor of its resolution (factor >= 1): pixel (c, r) holds the mean of the
// valid mosaic pixels [c f, c f + f) x [r f, r f + f) (NaN where none is valid), so its centre
// lies at mosaic pixel ((c + 0.5) f - 0.5, (r + 0.5) f - 0.5); ceil(width / f) x ceil(height / f)
// pixels of f times the size, from the mosaic's corner. Read in strips of rows of about
// `strip_pixels` mosaic pixels (never the whole mosaic at once); `progress`, when given, is
// advanced once per strip (the caller's stage, of overviewStrips(...) steps); `each_strip`,
// when given, sees every strip read (its heights, and its first row in the mosaic).
DemGrid readDemOverview(const DemMosaic& mosaic, std::int32_t factor, std::int64_t strip_pixels,
                        Progress* progress = nullptr,
                        const std::function<void(const DemGrid&, std::int64_t)>& each_strip = {});
// How many strips readDemOverview reads.
std::int64_t overviewStrips(const DemMosaic& mosaic, std::int32_t factor, std::int64_t strip_pixels);

// The whole mosaic; throws Error(Input) when every pixel is nodata.
DemGrid readDem(const DemMosaic& mosaic, const ReadDemOptions& options = {});
// scanDemMosaic, then readDem.
DemGrid readDem(const std::vector<std::string>& paths, const ReadDemOptions& options = {});
// The same, shown on `progress`: a stage "scanning N inputs" when there are several, then
// `stage` counting the files read, which the caller ends (it may read more inside it, such as
// the geoid).
DemGrid readDem(const std::vector<std::string>& paths, const std::string& stage, Progress& progress);
// The same for a mosaic already scanned.
DemGrid readDem(const DemMosaic& mosaic, const std::string& stage, Progress& progress);

}  // namespace terratiles
