// Benchmark: the cluster LoD level loop (DESIGN.md 2 step 3; paper sections 3.3-3.4) with our
// simplifyClusters against meshoptimizer's meshopt_simplify with meshopt_SimplifyLockBorder,
// on the same meshes and the same METIS clusters, on one core.
//
//   terratiles_bench_lod RASTER... [--tin-max-error 0.5] [--levels 4] [--cluster-triangles 1024]
//                        [--region-clusters 64] [--runs 3] [--simplifier native|cgal]
//
// For each raster: reads it with readDem and builds the finest TIN once (buildTin at
// --tin-max-error, untimed, all cores). Then --levels levels on ONE thread
// (tbb::global_control max_allowed_parallelism 1). At each level:
//   partition  buildFaceGraph + partitionFaces of the current mesh, METIS, k = ceil(triangles /
//              --cluster-triangles), seed 1 + level index, by grid cells of about
//              --region-clusters clusters (clusterCellRegions, offset on every other level), as
//              buildLevels does for `terratiles levels` (0: one METIS call per level);
//   terratiles simplifyClusters on that mesh and those clusters: edge_ratio 0.5, no error
//              budget, ground metres per pixel from groundMetresPerPixel;
//   meshopt    the same mesh and clusters: every cluster's faces as a submesh with local vertex
//              indices and float positions (x = col * metres_per_col, y = -row * metres_per_row,
//              z = height, relative to the cluster's first vertex), meshopt_simplify to half the
//              cluster's indices with target_error FLT_MAX (only the count stops it) and
//              meshopt_SimplifyLockBorder, merged back by global vertex index (meshoptimizer
//              keeps vertices where they are; unused ones are dropped, the rest keep their order).
// Each step gets one untimed warm-up run, then --runs timed runs (the two simplifiers in
// interleaved pairs); medians are reported, and every timed run must give the warm-up's result
// exactly. Both results are measured by measureTin against the DEM (max and RMS vertical error
// on every pixel) and their triangles checked seen from above: clockwise ("flipped", a fold-over
// of the height field) and zero-area. The loop then continues with OUR result, so both tools
// see identical input at every level.
//
// Not the same stop: ours counts edges, and with every cluster border locked, halving the edges
// leaves about T / 2 - B / 6 triangles (B border edges), so ours ends below half of the
// triangles, further below on coarse levels and ragged nodata borders; meshoptimizer counts
// triangles and ends at half. The out/in column shows both, so compare errors with that in mind.
//
// Prints a table per raster (a row per level and step) and a summary: whole-loop throughput
// (finest TIN triangles / the sum of partition + simplify medians over all levels) for each
// tool, the ratio, and the errors at the last level. Tables on stdout, progress on stderr.
#include <meshoptimizer.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <cfloat>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>
#include <system_error>
#include <vector>

#include "formats/dem/read_dem.h"
#include "tools/bench/bench_support.h"
#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/lod/build_levels.h"
#include "src/partition/face_graph.h"
#include "src/partition/partition_faces.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"
#include "src/tin/tin_mesh.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

using bench::median;
using bench::parseNumber;
using bench::secondsOf;

// Paper 3.4: every level keeps about half of the edges. Ours stops at this edge ratio,
// meshoptimizer at this fraction of each cluster's indices.
constexpr double kLevelRatio = 0.5;

struct BenchOptions {
  std::vector<std::string> rasters;
  double tin_max_error_m = 0.5;
  int levels = 4;
  int cluster_triangles = 1024;
  int region_clusters = 64;  // METIS per grid cell of about this many clusters (0: one call)
  int runs = 3;
  Simplifier simplifier = Simplifier::Native;
};

