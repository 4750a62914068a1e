// Benchmark: how `terratiles build` scales with the input's size, on real-derived rasters of
// 37 M and 149 M pixels (issue 16's targets: the larger at most 2 GiB peak RSS, at most 1.25x
// the smaller's peak, seconds per M pixels within 1.25x).
//
//   terratiles_bench_scale [--source ETOPO5] [--dir DIR] [--sizes 8640x4320,17280x8640]
//                          [--tin-max-error 10] [--threads N] [--no-check] [--terratiles PATH]
//                          [--command build|tin] [--ranks N] [--resume-at F] [-- OPTION...]
//
// The rasters are ETOPO5 (../shared/data/etopo5_global_4326.tif) resampled in-process with
// GDALWarp, as `gdalwarp -r cubic -te -180 -90 180 90 -ts W H` (the -te keeps the pixels
// square: ETOPO5's own extent runs 2.5' past the poles), written once to DIR (default
// bench_scale/ beside this program) and reused. Each is built once, as a child process:
//   terratiles build RASTER -o DIR/out_WxH --tin-max-error E --progress json -f [--threads N]
// timed from spawn to reap, its peak resident set from wait4's ru_maxrss and the stage where
// it was reached from the `stage_done` lines. Then `terratiles check DIR/out_WxH` (unless
// --no-check), timed and measured the same way. The table gives seconds, M pixels per second,
// peak RSS and bytes per pixel, and the ratios of the largest raster to the smallest.
// --command tin times `terratiles tin RASTER -o DIR/out_WxH.ply` instead (pass --block-pixels
// after --); --ranks N runs it under `mpirun --allow-run-as-root --oversubscribe -np N` (its
// peak is the largest process's, as wait4 reports mpirun's reaped children).
// --resume-at F (0 < F < 1; needs --block-pixels after --) then times an interrupted build per
// raster: the same command into DIR/out_WxH_resumed, SIGKILLed after F times the first build's
// seconds, run again with --resume (timed), and its output compared byte for byte with the
// first build's (issue 16: killed half-way, the resumed run takes at most 60 %).
#include <gdal_priv.h>
#include <gdal_utils.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "src/base/error.h"
#include "tools/bench/bench_support.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

constexpr double kMegabyte = 1e6;
constexpr double kTargetPeakBytes = 2.0 * 1024 * 1024 * 1024;  // 2 GiB
constexpr double kTargetRatio = 1.25;

struct Size {
  int width = 0;
  int height = 0;
  double pixels() const { return static_cast<double>(width) * height; }
  std::string text() const { return std::to_string(width) + "x" + std::to_string(height); }
};

struct BenchOptions {
  std::string source;
  fs::path dir;
  std::vector<Size> sizes{{8640, 4320}, {17280, 8640}};
  double tin_max_error_m = 10;
  int threads = -1;  // -1: not passed
  bool check = true;
  std::string terratiles;
  std::vector<std::string> build_options;
  std::string command = "build";  // or "tin"
  int ranks = 0;                   // > 0: under mpirun -np ranks
  double resume_at = 0;            // > 0: also kill a build after this fraction of its time and resume it
};

constexpr const char* kUsage =
    "usage: terratiles_bench_scale [--source ETOPO5] [--dir DIR] [--sizes 8640x4320,17280x8640]\n"
    "                              [--tin-max-error 10] [--threads N] [--no-check] [--terratiles PATH]\n"
    "                              [--command build|tin] [--ranks N] [--resume-at F] [-- BUILD_OPTION...]\n"
    "  --source         the raster to resample (default ../shared/data/etopo5_global_4326.tif)\n"
    "  --dir            where the resampled rasters and the outputs go (default bench_scale/ beside\n"
    "                   this program); rasters already there are reused\n"
    "  --sizes          WxH,... of the global rasters, smallest first (gdalwarp -r cubic -ts W H)\n"
    "  --tin-max-error  metres (default 10)\n"
    "  --threads        passed to terratiles build (default: not passed, all cores)\n"
    "  --no-check       do not run terratiles check on the outputs\n"
    "  --terratiles     the terratiles executable (default: next to this program)\n"
    "  --command        build (default) or tin (no check; e.g. -- --block-pixels 2048)\n"
    "  --ranks          run it under mpirun -np N (with --threads 1: one thread per rank)\n"
    "  --resume-at F    also kill a build after F (0 < F < 1) of the first build's time, run it\n"
    "                   with --resume and compare its output (pass --block-pixels after --)\n"
    "  -- OPTION...     further options for the command\n";

