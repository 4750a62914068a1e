#pragma once
// buildTin: DEM -> TIN by greedy insertion (Garland & Heckbert 1995, "Terra"; the algorithm
// of tin-terrain and Delatin; paper section 3.2.1).
//
// Starts from two triangles over the grid's corner pixels and repeatedly inserts the pixel
// with the largest vertical error |TIN(p) - DEM(p)| into a Delaunay triangulation (edge
// flips restore Delaunay after every insertion), until every pixel is within
// options.max_error_m. Each triangle keeps its worst pixel as its candidate (only the
// triangles an insertion changed are rescanned), and a max-heap orders the candidates.
// Vertices sit on pixel centres (GridPoint col/row are whole numbers); the result is
// counter-clockwise seen from above (TinMesh's convention).
//
// Guarantee: every pixel of the grid is within max_error_m of the TIN, measured at pixel
// centres by linear interpolation in the triangle containing the pixel.
// Memory: O(pixels) for the candidate bookkeeping plus O(vertices).
// Nodata (NaN) pixels are not supported yet: Error(Input).

#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

struct TinOptions {
  double max_error_m = 0.5;  // vertical error bound, metres (paper: 0.5 m)
};

TinMesh buildTin(const DemGrid& dem, const TinOptions& options, Progress& progress);

}  // namespace terratiles
