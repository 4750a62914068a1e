// Benchmark: the whole default `terratiles build` (TIN, cluster levels, tiles, tileset.json,
// report and its check) against the npm package delatin 0.2.0 building one TIN of the same
// raster at the same max error: the project's headline figure, build time / Delatin time
// (target <= 1.0x, aim 0.5x).
//
//   terratiles_bench_build RASTER... [--runs 3] [--tin-max-error 0.5] [--threads N]
//                          [--terratiles PATH] [--node node] [--script PATH] [--json]
//                          [-- BUILD_OPTION...]
//
// Every raster is read first (readDem: an unreadable one stops the benchmark before any run,
// exit 3) and its heights written once as the raw float32 grid run_delatin.mjs reads (as
// terratiles_bench_tin does). Nodata pixels, which Delatin cannot take, are filled in that grid
// only: each takes the height of its nearest valid pixel in 4-neighbour steps (breadth-first
// from every valid pixel at once, in row-major order, so ties go to the first found); the
// output says so. The build reads the raster itself, nodata and all.
//
// Then --runs interleaved pairs: the build as a child process,
//   terratiles build RASTER -o SCRATCH/out --tin-max-error E --progress json -f
//                    [--threads N] [BUILD_OPTION...]
// timed wall-clock from spawn to reap, its peak resident set from wait4's ru_maxrss, its
// per-stage seconds from the `stage_done` lines on its stderr and the total from the
// `summary` line; then `node run_delatin.mjs` (one untimed warm-up build inside node, then one
// timed `new Delatin()` + `run()`). Reported per raster: the medians, the median of the
// pairs' ratios build / Delatin (which cancels noise that lasts longer than a pair), the
// medians of the stage groups, the peak RSS and bytes per input pixel.
#include <malloc.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/dem/dem_grid.h"
#include "tools/bench/bench_support.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

using bench::median;
using bench::parseNumber;

constexpr double kRatioTarget = 1.0;  // build time / Delatin time, at most
constexpr double kRatioAim = 0.5;
constexpr double kMegabyte = 1e6;

struct BenchOptions {
  std::vector<std::string> rasters;
  int runs = 3;
  double tin_max_error_m = 0.5;
  int threads = -1;  // -1: not passed (the build's default, all cores)
  std::string terratiles;  // default: next to this program
  std::string node = "node";
  // Next to this source file, so the program runs from any directory of a source checkout.
  std::string script = (fs::path(__FILE__).parent_path() / "delatin" / "run_delatin.mjs").string();
  bool json = false;
  std::vector<std::string> build_options;  // after --
};

constexpr const char* kUsage =
    "usage: terratiles_bench_build RASTER... [--runs 3] [--tin-max-error 0.5] [--threads N]\n"
    "                              [--terratiles PATH] [--node node] [--script PATH] [--json]\n"
    "                              [-- BUILD_OPTION...]\n"
    "  --runs           pairs of runs (terratiles build, then Delatin); medians are reported (default 3)\n"
    "  --tin-max-error  max vertical error in metres, for both (default 0.5; SRTM wants 5-10)\n"
    "  --threads        passed to terratiles build as --threads N (0: all cores; default: not passed,\n"
    "                   the build's default, all cores); Delatin is single-threaded\n"
    "  --terratiles     the terratiles executable (default: next to this program)\n"
    "  --node           the node executable (default node, searched in PATH)\n"
    "  --script         tools/bench/delatin/run_delatin.mjs (default: next to this source file)\n"
    "  --json           print one JSON document on stdout instead of the tables\n"
    "  -- OPTION...     further options for terratiles build, e.g. -- --scheme geographic\n";

// The build options the benchmark sets itself: passing them after -- would contradict it.
bool isReservedBuildOption(const std::string& arg) {
  const std::string name = arg.substr(0, arg.find('='));
  for (const char* reserved : {"-o", "--output", "--progress", "-q", "--quiet", "--threads", "--tin-max-error"}) {
    if (name == reserved) return true;
  }
  return false;
}