constexpr const char* kUsage =
    "usage: terratiles_bench_lod RASTER... [--tin-max-error 0.5] [--levels 4]\n"
    "                            [--cluster-triangles 1024] [--region-clusters 64] [--runs 3]\n"
    "                            [--simplifier native]\n"
    "  --tin-max-error      max vertical error of the finest TIN, metres (default 0.5; 10 suits SRTM)\n"
    "  --levels             coarser levels to build, each from the one before (default 4)\n"
    "  --cluster-triangles  METIS clusters per level: ceil(triangles / this) (default 1024)\n"
    "  --region-clusters    METIS on each square cell of the grid of about this many clusters, as\n"
    "                       `terratiles levels --partition regional` does; 0: one METIS call per\n"
    "                       level (`--partition global`) (default 64)\n"
    "  --runs               timed runs per step and level, after one untimed warm-up; the median\n"
    "                       is reported (default 3)\n"
    "  --simplifier         terratiles' engine: native (default) or cgal (the reference)\n";

int parseCount(const std::string& text, const std::string& option, int min, int max) {
  const double value = parseNumber(text, option);
  if (value < min || value > max || value != std::floor(value)) {
    throw Error(ErrorCode::Usage, option + " expects a whole number in [" + std::to_string(min) + ", " +
                                      std::to_string(max) + "], found " + text);
  }
  return static_cast<int>(value);
}

BenchOptions parseOptions(int argc, char** argv) {
  BenchOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " expects a value (see --help)");
      return argv[++i];
    };
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (arg == "--tin-max-error") {
      const std::string text = value();
      options.tin_max_error_m = parseNumber(text, arg);
      if (!(options.tin_max_error_m > 0)) {
        throw Error(ErrorCode::Usage, "--tin-max-error expects metres > 0, found " + text);
      }
    } else if (arg == "--levels") {
      options.levels = parseCount(value(), arg, 1, 64);
    } else if (arg == "--cluster-triangles") {
      options.cluster_triangles = parseCount(value(), arg, 1, std::numeric_limits<std::int32_t>::max());
    } else if (arg == "--region-clusters") {
      options.region_clusters = parseCount(value(), arg, 0, std::numeric_limits<std::int32_t>::max());
    } else if (arg == "--runs") {
      options.runs = parseCount(value(), arg, 1, 1000);
    } else if (arg == "--simplifier") {
      const std::string text = value();
      if (text != "native" && text != "cgal") {
        throw Error(ErrorCode::Usage, "--simplifier expects native or cgal, found " + text);
      }
      options.simplifier = text == "cgal" ? Simplifier::Cgal : Simplifier::Native;
    } else if (arg.starts_with("-")) {
      throw Error(ErrorCode::Usage, "unknown option " + arg + " (see --help)");
    } else {
      options.rasters.push_back(arg);
    }
  }
  if (options.rasters.empty()) throw Error(ErrorCode::Usage, "no RASTER given; usage: terratiles_bench_lod RASTER... (see --help)");
  return options;
}

constexpr std::uint32_t kNoLocal = 0xffffffff;

