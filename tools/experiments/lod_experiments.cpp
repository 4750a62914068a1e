// terratiles_lod_experiments: the paper's comparisons of the cluster LoD method, on real
// rasters, printed as tables (paper sections 4.2, 6.1, figs 40 and 42).
//
//   terratiles_lod_experiments RASTER[:TIN_MAX_ERROR]... [--runs 5] [--experiment all|partition|rounds|constraints]
//                              [--clusters 8] [--rounds-clusters 8] [--region-clusters 0]
//
// --clusters sets the clusters of experiments 1 and 3, --rounds-clusters those of 2 (the paper
// used 8 and 64). --region-clusters R > 0 partitions as `terratiles levels --partition
// regional` does: METIS per square cell of about R clusters (partition_faces.h,
// clusterCellRegions), and the random partitioner grows inside the same cells; 0 (the default,
// the paper's) partitions every component in one call.
//
// 1. partition: METIS vs random partition (paper fig 40). The finest TIN is split into 8
//    clusters by each partitioner and simplified once to 50 % of the edges with the cluster
//    borders locked; the table gives the max and RMS vertical error against the DEM, the
//    edge cut and the ratio, averaged over --runs seeds.
// 2. rounds: five successive simplifications (50 % each) with a new METIS partition every
//    round vs the first round's borders kept (paper fig 42): error after every round.
// 3. constraints: the error of one simplification round (METIS, 8 clusters) as the number of
//    constrained edges grows (paper 6.1): random connected sets of 8 faces, every edge locked
//    (randomFaceSetConstraints).
//
// Progress goes to stderr, tables to stdout.

#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "formats/dem/read_dem.h"
#include "tools/bench/bench_support.h"
#include "src/base/error.h"
#include "src/lod/build_levels.h"
#include "src/partition/face_graph.h"
#include "src/partition/partition_faces.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tin/build_tin.h"
#include "src/tin/measure_tin.h"

namespace terratiles {
namespace {

struct ExperimentOptions {
  std::vector<bench::RasterSpec> rasters;
  int runs = 5;
  std::string experiment = "all";
  int rounds_clusters = 8;  // clusters per round of experiment 2 (the paper used 64 on one TIN)
  int clusters = 8;         // clusters of experiments 1 and 3
  int region_clusters = 0;  // > 0: METIS per grid cell of about this many clusters
};

double parsePositive(const std::string& text, const std::string& what) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !(value > 0) || !std::isfinite(value)) {
    throw Error(ErrorCode::Usage, what + " expects a number > 0, found '" + text + "'");
  }
  return value;
}

ExperimentOptions parseOptions(int argc, char** argv) {
  ExperimentOptions options;
  const std::string usage =
      "usage: terratiles_lod_experiments RASTER[:TIN_MAX_ERROR]... [--runs 5] "
      "[--experiment all|partition|rounds|constraints] [--rounds-clusters 8] [--clusters 8] [--region-clusters 0]";
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::printf("%s\n", usage.c_str());
      std::exit(0);
    }
    if (arg == "--runs" || arg == "--experiment" || arg == "--rounds-clusters" || arg == "--clusters" ||
        arg == "--region-clusters") {
      if (i + 1 >= argc) throw Error(ErrorCode::Usage, arg + " needs a value; " + usage);
      const std::string value = argv[++i];
      if (arg == "--runs") {
        options.runs = static_cast<int>(parsePositive(value, "--runs"));
      } else if (arg == "--rounds-clusters") {
        options.rounds_clusters = static_cast<int>(parsePositive(value, "--rounds-clusters"));
      } else if (arg == "--clusters") {
        options.clusters = static_cast<int>(parsePositive(value, "--clusters"));
      } else if (arg == "--region-clusters") {
        options.region_clusters = value == "0" ? 0 : static_cast<int>(parsePositive(value, "--region-clusters"));
      } else {
        if (value != "all" && value != "partition" && value != "rounds" && value != "constraints") {
          throw Error(ErrorCode::Usage, "--experiment expects all, partition, rounds or constraints, found '" + value + "'");
        }
        options.experiment = value;
      }
      continue;
    }
    if (!arg.empty() && arg[0] == '-') throw Error(ErrorCode::Usage, "unknown option " + arg + "; " + usage);
    options.rasters.push_back(bench::parseRasterSpec(arg));
  }
  if (options.rasters.empty()) throw Error(ErrorCode::Usage, "no raster given; " + usage);
  return options;
}

std::string regionNote(const ExperimentOptions& options) {
  return options.region_clusters > 0 ? " (METIS per grid cell of about " + std::to_string(options.region_clusters) + " clusters)"
                                     : "";
}

SimplifyOptions halfEdges(const DemGrid& dem) {
  const std::array<double, 2> metres = groundMetresPerPixel(dem);
  SimplifyOptions options;
  options.edge_ratio = 0.5;
  options.metres_per_col = metres[0];
  options.metres_per_row = metres[1];
  return options;
}