BenchOptions parseOptions(int argc, char** argv) {
  BenchOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " expects a value (see --help)");
      return argv[++i];
    };
    auto wholeNumber = [&](double minimum) {
      const std::string text = value();
      const double number = parseNumber(text, arg);
      if (number < minimum || number != std::floor(number) || number > 1e6) {
        throw Error(ErrorCode::Usage, arg + " expects a whole number >= " + std::to_string(static_cast<int>(minimum)) +
                                          ", found " + text);
      }
      return static_cast<int>(number);
    };
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (arg == "--") {
      for (++i; i < argc; ++i) {
        if (isReservedBuildOption(argv[i])) {
          throw Error(ErrorCode::Usage, std::string("the build option ") + argv[i] +
                                            " is set by the benchmark itself (-o, --progress, -q, --threads, --tin-max-error); "
                                            "give --threads and --tin-max-error before --");
        }
        options.build_options.push_back(argv[i]);
      }
    } else if (arg == "--runs") {
      options.runs = wholeNumber(1);
    } else if (arg == "--threads") {
      options.threads = wholeNumber(0);
    } else if (arg == "--tin-max-error") {
      const std::string text = value();
      options.tin_max_error_m = parseNumber(text, arg);
      if (!(options.tin_max_error_m > 0)) throw Error(ErrorCode::Usage, arg + " expects a number > 0, found " + text);
    } else if (arg == "--terratiles") {
      options.terratiles = value();
    } else if (arg == "--node") {
      options.node = value();
    } else if (arg == "--script") {
      options.script = value();
    } else if (arg == "--json") {
      options.json = true;
    } else if (arg.starts_with("-")) {
      throw Error(ErrorCode::Usage, "unknown option " + arg + " (see --help)");
    } else {
      options.rasters.push_back(arg);
    }
  }
  if (options.rasters.empty()) throw Error(ErrorCode::Usage, "no RASTER given (see --help)");
  if (options.terratiles.empty()) {
    std::error_code ec;
    const fs::path self = fs::read_symlink("/proc/self/exe", ec);
    options.terratiles = (self.parent_path() / "terratiles").string();
  }
  if (access(options.terratiles.c_str(), X_OK) != 0) {
    throw Error(ErrorCode::Usage, "--terratiles: " + options.terratiles +
                                      " is not an executable; build the terratiles target or pass --terratiles PATH");
  }
  bench::requireDelatinScript(options.script);
  return options;
}

// Fills every NaN of the width x height grid with the height of its nearest valid pixel in
// 4-neighbour steps: breadth-first from all valid pixels at once, seeded in row-major order,
// so of several equally near ones the first found wins. Returns the pixels filled; throws
// Error(Input) when no pixel is valid.
std::size_t fillNodataWithNearest(std::vector<float>& heights_m, int width, int height, const std::string& where) {
  std::vector<std::uint32_t> queue;
  queue.reserve(heights_m.size());
  for (std::size_t i = 0; i < heights_m.size(); ++i) {
    if (!std::isnan(heights_m[i])) queue.push_back(static_cast<std::uint32_t>(i));
  }
  if (queue.empty()) throw Error(ErrorCode::Input, where + ": every pixel is nodata; expected a DEM with heights");
  const std::size_t filled = heights_m.size() - queue.size();
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const std::uint32_t i = queue[head];
    const int col = static_cast<int>(i % static_cast<std::uint32_t>(width));
    const int row = static_cast<int>(i / static_cast<std::uint32_t>(width));
    auto visit = [&](int c, int r) {
      if (c < 0 || r < 0 || c >= width || r >= height) return;
      const std::uint32_t j = static_cast<std::uint32_t>(r) * static_cast<std::uint32_t>(width) + static_cast<std::uint32_t>(c);
      if (!std::isnan(heights_m[j])) return;
      heights_m[j] = heights_m[i];
      queue.push_back(j);
    };
    visit(col, row - 1);
    visit(col - 1, row);
    visit(col + 1, row);
    visit(col, row + 1);
  }
  return filled;
}

