#include "tools/terratiles/run_cli.h"

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>
#include <algorithm>
#include <csignal>
#include <cstring>
#include <cstdlib>
#include <cerrno>
#include <cstdio>
#include <exception>
#include <charconv>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <istream>
#include <optional>
#include <ostream>
#include <sstream>

#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/base/ranks.h"
#include "src/base/version.h"
#include "src/geo/point_transform.h"
#include "src/pipeline/run_pipeline.h"
#include "formats/dem/dem_inputs.h"
#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/output_directory.h"
#include "formats/tin/tin_file.h"
#include "formats/vector/read_break_lines.h"
#include "src/pipeline/block_tin.h"
#include "src/pipeline/build_report.h"
#include "src/pipeline/check_output.h"
#include "src/lod/build_levels.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "src/geo/dem_on_globe.h"

namespace terratiles {
namespace {

constexpr const char* kExitCodes =
    "Exit codes: 0 ok, 1 internal error, 2 usage, 3 bad input, 4 output not writable, "
    "6 out of memory, 130 interrupted (check: 5 a violation).";

// What a build needs (tools/bench/README.md: 118-119 bytes per pixel on Gabon, ETOPO5 and
// SRTM N57E011; small rasters are fixed cost, 83-96 MB, of which about 40 MB is the process).
constexpr const char* kOutOfMemory =
    "out of memory; a build needs about 120 bytes per input pixel at its peak (at least about 90 MB): split the input "
    "into smaller rasters (gdal_translate -srcwin) or raise --tin-max-error; with --lod grid, lower --tile-cells";

extern "C" void onInterrupt(int) { Progress::requestCancel(); }

// Installs the SIGINT handler for the duration of one command.
class InterruptGuard {
 public:
  InterruptGuard() {
    Progress::resetCancel();
    previous_ = std::signal(SIGINT, onInterrupt);
  }
  ~InterruptGuard() { std::signal(SIGINT, previous_); }

 private:
  void (*previous_)(int);
};

std::string humanBytes(std::size_t bytes) {
  std::ostringstream text;
  text.imbue(std::locale::classic());
  text << std::fixed << std::setprecision(1);
  if (bytes >= (1u << 20)) {
    text << static_cast<double>(bytes) / (1u << 20) << " MiB";
  } else {
    text << static_cast<double>(bytes) / 1024.0 << " KiB";
  }
  return text.str();
}

// `terratiles serve`: runs samples/viewer/serve.mjs on OUTDIR through node, in place of this
// process (it prints the URL and serves until interrupted). Everything it needs is checked
// first, each with its fix.
[[noreturn]] void serveOutput(const std::string& output_dir, int port) {
  namespace fs = std::filesystem;
  if (!fs::exists(fs::path(output_dir) / "tileset.json")) {
    throw Error(ErrorCode::Input, output_dir + " has no tileset.json; expected an output of terratiles build");
  }
  const char* override_dir = std::getenv("TERRATILES_VIEWER_DIR");
  const fs::path viewer = override_dir && *override_dir ? fs::path(override_dir) : fs::path(kViewerDir);
  if (!fs::exists(viewer / "serve.mjs")) {
    throw Error(ErrorCode::Input, "the viewer is not at " + viewer.string() +
                                      " (no serve.mjs); set TERRATILES_VIEWER_DIR to a samples/viewer directory");
  }
  if (!fs::exists(viewer / "node_modules/cesium/Build/Cesium/Cesium.js")) {
    throw Error(ErrorCode::Input, "the viewer at " + viewer.string() + " has no CesiumJS installed; run (cd " +
                                      viewer.string() + " && npm ci)");
  }
  std::string node;
  const char* path_variable = std::getenv("PATH");
  std::istringstream path_list(path_variable ? path_variable : "");
  for (std::string entry; node.empty() && std::getline(path_list, entry, ':');) {
    if (!entry.empty() && access((fs::path(entry) / "node").c_str(), X_OK) == 0) node = (fs::path(entry) / "node").string();
  }
  if (node.empty()) throw Error(ErrorCode::Input, "node (Node.js) is not on PATH; install it (apt-get install nodejs)");
  std::vector<std::string> args{node, (viewer / "serve.mjs").string(), output_dir, "--port", std::to_string(port)};
  std::vector<char*> argv;
  for (std::string& arg : args) argv.push_back(arg.data());
  argv.push_back(nullptr);
  std::fflush(nullptr);
  execv(node.c_str(), argv.data());
  throw Error(ErrorCode::Internal, "could not start " + node + ": " + std::strerror(errno));
}

// The summary as one JSON line (--progress json): the last line a machine reads.
void printJsonSummary(const BuildSummary& s, std::ostream& err) {
  nlohmann::json j;
  j["event"] = "summary";
  j[s.format == OutputFormat::QuantizedMesh ? "layer" : "tileset"] = s.output_dir + "/" + s.entry_file;
  j["format"] = outputFormatName(s.format);
  j["report"] = s.report_path;
  j["tiles"] = s.tiles;
  j["triangles"] = s.triangles;
  j["bytes"] = s.tile_bytes;        // the tiles
  j["bytes_written"] = s.bytes;     // every file, reports included
  const bool terrain = isTerrainLayer(s.format);
  j["worst_error_m"] = s.worst_error_m;
  if (terrain) j["fill"] = s.terrain_fill;
  j["seconds"] = s.seconds;
  if (!s.blocks.empty()) j["blocks"] = s.blocks;
  j["check"] = s.check_ran ? (s.check_ok ? "ok" : "failed") : "not run";
  err << j.dump() << "\n" << std::flush;
}

void printSummary(const BuildSummary& s, std::ostream& err) {
  std::ostringstream text;
  text.imbue(std::locale::classic());
  text << std::fixed;
  text << "terratiles: built " << s.output_dir << "/" << s.entry_file << "\n";
  text << "  input    " << s.width << " x " << s.height << " px, " << std::setprecision(6)
       << s.pixel_size << " " << s.crs_name << ", heights " << std::setprecision(1)
       << s.min_height_m << " .. " << s.max_height_m << " m, centre " << std::setprecision(5)
       << s.centre_lat_deg << " N " << s.centre_lon_deg << " E\n";
  text << "  placed   " << s.placement << "; geoid " << s.geoid << "\n";
  if (!s.blocks.empty()) text << "  blocks   " << s.blocks << "\n";
  for (const std::string& warning : s.warnings) text << "  warning  " << warning << "\n";
  if (isTerrainLayer(s.format)) {
    text << "  zoom  tiles   triangles  tile triangles        bytes  B/tri   max err m   rms err m  client err m\n";
    for (const ZoomSummary& z : s.zooms) {
      text << "  " << std::setw(4) << z.zoom << std::setw(7) << z.tiles << std::setw(12) << z.triangles << std::setw(16)
           << z.tile_triangles << std::setw(13) << z.bytes << std::setprecision(2) << std::setw(7)
           << (z.tile_triangles ? static_cast<double>(z.bytes) / static_cast<double>(z.tile_triangles) : 0.0)
           << std::setprecision(3) << std::setw(12) << z.max_error_m << std::setw(12) << z.rms_error_m
           << std::setprecision(1) << std::setw(14) << z.geometric_error_m << "\n";
    }
    text << "  total " << s.tiles << " tiles ("
         << (s.format == OutputFormat::QuantizedMesh ? "gzip'd quantized-mesh" : "3D Tiles terrain, meshopt GLB")
         << ", the whole globe at zoom 0), "
         << humanBytes(s.tile_bytes) << ", worst measured error " << std::setprecision(2) << s.worst_error_m
         << " m, " << s.seconds << " s\n";
    text << "  fill     " << s.terrain_fill << "\n";
    text << "  errors   each zoom's level against the DEM (as drawn, every valid pixel; the fill is not "
            "measured); client err: what CesiumJS's terrain providers assume; no report\n";
    err << text.str() << std::flush;
    return;
  }
  text << "  zoom clusters  tiles   triangles  redundancy        bytes  B/tri  step mm   max err m   rms err m  geomError m\n";
  std::size_t tile_triangles = 0;
  for (const ZoomSummary& z : s.zooms) {
    tile_triangles += z.tile_triangles;
    text << "  " << std::setw(4) << z.zoom << std::setw(9) << (z.step_pixels ? z.step_pixels : z.clusters) << std::setw(7)
         << z.tiles << std::setw(12) << z.triangles << std::setw(12) << std::setprecision(3)
         << (z.triangles ? static_cast<double>(z.tile_triangles) / static_cast<double>(z.triangles) : 0.0)
         << std::setw(13) << z.bytes << std::setprecision(2) << std::setw(7)
         << (z.tile_triangles ? static_cast<double>(z.bytes) / static_cast<double>(z.tile_triangles) : 0.0)
         << std::setprecision(1) << std::setw(9) << z.position_step_m * 1000
         << std::setprecision(3) << std::setw(12) << z.max_error_m << std::setw(12)
         << z.rms_error_m << std::setw(13) << z.geometric_error_m << "\n";
  }
  text << "  total " << s.tiles << " tiles, " << s.triangles << " triangles, "
       << humanBytes(s.tile_bytes) << " of tiles (" << std::setprecision(2)
       << (tile_triangles ? static_cast<double>(s.tile_bytes) / static_cast<double>(tile_triangles) : 0.0)
       << " B per tile triangle, finest step " << std::setprecision(1) << s.position_step_m * 1000
       << " mm), worst measured error " << std::setprecision(2)
       << s.worst_error_m << " m, " << s.seconds << " s\n";
  if (s.check_ran) {
    text << "  check    " << (s.check_ok ? "ok: seamless and honest errors" : "FAILED: see the report's check section")
         << "\n";
  }
  if (!s.report_path.empty()) text << "  report   " << s.report_path << "\n";
  text << "  view it: terratiles serve " << s.output_dir << "  (then open the printed URL)\n";
  err << text.str() << std::flush;
}

// Parses "x y [z]" (separated by blanks or commas) without the locale; false otherwise.
bool parsePointLine(const std::string& line, Point3& point) {
  double values[3] = {0, 0, 0};
  int count = 0;
  const char* p = line.data();
  const char* end = line.data() + line.size();
  while (p < end) {
    while (p < end && (*p == ' ' || *p == '\t' || *p == ',' || *p == '\r')) ++p;
    if (p == end) break;
    if (count == 3) return false;
    const auto [next, ec] = std::from_chars(p, end, values[count]);
    if (ec != std::errc() || next == p) return false;
    p = next;
    ++count;
  }
  if (count < 2) return false;
  point = {values[0], values[1], values[2]};
  return true;
}

// `terratiles transform`: "x y [z]" lines on `in` to transformed "x y z" lines on `out`.
// Blank lines and lines starting with '#' pass through unchanged.
void runTransform(const std::string& from, const std::string& to, const std::string& geoid_path,
                  std::istream& in, std::ostream& out) {
  std::optional<GeoidGrid> geoid;
  if (!geoid_path.empty()) geoid = readGeoidGrid(geoid_path);
  const PointTransform transform(from, to, geoid ? &*geoid : nullptr);
  const int decimals = transform.targetIsGeographic() ? 12 : 6;
  char buffer[128];
  constexpr std::size_t kBatch = 65536;
  std::vector<std::string> lines;
  std::vector<Point3> points;
  std::vector<std::size_t> point_line;
  std::size_t line_number = 0;
  bool more = true;
  while (more) {
    lines.clear();
    points.clear();
    point_line.clear();
    std::string line;
    while (points.size() < kBatch && (more = static_cast<bool>(std::getline(in, line)))) {
      ++line_number;
      const auto first = line.find_first_not_of(" \t\r");
      if (first != std::string::npos && line[first] != '#') {
        Point3 point;
        if (!parsePointLine(line, point)) {
          throw Error(ErrorCode::Input, "standard input line " + std::to_string(line_number) +
                                            ": expected 'x y [z]' numbers, found '" +
                                            line.substr(0, 60) + "'");
        }
        point_line.push_back(lines.size());
        points.push_back(point);
      }
      lines.push_back(std::move(line));
    }
    transform.transform(points);
    std::size_t next_point = 0;
    for (std::size_t i = 0; i < lines.size(); ++i) {
      if (next_point < point_line.size() && point_line[next_point] == i) {
        const Point3& p = points[next_point++];
        std::snprintf(buffer, sizeof buffer, "%.*f %.*f %.6f\n", decimals, p.x, decimals, p.y, p.z);
        out << buffer;
      } else {
        out << lines[i] << "\n";
      }
    }
  }
  out << std::flush;
}

// What DEM heights are relative to (--heights, --geoid), as build, tin and levels take it:
// every error is measured on the globe, where a geoid turns orthometric heights ellipsoidal.
struct HeightChoice {
  std::string heights = "orthometric";
  std::string geoid_path;  // empty: EGM96

