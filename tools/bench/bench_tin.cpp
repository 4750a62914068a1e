// Benchmark: our greedy-insertion TIN (buildTin, src/tin/build_tin.h) against the npm package
// delatin (Agafonkin's JavaScript port of the same algorithm, Garland & Heckbert 1995) on the
// same raster at the same max errors, side by side in one run.
//
//   terratiles_bench_tin RASTER... [--errors 0.5,1,2] [--runs 5] [--threads 1]
//                        [--node node] [--script tools/bench/delatin/run_delatin.mjs]
//
// For each raster: reads it with readDem, writes its heights once as raw little-endian float32
// (width * height, row-major, row 0 north: the layout Delatin reads, heightAt(x, y) =
// data[width * y + x], with vertices on whole pixel indices, i.e. our GridPoint pixel centres).
// For each max error: times buildTin (one untimed warm-up, then the median of --runs), then
// spawns `node run_delatin.mjs RAW WIDTH HEIGHT MAX_ERROR RUNS OUT`, which times
// `new Delatin(...)` + `run()` the same way and writes its mesh. Both meshes are then measured
// by the same measureTin, so the achieved max and RMS error are computed identically.
// Prints one table per raster and a summary with the ratios (speed = Delatin time / our time,
// triangles = ours / Delatin's) against the targets (speed >= 5x, triangles <= +5 %).
//
// Rasters with nodata are skipped for both tools (Delatin needs a complete grid and buildTin
// rejects nodata). Needs `npm install` in tools/bench/delatin once (see tools/bench/README.md).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include "formats/dem/read_dem.h"
#include "tools/bench/bench_support.h"
#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "src/tin/tin_mesh.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

using bench::median;
using bench::parseNumber;

constexpr double kSpeedTarget = 5.0;          // Delatin time / our time, at least
constexpr double kTriangleRatioTarget = 1.05;  // our triangles / Delatin's, at most

struct BenchOptions {
  std::vector<std::string> rasters;
  std::vector<double> max_errors_m{0.5, 1.0, 2.0};
  int runs = 5;
  int threads = 1;
  std::string node = "node";
  // Next to this source file, so the program runs from any directory of a source checkout.
  std::string script = (fs::path(__FILE__).parent_path() / "delatin" / "run_delatin.mjs").string();
};

constexpr const char* kUsage =
    "usage: terratiles_bench_tin RASTER... [--errors 0.5,1,2] [--runs 5] [--threads 1]\n"
    "                            [--node node] [--script PATH/run_delatin.mjs]\n"
    "  --errors   max vertical errors in metres, comma-separated (default 0.5,1,2)\n"
    "  --runs     timed runs per tool and error; the median is reported (default 5),\n"
    "             after one untimed warm-up run per tool\n"
    "  --threads  threads our buildTin may use (default 1: Delatin is single-threaded)\n"
    "  --node     the node executable (default node, searched in PATH)\n"
    "  --script   tools/bench/delatin/run_delatin.mjs (default: next to this source file)\n";

BenchOptions parseOptions(int argc, char** argv) {
  BenchOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " expects a value\n" + kUsage);
      return argv[++i];
    };
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (arg == "--errors") {
      options.max_errors_m.clear();
      const std::string list = value();
      for (std::size_t start = 0; start <= list.size();) {
        const std::size_t comma = std::min(list.find(',', start), list.size());
        const double error_m = parseNumber(list.substr(start, comma - start), "--errors");
        if (!(error_m > 0)) {
          throw Error(ErrorCode::Usage, "--errors: every max error must be > 0 m, found " + list);
        }
        options.max_errors_m.push_back(error_m);
        start = comma + 1;
      }
    } else if (arg == "--runs") {
      const std::string text = value();
      const double runs = parseNumber(text, "--runs");
      if (runs < 1 || runs != std::floor(runs)) {
        throw Error(ErrorCode::Usage, "--runs expects a whole number >= 1, found " + text);
      }
      options.runs = static_cast<int>(runs);
    } else if (arg == "--threads") {
      const std::string text = value();
      const double threads = parseNumber(text, "--threads");
      if (threads < 1 || threads != std::floor(threads)) {
        throw Error(ErrorCode::Usage, "--threads expects a whole number >= 1, found " + text);
      }
      options.threads = static_cast<int>(threads);
    } else if (arg == "--node") {
      options.node = value();
    } else if (arg == "--script") {
      options.script = value();
    } else if (arg.starts_with("-")) {
      throw Error(ErrorCode::Usage, "unknown option " + arg + "\n" + kUsage);
    } else {
      options.rasters.push_back(arg);
    }
  }
  if (options.rasters.empty()) throw Error(ErrorCode::Usage, std::string("no RASTER given\n") + kUsage);
  bench::requireDelatinScript(options.script);
  return options;
}

struct DelatinResult {
  TinMesh mesh;
  double build_s = 0;       // median of new Delatin() + run()
  double run_only_s = 0;    // median of run() alone
  double own_max_error_m = 0;  // Delatin's getMaxError(), for a cross-check
  std::size_t flipped_triangles = 0;  // clockwise from above, flipped to our convention
};

