// Benchmark: the partition stage of the cluster LoD loop (DESIGN.md 2 step 3a; paper 3.3) as
// `terratiles build` runs it, global METIS against METIS per tile neighbourhood, on the same
// meshes.
//
//   terratiles_bench_partition RASTER [--tin-max-error 0.5] [--runs 3] [--threads 0]
//                              [--scheme webmercator|geographic|local] [--tile-triangles 16384]
//                              [--clusters-per-tile 16] [--levels 0] [--global-runs 1] [--time wall|cpu]
//
// Reads the raster, builds the finest TIN (buildTin, untimed) and plans the zooms as build
// does (planZooms: clusters_per_tile per tile of each level's zoom). Then, level by level,
// on --threads threads (0: all cores):
//   graph     buildFaceGraph of the level's mesh;
//   global    partitionFaces over whole components: one METIS k-way call per component (the
//             old default; --global-runs timed runs, 0 skips it);
//   regional  tileNeighbourhoodRegions + partitionFaces by those regions (build's default);
//   regroup   groupClustersByTiles of the regional partition by the tiles of the next coarser
//             zoom (LevelOptions::regroup_clusters: part of build's partition stage).
// Times are wall clock, or with --time cpu the process's CPU time (all threads; on a machine
// shared with other work this shows the work itself). The TIN's time is printed for scale.
// Timed steps run --runs times after one untimed warm-up; medians are printed, and every run
// must give the warm-up's partition. Both partitions are checked (dense ids, every cluster
// contiguous) and their edge cuts printed with the ratio regional / global. The next level is
// the native simplifier's result on the regrouped regional partition (edge ratio 0.5, error
// budget tin-max-error * 2^(l + 1) in the grid frame), as build would make it.
// Tables on stdout, progress on stderr.
#include <tbb/global_control.h>
#include <time.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/lod/build_levels.h"
#include "src/partition/face_graph.h"
#include "src/partition/partition_faces.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tiling/assign_clusters.h"
#include "src/tin/build_tin.h"
#include "tools/bench/bench_support.h"

namespace terratiles {
namespace {

struct BenchOptions {
  std::string raster;
  double tin_max_error_m = 0.5;
  int runs = 3;
  int global_runs = 1;
  int threads = 0;
  int levels = 0;  // 0: all the plan's levels
  std::int32_t tile_triangles = 16384;
  std::int32_t clusters_per_tile = 16;
  TileSchemeKind scheme = TileSchemeKind::WebMercator;
  bool cpu_time = false;
};

BenchOptions parseOptions(int argc, char** argv) {
  const std::string usage =
      "usage: terratiles_bench_partition RASTER [--tin-max-error 0.5] [--runs 3] [--threads 0] "
      "[--scheme webmercator|geographic|local] [--tile-triangles 16384] [--clusters-per-tile 16] [--levels 0] "
      "[--global-runs 1] [--time wall|cpu]";
  BenchOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::printf("%s\n", usage.c_str());
      std::exit(0);
    }
    if (!arg.empty() && arg[0] == '-') {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " needs a value; " + usage);
      const std::string value = argv[++i];
      const auto whole = [&](double low) {
        const double number = bench::parseNumber(value, arg);
        if (number < low || number != std::floor(number)) {
          throw Error(ErrorCode::Usage, arg + " expects a whole number >= " + std::to_string(static_cast<int>(low)) +
                                            ", found '" + value + "'");
        }
        return static_cast<int>(number);
      };
      if (arg == "--tin-max-error") {
        options.tin_max_error_m = bench::parseNumber(value, arg);
        if (!(options.tin_max_error_m > 0)) throw Error(ErrorCode::Usage, "--tin-max-error expects a number > 0");
      } else if (arg == "--runs") {
        options.runs = whole(1);
      } else if (arg == "--global-runs") {
        options.global_runs = whole(0);
      } else if (arg == "--threads") {
        options.threads = whole(0);
      } else if (arg == "--levels") {
        options.levels = whole(0);
      } else if (arg == "--tile-triangles") {
        options.tile_triangles = whole(64);
      } else if (arg == "--clusters-per-tile") {
        options.clusters_per_tile = whole(1);
      } else if (arg == "--time") {
        if (value != "wall" && value != "cpu") throw Error(ErrorCode::Usage, "--time expects wall or cpu, found '" + value + "'");
        options.cpu_time = value == "cpu";
      } else if (arg == "--scheme") {
        options.scheme = parseTileSchemeKind(value);
      } else {
        throw Error(ErrorCode::Usage, "unknown option " + arg + "; " + usage);
      }
      continue;
    }
    if (!options.raster.empty()) throw Error(ErrorCode::Usage, "one raster only; " + usage);
    options.raster = arg;
  }
  if (options.raster.empty()) throw Error(ErrorCode::Usage, "no raster given; " + usage);
  return options;
}