double mean(const std::vector<double>& values) {
  double sum = 0;
  for (const double v : values) sum += v;
  return values.empty() ? 0 : sum / static_cast<double>(values.size());
}

// ---- 1. METIS vs random -------------------------------------------------------------------

void partitionExperiment(const DemGrid& dem, const TinMesh& tin, const std::string& name, int runs, int clusters,
                         int region_clusters) {
  const FaceGraph graph = buildFaceGraph(tin);
  const std::vector<std::int32_t> regions = clusterCellRegions(tin, clusters, region_clusters, false);
  const SimplifyOptions simplify = halfEdges(dem);
  std::vector<double> max_error[2], rms_error[2], cut[2];
  for (int run = 0; run < runs; ++run) {
    for (int method = 0; method < 2; ++method) {
      std::fprintf(stderr, "%s: partition experiment, run %d, %s\n", name.c_str(), run + 1, method ? "random" : "METIS");
      const FacePartition partition =
          partitionFaces(graph, {method ? Partitioner::Random : Partitioner::Metis, clusters, static_cast<std::uint32_t>(run + 1)},
                         regions);
      const ClusterSimplification result =
          simplifyClusters(dem, tin, partition.cluster_of_face, partition.cluster_count, {}, simplify);
      const TinErrorStatistics error = measureTin(dem, result.mesh);
      max_error[method].push_back(error.max_error_m);
      rms_error[method].push_back(error.rms_error_m);
      cut[method].push_back(static_cast<double>(edgeCut(graph, partition.cluster_of_face)));
    }
  }
  std::printf("%-34s %9zu %8.1f %8.1f %9.2f %9.2f %8.3f %8.3f %7.2fx\n", name.c_str(), tin.triangleCount(),
              mean(cut[0]), mean(cut[1]), mean(max_error[0]), mean(max_error[1]), mean(rms_error[0]),
              mean(rms_error[1]), mean(max_error[1]) / mean(max_error[0]));
}

// ---- 2. re-partition vs fixed borders -----------------------------------------------------

void roundsExperiment(const DemGrid& dem, const TinMesh& tin, const std::string& name, int runs, int clusters,
                      int region_clusters) {
  constexpr int kRounds = 5;
  std::vector<double> max_error[2][kRounds + 1], rms_error[2][kRounds + 1], triangles[2][kRounds + 1];
  for (int run = 0; run < runs; ++run) {
    for (int fixed = 0; fixed < 2; ++fixed) {
      std::fprintf(stderr, "%s: rounds experiment, run %d, %s\n", name.c_str(), run + 1, fixed ? "fixed" : "re-partition");
      LevelOptions options;
      options.clusters_per_level.assign(kRounds, clusters);
      options.coarser_levels = kRounds;
      options.repartition = fixed == 0;
      options.region_clusters = region_clusters;
      options.seed = static_cast<std::uint32_t>(run + 1);
      Progress quiet(ProgressMode::Quiet);
      const std::vector<Level> levels = buildLevels(dem, tin, options, {}, quiet);
      for (std::size_t l = 0; l < levels.size(); ++l) {
        max_error[fixed][l].push_back(levels[l].error.max_error_m);
        rms_error[fixed][l].push_back(levels[l].error.rms_error_m);
        triangles[fixed][l].push_back(static_cast<double>(levels[l].mesh.triangleCount()));
      }
    }
  }
  for (int round = 1; round <= kRounds; ++round) {
    std::printf("%-34s %5d %10.0f %10.0f %10.2f %10.2f %9.3f %9.3f\n", name.c_str(), round, mean(triangles[0][round]),
                mean(triangles[1][round]), mean(max_error[0][round]), mean(max_error[1][round]),
                mean(rms_error[0][round]), mean(rms_error[1][round]));
  }
  // Fixed borders stop simplifying once only border edges are left, so after five rounds the
  // two runs may hold very different triangle counts. Also compare at equal size: the first
  // re-partition round with no more triangles than the fixed run's last.
  const double fixed_triangles = mean(triangles[1][kRounds]), fixed_error = mean(max_error[1][kRounds]);
  int matched = kRounds;
  for (int round = 1; round <= kRounds; ++round) {
    if (mean(triangles[0][round]) <= fixed_triangles) {
      matched = round;
      break;
    }
  }
  std::printf("%-34s after %d rounds: re-partition %.2f m vs fixed %.2f m (%s); at equal size (re-partition round %d, "
              "%.0f vs %.0f triangles): %.2f m vs %.2f m (%s)\n",
              name.c_str(), kRounds, mean(max_error[0][kRounds]), fixed_error,
              mean(max_error[0][kRounds]) < fixed_error ? "re-partition lower" : "re-partition NOT lower", matched,
              mean(triangles[0][matched]), fixed_triangles, mean(max_error[0][matched]), fixed_error,
              mean(max_error[0][matched]) < fixed_error ? "re-partition lower" : "re-partition NOT lower");
}

// ---- 3. constraints -----------------------------------------------------------------------