// Delatin's output in our frame: its coords are (x = column, y = row) pixel indices; heights
// come from the DEM.
DelatinResult toDelatinResult(const bench::DelatinOutput& output, const DemGrid& dem) {
  DelatinResult result;
  result.build_s = output.build_s;
  result.run_only_s = output.run_only_s;
  result.own_max_error_m = output.own_max_error_m;
  const std::size_t vertex_count = output.vertexCount();
  result.mesh.triangle_indices = output.triangles;
  result.mesh.vertices.resize(vertex_count);
  for (std::size_t v = 0; v < vertex_count; ++v) {
    const std::uint32_t col = output.coords[2 * v], row = output.coords[2 * v + 1];
    if (col >= static_cast<std::uint32_t>(dem.width) || row >= static_cast<std::uint32_t>(dem.height)) {
      throw Error(ErrorCode::Internal, "Delatin's vertex " + std::to_string(v) + " at (" +
                                           std::to_string(col) + ", " + std::to_string(row) +
                                           ") is outside the grid");
    }
    result.mesh.vertices[v] = {static_cast<double>(col), static_cast<double>(row),
                               dem.heightAt(static_cast<std::int32_t>(col), static_cast<std::int32_t>(row))};
  }
  for (const std::uint32_t index : result.mesh.triangle_indices) {
    if (index >= vertex_count) throw Error(ErrorCode::Internal, "Delatin's triangle index out of range");
  }
  return result;
}

// Cross product in the (col, row) plane: row grows south, so > 0 is clockwise seen from above.
double crossColRow(const TinMesh& mesh, std::size_t t) {
  const GridPoint& a = mesh.vertices[mesh.triangle_indices[3 * t]];
  const GridPoint& b = mesh.vertices[mesh.triangle_indices[3 * t + 1]];
  const GridPoint& c = mesh.vertices[mesh.triangle_indices[3 * t + 2]];
  return (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
}

std::size_t countClockwise(const TinMesh& mesh) {
  std::size_t count = 0;
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t) count += crossColRow(mesh, t) > 0;
  return count;
}

// Delatin's triangles come out counter-clockwise from above already (checked on every run);
// any that do not are flipped so both meshes follow TinMesh's convention.
std::size_t flipToCounterClockwise(TinMesh& mesh) {
  std::size_t flipped = 0;
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t) {
    if (crossColRow(mesh, t) > 0) {
      std::swap(mesh.triangle_indices[3 * t + 1], mesh.triangle_indices[3 * t + 2]);
      ++flipped;
    }
  }
  return flipped;
}

// "ok" or what measureTin and the orientation check found wrong.
std::string checksOf(const TinErrorStatistics& stats, std::size_t clockwise, double max_error_m) {
  std::string issues;
  auto add = [&](std::size_t count, const char* what) {
    if (count) issues += (issues.empty() ? "" : ", ") + std::to_string(count) + " " + what;
  };
  add(stats.uncovered_valid_pixels, "uncovered pixels");
  add(stats.degenerate_triangles, "degenerate triangles");
  add(clockwise, "clockwise triangles");
  // Both tools compare float32 heights in double; allow rounding, not a real excess.
  if (stats.max_error_m > max_error_m * (1 + 1e-9) + 1e-9) issues += (issues.empty() ? "" : ", ") + std::string("max error above bound");
  return issues.empty() ? "ok" : issues;
}

struct Row {
  std::string raster;
  double max_error_m = 0;
  double speed = 0;  // median of the pairs' Delatin time / our time
  std::size_t ours_triangles = 0, delatin_triangles = 0;
};

void printToolLine(const char* label, const char* tool, double seconds, const TinMesh& mesh,
                   const TinErrorStatistics& stats, const std::string& checks) {
  std::printf("%-10s %-11s %9.3f %10zu %10zu %9.4f %9.4f  %s\n", label, tool, seconds,
              mesh.triangleCount(), mesh.vertices.size(), stats.max_error_m, stats.rms_error_m,
              checks.c_str());
}

