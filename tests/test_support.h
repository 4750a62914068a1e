#pragma once
// Shared helpers for the tests: real data paths, temporary directories, small DEMs built in
// code, GeoTIFF writing, running the CLI in-process, and the Khronos glTF validator.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "src/dem/dem_grid.h"

namespace terratiles::test {

// Path of a file in ../shared/data (the real rasters; see its README).
std::string sharedData(const std::string& relative);
std::string sourceDir();

class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

// A DEM in EPSG:2056 near Bern with `pixel_m` pixels and heights from `height(col, row)`
// (return NaN for nodata).
DemGrid makeDem(int width, int height, double pixel_m,
                const std::function<double(int col, int row)>& height_m);

// Writes `dem` as a Float32 GeoTIFF (nodata -9999); `with_crs` false leaves the CRS out.
void writeGeoTiff(const DemGrid& dem, const std::string& path, bool with_crs = true);

struct CliResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};
CliResult runTerratiles(const std::vector<std::string>& args, const std::string& standard_input = "");

struct GltfValidation {
  int files = 0;
  int errors = 0;
  int warnings = 0;
  std::string report;  // the validator's summary lines
  bool ran = false;    // false when node or the npm package is missing
};
// Runs the Khronos glTF validator (npm gltf-validator, installed by the test set-up) on
// every .glb below `dir`.
GltfValidation validateGltfTree(const std::string& dir);

}  // namespace terratiles::test
