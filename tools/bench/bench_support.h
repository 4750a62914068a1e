#pragma once
// What the benchmark and experiment programs share: medians, timing, number options, a
// main() that turns errors into one line on stderr and the documented exit codes, scratch
// directories, child processes with their peak memory, and running the npm package delatin
// (tools/bench/delatin/run_delatin.mjs) on a raw height grid.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <system_error>
#include <vector>

#include "src/base/error.h"

namespace terratiles::bench {

// The middle value (the upper one of the two middles for an even count). values: not empty.
inline double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

// Wall-clock seconds one call of `function` takes.
template <typename Function>
double secondsOf(Function&& function) {
  const auto start = std::chrono::steady_clock::now();
  function();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// A finite number given to `option`; Error(Usage) naming the option otherwise.
inline double parseNumber(const std::string& text, const std::string& option) {
  double value = 0;
  const char* end = text.data() + text.size();
  const auto [next, ec] = std::from_chars(text.data(), end, value);
  if (text.empty() || ec != std::errc() || next != end || !std::isfinite(value)) {
    throw Error(ErrorCode::Usage, option + " expects a number, found '" + text + "'");
  }
  return value;
}

// RASTER[:TIN_MAX_ERROR], a raster argument of the experiment programs (error in metres,
// > 0; default 0.5), and the row label of their tables ("file.tif @0.5m").
struct RasterSpec {
  std::string path;
  double tin_max_error_m = 0.5;
};

inline RasterSpec parseRasterSpec(const std::string& arg) {
  RasterSpec raster;
  const std::size_t colon = arg.rfind(':');
  raster.path = arg.substr(0, colon);
  if (colon != std::string::npos) {
    raster.tin_max_error_m = parseNumber(arg.substr(colon + 1), "TIN_MAX_ERROR of " + raster.path);
    if (!(raster.tin_max_error_m > 0)) {
      throw Error(ErrorCode::Usage, "TIN_MAX_ERROR of " + raster.path + " expects a number > 0, found '" +
                                        arg.substr(colon + 1) + "'");
    }
  }
  return raster;
}

inline std::string rasterLabel(const RasterSpec& raster) {
  const std::size_t slash = raster.path.find_last_of('/');
  char error[32];
  std::snprintf(error, sizeof error, " @%gm", raster.tin_max_error_m);
  return (slash == std::string::npos ? raster.path : raster.path.substr(slash + 1)) + error;
}

// Runs `body` (returning the exit code) as a program's main: an Error becomes
// "NAME: error: ..." and its exit code, any other exception exit code 1.
template <typename Body>
int runProgram(const char* name, Body&& body) {
  try {
    return body();
  } catch (const Error& error) {
    std::fprintf(stderr, "%s: error: %s\n", name, error.what());
    return exitCodeFor(error.code());
  } catch (const std::exception& error) {
    std::fprintf(stderr, "%s: error: %s\n", name, error.what());
    return 1;
  }
}

// A scratch directory under TMPDIR (NAME.XXXXXX), removed with everything in it on every exit
// path. Throws Error(Output) when it cannot be created.
class ScratchDirectory {
 public:
  explicit ScratchDirectory(const std::string& name) {
    std::string pattern = (std::filesystem::temp_directory_path() / (name + ".XXXXXX")).string();
    if (!mkdtemp(pattern.data())) {
      throw Error(ErrorCode::Output, pattern + ": cannot create a scratch directory: " +
                                         std::strerror(errno) + " (set TMPDIR to a writable one)");
    }
    path_ = pattern;
  }
  ~ScratchDirectory() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  ScratchDirectory(const ScratchDirectory&) = delete;
  ScratchDirectory& operator=(const ScratchDirectory&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

static_assert(std::endian::native == std::endian::little,
              "the raw grid and Delatin's output file are little-endian");

// Writes heights as raw little-endian float32, in their order (row-major, row 0 north: the
// layout run_delatin.mjs reads). Throws Error(Output).
inline void writeRawGrid(std::span<const float> heights_m, const std::filesystem::path& path) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(heights_m.data()),
            static_cast<std::streamsize>(heights_m.size_bytes()));
  if (!out.flush()) throw Error(ErrorCode::Output, path.string() + ": cannot write the raw grid");
}

// The outcome of one child process (runChild).
struct ChildRun {
  int status = 0;                       // as waitpid reports it
  double seconds = 0;                   // wall clock, from spawning to reaping
  std::uint64_t peak_rss_bytes = 0;     // wait4's ru_maxrss: the child's peak resident set
  std::uint64_t floor_rss_bytes = 0;    // our resident set when spawning: see runChild
  std::string output;                   // its stdout and stderr, when captured
  bool killed = false;                  // we sent it SIGKILL (runChild's kill_after_seconds)

  bool succeeded() const { return WIFEXITED(status) && WEXITSTATUS(status) == 0; }
  // "exited with status 3" or "killed by signal 9".
  std::string describe() const {
    return WIFEXITED(status) ? "exited with status " + std::to_string(WEXITSTATUS(status))
                             : "killed by signal " + std::to_string(WTERMSIG(status));
  }
};

// Our resident set size now, in bytes (/proc/self/statm); 0 when unknown.
inline std::uint64_t currentResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  std::uint64_t size_pages = 0, resident_pages = 0;
  if (!(statm >> size_pages >> resident_pages)) return 0;
  return resident_pages * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
}

// Runs args (args[0] searched in PATH unless it holds a '/') with our stdin; with
// capture_output its stdout and stderr go to ChildRun::output, otherwise to ours. Returns once
// it has ended, whatever its status. Throws Error(Usage) with `start_hint` appended when it
// cannot be started. kill_after_seconds > 0 (with capture_output): SIGKILL it once that much
// wall clock has passed (how a benchmark interrupts a run half-way; see ChildRun::killed).
//
// Peak memory: posix_spawn's child starts on our address space (vfork), and Linux carries that
// address space's high-water mark into the child's ru_maxrss at exec. So we first reset our
// own mark to our current resident set (writing 5 to /proc/self/clear_refs, Linux >= 4.0):
// the child's figure is then max(its own peak, floor_rss_bytes), and callers should hold
// little memory when they spawn.
inline ChildRun runChild(const std::vector<std::string>& args, bool capture_output, const std::string& start_hint,
                         double kill_after_seconds = 0) {
  if (kill_after_seconds > 0 && !capture_output) {
    throw Error(ErrorCode::Internal, "runChild: kill_after_seconds needs capture_output");
  }
  std::vector<char*> argv;
  for (const std::string& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
  argv.push_back(nullptr);
  int pipe_fds[2] = {-1, -1};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (capture_output) {
    if (pipe2(pipe_fds, O_CLOEXEC) != 0) {
      throw Error(ErrorCode::Internal, "pipe2: " + std::string(std::strerror(errno)));
    }
    posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], STDERR_FILENO);
  }
  {
    std::ofstream clear_refs("/proc/self/clear_refs");
    clear_refs << "5" << std::flush;
  }
  ChildRun run;
  run.floor_rss_bytes = currentResidentBytes();
  std::fflush(nullptr);
  const auto start = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int spawn_error = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (capture_output) close(pipe_fds[1]);
  if (spawn_error) {
    if (capture_output) close(pipe_fds[0]);
    throw Error(ErrorCode::Usage, "cannot start " + args[0] + ": " + std::strerror(spawn_error) + start_hint);
  }
  if (capture_output) {
    char buffer[1 << 16];
    for (;;) {
      if (kill_after_seconds > 0 && !run.killed) {
        const double left =
            kill_after_seconds - std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        pollfd readable{pipe_fds[0], POLLIN, 0};
        const int ready = left > 0 ? poll(&readable, 1, static_cast<int>(std::ceil(left * 1000))) : 0;
        if (ready == 0) {  // time is up: the child has not closed its output, so it is not reaped yet
          kill(pid, SIGKILL);
          run.killed = true;
          continue;
        }
        if (ready < 0 && errno == EINTR) continue;
      }
      const ssize_t n = read(pipe_fds[0], buffer, sizeof buffer);
      if (n > 0) {
        run.output.append(buffer, static_cast<std::size_t>(n));
      } else if (n == 0 || errno != EINTR) {
        break;
      }
    }
    close(pipe_fds[0]);
  }
  rusage usage{};
  while (wait4(pid, &run.status, 0, &usage) < 0) {
    if (errno != EINTR) throw Error(ErrorCode::Internal, "wait4: " + std::string(std::strerror(errno)));
  }
  run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  run.peak_rss_bytes = static_cast<std::uint64_t>(usage.ru_maxrss) * 1024;  // Linux: kilobytes
  return run;
}