  // The geoid grid, or none for ellipsoidal heights. Throws Error(Usage) for --geoid with
  // --heights ellipsoidal.
  std::optional<GeoidGrid> geoid() const {
    if (heights == "ellipsoidal") {
      if (!geoid_path.empty()) {
        throw Error(ErrorCode::Usage, "--geoid and --heights ellipsoidal exclude each other "
                                      "(a geoid only applies to orthometric heights)");
      }
      return std::nullopt;
    }
    return readGeoidGrid(geoid_path.empty() ? kDefaultGeoidPath : geoid_path);
  }
};

// INPUT... and --input-list, as build, tin and levels take them (see expandDemInputs).
struct InputChoice {
  std::vector<std::string> arguments;
  std::string list_path;
  std::vector<std::string> files() const { return expandDemInputs(arguments, list_path); }
};

void addInputOptions(CLI::App& command, InputChoice& choice) {
  command.add_option("INPUT", choice.arguments,
                     "DEM rasters GDAL reads (GeoTIFF, .hgt, a VRT, ...), any CRS with an EPSG code, or directories "
                     "of them (every .tif, .tiff, .vrt, .hgt, ... file directly inside); adjacent files that share "
                     "CRS, pixel size and lattice are mosaicked, the first valid value winning where they overlap");
  command.add_option("--input-list", choice.list_path,
                     "A text file naming more inputs, one path per line (relative to the current directory; blank "
                     "lines and lines starting with # ignored): for more files than a shell passes as arguments");
}

void addHeightOptions(CLI::App& command, std::string& heights, std::string& geoid_path) {
  command
      .add_option("--heights", heights,
                  "What DEM heights are relative to: orthometric (above a geoid; converted to "
                  "WGS84 ellipsoidal heights with --geoid) or ellipsoidal (used as they are)")
      ->check(CLI::IsMember({"orthometric", "ellipsoidal"}))
      ->capture_default_str();
  command
      .add_option("--geoid", geoid_path,
                  "Geoid grid for orthometric heights, any GDAL raster in lon/lat (e.g. "
                  "CHGeo2004 for LN02 heights) [default: EGM96, /usr/share/proj/egm96_15.gtx]")
      ->check(CLI::ExistingFile);
}

constexpr const char* kSimplifierHelp =
    "Edge-collapse engine inside the clusters: native (terratiles' own over flat arrays with CGAL's quadrics, "
    "filter and greedy order; the default: 1.5-3x faster on SRTM, per-zoom geometricError within +3.2 % of "
    "CGAL's on the test rasters but SRTM N57E011's coarsest zoom, +7 %, within what the partition alone moves "
    "it) or cgal (CGAL's Surface_mesh_simplification: the quality reference)";

void addSimplifierOption(CLI::App& command, std::string& simplifier) {
  command.add_option("--simplifier", simplifier, kSimplifierHelp)
      ->check(CLI::IsMember({"native", "cgal"}))
      ->capture_default_str();
}

constexpr const char* kTailStopHelp =
    "Native engine: a cluster's simplification also stops when fewer than APPLIED of its last TRIES collapse "
    "tries were applied (off, or TRIES,APPLIED). Where the error budget binds, a level's last few per cent of "
    "collapses take about half of its tries: on ETOPO5 at 10 m the default takes a quarter off the "
    "simplification for up to 5 % more triangles per zoom; the budget still holds for every collapse";

void addTailStopOption(CLI::App& command, std::string& tail_stop) {
  command.add_option("--tail-stop", tail_stop, kTailStopHelp)->capture_default_str();
}

Simplifier parseSimplifier(const std::string& name) { return name == "cgal" ? Simplifier::Cgal : Simplifier::Native; }

struct TinCommandOptions {
  std::vector<std::string> inputs;
  std::string output;
  double max_error_m = 0.5;
  std::string constraints;  // break lines (OGR vector file), or empty
  bool force = false;
  HeightChoice heights;
  // Blocks of this many pixels per side, each read and triangulated on its own (bounded
  // memory); 0: blocks of kTinBlockPixels when the mosaic has more than kTinBlocksAbovePixels.
  std::int32_t block_pixels = 0;
  bool resume = false;  // blocks: keep the block files an interrupted run left
  int threads = 0;      // 0: all cores
};

constexpr std::int32_t kTinBlockPixels = 2048;
constexpr std::int64_t kTinBlocksAbovePixels = 64'000'000;

void printTinSummary(std::ostream& err, const std::string& output, const std::string& crs_name, std::uint64_t vertices,
                     std::uint64_t triangles, const TinErrorStatistics& errors, double bound_m, double seconds,
                     const std::string& blocks) {
  char line[640];
  std::snprintf(line, sizeof line,
                "terratiles: wrote %s (%s): %llu vertices, %llu triangles; measured on %zu pixels%s: "
                "max error %.4f m (bound %.4g m), rms %.4f m; %.2f s\n",
                output.c_str(), crs_name.c_str(), static_cast<unsigned long long>(vertices),
                static_cast<unsigned long long>(triangles), errors.measured_pixels, blocks.c_str(), errors.max_error_m,
                bound_m, errors.rms_error_m, seconds);
  err << line << std::flush;
}

// Appends one block's mesh (vertices in its window's grid) to a TIN file of the whole mosaic,
// its border vertices stitched to those of the blocks before it (row-major order).
void appendBlockMesh(TinFileStream& file, BlockVertexNumbering& numbering, const DemMosaic& mosaic,
                     const BlockGrid& grid, std::size_t column, std::size_t row, const PixelWindow& window,
                     const TinMesh& mesh) {
  const std::vector<std::uint32_t> numbers =
      numbering.number(column, row, window, mesh.vertices, grid, [&](double col, double mosaic_row, double height) {
        return file.addVertex({mosaic.origin_x + (col + 0.5) * mosaic.pixel_size,
                               mosaic.origin_y - (mosaic_row + 0.5) * mosaic.pixel_size, height});
      });
  const std::vector<std::uint32_t>& idx = mesh.triangle_indices;
  for (std::size_t t = 0; t < idx.size(); t += 3) file.addTriangle(numbers[idx[t]], numbers[idx[t + 1]], numbers[idx[t + 2]]);
}


// `terratiles tin` on a mosaic cut into blocks (src/pipeline/block_tin.h). Every block's TIN
// is a file in OUTPUT.blocks/ (written whole or not at all), made by rank b mod N of N (one
// rank without mpirun); then rank 0 joins them in row-major order, border vertices stitched,
// into the output file and removes the folder. --resume keeps the block files an interrupted
// run left (same inputs and options, checked against the folder's manifest.json) and makes
// only the others: the file is the same, byte for byte, however many ranks or resumptions.
void runBlockTinCommand(const TinCommandOptions& options, const DemMosaic& mosaic, std::int32_t block_pixels,
                        Progress& progress, bool quiet, std::ostream& err,
                        std::chrono::steady_clock::time_point start) {
  if (!options.constraints.empty()) {
    throw Error(ErrorCode::Usage, "--constraints is not available with blocks yet (the mosaic has " +
                                      std::to_string(mosaic.width * mosaic.height) +
                                      " pixels); pass --block-pixels larger than its sides, or split the input");
  }
  const std::optional<GeoidGrid> geoid = options.heights.geoid();
  const BlockGrid grid = regularBlockGrid(mosaic.width, mosaic.height, block_pixels);
  BlockTinOptions block_options;
  block_options.max_error_m = options.max_error_m;
  block_options.geoid = geoid ? &*geoid : nullptr;
  const std::filesystem::path blocks_dir = options.output + ".blocks";
  const auto blockPath = [&](std::size_t i, std::size_t j) {
    return (blocks_dir / ("block_" + std::to_string(j) + "_" + std::to_string(i) + ".bin")).string();
  };
  nlohmann::json manifest;
  manifest["generator"] = std::string("terratiles ") + kVersion;
  std::vector<std::string> inputs;
  for (const std::string& input : options.inputs) inputs.push_back(std::filesystem::absolute(input).lexically_normal().string());
  manifest["inputs"] = inputs;
  manifest["tin_max_error_m"] = options.max_error_m;
  manifest["block_pixels"] = block_pixels;
  manifest["geoid"] = geoid ? geoid->name : std::string("none (heights are ellipsoidal)");
  const bool leader = Ranks::rank() == 0;
  Progress quiet_progress;
  Progress& shown = leader ? progress : quiet_progress;

  // 1. Rank 0 prepares the folder: kept for --resume when it holds the same work, else new.
  std::exception_ptr failure;
  if (leader) {
    try {
      prepareBlocksFolder(blocks_dir, manifest.dump(2) + "\n", options.resume, "", "run", progress);
    } catch (...) {
      failure = std::current_exception();
    }
  }
  Ranks::meet(failure);

  // 2. Every rank makes its blocks that are not there yet.
  std::size_t reused = 0, mine = 0;
  const auto ranks = static_cast<std::size_t>(Ranks::size()), rank = static_cast<std::size_t>(Ranks::rank());
  for (std::size_t b = rank; b < grid.blockCount(); b += ranks) ++mine;
  shown.beginStage("TIN in " + std::to_string(grid.blockCount()) + " blocks of " + std::to_string(block_pixels) +
                       " pixels (read, greedy insertion, measure)" +
                       (ranks > 1 ? ", " + std::to_string(mine) + " on rank 0 of " + std::to_string(ranks) : std::string()),
                   mine);
  try {
    for (std::size_t b = rank; b < grid.blockCount(); b += ranks) {
      const std::size_t i = b % grid.columnCount(), j = b / grid.columnCount();
      std::error_code ec;
      if (options.resume && std::filesystem::exists(blockPath(i, j), ec)) {
        ++reused;
      } else {
        writeBlockTinFile(buildBlockTin(mosaic, grid, i, j, block_options), blockPath(i, j));
      }
      shown.advance();
    }
    shown.endStage();
  } catch (...) {
    failure = std::current_exception();
  }
  Ranks::meet(failure);
  if (!leader) return;
  if (reused > 0) progress.note("resumed: " + std::to_string(reused) + " of " + std::to_string(mine) + " blocks were done already");

  // 3. Rank 0 joins the blocks.
  TinFileStream file(options.output);
  BlockVertexNumbering numbering;
  TinErrorStatistics errors;
  double sum_squares = 0;
  std::size_t repairs = 0, misses = 0;
  progress.beginStage("joining " + std::to_string(grid.blockCount()) + " blocks into " + options.output,
                      grid.blockCount());
  for (std::size_t j = 0; j < grid.rowCount(); ++j) {
    for (std::size_t i = 0; i < grid.columnCount(); ++i) {
      const BlockTin block = readBlockTinFile(blockPath(i, j));
      appendBlockMesh(file, numbering, mosaic, grid, i, j, block.window, block.mesh);
      errors.max_error_m = std::max(errors.max_error_m, block.errors.max_error_m);
      sum_squares += block.errors.rms_error_m * block.errors.rms_error_m * static_cast<double>(block.errors.measured_pixels);
      errors.measured_pixels += block.errors.measured_pixels;
      errors.uncovered_valid_pixels += block.errors.uncovered_valid_pixels;
      repairs += block.outline_repairs;
      misses += block.outline_misses;
      progress.advance();
    }
  }
  progress.endStage();
  if (repairs > 0) {
    progress.note("TIN: " + std::to_string(repairs) + " pixels on block borders that a triangle missed were repaired " +
                  "with vertices beside them" +
                  (misses ? ", " + std::to_string(misses) + " still over the bound (see the max error)" : std::string()));
  }
  if (file.triangleCount() == 0) {
    throw Error(ErrorCode::Input, options.inputs.front() + ": no triangle can be built: the DEM has no three "
                                  "neighbouring valid pixels; expected a DEM with some contiguous data");
  }
  errors.rms_error_m = errors.measured_pixels ? std::sqrt(sum_squares / static_cast<double>(errors.measured_pixels)) : 0;
  progress.beginStage("writing the TIN file", 0);
  file.commit();
  std::error_code ec;
  std::filesystem::remove_all(blocks_dir, ec);
  progress.endStage();
  if (!quiet) {
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::string blocks = " (" + std::to_string(grid.blockCount()) + " blocks";
    if (ranks > 1) blocks += " on " + std::to_string(ranks) + " ranks";
    if (reused > 0) blocks += ", " + std::to_string(reused) + " resumed";
    printTinSummary(err, options.output, mosaic.crs_name, file.vertexCount(), file.triangleCount(), errors,
                    options.max_error_m, seconds, blocks + "; border pixels measured in both blocks)");
  }
}

// `terratiles tin`: DEM -> greedy-insertion TIN -> OFF/OBJ/PLY in the DEM's CRS.
void runTinCommand(const TinCommandOptions& options, Progress& progress, bool quiet, std::ostream& err) {
  const auto start = std::chrono::steady_clock::now();
  std::optional<tbb::global_control> thread_limit;
  if (options.threads > 0) {
    thread_limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(options.threads));
  }
  tinFileFormatFor(options.output);  // validates the extension before any work
  std::error_code ec;
  if (std::filesystem::exists(options.output, ec) && !options.force) {
    throw Error(ErrorCode::Output, options.output + ": file exists; use --force to replace it");
  }
  if (options.block_pixels < 0 || options.block_pixels == 1) {
    throw Error(ErrorCode::Usage, "--block-pixels is " + std::to_string(options.block_pixels) +
                                      "; expected 0 (blocks above " + std::to_string(kTinBlocksAbovePixels) +
                                      " pixels) or at least 2");
  }
  const DemMosaic mosaic = scanDemMosaic(options.inputs, &progress);
  const std::int64_t pixels = mosaic.width * mosaic.height;
  const std::int32_t block_pixels =
      options.block_pixels > 0 ? options.block_pixels : pixels > kTinBlocksAbovePixels ? kTinBlockPixels : 0;
  if (block_pixels > 0 && (mosaic.width > block_pixels + 2 || mosaic.height > block_pixels + 2)) {
    runBlockTinCommand(options, mosaic, block_pixels, progress, quiet, err, start);
    return;
  }
  DemGrid dem = readDem(mosaic, "reading DEM", progress);
  const std::optional<GeoidGrid> geoid = options.heights.geoid();
  progress.endStage();
  TinErrorStatistics errors;
  TinMesh mesh;
  {
    const DemOnGlobe globe(dem, geoid ? &*geoid : nullptr, &progress);
    mesh = buildFinestTin(dem, &globe, options.max_error_m, options.constraints, progress).mesh;
    progress.beginStage("checking every pixel", 0);
    std::vector<EcefPoint> ecef(mesh.vertices.size());
    globe.place(mesh.vertices, {}, ecef);
    errors = measureTin(globe, mesh, ecef);
    progress.endStage();
  }
  const std::size_t vertex_count = mesh.vertices.size(), triangle_count = mesh.triangleCount();
  dem.heights_m = {};  // not needed any more
  writeTinFile(mesh, dem.origin_x, dem.origin_y, dem.pixel_size_x, options.output);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!quiet) {
    printTinSummary(err, options.output, dem.crs_name, vertex_count, triangle_count, errors, options.max_error_m,
                    seconds, "");
  }
}