// One level of the loop with meshoptimizer in place of simplifyClusters: the same mesh, the same
// clusters, the same stop (half of each cluster), borders locked; merged by global vertex index.
// Scratch is allocated once per call and reused by every cluster.
TinMesh simplifyClustersWithMeshopt(const TinMesh& mesh, const FacePartition& partition,
                                    const std::array<double, 2>& metres_per_pixel) {
  const std::size_t face_count = mesh.triangleCount();
  const auto& idx = mesh.triangle_indices;
  // Faces grouped by cluster (counting sort: each cluster's faces in mesh order).
  std::vector<std::uint32_t> cluster_start(static_cast<std::size_t>(partition.cluster_count) + 1, 0);
  for (const std::int32_t cluster : partition.cluster_of_face) ++cluster_start[static_cast<std::size_t>(cluster) + 1];
  for (std::size_t c = 1; c < cluster_start.size(); ++c) cluster_start[c] += cluster_start[c - 1];
  std::vector<std::uint32_t> faces_by_cluster(face_count);
  {
    std::vector<std::uint32_t> next(cluster_start.begin(), cluster_start.end() - 1);
    for (std::size_t f = 0; f < face_count; ++f) {
      faces_by_cluster[next[static_cast<std::size_t>(partition.cluster_of_face[f])]++] = static_cast<std::uint32_t>(f);
    }
  }

  std::vector<std::uint32_t> local_of_vertex(mesh.vertices.size(), kNoLocal);
  std::vector<std::uint32_t> global_of_local;
  std::vector<float> positions;
  std::vector<unsigned int> local_indices, simplified;
  TinMesh result;
  result.triangle_indices.reserve(idx.size() / 2 + idx.size() / 8);
  for (std::size_t c = 0; c + 1 < cluster_start.size(); ++c) {
    const std::uint32_t begin = cluster_start[c], end = cluster_start[c + 1];
    if (begin == end) continue;
    global_of_local.clear();
    positions.clear();
    local_indices.clear();
    // Relative to the cluster's first vertex: floats keep centimetres at any CRS offset.
    const GridPoint& origin = mesh.vertices[idx[3 * static_cast<std::size_t>(faces_by_cluster[begin])]];
    for (std::uint32_t i = begin; i < end; ++i) {
      for (std::size_t k = 0; k < 3; ++k) {
        const std::uint32_t v = idx[3 * static_cast<std::size_t>(faces_by_cluster[i]) + k];
        if (local_of_vertex[v] == kNoLocal) {
          local_of_vertex[v] = static_cast<std::uint32_t>(global_of_local.size());
          global_of_local.push_back(v);
          const GridPoint& p = mesh.vertices[v];
          positions.push_back(static_cast<float>((p.col - origin.col) * metres_per_pixel[0]));
          positions.push_back(static_cast<float>(-(p.row - origin.row) * metres_per_pixel[1]));
          positions.push_back(static_cast<float>(p.height_m - origin.height_m));
        }
        local_indices.push_back(local_of_vertex[v]);
      }
    }
    simplified.resize(local_indices.size());  // meshopt's worst case is the input size
    const std::size_t target_index_count =
        static_cast<std::size_t>(static_cast<double>(local_indices.size() / 3) * kLevelRatio) * 3;
    float relative_error = 0;
    const std::size_t count =
        meshopt_simplify(simplified.data(), local_indices.data(), local_indices.size(), positions.data(),
                         global_of_local.size(), 3 * sizeof(float), target_index_count, FLT_MAX,
                         meshopt_SimplifyLockBorder, &relative_error);
    for (std::size_t i = 0; i < count; ++i) result.triangle_indices.push_back(global_of_local[simplified[i]]);
    for (const std::uint32_t v : global_of_local) local_of_vertex[v] = kNoLocal;
  }

  // The vertices the triangles still use, in input order (as simplifyClusters keeps them).
  constexpr std::uint32_t kUsed = kNoLocal - 1;
  std::vector<std::uint32_t>& new_index = local_of_vertex;  // all kNoLocal again
  for (const std::uint32_t v : result.triangle_indices) new_index[v] = kUsed;
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (new_index[v] == kUsed) {
      new_index[v] = static_cast<std::uint32_t>(result.vertices.size());
      result.vertices.push_back(mesh.vertices[v]);
    }
  }
  for (std::uint32_t& v : result.triangle_indices) v = new_index[v];
  return result;
}

struct Orientation {
  std::size_t clockwise = 0;  // folded over, seen from above
  std::size_t zero_area = 0;
};

// Row grows south, so a positive cross product in the (col, row) plane is clockwise from above.
Orientation orientationOf(const TinMesh& mesh) {
  Orientation orientation;
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t) {
    const GridPoint& a = mesh.vertices[mesh.triangle_indices[3 * t]];
    const GridPoint& b = mesh.vertices[mesh.triangle_indices[3 * t + 1]];
    const GridPoint& c = mesh.vertices[mesh.triangle_indices[3 * t + 2]];
    const double cross = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
    orientation.clockwise += cross > 0;
    orientation.zero_area += cross == 0;
  }
  return orientation;
}