void benchRaster(const std::string& path, const BenchOptions& options, const fs::path& scratch,
                 std::vector<Row>& summary) {
  const DemGrid dem = readDem({path});
  const std::string name = fs::path(path).filename().string();
  const std::size_t nodata =
      static_cast<std::size_t>(std::count_if(dem.heights_m.begin(), dem.heights_m.end(),
                                             [](float h) { return std::isnan(h); }));
  std::printf("\n== %s: %d x %d pixels, %s\n", name.c_str(), dem.width, dem.height, dem.crs_name.c_str());
  if (nodata) {
    std::printf("skipped: nodata (%zu of %zu pixels) for both tools; Delatin needs a complete grid "
                "and buildTin rejects nodata\n", nodata, dem.pixelCount());
    return;
  }
  std::printf("%d pairs of runs (terratiles, then Delatin), each tool warmed up; medians; speed = "
              "median of the pairs' ratios; terratiles on %d thread(s); Delatin time = "
              "new Delatin() + run()\n", options.runs, options.threads);
  std::printf("%-10s %-11s %9s %10s %10s %9s %9s  %s\n", "max error", "tool", "time [s]",
              "triangles", "vertices", "max [m]", "rms [m]", "checks");

  const fs::path raw = scratch / "grid.f32";
  bench::writeRawGrid(dem.heights_m, raw);
  for (const double max_error_m : options.max_errors_m) {
    // Side by side: run r times ours, then Delatin (its own process: one warm-up build, then
    // one timed), so both see the same machine state; noise that lasts longer than a pair
    // cancels in the pair's ratio. Reported: the median times and the median of the ratios.
    Progress quiet(ProgressMode::Quiet);
    const TinOptions tin_options{.max_error_m = max_error_m};
    std::fprintf(stderr, "%s at %g m: warm-up\n", name.c_str(), max_error_m);
    TinMesh ours = buildTin(dem, tin_options, quiet);  // warm-up
    const fs::path out = scratch / "delatin.bin";
    std::vector<double> ours_runs, delatin_runs, delatin_run_only, ratios;
    DelatinResult delatin;
    for (int r = 0; r < options.runs; ++r) {
      std::fprintf(stderr, "%s at %g m: pair %d of %d\n", name.c_str(), max_error_m, r + 1, options.runs);
      const auto start = std::chrono::steady_clock::now();
      ours = buildTin(dem, tin_options, quiet);
      ours_runs.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      delatin = toDelatinResult(
          bench::runDelatin(options.node, options.script, raw, dem.width, dem.height, max_error_m, out), dem);
      delatin_runs.push_back(delatin.build_s);
      delatin_run_only.push_back(delatin.run_only_s);
      ratios.push_back(delatin.build_s / ours_runs.back());
    }
    const double ours_s = median(ours_runs);
    delatin.build_s = median(delatin_runs);
    delatin.run_only_s = median(delatin_run_only);
    delatin.flipped_triangles = flipToCounterClockwise(delatin.mesh);

    const TinErrorStatistics ours_stats = measureTin(dem, ours);
    const TinErrorStatistics delatin_stats = measureTin(dem, delatin.mesh);
    char label[32];
    std::snprintf(label, sizeof label, "%g m", max_error_m);
    printToolLine(label, "terratiles", ours_s, ours, ours_stats,
                  checksOf(ours_stats, countClockwise(ours), max_error_m));
    std::string delatin_checks = checksOf(delatin_stats, 0, max_error_m);
    if (delatin.flipped_triangles) {
      delatin_checks += "; flipped " + std::to_string(delatin.flipped_triangles) + " clockwise";
    }
    char run_only[96];
    std::snprintf(run_only, sizeof run_only, "; run() alone %.3f s, own getMaxError %.4f",
                  delatin.run_only_s, delatin.own_max_error_m);
    printToolLine("", "delatin", delatin.build_s, delatin.mesh, delatin_stats, delatin_checks + run_only);
    const double speed = median(ratios);
    const double triangles = static_cast<double>(ours.triangleCount()) /
                             static_cast<double>(delatin.mesh.triangleCount());
    std::printf("%-10s %-11s %8.2fx %10.4f %10s %9s %9s  speed >= %gx: %s, triangles <= %g: %s\n", "",
                "ratio", speed, triangles, "", "", "", kSpeedTarget, speed >= kSpeedTarget ? "yes" : "NO",
                kTriangleRatioTarget, triangles <= kTriangleRatioTarget ? "yes" : "NO");
    std::fflush(stdout);
    summary.push_back({name, max_error_m, speed, ours.triangleCount(), delatin.mesh.triangleCount()});
  }
}

int runBench(int argc, char** argv) {
  const BenchOptions options = parseOptions(argc, argv);
  // Delatin is single-threaded; by default so is buildTin here (it may use TBB internally).
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism,
                              static_cast<std::size_t>(options.threads));
  bench::ScratchDirectory scratch("terratiles_bench_tin");
  std::vector<Row> summary;
  for (const std::string& raster : options.rasters) benchRaster(raster, options, scratch.path(), summary);

  std::printf("\n== summary: speed = median over pairs of delatin time / terratiles time (target >= %gx), "
              "triangles = terratiles / delatin (target <= %g)\n", kSpeedTarget, kTriangleRatioTarget);
  for (const Row& row : summary) {
    const double speed = row.speed;
    const double triangles = static_cast<double>(row.ours_triangles) / static_cast<double>(row.delatin_triangles);
    std::printf("%-36s %6g m  speed %7.2fx %-3s  triangles %7.4f %s\n", row.raster.c_str(),
                row.max_error_m, speed, speed >= kSpeedTarget ? "ok" : "NO", triangles,
                triangles <= kTriangleRatioTarget ? "ok" : "NO");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_bench_tin", [&] { return runBench(argc, argv); });
}