// `terratiles check` found a violation (documented in its --help).
constexpr int kCheckFailedExitCode = 5;

constexpr const char* kConstraintsHelp =
    "Break lines: the lines and polygon rings of an OGR vector file (GeoJSON, GeoPackage, Shapefile; any CRS) are "
    "snapped to the DEM's pixels and kept as edges of the TIN (and of every level)";

struct LevelsCommandOptions {
  std::vector<std::string> inputs;
  std::string output;
  double tin_max_error_m = 0.5;
  std::string partitioner = "metis";
  std::string partition_scope = "regional";
  std::string simplifier = "native";
  std::string tail_stop = tailStopName(kDefaultTailStop);
  double level_error_growth = 2;  // 0: no budget
  std::size_t random_constraints = 0;
  std::string constraints;  // break lines (OGR vector file), or empty
  std::string format = "ply";
  bool force = false;
  int threads = 0;  // 0: all cores
  LevelOptions levels;
  HeightChoice heights;
  std::int32_t block_pixels = 0;  // > 0: every block's levels on its own, block borders locked
};

// What levels.json says of the run, whole or in blocks.
nlohmann::json levelsSummary(const LevelsCommandOptions& options, const std::string& crs_name) {
  nlohmann::json summary;
  summary["generator"] = std::string("terratiles ") + kVersion;
  summary["inputs"] = options.inputs;
  summary["crs"] = crs_name;
  summary["tin_max_error_m"] = options.tin_max_error_m;
  summary["partitioner"] = options.partitioner;
  summary["partition"] = options.partition_scope;
  summary["simplifier"] = options.simplifier;
  summary["tail_stop"] = tailStopName(options.levels.tail_stop);
  summary["cluster_triangles"] = options.levels.cluster_triangles;
  summary["level_ratio"] = options.levels.level_ratio;
  summary["level_error_growth"] = options.level_error_growth;
  return summary;
}

