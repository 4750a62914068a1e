// simplifyClusters: validation, the level's topology, the engine (native or CGAL) and the
// assembly of the clusters into the coarser level.

#include "src/simplify/simplify_clusters.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <string>

#include "src/base/error.h"
#include "src/geo/dem_on_globe.h"
#include "src/simplify/cluster_collapse.h"
#include "src/tin/measure_tin.h"

namespace terratiles {

std::string tailStopName(const TailStop& stop) {
  return stop.on() ? std::to_string(stop.tries) + "," + std::to_string(stop.applied) : std::string("off");
}

TailStop parseTailStop(std::string_view text) {
  if (text == "off") return {};
  const auto wholeNumber = [](std::string_view digits, std::uint32_t& value) {
    const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    return !digits.empty() && error == std::errc() && end == digits.data() + digits.size();
  };
  const std::size_t comma = text.find(',');
  std::uint32_t tries = 0, applied = 0;
  if (comma == std::string_view::npos || !wholeNumber(text.substr(0, comma), tries) ||
      !wholeNumber(text.substr(comma + 1), applied) || applied < 1 || applied > tries || applied > 4096) {
    throw Error(ErrorCode::Usage, "--tail-stop is '" + std::string(text) +
                                      "'; expected off or TRIES,APPLIED (whole numbers, 1 <= APPLIED <= TRIES, "
                                      "APPLIED <= 4096), for example 1000,5");
  }
  return {tries, applied};
}
namespace cluster_collapse {
namespace {

std::string edgeText(std::uint64_t key) {
  return "(" + std::to_string(key >> 32) + ", " + std::to_string(key & 0xffffffffu) + ")";
}

void validateOptions(const SimplifyOptions& options) {
  if (!(options.edge_ratio > 0 && options.edge_ratio <= 1)) {
    throw Error(ErrorCode::Usage, "simplify: edge ratio " + std::to_string(options.edge_ratio) +
                                      " is out of range; expected a fraction in (0, 1], e.g. 0.5");
  }
  if (!(options.max_error_m >= 0)) {
    throw Error(ErrorCode::Usage, "simplify: error budget " + std::to_string(options.max_error_m) +
                                      " m is out of range; expected metres >= 0 (infinity: no budget)");
  }
  for (const double metres : {options.metres_per_col, options.metres_per_row}) {
    if (!(metres > 0 && std::isfinite(metres))) {
      throw Error(ErrorCode::Usage, "simplify: grid unit of " + std::to_string(metres) +
                                        " m is out of range; expected a positive number of metres per column and row");
    }
  }
}

void validateMesh(const TinMesh& mesh, const std::vector<std::int32_t>& cluster_of_face, std::int32_t cluster_count) {
  if (mesh.triangle_indices.size() % 3 != 0) {
    throw Error(ErrorCode::Input, "simplifyClusters: " + std::to_string(mesh.triangle_indices.size()) +
                                      " triangle indices; expected 3 per triangle");
  }
  if (mesh.vertices.size() >= kNone || mesh.triangle_indices.size() >= kNone) {
    throw Error(ErrorCode::Input, "simplifyClusters: the mesh has more than 2^32 - 1 vertices or corners; split the input");
  }
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const GridPoint& v = mesh.vertices[i];
    if (!std::isfinite(v.col) || !std::isfinite(v.row) || !std::isfinite(v.height_m)) {
      throw Error(ErrorCode::Input, "simplifyClusters: vertex " + std::to_string(i) + " is not finite");
    }
  }
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t) {
    const std::uint32_t* v = &mesh.triangle_indices[3 * t];
    for (int k = 0; k < 3; ++k) {
      if (v[k] >= mesh.vertices.size()) {
        throw Error(ErrorCode::Input, "simplifyClusters: triangle " + std::to_string(t) + " uses vertex " +
                                          std::to_string(v[k]) + "; expected an index below " +
                                          std::to_string(mesh.vertices.size()));
      }
    }
    if (v[0] == v[1] || v[1] == v[2] || v[2] == v[0]) {
      throw Error(ErrorCode::Input, "simplifyClusters: triangle " + std::to_string(t) +
                                        " uses one vertex twice; expected three distinct vertices");
    }
  }
  if (cluster_of_face.size() != mesh.triangleCount()) {
    throw Error(ErrorCode::Input, "simplifyClusters: " + std::to_string(cluster_of_face.size()) +
                                      " cluster ids for " + std::to_string(mesh.triangleCount()) +
                                      " triangles; expected one per triangle");
  }
  for (std::size_t t = 0; t < cluster_of_face.size(); ++t) {
    if (cluster_of_face[t] < 0 || cluster_of_face[t] >= cluster_count) {
      throw Error(ErrorCode::Input, "simplifyClusters: triangle " + std::to_string(t) + " is in cluster " +
                                        std::to_string(cluster_of_face[t]) + "; expected an id in [0, " +
                                        std::to_string(cluster_count) + ")");
    }
  }
}

}  // namespace

