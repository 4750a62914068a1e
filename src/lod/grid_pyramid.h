#pragma once
// buildGridPyramid: the end-to-end slice's levels of detail, a quadtree over the DEM's pixel
// grid ("local" scheme in pixel space, origin at the north-west pixel centre).
//
// Zoom z_max samples every pixel; each coarser zoom samples every second vertex of the
// next finer one (a decimated grid). A tile of zoom z spans tile_cells * step pixels per side,
// so every tile holds at most tile_cells^2 * 2 triangles and the four children of tile
// (z, x, y) are (z+1, 2x..2x+1, 2y..2y+1). Zoom 0 is one tile over the whole raster.
// Every tile's max and RMS vertical error against the source DEM is measured on every valid
// pixel it covers (not estimated).
//
// This is a stand-in for the cluster LoD builder (paper 3.3-3.5): neighbouring tiles of
// different zooms do not share border vertices yet (T-junctions), which the cluster builder
// and the merge assignment remove.

#include <cstdint>
#include <vector>

#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/tiling/tile_key.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

struct GridPyramidOptions {
  std::int32_t tile_cells = 128;  // grid cells per tile side at every zoom
  std::int32_t max_zoom = -1;     // -1: as many zooms as needed for one root tile
};

struct PyramidTile {
  TileKey key;
  // The tile's triangles: faces of the level's mesh, ascending (the mesh holds their vertices).
  std::vector<std::uint32_t> faces;
  std::size_t triangleCount() const { return faces.size(); }
  // Vertex k (0 .. 2) of the tile's triangle t, in `mesh`, the level's.
  std::uint32_t corner(const TinMesh& mesh, std::size_t t, std::size_t k) const {
    return mesh.triangle_indices[3 * std::size_t{faces[t]} + k];
  }
  double max_error_m = 0;   // max |mesh - DEM| over the valid pixels the tile covers
  double rms_error_m = 0;
  std::size_t measured_pixels = 0;
  // Cluster levels: max |content - the next finer zoom's surface| over the pixels both cover,
  // so that where a viewer draws both (overlapping contents) they agree within the
  // geometricError (0 for the finest zoom and the grid pyramid).
  double finer_difference_m = 0;
};

struct PyramidLevel {
  std::int32_t zoom = 0;
  std::int32_t step = 1;        // pixels between samples
  std::int32_t tile_pixels = 0; // pixels per tile side
  TinMesh mesh;                 // the whole level
  std::vector<PyramidTile> tiles;  // only tiles with at least one triangle
  double max_error_m = 0;
  double rms_error_m = 0;
};

struct GridPyramid {
  std::vector<PyramidLevel> levels;  // levels[z] is zoom z; levels[0] is the root
};

GridPyramid buildGridPyramid(const DemGrid& dem, const GridPyramidOptions& options,
                             Progress& progress);

}  // namespace terratiles
