#pragma once
// runPipeline: the only code that knows the stage order of `terratiles build`:
// read DEM -> levels of detail -> reproject (CRS -> WGS84 -> ECEF) -> GLB tiles ->
// tileset.json, all written through an OutputDirectory that is moved into place at the end.

#include <cstdint>
#include <string>
#include <vector>

#include "src/base/progress.h"

namespace terratiles {

enum class HeightReference {
  Orthometric,  // heights above a geoid (LN02, NAP, EGM96...): add the geoid undulation
  Ellipsoidal,  // heights already above the WGS84 ellipsoid: use as they are
};

struct BuildOptions {
  std::vector<std::string> inputs;
  std::string output_dir;
  bool force = false;
  std::int32_t tile_cells = 128;       // grid cells per tile side
  std::int32_t max_zoom = -1;          // -1: enough zooms for one root tile
  HeightReference heights = HeightReference::Orthometric;
  std::string geoid_path;              // empty: EGM96 from Debian's proj-data
  bool draco = true;
  double position_step_m = 1.0 / 128;  // shared Draco quantisation grid
};

struct ZoomSummary {
  std::int32_t zoom = 0;
  std::int32_t step_pixels = 1;
  std::size_t tiles = 0;
  std::size_t vertices = 0;
  std::size_t triangles = 0;
  std::size_t bytes = 0;
  double max_error_m = 0;   // measured against the DEM
  double rms_error_m = 0;
  double geometric_error_m = 0;  // the largest geometricError written at this zoom
};

struct BuildSummary {
  std::string output_dir;
  std::string crs_name;
  std::int32_t width = 0;
  std::int32_t height = 0;
  double pixel_size = 0;
  std::size_t valid_pixels = 0;
  double min_height_m = 0;
  double max_height_m = 0;
  double centre_lon_deg = 0;
  double centre_lat_deg = 0;
  std::string placement;  // the CRS -> WGS84 path, e.g. "EPSG:2056 -> WGS84 by the rigorous ..."
  std::vector<std::string> warnings;  // things the user should know (e.g. a missing grid)
  std::string geoid;  // which geoid turned heights ellipsoidal, or "none (ellipsoidal input)"
  std::vector<ZoomSummary> zooms;
  std::size_t tiles = 0;
  std::size_t triangles = 0;
  std::size_t bytes = 0;
  double worst_error_m = 0;  // over the non-leaf zooms (the leaves hold the DEM itself)
  double seconds = 0;
};

BuildSummary runPipeline(const BuildOptions& options, Progress& progress);

}  // namespace terratiles