// The corners leaving each vertex (CSR): corner c runs from its vertex to the next corner's.
// An edge's other corner is then among the few leaving its far end: linear time, where a sort
// of every directed edge took a quarter of a level's simplification.
InputTopology buildTopology(const TinMesh& mesh) {
  const std::vector<std::uint32_t>& idx = mesh.triangle_indices;
  const std::size_t corners = idx.size();
  TERRATILES_ASSERT(corners < kNone);
  InputTopology topology;
  const CornersLeaving grouped = cornersLeaving(mesh);  // gone once the opposites are paired
  const std::vector<std::uint32_t>& start = grouped.start;
  const std::vector<std::uint32_t>& leaving = grouped.leaving;
  const std::vector<std::uint32_t>& end = grouped.end;  // per entry of `leaving`: the vertex it runs to
  topology.opposite_corner.assign(corners, kNone);
  const std::size_t vertices = mesh.vertices.size();
  for (std::uint32_t u = 0; u < vertices; ++u) {
    for (std::uint32_t e = start[u]; e < start[u + 1]; ++e) {
      const std::uint32_t c = leaving[e], v = end[e];
      // Found from the other side: that side counted both directions of the edge already.
      if (topology.opposite_corner[c] != kNone) continue;
      // Corners running u -> v (c among them, in corner order) and v -> u.
      std::uint32_t along[2], against = kNone;
      std::size_t same = 0, reverse = 0;
      for (std::uint32_t i = start[u]; i < start[u + 1]; ++i) {
        if (end[i] == v && same++ < 2) along[same - 1] = leaving[i];
      }
      for (std::uint32_t i = start[v]; i < start[v + 1]; ++i) {
        if (end[i] == u && reverse++ == 0) against = leaving[i];
      }
      if (same + reverse > 2) {
        throw Error(ErrorCode::Input,
                    "simplifyClusters: edge " + edgeText(edgeKey(u, v)) + " is in " + std::to_string(same + reverse) +
                        " triangles; expected an edge-manifold mesh (at most two triangles per edge)");
      }
      if (same == 2) {
        throw Error(ErrorCode::Input,
                    "simplifyClusters: triangles " + std::to_string(along[0] / 3) + " and " +
                        std::to_string(along[1] / 3) + " run edge " + edgeText(edgeKey(u, v)) +
                        " in the same direction; expected every triangle counter-clockwise seen from above");
      }
      if (reverse == 1) {
        topology.opposite_corner[c] = against;
        topology.opposite_corner[against] = c;
      }
    }
  }
  return topology;
}



// True when some valid DEM pixel the triangle covers is more than budget_m away from it. Same
// pixel inclusion and measure as measureTin (in the grid frame, or on the globe with the
// corners' ECEF positions), so measureTin confirms the budget.
bool exceedsBudget(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                   double budget_m) {
  bool exceeds = false;
  forEachCoveredPixel(dem, a, b, c, [&](std::size_t i, double surface_m) {
    const float h = dem.heights_m[i];
    exceeds = !std::isnan(h) && std::fabs(surface_m - h) > budget_m;
    return !exceeds;
  });
  return exceeds;
}

// exceedsBudgetOnGlobe: budget_scan.cpp.

bool exceedsBudgetAtPixel(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                          const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double budget_m,
                          std::size_t pixel) {
  const DemGrid& dem = globe.dem();
  if (std::isnan(dem.heights_m[pixel])) return false;
  const auto row = static_cast<std::int32_t>(pixel / static_cast<std::size_t>(dem.width));
  const auto col = static_cast<std::int32_t>(pixel % static_cast<std::size_t>(dem.width));
  double offset_m = 0;
  return coveredInsideOnGlobe(globe, a, b, c, pa, pb, pc, col, row, &offset_m) && !(std::fabs(offset_m) <= budget_m);
}

}  // namespace cluster_collapse

