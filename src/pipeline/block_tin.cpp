#include "src/pipeline/block_tin.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "src/base/block_record.h"
#include "src/base/error.h"
#include "src/geo/dem_on_globe.h"
#include "src/tin/build_tin.h"

namespace terratiles {
namespace {

std::vector<std::int64_t> borders(std::int64_t length, std::int64_t block) {
  std::vector<std::int64_t> out{0};
  if (length <= 2) {
    out.push_back(std::max<std::int64_t>(length - 1, 0));
    return out;
  }
  // A border every `block` pixels, but none within 2 pixels of the far edge (the last block
  // keeps at least 2 x 2 pixels).
  for (std::int64_t p = block; p < length - 2; p += block) out.push_back(p);
  out.push_back(length - 1);
  return out;
}

// The valid pixels of a block's window outside the block (the pixel around it).
std::size_t apronValidPixels(const BlockGround& ground) {
  const DemGrid& dem = ground.dem;
  std::size_t count = 0;
  for (std::int32_t y = 0; y < dem.height; ++y) {
    for (std::int32_t x = 0; x < dem.width; ++x) {
      const bool inside = x >= ground.box.x0 && x <= ground.box.x1 && y >= ground.box.y0 && y <= ground.box.y1;
      if (!inside && dem.isValid(x, y)) ++count;
    }
  }
  return count;
}

}  // namespace

BlockGrid regularBlockGrid(std::int64_t width, std::int64_t height, std::int32_t block_pixels) {
  if (block_pixels < 2) {
    throw Error(ErrorCode::Usage, "--block-pixels is " + std::to_string(block_pixels) + "; expected at least 2");
  }
  return {borders(width, block_pixels), borders(height, block_pixels)};
}

BlockGround readBlock(const DemMosaic& mosaic, const BlockGrid& grid, std::size_t column, std::size_t row,
                      const GeoidGrid* geoid) {
  TERRATILES_ASSERT(column < grid.columnCount() && row < grid.rowCount());
  const std::int64_t c0 = grid.cols[column], c1 = grid.cols[column + 1];
  const std::int64_t r0 = grid.rows[row], r1 = grid.rows[row + 1];
  // One pixel around the block where the mosaic has one (a neighbour's side of the border).
  const std::int64_t w0 = std::max<std::int64_t>(c0 - 1, 0), w1 = std::min(c1 + 1, mosaic.width - 1);
  const std::int64_t h0 = std::max<std::int64_t>(r0 - 1, 0), h1 = std::min(r1 + 1, mosaic.height - 1);
  BlockGround ground;
  ground.column = column;
  ground.row = row;
  ground.window = {w0, h0, static_cast<std::int32_t>(w1 - w0 + 1), static_cast<std::int32_t>(h1 - h0 + 1)};
  ground.dem = readDemWindow(mosaic, ground.window);
  ground.globe = std::make_unique<DemOnGlobe>(ground.dem, geoid, nullptr);
  ground.box = {static_cast<std::int32_t>(c0 - w0), static_cast<std::int32_t>(r0 - h0),
                static_cast<std::int32_t>(c1 - w0), static_cast<std::int32_t>(r1 - h0)};
  if (column > 0) ground.shared_sides |= TinOptions::kWestSide;
  if (column + 1 < grid.columnCount()) ground.shared_sides |= TinOptions::kEastSide;
  if (row > 0) ground.shared_sides |= TinOptions::kNorthSide;
  if (row + 1 < grid.rowCount()) ground.shared_sides |= TinOptions::kSouthSide;
  return ground;
}

BlockTin buildBlockTin(const BlockGround& ground, const BlockTinOptions& options) {
  const DemGrid& dem = ground.dem;
  BlockTin out;
  out.column = ground.column;
  out.row = ground.row;
  out.window = ground.window;
  TinOptions tin;
  tin.max_error_m = options.max_error_m;
  tin.block_pixels = options.window_pixels;
  tin.globe = ground.globe.get();
  tin.region = ground.box;
  tin.shared_sides = ground.shared_sides;
  Progress quiet;
  ConstrainedTin built = buildConstrainedTin(dem, tin, {}, quiet);
  out.mesh = std::move(built.mesh);
  out.outline_repairs = built.shared_outline_repairs;
  out.outline_misses = built.shared_outline_misses;
  if (options.measure && out.mesh.triangleCount() > 0) {
    std::vector<EcefPoint> ecef(out.mesh.vertices.size());
    ground.globe->place(out.mesh.vertices, {}, ecef);
    out.errors = measureTin(*ground.globe, out.mesh, ecef);
    out.errors.uncovered_valid_pixels -= std::min(apronValidPixels(ground), out.errors.uncovered_valid_pixels);
  }
  return out;
}

BlockTin buildBlockTin(const DemMosaic& mosaic, const BlockGrid& grid, std::size_t column, std::size_t row,
                       const BlockTinOptions& options) {
  return buildBlockTin(readBlock(mosaic, grid, column, row, options.geoid), options);
}

std::vector<Level> buildBlockLevels(const BlockGround& ground, BlockTin tin, LevelOptions options) {
  options.globe = ground.globe.get();
  Progress quiet;
  if (tin.mesh.triangleCount() == 0) return {};
  std::vector<Level> levels = buildLevels(ground.dem, std::move(tin.mesh), options, {}, quiet);
  // The pixel around the block is not the block's to cover.
  const std::size_t apron = apronValidPixels(ground);
  for (Level& level : levels) level.error.uncovered_valid_pixels -= std::min(apron, level.error.uncovered_valid_pixels);
  return levels;
}

namespace {

constexpr char kBlockMagic[8] = {'T', 'T', 'B', 'L', 'O', 'C', 'K', '1'};

}  // namespace

void prepareBlocksFolder(const std::filesystem::path& dir, const std::string& manifest, bool resume,
                         const std::string& inside, const std::string& run, Progress& progress) {
  const std::filesystem::path manifest_path = dir / "manifest.json";
  std::error_code ec;
  if (std::filesystem::exists(manifest_path, ec)) {
    if (resume) {
      if (readRecordFile(manifest_path.string()) != manifest) {
        throw Error(ErrorCode::Usage, dir.string() + " holds the blocks of another " + run + " (other inputs, options or "
                                      "version); run without --resume to start again");
      }
      return;
    }
    progress.note("an interrupted " + run + "'s blocks in " + dir.string() + " were dropped (--resume continues them)");
  }
  std::filesystem::remove_all(dir, ec);
  std::filesystem::create_directories(inside.empty() ? dir : dir / inside, ec);
  if (ec) {
    throw Error(ErrorCode::Output, dir.string() + ": cannot create the folder of the block files (" + ec.message() +
                                       "); check that the output's folder is writable");
  }
  writeRecordFile(manifest_path.string(), manifest);
}

void writeBlockTinFile(const BlockTin& block, const std::string& path) {
  RecordWriter out;
  out.bytes.assign(kBlockMagic, sizeof kBlockMagic);
  out.put(static_cast<std::uint64_t>(block.column));
  out.put(static_cast<std::uint64_t>(block.row));
  out.put(block.window.col0);
  out.put(block.window.row0);
  out.put(block.window.width);
  out.put(block.window.height);
  out.putArray(block.mesh.vertices);
  out.putArray(block.mesh.triangle_indices);
  const TinErrorStatistics& e = block.errors;
  for (const double value : {e.max_error_m, e.rms_error_m}) out.put(value);
  for (const std::size_t value : {e.measured_pixels, e.uncovered_valid_pixels, e.covered_nodata_pixels,
                                  e.degenerate_triangles, block.outline_repairs, block.outline_misses}) {
    out.put(static_cast<std::uint64_t>(value));
  }
  writeRecordFile(path, out.bytes);
}

BlockTin readBlockTinFile(const std::string& path) {
  const std::string bytes = readRecordFile(path);
  RecordReader reader{path, bytes};
  reader.expectMagic(kBlockMagic);
  BlockTin block;
  block.column = reader.get<std::uint64_t>();
  block.row = reader.get<std::uint64_t>();
  block.window.col0 = reader.get<std::int64_t>();
  block.window.row0 = reader.get<std::int64_t>();
  block.window.width = reader.get<std::int32_t>();
  block.window.height = reader.get<std::int32_t>();
  block.mesh.vertices = reader.getArray<GridPoint>();
  block.mesh.triangle_indices = reader.getArray<std::uint32_t>();
  TinErrorStatistics& e = block.errors;
  e.max_error_m = reader.get<double>();
  e.rms_error_m = reader.get<double>();
  e.measured_pixels = reader.get<std::uint64_t>();
  e.uncovered_valid_pixels = reader.get<std::uint64_t>();
  e.covered_nodata_pixels = reader.get<std::uint64_t>();
  e.degenerate_triangles = reader.get<std::uint64_t>();
  block.outline_repairs = reader.get<std::uint64_t>();
  block.outline_misses = reader.get<std::uint64_t>();
  reader.expectEnd();
  if (block.mesh.triangle_indices.size() % 3 != 0) reader.damaged();
  for (const std::uint32_t index : block.mesh.triangle_indices) {
    if (index >= block.mesh.vertices.size()) reader.damaged();
  }
  return block;
}

std::vector<std::uint32_t> BlockVertexNumbering::number(
    std::size_t column, std::size_t block_row, const PixelWindow& window, const std::vector<GridPoint>& vertices,
    const BlockGrid& grid, const std::function<std::uint32_t(double, double, double)>& add) {
  if (block_row != current_row_) {
    // The borders above this block row are done with.
    const std::int64_t first_row = grid.rows[block_row];
    std::erase_if(shared_, [&](const auto& entry) { return static_cast<std::int64_t>(entry.first >> 32) < first_row; });
    current_row_ = block_row;
  }
  const std::int64_t c0 = grid.cols[column], c1 = grid.cols[column + 1];
  const std::int64_t r0 = grid.rows[block_row], r1 = grid.rows[block_row + 1];
  std::vector<std::uint32_t> numbers(vertices.size());
  for (std::size_t v = 0; v < numbers.size(); ++v) {
    const GridPoint& p = vertices[v];
    // Mosaic pixel coordinates: exact (whole offsets plus window positions, which a coarser
    // level may have moved off the pixel centres inside the block; never on its outline).
    const double col = static_cast<double>(window.col0) + p.col;
    const double row = static_cast<double>(window.row0) + p.row;
    const bool on_border = ((col == static_cast<double>(c0) || col == static_cast<double>(c1)) && row == std::round(row)) ||
                           ((row == static_cast<double>(r0) || row == static_cast<double>(r1)) && col == std::round(col));
    if (!on_border) {
      numbers[v] = add(col, row, p.height_m);
      continue;
    }
    const std::uint64_t key = (static_cast<std::uint64_t>(row) << 32) | static_cast<std::uint64_t>(col);  // whole
    const auto found = shared_.find(key);
    if (found != shared_.end()) {
      numbers[v] = found->second;
    } else {
      numbers[v] = add(col, row, p.height_m);
      shared_.emplace(key, numbers[v]);
    }
  }
  return numbers;
}

}  // namespace terratiles