Size parseSize(const std::string& text) {
  const std::size_t x = text.find('x');
  Size size;
  if (x != std::string::npos) {
    size.width = static_cast<int>(bench::parseNumber(text.substr(0, x), "--sizes"));
    size.height = static_cast<int>(bench::parseNumber(text.substr(x + 1), "--sizes"));
  }
  if (size.width < 2 || size.height < 2) {
    throw Error(ErrorCode::Usage, "--sizes expects WxH with W, H >= 2 (e.g. 8640x4320), found '" + text + "'");
  }
  return size;
}

BenchOptions parseOptions(int argc, char** argv) {
  BenchOptions options;
  const fs::path program_dir = fs::absolute(fs::path(argv[0])).parent_path();
  options.terratiles = (program_dir / "terratiles").string();
  options.dir = program_dir / "bench_scale";
  options.source = (fs::path(__FILE__).parent_path() / "../../../shared/data/etopo5_global_4326.tif").lexically_normal().string();
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " expects a value (see --help)");
      return argv[++i];
    };
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (arg == "--") {
      for (++i; i < argc; ++i) options.build_options.push_back(argv[i]);
    } else if (arg == "--source") {
      options.source = value();
    } else if (arg == "--dir") {
      options.dir = value();
    } else if (arg == "--sizes") {
      options.sizes.clear();
      std::istringstream list(value());
      for (std::string item; std::getline(list, item, ',');) options.sizes.push_back(parseSize(item));
      if (options.sizes.empty()) throw Error(ErrorCode::Usage, "--sizes expects at least one WxH");
    } else if (arg == "--tin-max-error") {
      options.tin_max_error_m = bench::parseNumber(value(), arg);
      if (!(options.tin_max_error_m > 0)) throw Error(ErrorCode::Usage, "--tin-max-error expects metres > 0");
    } else if (arg == "--threads") {
      options.threads = static_cast<int>(bench::parseNumber(value(), arg));
    } else if (arg == "--command") {
      options.command = value();
      if (options.command != "build" && options.command != "tin") {
        throw Error(ErrorCode::Usage, "--command expects build or tin, found '" + options.command + "'");
      }
    } else if (arg == "--ranks") {
      options.ranks = static_cast<int>(bench::parseNumber(value(), "--ranks"));
      if (options.ranks < 1) throw Error(ErrorCode::Usage, "--ranks expects at least 1");
    } else if (arg == "--resume-at") {
      options.resume_at = bench::parseNumber(value(), arg);
      if (!(options.resume_at > 0 && options.resume_at < 1)) {
        throw Error(ErrorCode::Usage, "--resume-at expects a fraction of the build's time between 0 and 1");
      }
    } else if (arg == "--no-check") {
      options.check = false;
    } else if (arg == "--terratiles") {
      options.terratiles = value();
    } else {
      throw Error(ErrorCode::Usage, "unknown argument '" + arg + "' (see --help)");
    }
  }
  if (options.resume_at > 0 && options.ranks > 0) {
    // SIGKILL reaches mpirun, not the ranks it started
    throw Error(ErrorCode::Usage, "--resume-at cannot be combined with --ranks");
  }
  if (!fs::exists(options.source)) {
    throw Error(ErrorCode::Input, options.source + ": no such file; pass ETOPO5 with --source");
  }
  return options;
}

