#pragma once
// What the benchmark and experiment programs share: medians, timing, number options and a
// main() that turns errors into one line on stderr and the documented exit codes.

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
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

}  // namespace terratiles::bench