// The file run_delatin.mjs writes (its header comment is the format): Delatin's medians, its
// own error figures and its mesh as it returns it, coords (x = column, y = row) pixel indices.
struct DelatinOutput {
  double build_s = 0;             // median of new Delatin() + run()
  double run_only_s = 0;          // median of run() alone
  double own_max_error_m = 0;     // Delatin's getMaxError()
  double own_rmsd_m = 0;          // Delatin's getRMSD() (per triangle, not per pixel)
  std::vector<std::uint32_t> coords;     // 2 per vertex
  std::vector<std::uint32_t> triangles;  // 3 per triangle
  std::size_t vertexCount() const { return coords.size() / 2; }
  std::size_t triangleCount() const { return triangles.size() / 3; }
};

// Reads a run_delatin.mjs output; Error(Internal) when it is not one or is truncated.
inline DelatinOutput readDelatinOutput(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  const std::vector<char> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  const std::string where = path.string() + ": ";
  constexpr std::size_t kHeaderBytes = 8 + 4 * 4 + 4 * 8;
  if (bytes.size() < kHeaderBytes || std::memcmp(bytes.data(), "DELATIN1", 8) != 0) {
    throw Error(ErrorCode::Internal, where + "not a run_delatin.mjs output (no DELATIN1 header)");
  }
  std::uint32_t counts[4];
  double values[4];
  std::memcpy(counts, bytes.data() + 8, sizeof counts);
  std::memcpy(values, bytes.data() + 8 + sizeof counts, sizeof values);
  const std::size_t vertex_count = counts[0], triangle_count = counts[1];
  const std::size_t expected = kHeaderBytes + 4 * (2 * vertex_count + 3 * triangle_count);
  if (bytes.size() != expected) {
    throw Error(ErrorCode::Internal,
                where + std::to_string(bytes.size()) + " bytes, expected " + std::to_string(expected));
  }
  DelatinOutput output;
  output.build_s = values[0];
  output.run_only_s = values[1];
  output.own_max_error_m = values[2];
  output.own_rmsd_m = values[3];
  output.coords.resize(2 * vertex_count);
  output.triangles.resize(3 * triangle_count);
  std::memcpy(output.coords.data(), bytes.data() + kHeaderBytes, output.coords.size() * 4);
  std::memcpy(output.triangles.data(), bytes.data() + kHeaderBytes + output.coords.size() * 4,
              output.triangles.size() * 4);
  return output;
}