// gdalwarp -r cubic -te -180 -90 180 90 -ts W H, in-process; written to a temporary name and
// renamed when complete.
fs::path resampledRaster(const BenchOptions& options, const Size& size) {
  const fs::path path = options.dir / ("etopo5_" + size.text() + ".tif");
  if (fs::exists(path)) return path;
  std::printf("making %s (gdalwarp -r cubic -te -180 -90 180 90 -ts %d %d) ...\n", path.c_str(), size.width,
              size.height);
  std::fflush(stdout);
  GDALAllRegister();
  GDALDatasetH source = GDALOpen(options.source.c_str(), GA_ReadOnly);
  if (!source) throw Error(ErrorCode::Input, options.source + ": GDAL cannot open it");
  const std::vector<std::string> words{"-of", "GTiff", "-r", "cubic", "-te", "-180", "-90", "180", "90", "-ts",
                                       std::to_string(size.width), std::to_string(size.height),
                                       "-co", "TILED=YES", "-co", "COMPRESS=DEFLATE", "-co", "BIGTIFF=IF_SAFER",
                                       "-multi", "-wo", "NUM_THREADS=ALL_CPUS"};
  std::vector<char*> argv;
  for (const std::string& word : words) argv.push_back(const_cast<char*>(word.c_str()));
  argv.push_back(nullptr);
  GDALWarpAppOptions* warp = GDALWarpAppOptionsNew(argv.data(), nullptr);
  const fs::path partial = path.string() + ".partial";
  int failed = 0;
  GDALDatasetH out = GDALWarp(partial.c_str(), nullptr, 1, &source, warp, &failed);
  GDALWarpAppOptionsFree(warp);
  GDALClose(source);
  if (!out || failed) throw Error(ErrorCode::Output, partial.string() + ": gdalwarp failed");
  GDALClose(out);
  fs::rename(partial, path);
  return path;
}

// One child run: seconds, peak and where the peak was set.
struct Measured {
  double seconds = 0;
  std::uint64_t peak_rss_bytes = 0;
  std::string peak_stage;
  std::string summary;  // the build's tiles and triangles, or the check's verdict
  std::string resumed;  // a --resume build's account of the blocks it found done
};

// `check_exit`: an exit status the command may end with and still be measured (check's 5:
// violations found, reported in the table instead of stopping the benchmark).
Measured measure(const std::vector<std::string>& args, int check_exit = -1) {
  const bench::ChildRun child = bench::runChild(args, true, "");
  const bool allowed = WIFEXITED(child.status) && WEXITSTATUS(child.status) == check_exit;
  if (!child.succeeded() && !allowed) {
    std::string last;
    std::istringstream lines(child.output);
    for (std::string line; std::getline(lines, line);) {
      if (line.find("error") != std::string::npos) last = line;
    }
    throw Error(ErrorCode::Internal, args[0] + " " + args[1] + " " + child.describe() + ": " + last);
  }
  Measured measured;
  if (allowed) measured.summary = "FAILED (exit " + std::to_string(check_exit) + "): ";
  measured.seconds = child.seconds;
  measured.peak_rss_bytes = child.peak_rss_bytes;
  std::uint64_t stage_peak = 0;
  std::istringstream lines(child.output);
  for (std::string line; std::getline(lines, line);) {
    if (!line.starts_with("{")) {
      // check's verdict and the problems it names
      if (line.find("terratiles check") == 0 || line.find("problem:") != std::string::npos ||
          line.find("terratiles: wrote") == 0) {
        measured.summary += line + " ";
      }
      continue;
    }
    const nlohmann::json event = nlohmann::json::parse(line, nullptr, false);
    if (event.is_discarded() || !event.is_object()) continue;
    const std::string kind = event.value("event", "");
    if (kind == "stage_done") {
      const std::uint64_t peak = event.value("peak_rss_bytes", std::uint64_t{0});
      if (peak > stage_peak) {
        stage_peak = peak;
        measured.peak_stage = event.value("stage", "");
      }
    } else if (kind == "note") {
      const std::string message = event.value("message", "");
      const std::size_t at = message.find("resumed: ");
      if (at != std::string::npos) measured.resumed = message.substr(at + 9);
    } else if (kind == "summary") {
      measured.summary = std::to_string(event.value("tiles", std::size_t{0})) + " tiles, " +
                         std::to_string(event.value("triangles", std::size_t{0})) + " triangles, check " +
                         event.value("check", std::string("?"));
    }
  }
  return measured;
}

