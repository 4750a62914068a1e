#pragma once
// `terratiles build` in blocks (issue 16): the mosaic is cut along the tiles of one zoom Zb
// (a block is one tile of Zb, cut along the pixel rows and columns nearest its edges) and
// each block is built on its own, reading only its pixels and one pixel around them:
//
//   1. every block's TIN, its outline fixed from the border's own pixels (block_tin.h), so
//      neighbouring blocks meet vertex for vertex; the TINs wait in OUTDIR.blocks/ while
//      their triangle counts choose the zooms (planZooms, as the whole build does);
//   2. every block's levels of detail from the finest zoom down to Zb (the paper's method
//      inside the block: METIS clusters re-partitioned every level, the block's outline
//      locked), its clusters assigned to the tiles below its own tile (TileFrame::keepInside),
//      and the tiles of zooms Zb + 1 and finer drawn, measured against the block's pixels,
//      encoded and written. The block hands over only its level at Zb;
//   3. the handed-over levels, stitched by their border vertices, are the finest level of
//      the rest of the pyramid: re-partitioned as one mesh (so the block borders, locked so
//      far, move as the paper's re-partition wants), simplified to the coarsest zoom and
//      written as the whole build writes its zooms.
//
// Errors are measured as in the whole build (on the drawn, quantised triangles against every
// DEM pixel under them and against the next finer zoom's drawn surface), so `terratiles check`
// confirms them. Quantisation: one grid per zoom from the size of its tiles (known before any
// tile is made, so every block snaps a shared vertex alike); the zooms from Zb up share the
// coarsest of their grids, and a vertex on a zoom Zb + 1 tile outline that lives on in level
// Zb takes it too, so the tiles written by blocks and those written after meet bit for bit.
//
// Memory: steps 1 and 2 hold one block (its pixels, TIN and levels); step 3 holds the zoom Zb
// level of every block and, for now, the whole DEM to measure the coarse zooms against (what
// stands between this and a build in bounded memory: see the README's "Country scale").

#include <cstdint>

#include "formats/dem/read_dem.h"
#include "src/base/progress.h"
#include "src/pipeline/run_pipeline.h"

namespace terratiles {

// Pixels per block side when BuildOptions::block_pixels is 0 and the mosaic is larger than
// kBuildBlocksAbovePixels.
inline constexpr std::int32_t kBuildBlockPixels = 2048;
inline constexpr std::int64_t kBuildBlocksAbovePixels = 64'000'000;

// The largest tile side of the block zoom, in pixels, that a build of `mosaic` with `options`
// uses: 0 (the whole mosaic at once) or a block size.
std::int32_t buildBlockPixels(const BuildOptions& options, const DemMosaic& mosaic);

// The build in blocks of at most `block_pixels` pixels a side. Error(Usage) when the scheme's
// tiles do not follow the DEM's rows and columns (a projected DEM under a web scheme: use
// --scheme local, or reproject the DEM to EPSG:4326) or an option has no block form yet.
BuildSummary runBlockedPipeline(const BuildOptions& options, const DemMosaic& mosaic, std::int32_t block_pixels,
                                Progress& progress);

}  // namespace terratiles