// Dense ids and one connected piece per cluster; Error(Internal) naming `what` otherwise.
void checkPartition(const FaceGraph& graph, const FacePartition& partition, const std::string& what) {
  if (!clustersAreContiguous(graph, partition)) {
    throw Error(ErrorCode::Internal, what + ": a cluster id is out of range, unused or in two pieces");
  }
}

bool operator==(const FacePartition& a, const FacePartition& b) {
  return a.cluster_count == b.cluster_count && a.cluster_of_face == b.cluster_of_face;
}
bool operator==(const FaceGraph& a, const FaceGraph& b) {
  return a.across == b.across && a.offsets == b.offsets && a.neighbours == b.neighbours;
}

// Seconds of wall clock, or with `cpu` of CPU time of the whole process (all threads): on a
// machine shared with other work, CPU time shows the work itself.
bool g_cpu_time = false;
template <typename Function>
double secondsOf(Function&& function) {
  if (!g_cpu_time) return bench::secondsOf(function);
  timespec start{}, end{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &start);
  function();
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &end);
  return static_cast<double>(end.tv_sec - start.tv_sec) + 1e-9 * static_cast<double>(end.tv_nsec - start.tv_nsec);
}

// Median seconds of `runs` timed calls after one untimed warm-up; every call's result must
// equal the warm-up's.
template <typename Make>
double medianSeconds(int runs, Make&& make, decltype(make())& result, const std::string& what) {
  result = make();
  std::vector<double> seconds;
  for (int run = 0; run < runs; ++run) {
    decltype(make()) again;
    seconds.push_back(secondsOf([&] { again = make(); }));
    if (!(again == result)) throw Error(ErrorCode::Internal, what + ": run " + std::to_string(run + 1) + " differs");
  }
  return bench::median(seconds);
}