// A raster read and written as Delatin's grid, before any run.
struct PreparedRaster {
  std::string path;
  std::string name;  // file name
  std::string crs_name;
  int width = 0;
  int height = 0;
  std::size_t nodata_pixels = 0;  // filled for Delatin
  fs::path raw;
  std::size_t pixelCount() const { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
};

PreparedRaster prepareRaster(const std::string& path, const fs::path& raw) {
  PreparedRaster raster;
  raster.path = path;
  raster.name = fs::path(path).filename().string();
  raster.raw = raw;
  {
    DemGrid dem = readDem({path});
    raster.crs_name = dem.crs_name;
    raster.width = dem.width;
    raster.height = dem.height;
    raster.nodata_pixels = fillNodataWithNearest(dem.heights_m, dem.width, dem.height, path);
    bench::writeRawGrid(dem.heights_m, raw);
  }
  // Give the grid back to the system: a child's ru_maxrss is at least our resident set when it
  // is spawned (see bench::runChild).
  malloc_trim(0);
  return raster;
}

// The stage groups of the build, in the order of the table.
enum StageGroup { kTin, kPartition, kSimplify, kMeasure, kAssignWrite, kReportCheck, kOther, kGroupCount };
constexpr std::array<const char*, kGroupCount> kGroupNames = {"TIN", "partition", "simplify", "measure",
                                                              "assign + write", "report + check", "other"};
constexpr const char* kGroupRule =
    "TIN: stages starting with \"TIN\"; partition: \"level N: clusters\"; simplify: \"level N: simplifying ...\"; "
    "measure: \"level N: measuring\" or \"placing vertices\" and placing the pixels on the globe; assign + write: assigning clusters to "
    "tiles, writing tiles; report + check: every stage after writing tiles; other: the rest (reading the DEM...)";

// `after_writing`: a "writing tiles" stage has ended before this one.
StageGroup groupOf(const std::string& stage, bool after_writing) {
  if (after_writing) return kReportCheck;
  if (stage.starts_with("TIN")) return kTin;
  if (stage.starts_with("level ")) {
    if (stage.find(": clusters") != std::string::npos) return kPartition;
    if (stage.find(": simplifying") != std::string::npos) return kSimplify;
    if (stage.find(": measuring") != std::string::npos || stage.find(": placing vertices") != std::string::npos) {
      return kMeasure;
    }
  }
  if (stage.starts_with("placing the DEM")) return kMeasure;
  if (stage == "assigning clusters to tiles" || stage == "writing tiles") return kAssignWrite;
  return kOther;
}

// One `terratiles build` run, from its process and its JSON lines.
struct BuildRun {
  double wall_s = 0;
  double summary_s = 0;  // the summary event's seconds
  double staged_s = 0;   // sum of every stage_done
  std::array<double, kGroupCount> group_s{};
  std::uint64_t peak_rss_bytes = 0;
  std::uint64_t floor_rss_bytes = 0;
  std::string peak_stage;  // the first stage that ended at the final peak (the child's own figure)
  std::size_t tiles = 0;
  std::size_t triangles = 0;
  std::string check;
};

ErrorCode errorCodeOfExit(int status) {
  if (!WIFEXITED(status)) return ErrorCode::Internal;
  switch (WEXITSTATUS(status)) {
    case 2: return ErrorCode::Usage;
    case 3: return ErrorCode::Input;
    case 4: return ErrorCode::Output;
    case 6: return ErrorCode::OutOfMemory;
    default: return ErrorCode::Internal;
  }
}

BuildRun parseBuildOutput(const bench::ChildRun& child, const std::string& command) {
  BuildRun run;
  run.wall_s = child.seconds;
  run.peak_rss_bytes = child.peak_rss_bytes;
  run.floor_rss_bytes = child.floor_rss_bytes;
  bool after_writing = false, summary_seen = false;
  std::uint64_t stage_peak = 0;
  std::istringstream lines(child.output);
  for (std::string line; std::getline(lines, line);) {
    if (!line.starts_with("{")) continue;  // not one of the JSON lines (a library's warning)
    const nlohmann::json event = nlohmann::json::parse(line, nullptr, false);
    if (event.is_discarded() || !event.is_object()) continue;
    const std::string kind = event.value("event", "");
    if (kind == "stage_done") {
      const std::string stage = event.value("stage", "");
      const double seconds = event.value("seconds", 0.0);
      run.group_s[groupOf(stage, after_writing)] += seconds;
      run.staged_s += seconds;
      if (stage == "writing tiles") after_writing = true;
      const std::uint64_t peak = event.value("peak_rss_bytes", std::uint64_t{0});
      if (peak > stage_peak) {
        stage_peak = peak;
        run.peak_stage = stage;
      }
    } else if (kind == "summary") {
      summary_seen = true;
      run.summary_s = event.value("seconds", 0.0);
      run.tiles = event.value("tiles", std::size_t{0});
      run.triangles = event.value("triangles", std::size_t{0});
      run.check = event.value("check", "");
    }
  }
  if (!summary_seen) {
    throw Error(ErrorCode::Internal, command + ": printed no {\"event\":\"summary\"} line on stderr; expected "
                                               "--progress json output");
  }
  return run;
}

// The last line of the child's output that says what went wrong, for our one-line error.
std::string errorLineOf(const std::string& output) {
  std::istringstream lines(output);
  std::string found;
  for (std::string line; std::getline(lines, line);) {
    if (line.find("error") != std::string::npos) found = line;
  }
  return found.empty() ? "(no error message)" : found;
}

BuildRun runBuild(const BenchOptions& options, const PreparedRaster& raster, const fs::path& out) {
  std::error_code ignored;
  fs::remove_all(out, ignored);  // untimed: every build writes a fresh directory
  char error_text[64];
  std::snprintf(error_text, sizeof error_text, "%.17g", options.tin_max_error_m);
  std::vector<std::string> args{options.terratiles, "build", raster.path, "-o", out.string(),
                                "--tin-max-error", error_text, "--progress", "json", "-f"};
  if (options.threads >= 0) args.insert(args.end(), {"--threads", std::to_string(options.threads)});
  args.insert(args.end(), options.build_options.begin(), options.build_options.end());
  std::string command;
  for (std::size_t i = 1; i < args.size(); ++i) command += (command.empty() ? "terratiles " : " ") + args[i];
  const bench::ChildRun child = bench::runChild(args, true, " (build the terratiles target or pass --terratiles PATH)");
  if (!child.succeeded()) {
    throw Error(errorCodeOfExit(child.status), command + ": " + child.describe() + ": " + errorLineOf(child.output));
  }
  BuildRun run = parseBuildOutput(child, command);
  fs::remove_all(out, ignored);
  return run;
}

struct RasterResult {
  PreparedRaster raster;
  std::vector<BuildRun> builds;
  std::vector<double> delatin_s;
  std::vector<double> ratios;  // per pair: build wall seconds / Delatin seconds
  std::size_t delatin_triangles = 0, delatin_vertices = 0;