struct ToolResult {
  std::size_t triangles = 0;
  std::size_t vertices = 0;
  double seconds = 0;  // median simplify time
  TinErrorStatistics error;
  Orientation orientation;
};

// "ok" or what measureTin and the orientation check found wrong.
std::string checksOf(const ToolResult& tool) {
  std::string issues;
  auto add = [&](std::size_t count, const char* what) {
    if (count) issues += (issues.empty() ? "" : ", ") + std::to_string(count) + " " + what;
  };
  add(tool.orientation.zero_area, "zero-area triangles");
  add(tool.error.uncovered_valid_pixels, "uncovered pixels");
  add(tool.error.covered_nodata_pixels, "nodata pixels covered");
  return issues.empty() ? "ok" : issues;
}

struct RasterSummary {
  std::string name;
  std::size_t finest_triangles = 0;
  int levels = 0;
  double partition_s = 0, ours_s = 0, meshopt_s = 0;  // sums of the levels' medians
  std::size_t simplify_input_triangles = 0;           // sum of the levels' inputs
  ToolResult ours_last, meshopt_last;
  std::size_t ours_clockwise_all_levels = 0, meshopt_clockwise_all_levels = 0;
};

void printHeader() {
  std::printf("%-5s %-13s %8s %9s %9s %6s %9s %11s %9s %9s %7s  %s\n", "level", "step", "clusters",
              "in tris", "out tris", "out/in", "time [s]", "in tris/s", "max [m]", "rms [m]", "flipped",
              "checks");
}

void printToolRow(int level, const char* tool, std::size_t input_triangles, const ToolResult& result) {
  std::printf("%-5d %-13s %8s %9zu %9zu %6.3f %9.4f %11.0f %9.3f %9.4f %7zu  %s\n", level, tool, "",
              input_triangles, result.triangles,
              static_cast<double>(result.triangles) / static_cast<double>(input_triangles), result.seconds,
              static_cast<double>(input_triangles) / result.seconds, result.error.max_error_m,
              result.error.rms_error_m, result.orientation.clockwise, checksOf(result).c_str());
}

