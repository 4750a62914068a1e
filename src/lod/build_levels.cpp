#include "src/lod/build_levels.h"

#include <ogr_spatialref.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include "src/base/error.h"
#include "src/base/freed_memory.h"
#include "src/partition/face_graph.h"
#include "src/simplify/simplify_clusters.h"

namespace terratiles {
namespace {

std::uint64_t edgeKey(std::uint32_t a, std::uint32_t b) {
  return (static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
}

std::int32_t clustersFor(const LevelOptions& options, std::size_t level, std::size_t triangles) {
  if (level < options.clusters_per_level.size()) return std::max<std::int32_t>(1, options.clusters_per_level[level]);
  const std::size_t per = static_cast<std::size_t>(options.cluster_triangles);
  return static_cast<std::int32_t>(std::max<std::size_t>(1, (triangles + per - 1) / per));
}

void checkOptions(const LevelOptions& options) {
  const auto usage = [](const std::string& message) { throw Error(ErrorCode::Usage, message); };
  if (options.cluster_triangles < 1) usage("--cluster-triangles must be >= 1, found " + std::to_string(options.cluster_triangles));
  if (!(options.level_ratio > 0 && options.level_ratio < 1)) {
    usage("--level-ratio must be in (0, 1), found " + std::to_string(options.level_ratio));
  }
  if (!(options.first_budget_m >= 0)) usage("the first level's error budget must be >= 0 m");
  if (!(options.level_error_growth >= 1)) {
    usage("--level-error-growth must be >= 1, found " + std::to_string(options.level_error_growth));
  }
  if (options.coarser_levels < 0) usage("the number of levels must be >= 0");
  if (options.region_clusters < 0) usage("the clusters per partition region must be >= 0 (0: global), found " + std::to_string(options.region_clusters));
}

// The level's regions for partitionFaces (LevelOptions::partition_regions, region_clusters),
// or none: METIS over whole components.
std::vector<std::int32_t> partitionRegions(const LevelOptions& options, const TinMesh& mesh, std::size_t level,
                                           std::int32_t clusters) {
  if (options.partition_regions) return options.partition_regions(mesh, level);
  return clusterCellRegions(mesh, clusters, options.region_clusters, level % 2 == 1);
}

}  // namespace

std::array<double, 2> groundMetresPerPixel(const DemGrid& dem) {
  OGRSpatialReference crs;
  if (dem.crs_wkt.empty() || crs.importFromWkt(dem.crs_wkt.c_str()) != OGRERR_NONE) {
    return {dem.pixel_size_x, dem.pixel_size_y};  // no CRS: grid units taken as metres
  }
  if (crs.IsGeographic()) {
    // WGS84 meridian and parallel radii at the centre latitude; per degree.
    const double latitude = (dem.origin_y - 0.5 * dem.height * dem.pixel_size_y) * M_PI / 180.0;
    const double a = 6378137.0, e2 = 0.00669437999014;
    const double w = std::sqrt(1 - e2 * std::sin(latitude) * std::sin(latitude));
    const double meridian = a * (1 - e2) / (w * w * w), normal = a / w;
    const double per_degree = M_PI / 180.0;
    return {dem.pixel_size_x * per_degree * normal * std::cos(latitude), dem.pixel_size_y * per_degree * meridian};
  }
  const double unit = crs.GetLinearUnits();  // metres per CRS unit
  return {dem.pixel_size_x * unit, dem.pixel_size_y * unit};
}

std::vector<std::uint64_t> meshEdgeKeys(const TinMesh& mesh) {
  std::vector<std::uint64_t> keys;
  keys.reserve(mesh.triangle_indices.size());
  const auto& idx = mesh.triangle_indices;
  for (std::size_t s = 0; s < idx.size(); ++s) keys.push_back(edgeKey(idx[s], idx[s % 3 == 2 ? s - 2 : s + 1]));
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

std::size_t meshEdgeCount(const TinMesh& mesh) {
  const std::size_t vertices = mesh.vertices.size();
  const CornersLeaving grouped = cornersLeaving(mesh);
  const std::vector<std::uint32_t>& start = grouped.start;
  const std::vector<std::uint32_t>& end = grouped.end;
  const auto leaves = [&](std::uint32_t from, std::uint32_t to, std::uint32_t before) {
    for (std::uint32_t i = start[from]; i < before; ++i) {
      if (end[i] == to) return true;
    }
    return false;
  };
  std::size_t count = 0;
  for (std::uint32_t u = 0; u < vertices; ++u) {
    for (std::uint32_t e = start[u]; e < start[u + 1]; ++e) {
      const std::uint32_t v = end[e];
      if (leaves(u, v, e)) continue;                     // counted at its first appearance
      if (v < u && leaves(v, u, start[v + 1])) continue;  // counted at v, its lower end
      ++count;
    }
  }
  return count;
}

std::vector<std::array<std::uint32_t, 2>> randomFaceSetConstraints(const TinMesh& mesh, std::size_t count,
                                                                   std::size_t set_faces, std::uint32_t seed) {
  std::vector<std::array<std::uint32_t, 2>> edges;
  if (mesh.triangleCount() == 0 || count == 0) return edges;
  const FaceGraph graph = buildFaceGraph(mesh);
  std::mt19937 random(seed);
  std::vector<std::uint64_t> keys;
  std::vector<std::uint8_t> taken(mesh.triangleCount(), 0);
  std::uniform_int_distribution<std::size_t> pick(0, mesh.triangleCount() - 1);
  for (std::size_t s = 0; s < count; ++s) {
    std::vector<std::size_t> set{pick(random)};
    taken[set[0]] = 1;
    for (std::size_t i = 0; i < set.size() && set.size() < set_faces; ++i) {
      for (std::int32_t n = graph.offsets[set[i]]; n < graph.offsets[set[i] + 1] && set.size() < set_faces; ++n) {
        const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
        if (!taken[other]) {
          taken[other] = 1;
          set.push_back(other);
        }
      }
    }
    for (const std::size_t t : set) {
      for (std::size_t k = 0; k < 3; ++k) {
        keys.push_back(edgeKey(mesh.triangle_indices[3 * t + k], mesh.triangle_indices[3 * t + (k + 1) % 3]));
      }
    }
  }
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  for (const std::uint64_t key : keys) edges.push_back({static_cast<std::uint32_t>(key >> 32), static_cast<std::uint32_t>(key)});
  return edges;
}

std::vector<Level> buildLevels(const DemGrid& dem, TinMesh finest, const LevelOptions& options,
                               std::vector<std::array<std::uint32_t, 2>> constraints, Progress& progress) {
  checkOptions(options);
  const std::array<double, 2> metres = groundMetresPerPixel(dem);
  std::vector<Level> levels;
  levels.emplace_back();
  levels[0].mesh = std::move(finest);
  FacePartition inherited;  // fixed borders: the clusters of the level just built
  for (std::size_t l = 0;; ++l) {
    Level& level = levels[l];
    // The level's vertices on the globe, while it is measured and simplified: a level keeps
    // none (DemOnGlobe::place finds a lattice vertex's point among the DEM's pixels, so
    // whoever needs them later places them again for little), and a build, which measures its
    // tiles instead, places them only after the partition, whose face graph and METIS
    // workspace are the level's largest memory.
    std::vector<EcefPoint> vertex_ecef;
    const auto placeVertices = [&] {
      vertex_ecef.resize(level.mesh.vertices.size());
      options.globe->place(level.mesh.vertices, {}, vertex_ecef);
    };
    if (options.measure) {
      progress.beginStage("level " + std::to_string(l) + ": measuring", 0);
      if (options.globe) {
        placeVertices();
        level.error = measureTin(*options.globe, level.mesh, vertex_ecef);
      } else {
        level.error = measureTin(dem, level.mesh);
      }
      progress.endStage();
    }
    const std::size_t triangles = level.mesh.triangleCount();
    // A level's edges are counted by its simplification (from the topology it builds), or here
    // when it is the coarsest (or when the stop rule below counted them already).
    if ((options.coarser_levels > 0 && l >= static_cast<std::size_t>(options.coarser_levels)) ||
        (l > 0 && options.coarser_levels == 0 && levels[l - 1].partition.cluster_count == 1) || triangles < 2) {
      if (level.edge_count == 0) level.edge_count = meshEdgeCount(level.mesh);
      break;
    }

    progress.beginStage("level " + std::to_string(l + 1) + ": clusters", 0);
    if (options.repartition || l == 0) {
      PartitionOptions partition_options;
      partition_options.method = options.partitioner;
      partition_options.clusters = clustersFor(options, l, triangles);
      partition_options.seed = options.seed + static_cast<std::uint32_t>(l);
      // The face graph lives only while the partition is made (at level 0 it is as large as
      // the mesh itself).
      const FaceGraph graph = buildFaceGraph(level.mesh);
      const std::vector<std::int32_t> regions = partitionRegions(options, level.mesh, l, partition_options.clusters);
      level.partition = partitionFaces(graph, partition_options, regions);
      if (options.regroup_clusters) level.partition = options.regroup_clusters(level.mesh, l, level.partition);
    } else {
      level.partition = std::move(inherited);
    }
    progress.endStage();

    returnFreedMemory();  // the face graph and METIS's workspace, which the simplification does not reuse
    if (options.globe && vertex_ecef.empty()) {
      progress.beginStage("level " + std::to_string(l) + ": placing vertices", 0);
      placeVertices();
      progress.endStage();
    }
    progress.beginStage("level " + std::to_string(l + 1) + ": simplifying " +
                            std::to_string(level.partition.cluster_count) + " clusters", 0);
    SimplifyOptions simplify;
    simplify.simplifier = options.simplifier;
    simplify.tail_stop = options.tail_stop;
    simplify.edge_ratio = options.level_ratio;
    simplify.metres_per_col = metres[0];
    simplify.metres_per_row = metres[1];
    simplify.globe = options.globe;
    simplify.vertex_ecef = vertex_ecef;
    Level next;
    if (options.first_budget_m > 0 && std::isfinite(options.first_budget_m)) {
      next.budget_m = options.first_budget_m * std::pow(options.level_error_growth, static_cast<double>(l));
      simplify.max_error_m = next.budget_m;
    }
    ClusterSimplification simplified = simplifyClusters(dem, level.mesh, level.partition.cluster_of_face,
                                                        level.partition.cluster_count, constraints, simplify);
    progress.endStage();
    progress.throwIfCancelled();
    level.edge_count = simplified.input_edges;
    // The coarser level's edges: listed when constraints must be found among them, counted
    // now when the stop rule needs them (the list's length, if listed), else by its own
    // simplification or when it is the coarsest.
    const std::vector<std::uint64_t> edges = constraints.empty() ? std::vector<std::uint64_t>() : meshEdgeKeys(simplified.mesh);
    const std::size_t edge_count = options.coarser_levels != 0 ? 0 : !constraints.empty() ? edges.size() : meshEdgeCount(simplified.mesh);
    if (options.coarser_levels == 0) {
      // A level must be worth its tiles: about level_ratio of the edges, or (when the budget
      // stopped it) at least 10 % fewer triangles. Otherwise the locked edges (outer border,
      // constraints) dominate and the finer level is the coarsest.
      const double edge_ratio = static_cast<double>(edge_count) / static_cast<double>(level.edge_count);
      const bool halved = edge_ratio <= options.level_ratio + 0.1;
      const bool budget_bound = simplified.refused_for_error > 0 && simplified.mesh.triangleCount() <= triangles * 9 / 10;
      if (!halved && !budget_bound) {
        level.partition = {};
        break;
      }
    }

    // Paper algorithm 2: every constrained edge must still be an edge of the coarser level.
    for (std::array<std::uint32_t, 2>& edge : constraints) {
      const std::uint32_t a = simplified.new_index_of_vertex[edge[0]], b = simplified.new_index_of_vertex[edge[1]];
      if (a == kRemovedVertex || b == kRemovedVertex || !std::binary_search(edges.begin(), edges.end(), edgeKey(a, b))) {
        throw Error(ErrorCode::Internal, "level " + std::to_string(l + 1) + " lost the constrained edge " +
                                             std::to_string(edge[0]) + "-" + std::to_string(edge[1]) +
                                             " of level " + std::to_string(l));
      }
      edge = {a, b};
    }
    level.index_in_coarser = std::move(simplified.new_index_of_vertex);
    next.mesh = std::move(simplified.mesh);
    next.edge_count = edge_count;
    if (!options.repartition) inherited = {simplified.cluster_of_face, level.partition.cluster_count};
    next.inherited_partition = {std::move(simplified.cluster_of_face), level.partition.cluster_count};
    next.refused_for_error = simplified.refused_for_error;
    next.refused_for_flip = simplified.refused_for_flip;
    levels.push_back(std::move(next));
  }
  return levels;
}

}  // namespace terratiles