// The regular files under `path`, relative to it, sorted; for a regular file, one empty path.
std::vector<fs::path> filesUnder(const fs::path& path) {
  if (fs::is_regular_file(path)) return {fs::path()};
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(path)) {
    if (entry.is_regular_file()) files.push_back(fs::relative(entry.path(), path));
  }
  std::sort(files.begin(), files.end());
  return files;
}

// "identical" when both hold the same files with the same bytes, else the first difference.
std::string compareOutputs(const fs::path& expected, const fs::path& found) {
  const std::vector<fs::path> expected_files = filesUnder(expected), found_files = filesUnder(found);
  if (expected_files != found_files) {
    return "DIFFERENT: " + std::to_string(found_files.size()) + " files against " +
           std::to_string(expected_files.size());
  }
  std::vector<char> a(1 << 20), b(1 << 20);
  for (const fs::path& file : expected_files) {
    // file is empty when the outputs are single files (`tin`'s .ply)
    std::ifstream in_a(file.empty() ? expected : expected / file, std::ios::binary);
    std::ifstream in_b(file.empty() ? found : found / file, std::ios::binary);
    if (!in_a || !in_b) return "DIFFERENT: cannot read " + (found / file).string();
    for (;;) {
      in_a.read(a.data(), static_cast<std::streamsize>(a.size()));
      in_b.read(b.data(), static_cast<std::streamsize>(b.size()));
      if (in_a.gcount() != in_b.gcount() || !std::equal(a.begin(), a.begin() + in_a.gcount(), b.begin())) {
        return "DIFFERENT: " + file.string();
      }
      if (in_a.gcount() == 0) break;
    }
  }
  return "identical (" + std::to_string(expected_files.size()) + " files)";
}

// An interrupted build and its resumption (--resume-at).
struct Resumed {
  double killed_at_seconds = 0;
  Measured resumed;
  std::string comparison;   // compareOutputs against the uninterrupted build
};

Resumed interruptAndResume(std::vector<std::string> args, const fs::path& out, const fs::path& resumed_out,
                           double full_seconds, double fraction) {
  for (std::string& arg : args) {
    if (arg == out.string()) arg = resumed_out.string();
  }
  Resumed result;
  result.killed_at_seconds = fraction * full_seconds;
  std::printf("interrupting %s after %.1f s ...\n", resumed_out.filename().c_str(), result.killed_at_seconds);
  std::fflush(stdout);
  const bench::ChildRun killed = bench::runChild(args, true, "", result.killed_at_seconds);
  if (!killed.killed) {
    throw Error(ErrorCode::Internal, "the run to interrupt " + killed.describe() + " before " +
                                         std::to_string(result.killed_at_seconds) + " s; pass a smaller --resume-at");
  }
  std::printf("resuming %s ...\n", resumed_out.filename().c_str());
  std::fflush(stdout);
  args.push_back("--resume");
  result.resumed = measure(args);
  result.comparison = compareOutputs(out, resumed_out);
  return result;
}