// `terratiles levels --block-pixels N`: every block's TIN and levels on its own
// (src/pipeline/block_tin.h), its outline locked at every level, each level stitched into one
// file. Measures what block borders cost against the whole build. A block whose levels stop
// early (its locked outline dominates) shows its coarsest level at the coarser ones.
void runBlockLevelsCommand(const LevelsCommandOptions& options, const DemMosaic& mosaic, OutputDirectory& directory,
                           Progress& progress, bool quiet, std::ostream& err,
                           std::chrono::steady_clock::time_point start) {
  if (options.levels.coarser_levels < 1 || !options.constraints.empty() || options.random_constraints > 0) {
    throw Error(ErrorCode::Usage, "--block-pixels needs --levels N (the number of levels every block builds) and "
                                  "takes no --constraints or --random-constraints yet");
  }
  const std::optional<GeoidGrid> geoid = options.heights.geoid();
  const BlockGrid grid = regularBlockGrid(mosaic.width, mosaic.height, options.block_pixels);
  BlockTinOptions tin_options;
  tin_options.max_error_m = options.tin_max_error_m;
  tin_options.measure = false;  // buildLevels measures level 0
  const std::size_t level_count = static_cast<std::size_t>(options.levels.coarser_levels) + 1;
  struct LevelFile {
    std::string name;
    std::unique_ptr<TinFileStream> stream;
    BlockVertexNumbering numbering;
    double max_error_m = 0, sum_squares = 0;
    std::size_t measured_pixels = 0, uncovered_valid_pixels = 0, clusters = 0, edges = 0;
  };
  std::vector<LevelFile> files(level_count);
  for (std::size_t l = 0; l < level_count; ++l) {
    files[l].name = "level_" + std::to_string(l) + "." + options.format;
    files[l].stream = std::make_unique<TinFileStream>((directory.staging() / files[l].name).string());
  }
  progress.beginStage("levels in " + std::to_string(grid.blockCount()) + " blocks of " +
                          std::to_string(options.block_pixels) + " pixels",
                      grid.blockCount());
  for (std::size_t j = 0; j < grid.rowCount(); ++j) {
    for (std::size_t i = 0; i < grid.columnCount(); ++i) {
      const BlockGround ground = readBlock(mosaic, grid, i, j, geoid ? &*geoid : nullptr);
      const std::vector<Level> levels = buildBlockLevels(ground, buildBlockTin(ground, tin_options), options.levels);
      for (std::size_t l = 0; l < level_count && !levels.empty(); ++l) {
        const Level& level = levels[std::min(l, levels.size() - 1)];
        LevelFile& file = files[l];
        appendBlockMesh(*file.stream, file.numbering, mosaic, grid, i, j, ground.window, level.mesh);
        file.max_error_m = std::max(file.max_error_m, level.error.max_error_m);
        file.sum_squares += level.error.rms_error_m * level.error.rms_error_m *
                            static_cast<double>(level.error.measured_pixels);
        file.measured_pixels += level.error.measured_pixels;
        file.uncovered_valid_pixels += level.error.uncovered_valid_pixels;
        file.clusters += static_cast<std::size_t>(std::max(level.partition.cluster_count, 0));
        file.edges += level.edge_count;
      }
      progress.advance();
    }
  }
  progress.endStage();
  nlohmann::json summary = levelsSummary(options, mosaic.crs_name);
  summary["block_pixels"] = options.block_pixels;
  summary["blocks"] = grid.blockCount();
  std::ostringstream table;
  table << "level  triangles   vertices  clusters   max error   rms error  file   (" << grid.blockCount()
        << " blocks of " << options.block_pixels << " px; border pixels measured in both blocks)\n";
  for (std::size_t l = 0; l < level_count; ++l) {
    LevelFile& file = files[l];
    progress.beginStage("writing " + file.name, 0);
    const std::uint64_t triangles = file.stream->triangleCount(), vertices = file.stream->vertexCount();
    file.stream->commit();
    progress.endStage();
    const double rms = file.measured_pixels ? std::sqrt(file.sum_squares / static_cast<double>(file.measured_pixels)) : 0;
    summary["levels"].push_back({{"level", l},
                                 {"file", file.name},
                                 {"triangles", triangles},
                                 {"vertices", vertices},
                                 {"clusters", file.clusters},
                                 {"max_error_m", file.max_error_m},
                                 {"rms_error_m", rms},
                                 {"measured_pixels", file.measured_pixels},
                                 {"uncovered_valid_pixels", file.uncovered_valid_pixels}});
    char line[160];
    std::snprintf(line, sizeof line, "%5zu %10llu %10llu %9zu %9.3f m %9.3f m  %s\n", l,
                  static_cast<unsigned long long>(triangles), static_cast<unsigned long long>(vertices), file.clusters,
                  file.max_error_m, rms, file.name.c_str());
    table << line;
  }
  directory.writeFile("levels.json", summary.dump(2) + "\n");
  directory.commit();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!quiet) {
    err << table.str() << "terratiles: wrote " << level_count << " levels to " << options.output << " ("
        << mosaic.crs_name << ", " << grid.blockCount() << " blocks); " << std::fixed << std::setprecision(2)
        << seconds << " s\n" << std::flush;
  }
}

