#pragma once
// The finest TIN of a mosaic too large to hold, built block by block (issue 16's blocks, first
// stage): the mosaic is cut into blocks along whole pixel columns and rows; a block reads only
// its pixels and one pixel around them (readDemWindow), places them on the globe, and builds
// its TIN with its outline fixed: the outline polylines are chosen in 1D from the border's own
// pixels and their neighbours (TinOptions::region), so the block on the other side of a border,
// built on its own, in another process or another day, chooses the same polyline, and the two
// meshes meet vertex for vertex without talking. Memory: one block's pixels (4 bytes each, plus
// 8 on the globe for a longitude/latitude DEM or 48 for a projected one) and its TIN.
//
// Vertices carry positions in the block's own grid (its window of the mosaic) and are placed
// from the mosaic's corner, so a vertex on a border has the same pixel position and height,
// bit for bit, in both blocks (BlockVertexNumbering stitches on that).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "formats/dem/read_dem.h"
#include "src/base/progress.h"
#include "src/geo/dem_on_globe.h"
#include "src/geo/geoid.h"
#include "src/lod/build_levels.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

// Where the blocks' borders lie: block (i, j) spans mosaic columns cols[i]..cols[i + 1] and
// rows rows[j]..rows[j + 1], inclusive, so the pixels of a border belong to both blocks.
struct BlockGrid {
  std::vector<std::int64_t> cols;
  std::vector<std::int64_t> rows;
  std::size_t columnCount() const { return cols.size() - 1; }
  std::size_t rowCount() const { return rows.size() - 1; }
  std::size_t blockCount() const { return columnCount() * rowCount(); }
};

// Borders every `block_pixels` pixels from the mosaic's north-west corner (the last block takes
// what is left, at least 2 pixels; a side of 2 or fewer pixels is one block).
BlockGrid regularBlockGrid(std::int64_t width, std::int64_t height, std::int32_t block_pixels);

// A block's pixels: its window of the mosaic (the block and one pixel around it) on the globe,
// and where the block lies in it.
struct BlockGround {
  std::size_t column = 0, row = 0;  // the block's place in the BlockGrid
  PixelWindow window;               // the pixels read
  DemGrid dem;                      // the window's heights, placed from the mosaic's corner
  std::unique_ptr<DemOnGlobe> globe;
  TinOptions::Box box;              // the block in the window's grid
  std::uint8_t shared_sides = 0;    // TinOptions::shared_sides: where another block lies
};

// Reads block (column, row) of `grid` and places it on the globe (heights orthometric on
// `geoid`, or ellipsoidal when nullptr). Error(Input) as readDemWindow and DemOnGlobe.
BlockGround readBlock(const DemMosaic& mosaic, const BlockGrid& grid, std::size_t column, std::size_t row,
                      const GeoidGrid* geoid);

struct BlockTinOptions {
  double max_error_m = 0.5;
  const GeoidGrid* geoid = nullptr;  // heights orthometric on this geoid; nullptr: ellipsoidal
  std::int32_t window_pixels = 128;  // TinOptions::block_pixels inside a block
  bool measure = true;               // measure the block's TIN on its pixels (BlockTin::errors)
};

struct BlockTin {
  std::size_t column = 0, row = 0;  // the block's place in the BlockGrid
  PixelWindow window;               // the pixels read: the block and one pixel around it
  TinMesh mesh;                     // in the window's grid (col, row relative to window.col0/row0)
  // Against the DEM on the globe, over the valid pixels the block's triangles cover (a border's
  // pixels are measured by both blocks); uncovered_valid_pixels counts the block's own pixels
  // only (not the pixel around it).
  TinErrorStatistics errors;
  // Pixels of its shared sides a triangle missed: repaired inside, or (misses) left over the
  // bound (ConstrainedTin).
  std::size_t outline_repairs = 0;
  std::size_t outline_misses = 0;
};

// Triangulates a block read by readBlock (options.geoid is not used: the ground has its globe).
BlockTin buildBlockTin(const BlockGround& ground, const BlockTinOptions& options);
// readBlock, then the above. Error(Input) as readDemWindow and DemOnGlobe (a pixel outside
// the geoid grid, no path to WGS84).
BlockTin buildBlockTin(const DemMosaic& mosaic, const BlockGrid& grid, std::size_t column, std::size_t row,
                       const BlockTinOptions& options);

// The cluster levels of detail of a block (buildLevels on its TIN, on its ground): its outline
// is the mesh's outer border, locked at every level, so every level of two neighbouring blocks
// still meets vertex for vertex. Level 0 holds the block's TIN. Cluster borders inside the block
// move from level to level as in a whole build; the block borders stay: what they cost is
// measured by `terratiles levels --block-pixels` against the whole build.
std::vector<Level> buildBlockLevels(const BlockGround& ground, BlockTin tin, LevelOptions options);

// Rank 0's preparation of the folder of a run in blocks: kept for --resume when its
// manifest.json holds `manifest` (the inputs and every option the blocks depend on; with
// --resume and another manifest: Error(Usage), naming `run`, "run" or "build"), else emptied
// (said on `progress` when it held an interrupted run's blocks) and made again with the
// manifest and the folder `inside` (empty: none). Error(Output) when it cannot be written.
void prepareBlocksFolder(const std::filesystem::path& dir, const std::string& manifest, bool resume,
                         const std::string& inside, const std::string& run, Progress& progress);

// A block's TIN as a file, the unit a resumed or multi-process run keeps and hands over:
// binary, every number as in memory (doubles bit for bit), written through path + ".tmp" and
// renamed when complete, so a file that exists is whole. readBlockTinFile throws
// Error(Input) naming the file when it is not one (damaged, another version).
void writeBlockTinFile(const BlockTin& block, const std::string& path);
BlockTin readBlockTinFile(const std::string& path);

// Numbers the vertices of blocks handed over in row-major block order as one mesh: a vertex on
// a block border gets the number it got in the block before (found by its mosaic pixel), every
// other vertex a new one. Holds only the vertices of borders whose other block is still to
// come (the block row above and the block to the west).
class BlockVertexNumbering {
 public:
  // Per vertex of a block's mesh: its number in the whole mesh. `add(mosaic_col, mosaic_row,
  // height)` is called for every new vertex, in order, and returns its number (positions in
  // mosaic pixels: whole on the outline and in a TIN, anywhere inside the block on a coarser
  // level whose collapses moved vertices).
  // `vertices` are those of block (column, row), in its window's grid.
  std::vector<std::uint32_t> number(std::size_t column, std::size_t row, const PixelWindow& window,
                                    const std::vector<GridPoint>& vertices, const BlockGrid& grid,
                                    const std::function<std::uint32_t(double, double, double)>& add);

 private:
  std::unordered_map<std::uint64_t, std::uint32_t> shared_;  // key: mosaic row << 32 | column
  std::size_t current_row_ = 0;
};

}  // namespace terratiles
