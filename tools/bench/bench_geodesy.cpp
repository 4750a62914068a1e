// Benchmark: EPSG:2056 (LV95) -> WGS84 lon/lat for a batch of points on one core, by the
// rigorous swisstopo formulas (terratiles) and by PROJ through GDAL, side by side in one run.
// Prints the median of several alternating repetitions, points per second and the ratio,
// and the largest difference between the two answers.
//
//   terratiles_bench_geodesy [POINTS=10000000] [REPETITIONS=5]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <vector>

#include "tools/bench/bench_support.h"
#include "src/geo/crs_transform.h"
#include "src/geo/swiss_lv95.h"

using namespace terratiles;

using bench::median;
using bench::secondsOf;

int main(int argc, char** argv) {
  const std::size_t count = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 10'000'000;
  const int repetitions = argc > 2 ? std::atoi(argv[2]) : 5;
  // A dense grid over the LV95 domain with terrain-like heights.
  std::vector<CrsPoint> lv95(count);
  std::vector<double> heights(count);
  const std::size_t side = static_cast<std::size_t>(std::sqrt(static_cast<double>(count))) + 1;
  for (std::size_t i = 0; i < count; ++i) {
    const double u = static_cast<double>(i % side) / side, v = static_cast<double>(i / side) / side;
    lv95[i] = {2485000.0 + u * 349000.0, 1075000.0 + v * 221000.0};
    heights[i] = 400.0 + 3000.0 * u * v;
  }
  std::vector<GeodeticPoint> rigorous(count), proj(count);
  const CrsToWgs84 via_proj("EPSG:2056", TransformEngine::Proj);

  std::vector<double> rigorous_s, proj_s;
  for (int r = 0; r < repetitions; ++r) {
    for (std::size_t i = 0; i < count; ++i) rigorous[i].height_m = proj[i].height_m = heights[i];
    rigorous_s.push_back(secondsOf([&] { lv95ToWgs84(lv95, rigorous); }));
    proj_s.push_back(secondsOf([&] { via_proj.transform(lv95, proj); }));
  }
  double worst_m = 0;
  const double metres_per_degree = 6371000.0 * std::numbers::pi / 180.0;
  for (std::size_t i = 0; i < count; ++i) {
    const double dlat = (rigorous[i].lat_deg - proj[i].lat_deg) * metres_per_degree;
    const double dlon = (rigorous[i].lon_deg - proj[i].lon_deg) * metres_per_degree *
                        std::cos(proj[i].lat_deg * std::numbers::pi / 180.0);
    worst_m = std::max(worst_m, std::hypot(dlat, dlon));
  }
  const double rigorous_median = median(rigorous_s), proj_median = median(proj_s);
  std::printf("EPSG:2056 -> WGS84, %zu points, one core, median of %d runs\n", count, repetitions);
  std::printf("  terratiles rigorous  %8.3f s  %12.0f points/s\n", rigorous_median, count / rigorous_median);
  std::printf("  PROJ via GDAL        %8.3f s  %12.0f points/s\n", proj_median, count / proj_median);
  std::printf("  speed ratio terratiles/PROJ  %.2fx\n", proj_median / rigorous_median);
  std::printf("  max horizontal difference    %.3g mm\n", worst_m * 1000);
  return 0;
}