void constraintExperiment(const DemGrid& dem, const TinMesh& tin, const std::string& name, int runs, int clusters,
                          int region_clusters) {
  const FaceGraph graph = buildFaceGraph(tin);
  const std::vector<std::int32_t> regions = clusterCellRegions(tin, clusters, region_clusters, false);
  const SimplifyOptions simplify = halfEdges(dem);
  const std::size_t edges = meshEdgeKeys(tin).size();
  for (const double share : {0.0, 0.01, 0.05, 0.10, 0.20}) {
    std::vector<double> max_error, rms_error, ratio, constrained;
    for (int run = 0; run < runs; ++run) {
      std::fprintf(stderr, "%s: constraint experiment, %.0f %%, run %d\n", name.c_str(), share * 100, run + 1);
      // Sets of 8 faces hold about 13 distinct edges.
      const auto sets = static_cast<std::size_t>(std::round(share * static_cast<double>(edges) / 13.0));
      const auto constraints = randomFaceSetConstraints(tin, sets, 8, static_cast<std::uint32_t>(run + 1));
      const FacePartition partition =
          partitionFaces(graph, {Partitioner::Metis, clusters, static_cast<std::uint32_t>(run + 1)}, regions);
      const ClusterSimplification result =
          simplifyClusters(dem, tin, partition.cluster_of_face, partition.cluster_count, constraints, simplify);
      const TinErrorStatistics error = measureTin(dem, result.mesh);
      max_error.push_back(error.max_error_m);
      rms_error.push_back(error.rms_error_m);
      ratio.push_back(static_cast<double>(meshEdgeKeys(result.mesh).size()) / static_cast<double>(edges));
      constrained.push_back(static_cast<double>(constraints.size()) / static_cast<double>(edges));
    }
    std::printf("%-34s %11.1f %% %11.3f %9.2f %8.3f\n", name.c_str(), 100 * mean(constrained), mean(ratio),
                mean(max_error), mean(rms_error));
  }
}

int runExperiments(int argc, char** argv) {
  const ExperimentOptions options = parseOptions(argc, argv);
  struct Input {
    std::string name;
    DemGrid dem;
    TinMesh tin;
  };
  std::vector<Input> inputs;
  for (const bench::RasterSpec& raster : options.rasters) {
    std::fprintf(stderr, "%s: reading and building the TIN (max error %g m)\n", raster.path.c_str(), raster.tin_max_error_m);
    Input input;
    input.dem = readDem({raster.path});
    Progress quiet(ProgressMode::Quiet);
    input.tin = buildTin(input.dem, TinOptions{raster.tin_max_error_m}, quiet);
    input.name = bench::rasterLabel(raster);
    inputs.push_back(std::move(input));
  }
  const bool all = options.experiment == "all";
  if (all || options.experiment == "partition") {
    std::printf("\n== 1. METIS vs random partition (paper fig 40: METIS 8.6 m vs random 35.5 m max error on average)\n"
                "%d clusters%s, one simplification to 50 %% of the edges, cluster borders locked; mean of %d seeds\n",
                options.clusters, regionNote(options).c_str(), options.runs);
    std::printf("%-34s %9s %8s %8s %9s %9s %8s %8s %8s\n", "raster @ TIN max error", "triangles", "cut METIS",
                "cut rand", "max METIS", "max rand", "rms METIS", "rms rand", "rand/METIS");
    for (const Input& input : inputs) {
      partitionExperiment(input.dem, input.tin, input.name, options.runs, options.clusters, options.region_clusters);
    }
  }
  if (all || options.experiment == "rounds") {
    std::printf("\n== 2. five rounds: re-partition every round vs fixed borders (paper fig 42)\n"
                "METIS %d clusters%s, each round to 50 %% of the edges, no error budget; mean of %d seeds\n",
                options.rounds_clusters, regionNote(options).c_str(), options.runs);
    std::printf("%-34s %5s %10s %10s %10s %10s %9s %9s\n", "raster @ TIN max error", "round", "tri repart",
                "tri fixed", "max repart", "max fixed", "rms repart", "rms fixed");
    for (const Input& input : inputs) {
      roundsExperiment(input.dem, input.tin, input.name, options.runs, options.rounds_clusters, options.region_clusters);
    }
  }
  if (all || options.experiment == "constraints") {
    std::printf("\n== 3. constrained edges vs error (paper 6.1)\n"
                "random connected sets of 8 faces, all their edges locked; METIS %d clusters%s, one simplification to 50 %%; "
                "mean of %d seeds\n", options.clusters, regionNote(options).c_str(), options.runs);
    std::printf("%-34s %13s %11s %9s %8s\n", "raster @ TIN max error", "constrained", "edges kept", "max [m]", "rms [m]");
    for (const Input& input : inputs) {
      constraintExperiment(input.dem, input.tin, input.name, options.runs, options.clusters, options.region_clusters);
    }
  }
  std::fflush(stdout);
  return 0;
}

}  // namespace
}  // namespace terratiles

int main(int argc, char** argv) {
  return terratiles::bench::runProgram("terratiles_lod_experiments", [&] { return terratiles::runExperiments(argc, argv); });
}
