#pragma once
// DemGrid: a north-up raster of heights in one CRS, the input of every later stage.
//
// Heights are metres (float), row-major, row 0 at the north edge. A pixel without data holds
// NaN. Vertex positions are pixel centres: pixel (col, row) is at
//   x = origin_x + (col + 0.5) * pixel_size_x,  y = origin_y - (row + 0.5) * pixel_size_y
// where (origin_x, origin_y) is the north-west corner of the raster, in CRS units.
// A window of a larger lattice (readDemWindow) places its pixels from the lattice's corner
// instead: pixel (col, row) of the window is pixel (col_offset + col, row_offset + row) of the
// lattice, at the very same coordinates bit for bit, so two windows (blocks) that share pixels
// place them, and everything measured on them, identically.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace terratiles {

struct CrsPoint {
  double x = 0;
  double y = 0;
};

struct DemGrid {
  std::int32_t width = 0;
  std::int32_t height = 0;
  double origin_x = 0;      // north-west corner, CRS units
  double origin_y = 0;
  double pixel_size_x = 1;  // > 0, CRS units per pixel
  double pixel_size_y = 1;  // > 0; rows go south
  std::string crs_wkt;      // WKT2 of the horizontal CRS
  std::string crs_name;     // for messages and reports, e.g. "EPSG:2056"
  std::vector<float> heights_m;  // width * height, NaN where there is no data
  // A window of a larger lattice: its place in it and the lattice's north-west corner (both
  // unused while the offsets are 0).
  std::int64_t col_offset = 0;
  std::int64_t row_offset = 0;
  double lattice_origin_x = 0;
  double lattice_origin_y = 0;

  static constexpr float kNoData = std::numeric_limits<float>::quiet_NaN();

  std::size_t pixelCount() const { return static_cast<std::size_t>(width) * height; }
  std::size_t index(std::int32_t col, std::int32_t row) const {
    return static_cast<std::size_t>(row) * width + col;
  }
  float heightAt(std::int32_t col, std::int32_t row) const { return heights_m[index(col, row)]; }
  bool isValid(std::int32_t col, std::int32_t row) const {
    return !std::isnan(heights_m[index(col, row)]);
  }
  CrsPoint pixelCentre(double col, double row) const {
    if (col_offset == 0 && row_offset == 0) {
      return {origin_x + (col + 0.5) * pixel_size_x, origin_y - (row + 0.5) * pixel_size_y};
    }
    return {lattice_origin_x + (static_cast<double>(col_offset) + col + 0.5) * pixel_size_x,
            lattice_origin_y - (static_cast<double>(row_offset) + row + 0.5) * pixel_size_y};
  }
};

// Counts of the grid's valid pixels and their height range.
struct DemStatistics {
  std::size_t valid_pixels = 0;
  float min_height_m = 0;
  float max_height_m = 0;
};

DemStatistics computeStatistics(const DemGrid& dem);

}  // namespace terratiles