int runBench(int argc, char** argv) {
  const BenchOptions options = parseOptions(argc, argv);
  std::optional<tbb::global_control> thread_limit;
  if (options.threads > 0) {
    thread_limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(options.threads));
  }
  std::fprintf(stderr, "%s: reading and building the TIN (max error %g m)\n", options.raster.c_str(), options.tin_max_error_m);
  g_cpu_time = options.cpu_time;
  const DemGrid dem = readDem({options.raster});
  Progress quiet(ProgressMode::Quiet);
  TinMesh mesh;
  const double tin_s = secondsOf([&] { mesh = buildTin(dem, TinOptions{options.tin_max_error_m}, quiet); });
  const TileFrame frame(options.scheme, dem);
  const ZoomPlan plan = planZooms(frame, mesh, options.tile_triangles, -1, options.clusters_per_tile);
  const std::array<double, 2> metres = groundMetresPerPixel(dem);
  std::size_t levels = plan.clusters_per_level.size();
  if (options.levels > 0) levels = std::min(levels, static_cast<std::size_t>(options.levels));
  std::printf("%s @%gm: %zu triangles (TIN %.3f s), zooms %d..%d (%s), %d threads, %s seconds, medians of %d runs (global: %d)\n",
              options.raster.c_str(), options.tin_max_error_m, mesh.triangleCount(), tin_s, plan.min_zoom, plan.max_zoom,
              std::string(tileSchemeName(options.scheme)).c_str(),
              options.threads > 0 ? options.threads
                                  : static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)),
              options.cpu_time ? "CPU" : "wall", options.runs, options.global_runs);
  std::printf("%5s %4s %9s %6s %7s | %8s %7s %9s | %8s %8s %7s %9s %6s | %8s | %9s %9s %6s\n", "level", "zoom", "faces",
              "k", "graph s", "global s", "parts", "cut", "region s", "metis s", "parts", "cut", "cut/gl", "regroup",
              "stage gl", "stage reg", "speed");
  double total_global = 0, total_regional = 0;
  for (std::size_t l = 0; l < levels; ++l) {
    const std::int32_t zoom = plan.max_zoom - static_cast<std::int32_t>(l);
    std::fprintf(stderr, "level %zu (zoom %d): %zu faces\n", l, zoom, mesh.triangleCount());
    const PartitionOptions partition_options{Partitioner::Metis, plan.clusters_per_level[l], static_cast<std::uint32_t>(1 + l)};
    FaceGraph graph;
    const double graph_s = medianSeconds(options.runs, [&] { return buildFaceGraph(mesh); }, graph, "buildFaceGraph");
    FacePartition global;
    double global_s = 0;
    if (options.global_runs > 0) {
      global_s = medianSeconds(options.global_runs, [&] { return partitionFaces(graph, partition_options); }, global,
                               "global partitionFaces");
      checkPartition(graph, global, "global partition");
    }
    std::vector<std::int32_t> regions;
    const double regions_s =
        medianSeconds(options.runs, [&] { return tileNeighbourhoodRegions(frame, mesh, zoom); }, regions, "tileNeighbourhoodRegions");
    FacePartition regional;
    const double regional_s = medianSeconds(
        options.runs, [&] { return partitionFaces(graph, partition_options, regions); }, regional, "regional partitionFaces");
    checkPartition(graph, regional, "regional partition");
    FacePartition grouped;
    const double regroup_s =
        medianSeconds(options.runs, [&] { return groupClustersByTiles(frame, mesh, regional, zoom - 1); }, grouped,
                      "groupClustersByTiles");
    const std::size_t regional_cut = edgeCut(graph, regional.cluster_of_face);
    const std::size_t global_cut = options.global_runs > 0 ? edgeCut(graph, global.cluster_of_face) : 0;
    const double stage_global = graph_s + global_s + regroup_s, stage_regional = graph_s + regions_s + regional_s + regroup_s;
    total_global += stage_global;
    total_regional += stage_regional;
    std::printf("%5zu %4d %9zu %6d %7.3f | %8.3f %7d %9zu | %8.3f %8.3f %7d %9zu %6.3f | %8.3f | %9.3f %9.3f %5.1fx\n", l,
                zoom, mesh.triangleCount(), partition_options.clusters, graph_s, global_s, global.cluster_count, global_cut,
                regions_s, regional_s, regional.cluster_count, regional_cut,
                global_cut > 0 ? static_cast<double>(regional_cut) / static_cast<double>(global_cut) : 0.0, regroup_s,
                stage_global, stage_regional, stage_regional > 0 ? stage_global / stage_regional : 0.0);
    std::fflush(stdout);
    if (l + 1 == levels) break;
    SimplifyOptions simplify;
    simplify.simplifier = Simplifier::Native;
    simplify.edge_ratio = 0.5;
    simplify.metres_per_col = metres[0];
    simplify.metres_per_row = metres[1];
    simplify.max_error_m = options.tin_max_error_m * std::pow(2.0, static_cast<double>(l + 1));
    mesh = simplifyClusters(dem, mesh, grouped.cluster_of_face, grouped.cluster_count, {}, simplify).mesh;
  }
  std::printf("all levels: stage (graph + partition + regroup) global %.3f s, regional %.3f s: %.1fx\n", total_global,
              total_regional, total_regional > 0 ? total_global / total_regional : 0.0);
  return 0;
}

}  // namespace
}  // namespace terratiles

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_bench_partition", [&] { return terratiles::runBench(argc, argv); });
}