  template <typename Field>
  double medianOf(Field field) const {
    std::vector<double> values;
    for (const BuildRun& build : builds) values.push_back(field(build));
    return median(values);
  }
  double buildS() const { return medianOf([](const BuildRun& b) { return b.wall_s; }); }
  double summaryS() const { return medianOf([](const BuildRun& b) { return b.summary_s; }); }
  double peakRssBytes() const { return medianOf([](const BuildRun& b) { return static_cast<double>(b.peak_rss_bytes); }); }
  double bytesPerPixel() const { return peakRssBytes() / static_cast<double>(raster.pixelCount()); }
};

RasterResult benchRaster(const PreparedRaster& raster, const BenchOptions& options, const fs::path& scratch) {
  RasterResult result;
  result.raster = raster;
  const fs::path out = scratch / "out";
  const fs::path delatin_out = scratch / "delatin.bin";
  for (int r = 0; r < options.runs; ++r) {
    std::fprintf(stderr, "%s: pair %d of %d: terratiles build\n", raster.name.c_str(), r + 1, options.runs);
    result.builds.push_back(runBuild(options, raster, out));
    const BuildRun& build = result.builds.back();
    std::fprintf(stderr, "%s: pair %d of %d: build %.3f s, peak %.1f MB; Delatin\n", raster.name.c_str(), r + 1,
                 options.runs, build.wall_s, static_cast<double>(build.peak_rss_bytes) / kMegabyte);
    const bench::DelatinOutput delatin = bench::runDelatin(options.node, options.script, raster.raw, raster.width,
                                                           raster.height, options.tin_max_error_m, delatin_out);
    result.delatin_s.push_back(delatin.build_s);
    result.ratios.push_back(build.wall_s / delatin.build_s);
    result.delatin_triangles = delatin.triangleCount();
    result.delatin_vertices = delatin.vertexCount();
    std::fprintf(stderr, "%s: pair %d of %d: Delatin %.3f s; ratio %.2fx\n", raster.name.c_str(), r + 1,
                 options.runs, delatin.build_s, result.ratios.back());
  }
  return result;
}

std::string threadsLabel(const BenchOptions& options) {
  if (options.threads < 0) return "all cores (the build's default)";
  if (options.threads == 0) return "--threads 0 (all cores)";
  return "--threads " + std::to_string(options.threads);
}

std::string joined(const std::vector<std::string>& words) {
  std::string text;
  for (const std::string& word : words) text += (text.empty() ? "" : " ") + word;
  return text;
}

std::string filledNote(const PreparedRaster& raster) {
  char text[256];
  std::snprintf(text, sizeof text,
                "Delatin saw a filled grid: %zu nodata pixels (%.2f %%) took the height of their nearest valid "
                "pixel (4-neighbour steps); the build saw the nodata",
                raster.nodata_pixels, 100.0 * static_cast<double>(raster.nodata_pixels) /
                                          static_cast<double>(raster.pixelCount()));
  return text;
}

// "1.234 1.301 1.250": the runs in order, for the tables.
template <typename Values>
std::string runsText(const Values& values, const char* format) {
  std::string text;
  for (const double value : values) {
    char number[32];
    std::snprintf(number, sizeof number, format, value);
    if (!text.empty()) text += ' ';
    text += number;
  }
  return text;
}

void printRasterTable(const RasterResult& result, const BenchOptions& options) {
  const PreparedRaster& raster = result.raster;
  std::printf("\n== %s: %d x %d px (%zu), %s, max error %g m\n", raster.name.c_str(), raster.width, raster.height,
              raster.pixelCount(), raster.crs_name.c_str(), options.tin_max_error_m);
  if (raster.nodata_pixels) std::printf("%s\n", filledNote(raster).c_str());
  std::printf("%d pair(s) of runs (terratiles build, then Delatin); build threads: %s%s%s\n", options.runs,
              threadsLabel(options).c_str(), options.build_options.empty() ? "" : "; build options: ",
              joined(options.build_options).c_str());
  const BuildRun& last = result.builds.back();
  std::printf("build: %zu tiles, %zu triangles (all zooms), check %s; Delatin: %zu triangles, %zu vertices\n",
              last.tiles, last.triangles, last.check.c_str(), result.delatin_triangles, result.delatin_vertices);
  std::vector<double> wall, summary, peak_mb;
  for (const BuildRun& build : result.builds) {
    wall.push_back(build.wall_s);
    summary.push_back(build.summary_s);
    peak_mb.push_back(static_cast<double>(build.peak_rss_bytes) / kMegabyte);
  }
  const double ratio = median(result.ratios);
  std::printf("%-36s %10s  %s\n", "", "median", "runs");
  std::printf("%-36s %10.3f  %s\n", "build wall [s]", result.buildS(), runsText(wall, "%.3f").c_str());
  std::printf("%-36s %10.3f  %s\n", "build summary seconds [s]", result.summaryS(), runsText(summary, "%.3f").c_str());
  std::printf("%-36s %10.3f  %s\n", "Delatin, one TIN [s]", median(result.delatin_s),
              runsText(result.delatin_s, "%.3f").c_str());
  std::printf("%-36s %9.2fx  %s   target <= %.1fx: %s, aim %.1fx\n", "ratio build / Delatin (pair median)", ratio,
              runsText(result.ratios, "%.2f").c_str(), kRatioTarget, ratio <= kRatioTarget ? "yes" : "NO", kRatioAim);
  const double summary_s = result.summaryS();
  for (int g = 0; g < kGroupCount; ++g) {
    std::vector<double> values;
    for (const BuildRun& build : result.builds) values.push_back(build.group_s[static_cast<std::size_t>(g)]);
    const double m = median(values);
    std::printf("  %-34s %10.3f  %s   %4.1f %%\n", (std::string("stage ") + kGroupNames[static_cast<std::size_t>(g)]).c_str(),
                m, runsText(values, "%.3f").c_str(), summary_s > 0 ? 100 * m / summary_s : 0.0);
  }
  std::vector<double> unstaged, outside;
  for (const BuildRun& build : result.builds) {
    unstaged.push_back(build.summary_s - build.staged_s);
    outside.push_back(build.wall_s - build.summary_s);
  }
  std::printf("  %-38s %6.3f  %s\n", "in no stage (summary - stages)", median(unstaged), runsText(unstaged, "%.3f").c_str());
  std::printf("  %-38s %6.3f  %s\n", "outside the pipeline (wall - summary)", median(outside),
              runsText(outside, "%.3f").c_str());
  const double floor_mb = static_cast<double>(last.floor_rss_bytes) / kMegabyte;
  std::printf("%-36s %10.1f  %s   (set in stage \"%s\"; floor %.1f MB: the benchmark's own RSS at spawn)\n",
              "peak RSS [MB]", result.peakRssBytes() / kMegabyte, runsText(peak_mb, "%.1f").c_str(),
              last.peak_stage.c_str(), floor_mb);
  std::printf("%-36s %10.0f\n", "peak RSS / input pixel [bytes]", result.bytesPerPixel());
  std::fflush(stdout);
}

void printSummary(const std::vector<RasterResult>& results, const BenchOptions& options) {
  std::printf("\n== summary: max error %g m, build threads: %s; ratio = median over pairs of build wall time / "
              "Delatin time (target <= %.1fx, aim %.1fx)\n",
              options.tin_max_error_m, threadsLabel(options).c_str(), kRatioTarget, kRatioAim);
  std::printf("%-36s %10s %10s %8s %9s %9s\n", "raster", "build [s]", "Delatin [s]", "ratio", "peak MB", "B/pixel");
  bool any_filled = false;
  for (const RasterResult& result : results) {
    const double ratio = median(result.ratios);
    any_filled = any_filled || result.raster.nodata_pixels > 0;
    std::printf("%-36s %10.3f %10.3f %7.2fx %9.1f %9.0f  %s%s\n", result.raster.name.c_str(), result.buildS(),
                median(result.delatin_s), ratio, result.peakRssBytes() / kMegabyte, result.bytesPerPixel(),
                ratio <= kRatioTarget ? "ok" : "NO", result.raster.nodata_pixels ? "  *" : "");
  }
  if (any_filled) std::printf("* Delatin saw a filled grid (nodata pixels took their nearest valid pixel's height)\n");
}

nlohmann::json toJson(const std::vector<RasterResult>& results, const BenchOptions& options) {
  nlohmann::json doc;
  doc["tin_max_error_m"] = options.tin_max_error_m;
  doc["runs"] = options.runs;
  doc["threads"] = options.threads < 0 ? nlohmann::json(nullptr) : nlohmann::json(options.threads);
  doc["build_options"] = options.build_options;
  doc["stage_groups"] = kGroupRule;
  doc["ratio_target"] = kRatioTarget;
  doc["ratio_aim"] = kRatioAim;
  for (const RasterResult& result : results) {
    const PreparedRaster& raster = result.raster;
    nlohmann::json entry;
    entry["raster"] = raster.path;
    entry["width"] = raster.width;
    entry["height"] = raster.height;
    entry["crs"] = raster.crs_name;
    entry["nodata_pixels"] = raster.nodata_pixels;
    entry["delatin_grid"] = raster.nodata_pixels ? "filled: nodata pixels took their nearest valid pixel's height "
                                                   "(4-neighbour steps)"
                                                 : "as read";
    entry["build_s"] = result.buildS();
    entry["build_summary_s"] = result.summaryS();
    entry["delatin_s"] = median(result.delatin_s);
    entry["ratio"] = median(result.ratios);
    entry["peak_rss_bytes"] = result.peakRssBytes();
    entry["peak_rss_bytes_per_pixel"] = result.bytesPerPixel();
    entry["delatin_triangles"] = result.delatin_triangles;
    entry["delatin_vertices"] = result.delatin_vertices;
    for (int g = 0; g < kGroupCount; ++g) {
      std::vector<double> values;
      for (const BuildRun& build : result.builds) values.push_back(build.group_s[static_cast<std::size_t>(g)]);
      entry["stage_s"][kGroupNames[static_cast<std::size_t>(g)]] = median(values);
    }
    for (std::size_t r = 0; r < result.builds.size(); ++r) {
      const BuildRun& build = result.builds[r];
      nlohmann::json run;
      run["build_s"] = build.wall_s;
      run["build_summary_s"] = build.summary_s;
      run["build_staged_s"] = build.staged_s;
      run["delatin_s"] = result.delatin_s[r];
      run["ratio"] = result.ratios[r];
      run["peak_rss_bytes"] = build.peak_rss_bytes;
      run["floor_rss_bytes"] = build.floor_rss_bytes;
      run["peak_stage"] = build.peak_stage;
      run["tiles"] = build.tiles;
      run["triangles"] = build.triangles;
      run["check"] = build.check;
      for (int g = 0; g < kGroupCount; ++g) {
        run["stage_s"][kGroupNames[static_cast<std::size_t>(g)]] = build.group_s[static_cast<std::size_t>(g)];
      }
      entry["runs"].push_back(run);
    }
    doc["rasters"].push_back(entry);
  }
  return doc;
}

int runBench(int argc, char** argv) {
  const BenchOptions options = parseOptions(argc, argv);
  bench::ScratchDirectory scratch("terratiles_bench_build");
  // Every raster first, so an unreadable one stops us before the first (long) run.
  std::vector<PreparedRaster> rasters;
  for (std::size_t i = 0; i < options.rasters.size(); ++i) {
    std::fprintf(stderr, "reading %s\n", options.rasters[i].c_str());
    rasters.push_back(prepareRaster(options.rasters[i], scratch.path() / ("grid" + std::to_string(i) + ".f32")));
  }
  if (!options.json) std::printf("stage groups: %s\n", kGroupRule);
  std::vector<RasterResult> results;
  for (const PreparedRaster& raster : rasters) {
    results.push_back(benchRaster(raster, options, scratch.path()));
    if (!options.json) printRasterTable(results.back(), options);
  }
  if (options.json) {
    std::printf("%s\n", toJson(results, options).dump(2).c_str());
  } else {
    printSummary(results, options);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_bench_build", [&] { return runBench(argc, argv); });
}