RasterSummary benchRaster(const std::string& path, const BenchOptions& options) {
  RasterSummary summary;
  summary.name = fs::path(path).filename().string();
  const char* name = summary.name.c_str();
  std::fprintf(stderr, "%s: reading and building the finest TIN\n", name);
  const DemGrid dem = readDem({path});
  Progress quiet(ProgressMode::Quiet);
  TinMesh current = buildTin(dem, TinOptions{.max_error_m = options.tin_max_error_m}, quiet);
  const TinErrorStatistics finest_error = measureTin(dem, current);
  const std::array<double, 2> metres = groundMetresPerPixel(dem);
  summary.finest_triangles = current.triangleCount();

  std::printf("\n== %s: %d x %d pixels, %s, %.3f x %.3f m per pixel\n", name, dem.width, dem.height,
              dem.crs_name.c_str(), metres[0], metres[1]);
  std::printf("finest TIN at %g m: %zu triangles, %zu vertices, max %.3f m, rms %.4f m (built untimed)\n",
              options.tin_max_error_m, current.triangleCount(), current.vertices.size(),
              finest_error.max_error_m, finest_error.rms_error_m);
  std::printf("one thread; terratiles' %s engine; METIS %s; per step 1 warm-up + %d timed runs, medians; both "
              "tools simplify the same mesh (terratiles' previous level) with the same clusters to %g\n",
              simplifierName(options.simplifier),
              options.region_clusters > 0
                  ? ("per grid cell of about " + std::to_string(options.region_clusters) + " clusters").c_str()
                  : "one call per level",
              options.runs, kLevelRatio);
  printHeader();

  // Everything timed runs on one core: meshoptimizer is single-threaded, simplifyClusters and
  // the partition would otherwise use TBB's workers.
  const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  SimplifyOptions simplify;
  simplify.simplifier = options.simplifier;
  simplify.edge_ratio = kLevelRatio;  // max_error_m stays infinite: the ratio alone stops it
  simplify.metres_per_col = metres[0];
  simplify.metres_per_row = metres[1];
  const std::vector<std::array<std::uint32_t, 2>> no_constraints;

  for (int level = 1; level <= options.levels; ++level) {
    const std::size_t input_triangles = current.triangleCount();
    if (input_triangles < 2) {
      std::printf("stopped before level %d: %zu triangle(s) left\n", level, input_triangles);
      break;
    }
    const std::size_t per = static_cast<std::size_t>(options.cluster_triangles);
    PartitionOptions partition_options;
    partition_options.method = Partitioner::Metis;
    partition_options.clusters = static_cast<std::int32_t>((input_triangles + per - 1) / per);
    partition_options.seed = static_cast<std::uint32_t>(level);  // buildLevels: seed 1 + level index

    std::fprintf(stderr, "%s level %d: partition\n", name, level);
    FacePartition partition;
    std::vector<double> partition_runs;
    for (int r = 0; r <= options.runs; ++r) {
      FacePartition run;
      // The regions as buildLevels makes them (its level index is ours - 1), timed with METIS.
      const double seconds = secondsOf([&] {
        const std::vector<std::int32_t> regions = clusterCellRegions(current, partition_options.clusters,
                                                                     options.region_clusters, (level - 1) % 2 == 1);
        run = partitionFaces(buildFaceGraph(current), partition_options, regions);
      });
      if (r == 0) {
        partition = std::move(run);
        continue;
      }
      partition_runs.push_back(seconds);
      if (run.cluster_of_face != partition.cluster_of_face) {
        throw Error(ErrorCode::Internal, summary.name + " level " + std::to_string(level) +
                                             ": partitionFaces gave a different partition on run " +
                                             std::to_string(r) + " with the same seed");
      }
    }
    const double partition_s = median(partition_runs);
    std::printf("%-5d %-13s %8d %9zu %9s %6s %9.4f %11.0f\n", level, "partition", partition.cluster_count,
                input_triangles, "", "", partition_s, static_cast<double>(input_triangles) / partition_s);

    // Interleaved pairs, after one untimed warm-up pair whose results are the ones measured.
    ClusterSimplification ours;
    TinMesh meshopt;
    std::vector<double> ours_runs, meshopt_runs;
    for (int r = 0; r <= options.runs; ++r) {
      std::fprintf(stderr, "%s level %d: %s %d of %d\n", name, level, r == 0 ? "warm-up" : "pair", r,
                   options.runs);
      ClusterSimplification ours_run;
      const double ours_s = secondsOf([&] {
        ours_run = simplifyClusters(dem, current, partition.cluster_of_face, partition.cluster_count,
                                    no_constraints, simplify);
      });
      TinMesh meshopt_run;
      const double meshopt_s = secondsOf([&] { meshopt_run = simplifyClustersWithMeshopt(current, partition, metres); });
      if (r == 0) {
        ours = std::move(ours_run);
        meshopt = std::move(meshopt_run);
        continue;
      }
      ours_runs.push_back(ours_s);
      meshopt_runs.push_back(meshopt_s);
      if (ours_run.mesh.triangle_indices != ours.mesh.triangle_indices ||
          meshopt_run.triangle_indices != meshopt.triangle_indices) {
        throw Error(ErrorCode::Internal, summary.name + " level " + std::to_string(level) + ": " +
                                             (ours_run.mesh.triangle_indices != ours.mesh.triangle_indices
                                                  ? "simplifyClusters"
                                                  : "meshopt_simplify") +
                                             " gave a different mesh on run " + std::to_string(r));
      }
    }

    std::fprintf(stderr, "%s level %d: measuring\n", name, level);
    ToolResult ours_result{ours.mesh.triangleCount(), ours.mesh.vertices.size(), median(ours_runs),
                           measureTin(dem, ours.mesh), orientationOf(ours.mesh)};
    ToolResult meshopt_result{meshopt.triangleCount(), meshopt.vertices.size(), median(meshopt_runs),
                              measureTin(dem, meshopt), orientationOf(meshopt)};
    printToolRow(level, "terratiles", input_triangles, ours_result);
    printToolRow(level, "meshoptimizer", input_triangles, meshopt_result);
    std::fflush(stdout);

    summary.levels = level;
    summary.partition_s += partition_s;
    summary.ours_s += ours_result.seconds;
    summary.meshopt_s += meshopt_result.seconds;
    summary.simplify_input_triangles += input_triangles;
    summary.ours_clockwise_all_levels += ours_result.orientation.clockwise;
    summary.meshopt_clockwise_all_levels += meshopt_result.orientation.clockwise;
    summary.ours_last = ours_result;
    summary.meshopt_last = meshopt_result;
    current = std::move(ours.mesh);  // the loop goes on with our level
  }
  return summary;
}