int runBench(int argc, char** argv) {
  const BenchOptions options = parseOptions(argc, argv);
  fs::create_directories(options.dir);
  std::vector<fs::path> rasters;
  for (const Size& size : options.sizes) rasters.push_back(resampledRaster(options, size));

  struct Row {
    Size size;
    Measured build, check;
    Resumed resumed;
  };
  std::vector<Row> rows;
  for (std::size_t i = 0; i < rasters.size(); ++i) {
    const bool tin = options.command == "tin";
    const fs::path out = options.dir / ("out_" + options.sizes[i].text() + (tin ? ".ply" : ""));
    char error_text[32];
    std::snprintf(error_text, sizeof error_text, "%g", options.tin_max_error_m);
    std::vector<std::string> args{options.terratiles, options.command, rasters[i].string(), "-o", out.string(),
                                  "--tin-max-error", error_text, "--progress", "json", "-f"};
    if (options.ranks > 0) {
      args.insert(args.begin(), {"mpirun", "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(options.ranks)});
    }
    if (options.threads >= 0) {
      args.push_back("--threads");
      args.push_back(std::to_string(options.threads));
    }
    args.insert(args.end(), options.build_options.begin(), options.build_options.end());
    std::printf("%s %s ...\n", tin ? "triangulating" : "building", rasters[i].filename().c_str());
    std::fflush(stdout);
    Row row{options.sizes[i], measure(args), {}, {}};
    if (options.check && !tin) {
      std::printf("checking %s ...\n", out.filename().c_str());
      std::fflush(stdout);
      row.check = measure({options.terratiles, "check", out.string(), "--progress", "json"}, 5);
    }
    if (options.resume_at > 0) {
      fs::path resumed_out = out;
      resumed_out.replace_filename(out.stem().string() + "_resumed" + out.extension().string());
      row.resumed = interruptAndResume(args, out, resumed_out, row.build.seconds, options.resume_at);
    }
    rows.push_back(row);
  }

  std::printf("\n%-12s %9s %9s %9s %10s %10s %7s  %-28s %9s %10s\n", "raster", "M px", "build s", "M px/s",
              "s per M px", "peak MB", "B/px", "peak set in", "check s", "check MB");
  for (const Row& row : rows) {
    const double mpx = row.size.pixels() / 1e6;
    std::printf("%-12s %9.1f %9.1f %9.3f %10.3f %10.0f %7.1f  %-28s %9.1f %10.0f\n", row.size.text().c_str(), mpx,
                row.build.seconds, mpx / row.build.seconds, row.build.seconds / mpx,
                static_cast<double>(row.build.peak_rss_bytes) / kMegabyte,
                static_cast<double>(row.build.peak_rss_bytes) / row.size.pixels(), row.build.peak_stage.c_str(),
                row.check.seconds, static_cast<double>(row.check.peak_rss_bytes) / kMegabyte);
  }
  for (const Row& row : rows) {
    std::printf("  %s: %s\n", row.size.text().c_str(), row.build.summary.c_str());
    if (options.check && options.command == "build") {
      std::printf("  %s check: %s\n", row.size.text().c_str(), row.check.summary.c_str());
    }
  }
  if (options.resume_at > 0) {
    std::printf("\nkilled after %.0f %% of the build's time, then run with --resume:\n", options.resume_at * 100);
    std::printf("%-12s %9s %10s %10s %11s  %s\n", "raster", "build s", "killed at", "resumed s", "resumed/all",
                "output against the build's");
    for (const Row& row : rows) {
      std::printf("%-12s %9.1f %10.1f %10.1f %10.0f%%  %s\n", row.size.text().c_str(), row.build.seconds,
                  row.resumed.killed_at_seconds, row.resumed.resumed.seconds,
                  100 * row.resumed.resumed.seconds / row.build.seconds, row.resumed.comparison.c_str());
      std::printf("  %s resumed: %s\n", row.size.text().c_str(), row.resumed.resumed.resumed.c_str());
    }
  }
  if (rows.size() >= 2) {
    const Row& small = rows.front();
    const Row& large = rows.back();
    const double time_ratio = (large.build.seconds / large.size.pixels()) / (small.build.seconds / small.size.pixels());
    const double peak_ratio =
        static_cast<double>(large.build.peak_rss_bytes) / static_cast<double>(small.build.peak_rss_bytes);
    std::printf("\n%s against %s: seconds per M px %.2fx (target <= %.2fx), peak RSS %.2fx (target <= %.2fx), "
                "peak %.0f MB (target <= %.0f MB)\n",
                large.size.text().c_str(), small.size.text().c_str(), time_ratio, kTargetRatio, peak_ratio,
                kTargetRatio, static_cast<double>(large.build.peak_rss_bytes) / kMegabyte, kTargetPeakBytes / kMegabyte);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_bench_scale", [&] { return runBench(argc, argv); });
}
