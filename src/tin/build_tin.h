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
// Guarantee: every valid pixel inside the TIN is within max_error_m of it, measured at
// pixel centres against the triangle containing the pixel in the grid: on the globe
// (options.globe), from the pixel's DEM point to the triangle's plane in ECEF along the
// pixel's vertical, exactly (measureTin with the globe gives the same numbers); without one,
// by linear interpolation of the heights. On the globe every scan is exact (vectorised, as the
// grid scan); a windowed build's outline polylines are chosen in 1D against the chord, and a
// pixel of them that a window's triangle still misses by more than the bound joins the outline
// (the windows are then built again). Triangles degenerate in ECEF (two corners at a pole) are
// measured in the grid.
// Nodata (NaN): no triangle covers a nodata pixel. Nodata corners become virtual vertices,
// and a triangle covering nodata or a virtual vertex is refined while it holds valid pixels
// other than its vertices, then left out, so the TIN follows holes and ragged borders of
// the valid data to within one pixel (a valid pixel left uncovered touches nodata).
// Memory: O(pixels) for the candidate bookkeeping plus O(vertices).

#include <array>
#include <cstdint>
#include <vector>

#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

class DemOnGlobe;

struct TinOptions {
  double max_error_m = 0.5;  // vertical error bound, metres (paper: 0.5 m)
  // Windowed build: > 0 splits the grid into windows of this many pixels per side. Their
  // shared border polylines are simplified first (to the same bound), every window is
  // triangulated on its own, in parallel (TBB), and the windows are stitched exactly by pixel
  // position. Same guarantee; a few more triangles along the borders; edges on window
  // borders are constrained, not Delaunay. 0: one triangulation of the whole grid.
  // 128 keeps each window's working set in cache: on the 2401 x 1201 SRTM raster at 10 m one
  // core takes 1.16 s (256: 1.45 s, 512: 1.60 s, one triangulation: about 2x the 256 time)
  // for 0.01 % fewer triangles than Delatin's single triangulation; 64 is faster still but
  // adds 2 % triangles at 20 m on N57E011.
  std::int32_t block_pixels = 128;
  // A block of a larger TIN (src/pipeline/block_tin.h): only the pixels of this box of the
  // grid (columns x0..x1, rows y0..y1, inclusive) are triangulated; the grid holds the box and,
  // where the box has a neighbour, one pixel around it (for the slope across the outline).
  // The box's outline is always fixed, chosen in 1D from its own pixels and their neighbours
  // (windowed as above, windows counted from the box's corner), so the block on the other
  // side, built on its own, chooses the same polyline. An empty box (x1 < x0): the whole grid.
  struct Box {
    std::int32_t x0 = 0, y0 = 0, x1 = -1, y1 = -1;
    bool empty() const { return x1 < x0 || y1 < y0; }
  };
  Box region{};
  // Sides of `region` a neighbouring block shares (kWestSide | kNorthSide | ...): their
  // polylines never change. On the globe, a pixel of one that a triangle as drawn misses by
  // more than the bound (rare: the 1D choice cannot see a triangle's cross slope) is repaired
  // inside the block: the pixels next to it on the inner side become vertices. Other sides
  // take such a pixel into their polyline, as window borders do.
  std::uint8_t shared_sides = 0;
  static constexpr std::uint8_t kWestSide = 1, kNorthSide = 2, kEastSide = 4, kSouthSide = 8;
  // The DEM on the globe (for the DEM that is built): the error is measured on the triangle as
  // a renderer draws it, straight in ECEF, along each pixel's vertical (DemOnGlobe), so long
  // edges over flat ground are refined where their sag would break the bound. nullptr: in
  // the grid frame, heights interpolated linearly (a flat earth, for experiments and tests).
  const DemOnGlobe* globe = nullptr;
};

// A break line piece between two pixel centres (col, row) of the grid, e.g. part of a road or
// a building outline snapped to the grid (formats/vector/read_constraints.h makes them).
struct PixelSegment {
  std::int32_t col0 = 0, row0 = 0, col1 = 0, row1 = 0;
};

struct ConstrainedTin {
  TinMesh mesh;
  // The constrained edges as vertex pairs, each an edge of the mesh. A segment becomes a
  // chain of them where a vertex lies on it (another segment's end, a window border vertex,
  // or a pixel the greedy insertion added on it).
  std::vector<std::array<std::uint32_t, 2>> constrained_edges;
  // Crossings of two segments away from a pixel centre: both are bent through the pixel
  // nearest the crossing (under a pixel off their lines)...
  std::size_t segments_bent = 0;
  // ... or, of those, where no pixel around the crossing could take a vertex (nodata, or a
  // window border), the later segment is bent through the crossed edge's nearer end.
  std::size_t segments_bent_to_end = 0;
  // Segments, or pieces of them, left out: over nodata or out of the grid (counted by the
  // reader), or whose edge fell in a triangle over nodata (counted here).
  std::size_t edges_dropped = 0;
  // A block's shared-side pixels (TinOptions::shared_sides) that a triangle as drawn still
  // missed by more than the bound after 16 rounds of repair: left so (the TIN's measure shows
  // their error), since the polyline the neighbour shares cannot change.
  std::size_t shared_outline_misses = 0;
  // Of those pixels, how many were missed at all (and repaired by vertices next to them).
  std::size_t shared_outline_repairs = 0;
};

// Greedy insertion with break lines: every segment is inserted as a constrained edge (a
// constrained Delaunay triangulation: no flip ever removes it) before any error-driven
// insertion, so the same error guarantee holds and every segment is a chain of TIN edges.
// Segments are split at the window borders of a windowed build (the crossing snapped to the
// nearest border pixel, which both windows take as a border vertex) and where they cross
// each other away from a pixel centre (see segments_bent; after 8 bends per segment of a
// window, further crossings drop the later segment, counted in edges_dropped). Each segment's two ends must be
// valid pixels of the grid.
ConstrainedTin buildConstrainedTin(const DemGrid& dem, const TinOptions& options,
                                   const std::vector<PixelSegment>& segments, Progress& progress);

TinMesh buildTin(const DemGrid& dem, const TinOptions& options, Progress& progress);

}  // namespace terratiles