// `terratiles levels`: DEM -> TIN -> the cluster levels of detail, each written as a TIN file
// in the DEM's CRS, with levels.json (what each level is and its measured error).
void runLevelsCommand(LevelsCommandOptions options, Progress& progress, bool quiet, std::ostream& err) {
  const auto start = std::chrono::steady_clock::now();
  std::optional<tbb::global_control> thread_limit;
  if (options.threads > 0) {
    thread_limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(options.threads));
  }
  options.levels.tail_stop = parseTailStop(options.tail_stop);  // before anything is written
  OutputDirectory directory(options.output, options.force, "levels.json");
  options.levels.partitioner = options.partitioner == "random" ? Partitioner::Random : Partitioner::Metis;
  // regional: square cells of the grid of about 64 clusters each (build's tile neighbourhoods
  // hold 2 x 2 tiles of 16).
  options.levels.region_clusters = options.partition_scope == "regional" ? 64 : 0;
  options.levels.simplifier = parseSimplifier(options.simplifier);
  if (options.level_error_growth > 0) {
    options.levels.level_error_growth = options.level_error_growth;
    options.levels.first_budget_m = options.tin_max_error_m * options.level_error_growth;
  }
  const DemMosaic mosaic = scanDemMosaic(options.inputs, &progress);
  if (options.block_pixels > 0) {
    runBlockLevelsCommand(options, mosaic, directory, progress, quiet, err, start);
    return;
  }
  const DemGrid dem = readDem(mosaic, "reading DEM", progress);
  const std::optional<GeoidGrid> geoid = options.heights.geoid();
  progress.endStage();
  const DemOnGlobe globe(dem, geoid ? &*geoid : nullptr, &progress);
  options.levels.globe = &globe;
  ConstrainedTin finest = buildFinestTin(dem, &globe, options.tin_max_error_m, options.constraints, progress);
  TinMesh tin = std::move(finest.mesh);
  std::vector<std::array<std::uint32_t, 2>> constraints = std::move(finest.constrained_edges);
  const std::size_t break_line_edges = constraints.size();
  if (options.random_constraints > 0) {
    const auto random = randomFaceSetConstraints(tin, options.random_constraints, 8, options.levels.seed);
    constraints.insert(constraints.end(), random.begin(), random.end());
  }
  const std::size_t constraint_count = constraints.size();
  const std::vector<Level> levels = buildLevels(dem, std::move(tin), options.levels, std::move(constraints), progress);

  nlohmann::json summary = levelsSummary(options, dem.crs_name);
  summary["constrained_edges"] = constraint_count;
  summary["break_lines"] = options.constraints.empty() ? nlohmann::json(nullptr)
                                                       : nlohmann::json{{"file", options.constraints},
                                                                        {"constrained_edges", break_line_edges},
                                                                        {"segments_bent", finest.segments_bent}};
  std::ostringstream table;
  table << "level  triangles   vertices  clusters   max error   rms error     budget  file\n";
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const Level& level = levels[l];
    const std::string file = "level_" + std::to_string(l) + "." + options.format;
    progress.beginStage("writing " + file, 0);
    writeTinFile(level.mesh, dem.origin_x, dem.origin_y, dem.pixel_size_x, (directory.staging() / file).string());
    progress.endStage();
    summary["levels"].push_back({{"level", l},
                                 {"file", file},
                                 {"triangles", level.mesh.triangleCount()},
                                 {"vertices", level.mesh.vertices.size()},
                                 {"edges", level.edge_count},
                                 {"clusters", level.partition.cluster_count},
                                 {"max_error_m", level.error.max_error_m},
                                 {"rms_error_m", level.error.rms_error_m},
                                 {"budget_m", level.budget_m},
                                 {"collapses_refused_for_error", level.refused_for_error},
                                 {"collapses_refused_for_fold_over", level.refused_for_flip}});
    char line[160];
    std::snprintf(line, sizeof line, "%5zu %10zu %10zu %9d %9.3f m %9.3f m %8.3g m  %s\n", l,
                  level.mesh.triangleCount(), level.mesh.vertices.size(), level.partition.cluster_count,
                  level.error.max_error_m, level.error.rms_error_m, level.budget_m, file.c_str());
    table << line;
  }
  directory.writeFile("levels.json", summary.dump(2) + "\n");
  directory.commit();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!quiet) {
    err << table.str() << "terratiles: wrote " << levels.size() << " levels to " << options.output << " ("
        << dem.crs_name << ", clusters by " << options.partitioner << "); " << std::fixed << std::setprecision(2)
        << seconds << " s\n" << std::flush;
  }
}