void printSummary(const std::vector<RasterSummary>& summaries) {
  std::printf("\n== summary, one thread. loop [s] = sum over the levels of the partition + simplify "
              "medians; loop tris/s = finest TIN triangles / loop [s]; simplify tris/s = the levels' "
              "input triangles / simplify time alone; ratio = terratiles / meshoptimizer (throughput: > 1 "
              "means terratiles is faster; errors: > 1 means its error is larger); errors and triangles "
              "of the last level; flipped = clockwise seen from above, all levels\n");
  std::printf("%-44s %-13s %9s %12s %14s %9s %9s %9s %7s\n", "raster (levels, finest triangles)", "tool",
              "loop [s]", "loop tris/s", "simplify tri/s", "last tris", "max [m]", "rms [m]", "flipped");
  for (const RasterSummary& s : summaries) {
    if (s.levels == 0) continue;
    const double finest = static_cast<double>(s.finest_triangles);
    const double inputs = static_cast<double>(s.simplify_input_triangles);
    const double ours_loop = s.partition_s + s.ours_s, meshopt_loop = s.partition_s + s.meshopt_s;
    char label[96];
    std::snprintf(label, sizeof label, "%s (%d, %zu)", s.name.c_str(), s.levels, s.finest_triangles);
    std::printf("%-44s %-13s %9.3f %12.0f %14.0f %9zu %9.3f %9.4f %7zu\n", label, "terratiles", ours_loop,
                finest / ours_loop, inputs / s.ours_s, s.ours_last.triangles, s.ours_last.error.max_error_m,
                s.ours_last.error.rms_error_m, s.ours_clockwise_all_levels);
    std::printf("%-44s %-13s %9.3f %12.0f %14.0f %9zu %9.3f %9.4f %7zu\n", "", "meshoptimizer", meshopt_loop,
                finest / meshopt_loop, inputs / s.meshopt_s, s.meshopt_last.triangles,
                s.meshopt_last.error.max_error_m, s.meshopt_last.error.rms_error_m, s.meshopt_clockwise_all_levels);
    // Ratios terratiles / meshoptimizer: > 1 means we are faster, or have the larger error.
    std::printf("%-44s %-13s %9s %11.3fx %13.3fx %9s %8.3fx %8.3fx\n", "", "ratio", "", meshopt_loop / ours_loop,
                s.meshopt_s / s.ours_s, "", s.ours_last.error.max_error_m / s.meshopt_last.error.max_error_m,
                s.ours_last.error.rms_error_m / s.meshopt_last.error.rms_error_m);
  }
}

int runBench(int argc, char** argv) {
  const BenchOptions options = parseOptions(argc, argv);
  std::vector<RasterSummary> summaries;
  for (const std::string& raster : options.rasters) summaries.push_back(benchRaster(raster, options));
  printSummary(summaries);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_bench_lod", [&] { return runBench(argc, argv); });
}