ClusterSimplification simplifyClusters(const DemGrid& dem, const TinMesh& mesh,
                                       const std::vector<std::int32_t>& cluster_of_face,
                                       std::int32_t cluster_count,
                                       const std::vector<std::array<std::uint32_t, 2>>& constrained_edges,
                                       const SimplifyOptions& options) {
  using namespace cluster_collapse;
  validateOptions(options);
  validateMesh(mesh, cluster_of_face, cluster_count);
  if (options.globe && options.vertex_ecef.size() != mesh.vertices.size()) {
    throw Error(ErrorCode::Usage, "simplifyClusters: " + std::to_string(options.vertex_ecef.size()) +
                                      " vertex positions on the globe for " + std::to_string(mesh.vertices.size()) +
                                      " vertices; expected one per vertex");
  }
  InputTopology topology = buildTopology(mesh);
  const auto border_sides = static_cast<std::size_t>(
      std::count(topology.opposite_corner.begin(), topology.opposite_corner.end(), kNone));
  const std::size_t input_edges = (topology.opposite_corner.size() + border_sides) / 2;

  std::vector<std::uint64_t> constrained_keys;
  constrained_keys.reserve(constrained_edges.size());
  for (const auto& edge : constrained_edges) constrained_keys.push_back(edgeKey(edge[0], edge[1]));
  std::sort(constrained_keys.begin(), constrained_keys.end());
  constrained_keys.erase(std::unique(constrained_keys.begin(), constrained_keys.end()), constrained_keys.end());
  if (!constrained_keys.empty()) {
    // Every constrained edge must be an edge of the mesh: one pass over the corners.
    std::vector<std::uint8_t> found(constrained_keys.size(), 0);
    for (std::uint32_t c = 0; c < mesh.triangle_indices.size(); ++c) {
      const std::uint64_t key = edgeKey(mesh.triangle_indices[c], mesh.triangle_indices[nextCorner(c)]);
      const auto it = std::lower_bound(constrained_keys.begin(), constrained_keys.end(), key);
      if (it != constrained_keys.end() && *it == key) found[static_cast<std::size_t>(it - constrained_keys.begin())] = 1;
    }
    for (const auto& edge : constrained_edges) {
      const std::uint64_t key = edgeKey(edge[0], edge[1]);
      const auto it = std::lower_bound(constrained_keys.begin(), constrained_keys.end(), key);
      if (edge[0] == edge[1] || !found[static_cast<std::size_t>(it - constrained_keys.begin())]) {
        throw Error(ErrorCode::Input, "simplifyClusters: constrained edge (" + std::to_string(edge[0]) + ", " +
                                          std::to_string(edge[1]) + ") is not an edge of the mesh");
      }
    }
  }

  // Faces of each cluster, in input order (counting sort).
  const std::size_t clusters = static_cast<std::size_t>(std::max<std::int32_t>(cluster_count, 0));
  std::vector<std::uint32_t> cluster_start(clusters + 1, 0);
  for (const std::int32_t c : cluster_of_face) ++cluster_start[static_cast<std::size_t>(c) + 1];
  for (std::size_t c = 0; c < clusters; ++c) cluster_start[c + 1] += cluster_start[c];
  std::vector<std::uint32_t> faces_by_cluster(cluster_of_face.size());
  {
    std::vector<std::uint32_t> fill(cluster_start.begin(), cluster_start.end() - 1);
    for (std::uint32_t f = 0; f < cluster_of_face.size(); ++f) faces_by_cluster[fill[cluster_of_face[f]]++] = f;
  }

  LevelInput in;
  in.dem = &dem;
  in.mesh = &mesh;
  in.options = &options;
  in.topology = &topology;
  in.cluster_of_face = &cluster_of_face;
  in.constrained_keys = &constrained_keys;
  in.cluster_start = &cluster_start;
  in.faces_by_cluster = &faces_by_cluster;
  const std::vector<ClusterOutput> outputs =
      options.simplifier == Simplifier::Cgal ? collapseWithCgal(in) : collapseNatively(in);
  // Not needed to assemble the coarser mesh, which would otherwise be made beside them (16
  // bytes per input face, 40 MB at SRTM Gabon's level 0).
  topology = InputTopology();
  faces_by_cluster = std::vector<std::uint32_t>();

  // Assemble by vertex index: a vertex shared by clusters is locked in each, so it is the same
  // input vertex at the same input position in all of them.
  ClusterSimplification result;
  result.input_edges = input_edges;
  const std::size_t vertex_count = mesh.vertices.size();
  // Per input vertex: bit 1 moved (maybe removed after), bit 0 used by a triangle (survives).
  std::vector<std::uint8_t> state(vertex_count, 0);
  std::size_t triangle_corners = 0;
  for (const ClusterOutput& out : outputs) {
    for (const auto& moved : out.moved) {
      if (state[moved.first] & 2) {
        throw Error(ErrorCode::Internal, "simplifyClusters: vertex " + std::to_string(moved.first) +
                                             " moved in two clusters; a shared vertex must be locked");
      }
      state[moved.first] = 2;
    }
    triangle_corners += out.triangles.size();
    result.refused_for_error += out.refused_for_error;
    result.refused_for_flip += out.refused_for_flip;
  }
  for (const ClusterOutput& out : outputs) {
    for (const std::uint32_t v : out.triangles) state[v] |= 1;
  }
  result.new_index_of_vertex.assign(vertex_count, kRemovedVertex);
  std::size_t survivors = 0;
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (state[v] & 1) result.new_index_of_vertex[v] = static_cast<std::uint32_t>(survivors++);
  }
  result.mesh.vertices.resize(survivors);
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (state[v] & 1) result.mesh.vertices[result.new_index_of_vertex[v]] = mesh.vertices[v];
  }
  for (const ClusterOutput& out : outputs) {
    for (const auto& [v, g] : out.moved) {
      if (result.new_index_of_vertex[v] != kRemovedVertex) result.mesh.vertices[result.new_index_of_vertex[v]] = g;
    }
  }
  result.mesh.triangle_indices.reserve(triangle_corners);
  result.cluster_of_face.reserve(triangle_corners / 3);
  for (std::size_t c = 0; c < outputs.size(); ++c) {
    for (const std::uint32_t v : outputs[c].triangles) result.mesh.triangle_indices.push_back(result.new_index_of_vertex[v]);
    result.cluster_of_face.insert(result.cluster_of_face.end(), outputs[c].triangles.size() / 3, static_cast<std::int32_t>(c));
  }
  return result;
}

}  // namespace terratiles