// -q and --progress, shared by the commands that do long work.
void addProgressOptions(CLI::App& command, bool& quiet, std::string& choice) {
  command.add_flag("-q,--quiet", quiet, "No progress and no summary on stderr");
  command
      .add_option("--progress", choice,
                  "Progress on stderr: auto (a bar on a terminal, else nothing), bar, json, none")
      ->check(CLI::IsMember({"auto", "bar", "json", "none"}))
      ->capture_default_str();
}

ProgressMode progressModeFor(const std::string& choice, bool quiet) {
  if (quiet || choice == "none") return ProgressMode::Quiet;
  if (choice == "json") return ProgressMode::Json;
  if (choice == "bar") return ProgressMode::Bar;
  return ::isatty(STDERR_FILENO) ? ProgressMode::Bar : ProgressMode::Quiet;
}

int runCliOrThrow(const std::vector<std::string>& args, std::istream& in, std::ostream& out,
                  std::ostream& err) {
  CLI::App app{"terratiles " + std::string(kVersion) +
                   ": DEM rasters to seamless multi-level-of-detail 3D Tiles terrain "
                   "(Draco glTF tiles and tileset.json for CesiumJS).",
               "terratiles"};
  app.footer(kExitCodes);
  app.set_version_flag("--version", std::string("terratiles ") + kVersion);
  app.require_subcommand(1);

  BuildOptions build;
  bool quiet = false;
  std::string progress_choice = "auto";
  CLI::App* build_command = app.add_subcommand(
      "build", "Turn one or several adjacent DEM rasters into a 3D Tiles tileset");
  build_command->footer(kExitCodes);
  InputChoice build_inputs;
  addInputOptions(*build_command, build_inputs);
  build_command->add_option("-o,--output", build.output_dir, "Output directory (tileset.json, tiles/)")
      ->required();
  build_command->add_flag("-f,--force", build.force,
                          "Replace OUTDIR when it holds a previous output (tileset.json)");
  std::string lod_choice = "clusters", scheme_choice = "webmercator", assign_choice = "merge";
  std::string format_choice = "tileset";
  build_command
      ->add_option("--format", format_choice,
                   "What to write: tileset (3D Tiles: tileset.json and Draco GLB tiles), quantized-mesh (a "
                   "quantized-mesh-1.0 terrain layer, layer.json and gzip'd {z}/{x}/{y}.terrain tiles, that "
                   "CesiumJS's CesiumTerrainProvider takes as the globe's terrain) or terrain (3D Tiles terrain: "
                   "implicit quadtrees of meshopt GLBs with tile edges, for Cesium3DTilesTerrainProvider); both "
                   "terrain layers use the geographic scheme")
      ->check(CLI::IsMember({"tileset", "quantized-mesh", "terrain"}))
      ->capture_default_str();
  build_command->add_option("--fill", build.fill_dem,
                            "--format quantized-mesh or terrain: outside the data, the terrain of this raster (WGS84 longitude "
                            "and latitude, heights as --heights says, e.g. ETOPO5) instead of the geoid surface");
  build_command
      ->add_option("--lod", lod_choice,
                   "Levels of detail: clusters (greedy TIN, cluster levels, clusters assigned to web tiles: the "
                   "paper's method) or grid (a decimated pixel grid per zoom, local pixel tiles; for comparison)")
      ->check(CLI::IsMember({"clusters", "grid"}))
      ->capture_default_str();
  build_command
      ->add_option("--scheme", scheme_choice,
                   "Tile pyramid: webmercator (EPSG:3857 XYZ), geographic (EPSG:4326, 2 x 1 at zoom 0) or local "
                   "(the DEM's CRS, origin at its lower-left corner)")
      ->check(CLI::IsMember({"webmercator", "geographic", "local"}))
      ->capture_default_str();
  build_command
      ->add_option("--assign", assign_choice,
                   "Clusters to tiles: merge (both cluster sets of a level, no holes), duplicate (every tile a "
                   "cluster crosses) or centroid (the tile of its centroid; leaves holes, for comparison)")
      ->check(CLI::IsMember({"merge", "duplicate", "centroid"}))
      ->capture_default_str();
  build_command->add_option("--tin-max-error", build.tin_max_error_m, "The finest TIN's max vertical error, metres")
      ->capture_default_str();
  build_command
      ->add_option("--tile-triangles", build.tile_triangles,
                   "The finest zoom is the first whose tiles hold at most about N triangles of the finest TIN")
      ->capture_default_str();
  build_command->add_flag("--no-join-tile-clusters", [&build](std::int64_t) { build.join_tile_clusters = false; },
                          "merge: keep every METIS cluster border locked, instead of simplifying the clusters that "
                          "cross the same tiles as one (paper fig 34)");
  std::string build_partition = "regional";
  build_command
      ->add_option("--partition", build_partition,
                   "How METIS sees a level: regional (per tile neighbourhood, in parallel) or global (one k-way call "
                   "over the whole level, seconds for thousands of clusters; for comparison)")
      ->check(CLI::IsMember({"regional", "global"}))
      ->capture_default_str();
  build_command
      ->add_option("--clusters-per-tile", build.clusters_per_tile,
                   "Clusters a level is split into per tile of its zoom (paper: about 4); more make thinner "
                   "overlaps between tiles but lock more edges")
      ->capture_default_str();
  build_command
      ->add_option("--level-ratio", build.level_ratio, "Edges a simplification keeps in every cluster (paper: 0.5)")
      ->capture_default_str();
  build_command
      ->add_option("--level-error-growth", build.level_error_growth,
                   "Error budget of a level: tin-max-error * G^level metres (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  std::string build_simplifier = "native";
  addSimplifierOption(*build_command, build_simplifier);
  std::string build_tail_stop = tailStopName(kDefaultTailStop);
  addTailStopOption(*build_command, build_tail_stop);
  build_command->add_option("--constraints", build.constraints, kConstraintsHelp);
  build_command
      ->add_option("--tile-cells", build.tile_cells,
                   "--lod grid: grid cells per tile side at every zoom; a tile holds up to 2*N^2 triangles")
      ->capture_default_str();
  build_command
      ->add_option("--max-zoom", build.max_zoom,
                   "Finest zoom (-1: from the data: --tile-triangles, or for --lod grid one root tile)")
      ->capture_default_str();
  build_command
      ->add_option("--block-pixels", build.block_pixels,
                   "Build in blocks: each a tile of one zoom at most this many pixels a side, read, triangulated, "
                   "simplified and written on its own, its outline locked until the blocks' levels join for the "
                   "coarser zooms (0: blocks of 2048 when the mosaic has more than 64 M pixels)")
      ->capture_default_str();
  build_command
      ->add_option("--strip-pixels", build.strip_pixels,
                   "Blocks: the zooms from the blocks' zoom up are measured against the DEM in strips of rows of "
                   "about this many pixels (28 bytes each, plus the rows the tallest triangle reaches)")
      ->capture_default_str();
  build_command
      ->add_option("--overview-pixels", build.overview_pixels,
                   "Blocks: the levels from the blocks' zoom up are simplified against an overview of the DEM of at "
                   "most this many pixels (means of 2 x 2, 4 x 4, ... pixels; 12 bytes each for WGS84 longitude and "
                   "latitude DEMs, 52 otherwise); their tiles are still measured against every pixel")
      ->capture_default_str();
  build_command->add_flag("--resume", build.resume,
                          "Blocks: continue an interrupted build (killed, power lost) from the block files it left in "
                          "OUTDIR.blocks/, making only the missing blocks; the output is the same as an "
                          "uninterrupted build's");
  HeightChoice build_heights;
  addHeightOptions(*build_command, build_heights.heights, build.geoid_path);
  build_command->add_flag("--implicit", build.implicit_tiling,
                          "Geographic scheme: write 3D Tiles implicit tiling (quadtree, subtree files with tile and "
                          "content availability, each tile's measured error and region as tile metadata)");
  build_command->add_option("--subtree-levels", build.subtree_levels, "--implicit: tree levels per subtree file")
      ->capture_default_str();
  build_command
      ->add_option("--tileset-levels", build.tileset_levels,
                   "Explicit tilesets: tree levels per JSON file, deeper tiles in external tilesets "
                   "(tilesets/z/x/y.json), so no file grows with the data (0: one file up to 10,000 tiles, else 6)")
      ->check(CLI::Range(0, 20))
      ->capture_default_str();
  build_command->add_flag("--no-report", [&build](std::int64_t) { build.report = false; },
                          "Write no report.json / report.html");
  build_command
      ->add_option("--report-check-cuts", build.report_check_cuts,
                   "Random cuts `terratiles check` tries for the report (0: no check in the report)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  build_command->add_flag("--no-draco", [&build](std::int64_t) { build.draco = false; },
                          "Write plain GLB without KHR_draco_mesh_compression");
  CLI::Option* position_step =
      build_command
          ->add_option("--position-step", build.position_step_m,
                       "Draco position quantisation grid in metres (a power of two) that all tiles share; a zoom "
                       "whose tiles span more than 2^23 steps uses a power-of-two multiple")
          ->capture_default_str();
  build_command
      ->add_option("--draco-position-bits", build.draco_position_bits,
                   "Instead of --position-step: the grid at which the finest zoom's widest tile takes B bits (8-23)")
      ->excludes(position_step);
  build_command
      ->add_option("--draco-normal-bits", build.draco_normal_bits, "Draco normal quantisation bits (4-16)")
      ->capture_default_str();
  build_command
      ->add_option("--draco-speed", build.draco_speed, "Draco encoder speed, 0 (smallest files) to 10 (fastest)")
      ->capture_default_str();
  int build_threads = 0;  // 0: all cores
  build_command->add_option("--threads", build_threads, "Threads to use (0: all cores); the output is the same")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  addProgressOptions(*build_command, quiet, progress_choice);

  std::string transform_from, transform_to, transform_geoid;
  CLI::App* transform_command = app.add_subcommand(
      "transform",
      "Transform 'x y [z]' lines from standard input to standard output, like cs2cs, by the "
      "paths terratiles uses (EPSG:2056 by the rigorous swisstopo formulas)");
  transform_command->footer(kExitCodes);
  transform_command
      ->add_option("--from", transform_from,
                   "Source CRS: EPSG code (EPSG:2056, EPSG:2056+5728, EPSG:4326...), WKT or PROJ "
                   "string; x y in its units (lon lat in degrees), z in metres")
      ->required();
  transform_command
      ->add_option("--to", transform_to,
                   "Target CRS, e.g. EPSG:4326 or EPSG:4979 (lon lat h), EPSG:4978 (ECEF "
                   "metres), EPSG:3857 (Web Mercator metres)")
      ->required();
  transform_command
      ->add_option("--geoid", transform_geoid,
                   "Geoid grid: heights on the non-WGS84 side are orthometric (h = H + N)")
      ->check(CLI::ExistingFile);

  TinCommandOptions tin;
  CLI::App* tin_command = app.add_subcommand(
      "tin", "Turn DEM rasters into one TIN by greedy insertion, written as OFF, OBJ or PLY");
  tin_command->footer(kExitCodes);
  InputChoice tin_inputs;
  addInputOptions(*tin_command, tin_inputs);
  tin_command
      ->add_option("-o,--output", tin.output,
                   "Output TIN file, .off, .obj or .ply (binary), coordinates in the DEM's CRS")
      ->required();
  tin_command
      ->add_option("--tin-max-error", tin.max_error_m,
                   "Largest vertical error in metres allowed at any pixel")
      ->capture_default_str();
  tin_command->add_option("--constraints", tin.constraints, kConstraintsHelp);
  tin_command->add_option(
      "--block-pixels", tin.block_pixels,
      "Cut the mosaic into blocks of this many pixels per side, each read and triangulated on its own in bounded "
      "memory, their outlines chosen so that neighbours meet vertex for vertex (0: blocks of 2048 when the mosaic "
      "has more than 64 M pixels)")
      ->capture_default_str();
  tin_command->add_flag("--resume", tin.resume,
                        "Blocks: continue an interrupted run (killed, power lost) from the block files it left in "
                        "OUTPUT.blocks/, making only the missing ones; the file is the same as an uninterrupted run's");
  tin_command->add_option("--threads", tin.threads, "Threads to use (0: all cores); the output is the same")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  addHeightOptions(*tin_command, tin.heights.heights, tin.heights.geoid_path);
  tin_command->add_flag("-f,--force", tin.force, "Replace an existing output file");
  addProgressOptions(*tin_command, quiet, progress_choice);

  LevelsCommandOptions levels;
  CLI::App* levels_command = app.add_subcommand(
      "levels", "Build the cluster levels of detail (METIS clusters, CGAL edge collapse with "
                "locked borders, re-partition per level) and write each level as a TIN file");
  levels_command->footer(kExitCodes);
  InputChoice levels_inputs;
  addInputOptions(*levels_command, levels_inputs);
  levels_command
      ->add_option("-o,--output", levels.output,
                   "Output directory: level_0 (the finest TIN) .. level_N files and levels.json")
      ->required();
  levels_command->add_option("--tin-max-error", levels.tin_max_error_m, "The finest TIN's max vertical error, metres")
      ->capture_default_str();
  levels_command
      ->add_option("--cluster-triangles", levels.levels.cluster_triangles,
                   "Triangles per cluster: each level is split into ceil(triangles / N) clusters")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  levels_command
      ->add_option("--level-ratio", levels.levels.level_ratio,
                   "Edges a simplification keeps in every cluster, as a fraction (paper: 0.5)")
      ->check(CLI::Range(0.01, 0.99))
      ->capture_default_str();
  levels_command
      ->add_option("--level-error-growth", levels.level_error_growth,
                   "Error budget: level l may not exceed tin-max-error * G^l metres anywhere "
                   "(collapses that would are refused); 0: no budget, the ratio alone decides")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  levels_command
      ->add_option("--levels", levels.levels.coarser_levels,
                   "Coarser levels to build (0: until a level would not reach about --level-ratio of the "
                   "edges, or 90 % of the triangles when held back by the error budget)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  levels_command
      ->add_option("--partitioner", levels.partitioner,
                   "metis (edge-cut minimisation) or random (random contiguous growth, for comparison)")
      ->check(CLI::IsMember({"metis", "random"}))
      ->capture_default_str();
  levels_command
      ->add_option("--partition", levels.partition_scope,
                   "How METIS sees a level: regional (square cells of the grid of about 64 clusters each, in "
                   "parallel; the cell outlines move from level to level) or global (one k-way call over the whole "
                   "level, seconds for thousands of clusters)")
      ->check(CLI::IsMember({"regional", "global"}))
      ->capture_default_str();
  levels_command
      ->add_option("--random-constraints", levels.random_constraints,
                   "Lock every edge of N random connected sets of 8 triangles at every level "
                   "(the paper's stand-in for roads and buildings)")
      ->capture_default_str();
  addSimplifierOption(*levels_command, levels.simplifier);
  addTailStopOption(*levels_command, levels.tail_stop);
  levels_command->add_option("--constraints", levels.constraints, kConstraintsHelp);
  addHeightOptions(*levels_command, levels.heights.heights, levels.heights.geoid_path);
  levels_command->add_option("--seed", levels.levels.seed, "Seed of METIS and of the random choices")
      ->capture_default_str();
  levels_command->add_option("--format", levels.format, "TIN file format: ply (binary), off or obj")
      ->check(CLI::IsMember({"ply", "off", "obj"}))
      ->capture_default_str();
  levels_command->add_option("--threads", levels.threads, "Threads to use (0: all cores); the output is the same")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  levels_command
      ->add_option("--block-pixels", levels.block_pixels,
                   "Cut the mosaic into blocks of this many pixels per side and build every block's TIN and levels "
                   "on its own, its outline locked at every level (needs --levels N; measures what block borders "
                   "cost against the whole build; 0: one build)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  levels_command->add_flag("-f,--force", levels.force, "Replace OUTDIR when it holds a previous levels output");
  addProgressOptions(*levels_command, quiet, progress_choice);

  std::string check_dir;
  CheckOptions check_options;
  CLI::App* check_command = app.add_subcommand(
      "check", "Prove a built OUTDIR seamless and honest: decode every tile and check coverage of random cuts, "
               "overlap agreement between zooms and every geometricError against the source DEM");
  check_command->footer(std::string(kExitCodes) + " 5: the check found violations.");
  check_command->add_option("OUTDIR", check_dir, "A directory written by terratiles build")->required();
  check_command->add_option("--cuts", check_options.cuts, "Random cuts of the tile tree to check")
      ->capture_default_str();
  check_command->add_option("--seed", check_options.seed, "Seed of the random cuts")->capture_default_str();
  check_command
      ->add_option("--strip-pixels", check_options.strip_pixels,
                   "The DEM is read and measured in strips of rows of about this many pixels (33 bytes each for a "
                   "DEM in longitude and latitude, 73 for another CRS, plus the rows the tallest triangle reaches); "
                   "the result is the same for any strip size")
      ->capture_default_str();
  addProgressOptions(*check_command, quiet, progress_choice);

  std::string serve_dir;
  int serve_port = 8080;
  CLI::App* serve_command = app.add_subcommand(
      "serve", "View OUTDIR in the CesiumJS viewer (samples/viewer): serves it on 127.0.0.1 and prints the URL "
               "(needs node and the viewer's npm packages)");
  serve_command->footer(kExitCodes);
  serve_command->add_option("OUTDIR", serve_dir, "A directory written by terratiles build")->required();
  serve_command->add_option("--port", serve_port, "Port (0: any free port)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();

  std::string report_dir;
  ReportOptions report_options;
  CLI::App* report_command = app.add_subcommand(
      "report", "Regenerate OUTDIR/report.json and report.html from an existing output (re-running the check); "
                "an output from before reports existed gets what its files tell");
  report_command->footer(kExitCodes);
  report_command->add_option("OUTDIR", report_dir, "A directory written by terratiles build")->required();
  report_command
      ->add_option("--cuts", report_options.check_cuts, "Random cuts for the check (0: keep the recorded check)")
      ->capture_default_str();
  addProgressOptions(*report_command, quiet, progress_choice);

  try {
    std::vector<const char*> argv;
    for (const auto& arg : args) argv.push_back(arg.c_str());
    app.parse(static_cast<int>(argv.size()), argv.data());
  } catch (const CLI::CallForHelp&) {
    out << (app.get_subcommands().empty() ? app.help() : app.get_subcommands().front()->help());
    return 0;
  } catch (const CLI::CallForAllHelp&) {
    out << app.help("", CLI::AppFormatMode::All);
    return 0;
  } catch (const CLI::CallForVersion&) {
    out << "terratiles " << kVersion << "\n";
    return 0;
  } catch (const CLI::ParseError& e) {
    std::string message = e.what();
    std::replace(message.begin(), message.end(), '\n', ' ');
    const std::string command =
        app.get_subcommands().empty() ? "" : " " + app.get_subcommands().front()->get_name();
    throw Error(ErrorCode::Usage, message + " (see 'terratiles" + command + " --help')");
  }

  if (check_command->parsed()) {
    Progress progress(progressModeFor(progress_choice, quiet));
    InterruptGuard interrupt_guard;
    const CheckReport report = checkOutput(check_dir, check_options, progress);
    out << describeCheck(report) << std::flush;
    return report.ok() ? 0 : kCheckFailedExitCode;
  }
  if (serve_command->parsed()) serveOutput(serve_dir, serve_port);
  if (report_command->parsed()) {
    Progress progress(progressModeFor(progress_choice, quiet));
    InterruptGuard interrupt_guard;
    const RegeneratedReport report = regenerateReport(report_dir, report_options, progress);
    if (!quiet) {
      err << "terratiles: report " << report.html_path << " ("
          << (report.from_build_record ? "from the build's report.json"
                                       : "rebuilt from the files: no cluster maps or stage times, which only the "
                                         "build records")
          << "; check " << (report.report["check"].is_null() ? "not run" : report.report["check"].value("ok", false) ? "ok" : "FAILED")
          << ")\n";
    }
    return 0;
  }
  if (levels_command->parsed()) {
    Progress progress(progressModeFor(progress_choice, quiet));
    InterruptGuard interrupt_guard;
    levels.inputs = levels_inputs.files();
    runLevelsCommand(levels, progress, quiet, err);
    return 0;
  }
  // Under mpirun: `tin` and `build` in blocks spread them over the ranks; any other command
  // runs on rank 0 alone, as without mpirun (the others leave at once).
  if (Ranks::size() > 1 && !tin_command->parsed() && !build_command->parsed() && Ranks::rank() != 0) return 0;
  if (tin_command->parsed()) {
    Progress progress(progressModeFor(progress_choice, quiet));
    InterruptGuard interrupt_guard;
    tin.inputs = tin_inputs.files();
    runTinCommand(tin, progress, quiet, err);
    return 0;
  }
  if (transform_command->parsed()) {
    runTransform(transform_from, transform_to, transform_geoid, in, out);
    return 0;
  }
  if (build_command->parsed()) {
    build.inputs = build_inputs.files();
    build.lod = lod_choice == "grid" ? LodMethod::Grid : LodMethod::Clusters;
    build.simplifier = parseSimplifier(build_simplifier);
    build.tail_stop = parseTailStop(build_tail_stop);
    build.global_partition = build_partition == "global";
    build.format = format_choice == "quantized-mesh" ? OutputFormat::QuantizedMesh
                   : format_choice == "terrain"      ? OutputFormat::TerrainTiles3d
                                                     : OutputFormat::Tileset;
    // Terrain tiles are the geographic quadtree's: its scheme unless one is asked for.
    if (isTerrainLayer(build.format) && build_command->count("--scheme") == 0) {
      scheme_choice = "geographic";
    }
    build.scheme = parseTileSchemeKind(scheme_choice);
    build.assignment = parseAssignment(assign_choice);
    if (build_heights.heights == "ellipsoidal") {
      if (!build.geoid_path.empty()) {
        throw Error(ErrorCode::Usage, "--geoid and --heights ellipsoidal exclude each other "
                                      "(a geoid only applies to orthometric heights)");
      }
      build.heights = HeightReference::Ellipsoidal;
    }
    std::optional<tbb::global_control> thread_limit;
    if (build_threads > 0) {
      thread_limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(build_threads));
    }
    Progress progress(progressModeFor(Ranks::rank() == 0 ? progress_choice : std::string("none"), quiet));
    InterruptGuard interrupt_guard;
    const BuildSummary summary = runPipeline(build, progress);
    if (Ranks::rank() != 0) return 0;  // rank 0 tells
    if (!quiet && progress_choice == "json") {
      printJsonSummary(summary, err);
    } else if (!quiet) {
      printSummary(summary, err);
    }
  }
  return 0;
}

}  // namespace

int runCli(const std::vector<std::string>& args, std::istream& in, std::ostream& out,
           std::ostream& err) {
  try {
    return runCliOrThrow(args, in, out, err);
  } catch (const Error& e) {
    err << "terratiles: error: " << e.what() << "\n";
    return exitCodeFor(e.code());
  } catch (const std::bad_alloc&) {
    err << "terratiles: error: " << kOutOfMemory << "\n";
    return exitCodeFor(ErrorCode::OutOfMemory);
  } catch (const std::exception& e) {
    err << "terratiles: error: internal: " << e.what() << "\n";
    return exitCodeFor(ErrorCode::Internal);
  }
}

}  // namespace terratiles
