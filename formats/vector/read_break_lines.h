#pragma once
// readBreakLines: feature lines (roads, rivers, building footprints, ...) from any OGR
// vector source (GeoJSON, GeoPackage, Shapefile, ...) as break line segments on a DEM's grid,
// for buildConstrainedTin (the paper's constrained edges, section 4.2).
//
// Every line and every polygon ring of every layer (multi-geometries and collections
// included, curves linearised, points ignored) is transformed from the layer's CRS to the
// DEM's, clipped to the grid, and its vertices snapped to the nearest pixel centre: "draped"
// on the surface, since the TIN's vertices take the DEM's heights there. A segment is cut
// where it passes over nodata (sampled at every pixel along it) and only its valid pieces
// are kept.
// Throws Error(Input) with a one-line message for a file GDAL cannot open as vectors, a
// layer without a CRS, or a CRS that cannot be transformed to the DEM's.

#include <cstddef>
#include <string>
#include <vector>

#include "src/dem/dem_grid.h"
#include "src/tin/build_tin.h"

namespace terratiles {

struct BreakLines {
  std::vector<PixelSegment> segments;
  std::size_t features = 0;           // features that gave at least one line
  std::size_t segments_read = 0;      // line segments in the source, before clipping
  std::size_t pieces_left_out = 0;    // segments (or pieces) outside the grid or over nodata
};

BreakLines readBreakLines(const std::string& path, const DemGrid& dem);

}  // namespace terratiles
