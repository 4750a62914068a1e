#pragma once
// expandDemInputs: the DEM rasters a command line names, as the list of files a build reads.
//
// A country is tens of thousands of files (swissALTI3D: about 43,000 GeoTIFFs), more than a
// shell passes as arguments, so an input may be:
//   - a raster file GDAL reads (GeoTIFF, .hgt, a GDAL VRT, ...): kept as it is;
//   - a directory: every raster file directly inside it (not in subdirectories) whose name
//     ends in one of kRasterExtensions (case-insensitive), in byte order of the names, so the
//     order (which decides overlaps: the first valid value wins) does not depend on the file
//     system;
//   - the lines of an input list file (`--input-list FILE`): one path per line, relative paths
//     relative to the current directory (as gdalbuildvrt -input_file_list), blank lines and
//     lines starting with '#' ignored; a listed directory is expanded as above.
// Arguments come first, then the list's lines. Throws Error(Input) for a missing path, an
// unreadable list, or a directory without rasters; the message names the path and the fix.

#include <string>
#include <vector>

namespace terratiles {

// Extensions a directory's rasters are recognised by (lower case, with the dot).
inline constexpr const char* kRasterExtensions[] = {".tif", ".tiff", ".vrt", ".hgt", ".asc", ".img",
                                                   ".bil", ".flt", ".dem", ".nc",  ".jp2"};

// Whether `path`'s extension is `extension` (lower case, with the dot), in any case.
bool hasExtension(const std::string& path, const char* extension);

std::vector<std::string> expandDemInputs(const std::vector<std::string>& arguments,
                                         const std::string& input_list_path = {});

}  // namespace terratiles