// Fails fast, before any timed run, when `script` (run_delatin.mjs) does not exist or Node
// would not find the delatin package from it: no node_modules/delatin in its folder or any
// folder above (Node's own lookup). Throws Error(Usage) naming the fix.
inline void requireDelatinScript(const std::string& script) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(script, ec)) {
    throw Error(ErrorCode::Usage,
                "--script: " + script + " does not exist; pass the path of tools/bench/delatin/run_delatin.mjs");
  }
  for (fs::path folder = fs::absolute(script, ec).parent_path(); !folder.empty(); folder = folder.parent_path()) {
    if (fs::exists(folder / "node_modules" / "delatin" / "package.json", ec)) return;
    if (folder == folder.root_path()) break;
  }
  throw Error(ErrorCode::Usage, "--script: " + script +
                                    " cannot find the delatin package (no node_modules/delatin beside it or "
                                    "above); run npm ci in tools/bench/delatin");
}

// Runs `node script RAW WIDTH HEIGHT MAX_ERROR 1 OUT` (one untimed warm-up build inside node,
// then one timed: see run_delatin.mjs) on the raw grid `raw` (writeRawGrid; no NaN) and
// returns what it wrote to `out`. Throws Error(Usage) when node cannot be started,
// Error(Internal) when the script fails.
inline DelatinOutput runDelatin(const std::string& node, const std::string& script,
                                const std::filesystem::path& raw, int width, int height, double max_error_m,
                                const std::filesystem::path& out) {
  char error_text[64];
  std::snprintf(error_text, sizeof error_text, "%.17g", max_error_m);
  const std::vector<std::string> args{node, script, raw.string(), std::to_string(width),
                                      std::to_string(height), error_text, "1", out.string()};
  const ChildRun run = runChild(args, false, " (install Node.js >= 20 or pass --node PATH)");
  if (!run.succeeded()) {
    std::string command;
    for (const std::string& arg : args) command += (command.empty() ? "" : " ") + arg;
    throw Error(ErrorCode::Internal,
                command + ": " + run.describe() + " (did you run npm ci in tools/bench/delatin?)");
  }
  return readDelatinOutput(out);
}

}  // namespace terratiles::bench
