// The one translation unit holding CGAL's Surface_mesh_simplification templates (they take
// most of a minute to compile): simplifyClusters' `--simplifier cgal` engine, the quality
// reference the native engine is measured against. The rest of terratiles sees only flat
// arrays.

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Edge_collapse_visitor_base.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Constrained_placement.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_ratio_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>

#include "src/base/error.h"
#include "src/geo/dem_on_globe.h"
#include "src/simplify/cluster_collapse.h"

namespace terratiles {
namespace cluster_collapse {
namespace {

namespace SMS = CGAL::Surface_mesh_simplification;

using Kernel = CGAL::Simple_cartesian<double>;
using Point3 = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point3>;
using VertexIndex = Mesh::Vertex_index;
using LockedMap = Mesh::Property_map<Mesh::Edge_index, bool>;

bool sameBits(const Point3& p, const Point3& q) {
  return p.x() == q.x() && p.y() == q.y() && p.z() == q.z();
}

// Union-find over corners: two corners of one vertex are joined when their triangles are in the
// same cluster and share an edge at that vertex. Each class is one fan of triangles around the
// vertex, so one manifold vertex of the cluster's submesh; a vertex where two fans of one
// cluster touch becomes two submesh vertices (both on border edges, so both locked).
std::vector<std::uint32_t> vertexClassOfCorner(const TinMesh& mesh, const InputTopology& topology,
                                               const std::vector<std::int32_t>& cluster_of_face) {
  const auto corners = static_cast<std::uint32_t>(mesh.triangle_indices.size());
  std::vector<std::uint32_t> parent(corners);
  for (std::uint32_t c = 0; c < corners; ++c) parent[c] = c;
  auto find = [&](std::uint32_t c) {
    while (parent[c] != c) {
      parent[c] = parent[parent[c]];
      c = parent[c];
    }
    return c;
  };
  auto unite = [&](std::uint32_t a, std::uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  };
  for (std::uint32_t c = 0; c < corners; ++c) {
    const std::uint32_t o = topology.opposite_corner[c];
    if (o == kNone || o < c || cluster_of_face[c / 3] != cluster_of_face[o / 3]) continue;
    // c runs u -> v, o runs v -> u.
    unite(c, nextCorner(o));
    unite(nextCorner(c), o);
  }
  for (std::uint32_t c = 0; c < corners; ++c) parent[c] = find(c);
  return parent;
}

// ---------------------------------------------------------------------------------------------
// One cluster's simplification state, shared by the policies, the filter and the visitor.

Quadric planeQuadric(double nx, double ny, double nz, const Point3& on_plane) {
  return cluster_collapse::planeQuadric(nx, ny, nz, on_plane.x(), on_plane.y(), on_plane.z());
}

struct ClusterState {
  const DemGrid* dem = nullptr;
  const SimplifyOptions* options = nullptr;
  std::vector<std::uint32_t> identity;  // per submesh vertex: the input vertex it is
  std::vector<GridPoint> grid;          // per submesh vertex: its position as it will be output
  std::vector<EcefPoint> ecef;          // on the globe: per submesh vertex, grid placed
  // On the globe: the last placement the filter placed (a collapse follows its filter).
  GridPoint filtered_grid;
  EcefPoint filtered_ecef;
  std::vector<Quadric> quadrics;        // per submesh vertex
  std::size_t refused_for_error = 0;
  std::size_t refused_for_flip = 0;
  // The collapse under way (visitor's OnCollapsing -> OnCollapsed).
  bool pending = false;
  Point3 pending_p0, pending_p1, pending_placement;

  GridPoint toGrid(const Point3& p) const {
    return {p.x() / options->metres_per_col, -p.y() / options->metres_per_row, p.z()};
  }
  // ECEF of a vertex at `placed` by collapsing profile's edge: an end's own when it is that
  // end's position, else placed on the globe (exactly as the pipeline will place it).
  template <typename Profile>
  EcefPoint placedEcef(const Profile& profile, const Point3& placement, const GridPoint& placed) {
    if (sameBits(placement, profile.p0())) return ecef[profile.v0()];
    if (sameBits(placement, profile.p1())) return ecef[profile.v1()];
    if (placed.col != filtered_grid.col || placed.row != filtered_grid.row || placed.height_m != filtered_grid.height_m) {
      filtered_grid = placed;
      filtered_ecef = options->globe->place(placed);
    }
    return filtered_ecef;
  }
};

// The grid position a vertex placed at `placement` by collapsing profile's edge would have:
// an end's own position (bit for bit) when the placement is that end's point.
template <typename Profile>
GridPoint placedGrid(const ClusterState& state, const Profile& profile, const Point3& placement) {
  if (sameBits(placement, profile.p0())) return state.grid[profile.v0()];
  if (sameBits(placement, profile.p1())) return state.grid[profile.v1()];
  return state.toGrid(placement);
}

// The triangles a collapse creates are profile.triangles() after the one or two that vanish,
// each (t.v0, placed, t.v2) in the face's order (CGAL's Edge_profile).
template <typename Profile, typename Function>
bool allNewTriangles(const Profile& profile, Function&& function) {
  const auto& triangles = profile.triangles();
  std::size_t first = 0;
  if (profile.left_face_exists()) ++first;
  if (profile.right_face_exists()) ++first;
  for (std::size_t i = first; i < triangles.size(); ++i) {
    if (!function(triangles[i].v0, triangles[i].v2)) return false;
  }
  return true;
}

template <typename Profile>
bool keepsHeightField(const ClusterState& state, const Profile& profile, const GridPoint& placed) {
  return allNewTriangles(profile, [&](VertexIndex a, VertexIndex c) {
    return isUpwardTriangle(state.grid[a], placed, state.grid[c]);
  });
}

// Garland-Heckbert plane quadrics, the cost and placement of CGAL's
// GarlandHeckbert_plane_policies (CGAL 5.5) on plain doubles instead of Eigen matrices. One
// change to the placement: CGAL takes the quadric optimum whenever the 3x3 system's determinant
// is not exactly zero; here it must be well conditioned and keep the star a height field,
// otherwise the best point on the edge, then the cheaper end, then the other end is taken, so
// nearly flat areas (lakes) do not send vertices far away and the filter rarely has to refuse.
class TerrainQuadrics {
 public:
  using Update_tag = CGAL::Tag_true;  // CGAL calls initialize() and update_after_collapse()

  explicit TerrainQuadrics(ClusterState* state) : state_(state) {}

  template <typename VertexPointMap, typename GeomTraits>
  void initialize(const Mesh& mesh, VertexPointMap vpm, const GeomTraits&) const {
    auto& quadrics = state_->quadrics;
    quadrics.assign(mesh.number_of_vertices(), Quadric{});
    constexpr double kDiscontinuityMultiplier = 100;  // CGAL's default
    for (const auto f : mesh.faces()) {
      const auto h = mesh.halfedge(f);
      const Point3& p = get(vpm, mesh.target(h));
      const Point3& q = get(vpm, mesh.target(mesh.next(h)));
      const Point3& r = get(vpm, mesh.source(h));
      auto normal = CGAL::cross_product(q - p, r - p);
      const double length = std::sqrt(normal.squared_length());
      if (length != 0) normal = normal / length;
      const Quadric face_quadric = planeQuadric(normal.x(), normal.y(), normal.z(), p);
      for (const auto s : CGAL::halfedges_around_face(h, mesh)) {
        addTo(quadrics[mesh.source(s)], face_quadric);
        if (!mesh.is_border(mesh.edge(s))) continue;
        // The plane through the border edge, perpendicular to the face (CGAL's edge normal).
        const Point3& sp = get(vpm, mesh.target(s));
        const Point3& sq = get(vpm, mesh.target(mesh.next(s)));
        const Point3& sr = get(vpm, mesh.source(s));
        auto edge_normal = CGAL::cross_product(sp - sr, CGAL::cross_product(sq - sp, sr - sp));
        const double edge_length = std::sqrt(edge_normal.squared_length());
        if (edge_length != 0) edge_normal = edge_normal / edge_length;
        const Quadric edge_quadric = planeQuadric(edge_normal.x(), edge_normal.y(), edge_normal.z(), sp);
        addTo(quadrics[mesh.source(s)], edge_quadric, kDiscontinuityMultiplier);
        addTo(quadrics[mesh.target(s)], edge_quadric, kDiscontinuityMultiplier);
      }
    }
  }

  template <typename Profile>
  void update_after_collapse(const Profile& profile, VertexIndex kept) const {
    Quadric sum = state_->quadrics[profile.v0()];
    addTo(sum, state_->quadrics[profile.v1()]);
    state_->quadrics[kept] = sum;
  }

  // Cost: the combined quadric at the placement.
  template <typename Profile>
  boost::optional<double> operator()(const Profile& profile, const boost::optional<Point3>& placement) const {
    if (!placement) return {};
    return evaluate(combined(profile), placement->x(), placement->y(), placement->z());
  }

  // Placement.
  template <typename Profile>
  boost::optional<Point3> operator()(const Profile& profile) const {
    const Quadric q = combined(profile);
    auto valid = [&](const Point3& p) { return keepsHeightField(*state_, profile, placedGrid(*state_, profile, p)); };
    std::array<double, 3> optimum;
    if (quadricMinimum(q, optimum)) {
      const Point3 point(optimum[0], optimum[1], optimum[2]);
      if (valid(point)) return point;
    }
    // On the segment p0 + t (p1 - p0), as CGAL's construct_optimal_point_singular.
    const Point3& p0 = profile.p0();
    const Point3& p1 = profile.p1();
    const double cost0 = evaluate(q, p0.x(), p0.y(), p0.z());
    const double cost1 = evaluate(q, p1.x(), p1.y(), p1.z());
    const Point3& cheaper = cost0 > cost1 ? p1 : p0;
    const Point3& dearer = cost0 > cost1 ? p0 : p1;
    const auto d = p1 - p0;
    if (const std::optional<double> t = segmentMinimum(q, {p0.x(), p0.y(), p0.z()}, {d.x(), d.y(), d.z()})) {
      const Point3 on_edge = p0 + *t * d;
      if (valid(on_edge)) return on_edge;
    }
    if (valid(cheaper)) return cheaper;
    if (valid(dearer)) return dearer;
    return cheaper;  // the filter refuses it
  }

 private:
  template <typename Profile>
  Quadric combined(const Profile& profile) const {
    Quadric sum = state_->quadrics[profile.v0()];
    addTo(sum, state_->quadrics[profile.v1()]);
    return sum;
  }

  ClusterState* state_;
};

// A face steeper than this (rise over run, about 89.4 degrees) is a wall no terrain level
// needs: simplification only makes one when it pulls a vertex next to a much higher or lower
// one (a sliver), and such a face turns a quantisation step of the vertices into a height
// jump as large as the wall.


// Refuses fold-overs, near-vertical faces and collapses above the error budget (see the
// header).
class TerrainFilter {
 public:
  explicit TerrainFilter(ClusterState* state) : state_(state) {}

  template <typename Profile>
  boost::optional<Point3> operator()(const Profile& profile, boost::optional<Point3> placement) const {
    if (!placement) return placement;
    const GridPoint placed = placedGrid(*state_, profile, *placement);
    if (!keepsHeightField(*state_, profile, placed)) {
      ++state_->refused_for_flip;
      return {};
    }
    const bool walls = !allNewTriangles(profile, [&](VertexIndex a, VertexIndex c) {
      return !isSteeperThan(state_->grid[a], placed, state_->grid[c], state_->options->metres_per_col,
                            state_->options->metres_per_row, kMaxSlope);
    });
    if (walls) {
      ++state_->refused_for_flip;
      return {};
    }
    const double budget_m = state_->options->max_error_m;
    if (std::isfinite(budget_m)) {
      const DemOnGlobe* globe = state_->options->globe;
      const EcefPoint placed_ecef = globe ? state_->placedEcef(profile, *placement, placed) : EcefPoint{};
      const bool within = allNewTriangles(profile, [&](VertexIndex a, VertexIndex c) {
        return globe ? !exceedsBudgetOnGlobe(*globe, state_->grid[a], placed, state_->grid[c], state_->ecef[a],
                                             placed_ecef, state_->ecef[c], budget_m)
                     : !exceedsBudget(*state_->dem, state_->grid[a], placed, state_->grid[c], budget_m);
      });
      if (!within) {
        ++state_->refused_for_error;
        return {};
      }
    }
    return placement;
  }

 private:
  ClusterState* state_;
};

// Keeps each submesh vertex's identity and output position through the collapses. CGAL keeps
// the target of the edge's halfedge whatever the placement, so when the placement is the other
// end's point (a locked end, through Constrained_placement), the kept vertex takes that end's
// identity: a locked vertex keeps its input index and its input GridPoint bit for bit.
class TrackingVisitor : public SMS::Edge_collapse_visitor_base<Mesh> {
 public:
  explicit TrackingVisitor(ClusterState* state) : state_(state) {}

  template <typename Profile>
  void OnCollapsing(const Profile& profile, const boost::optional<Point3>& placement) {
    state_->pending = true;
    state_->pending_p0 = profile.p0();
    state_->pending_p1 = profile.p1();
    state_->pending_placement = placement ? *placement : profile.p0();
  }

  template <typename Profile>
  void OnCollapsed(const Profile& profile, VertexIndex kept) {
    // Zero-length edges are collapsed onto p0 without OnCollapsing.
    const Point3 p0 = state_->pending ? state_->pending_p0 : Point3(profile.p0());
    const Point3 placement = state_->pending ? state_->pending_placement : p0;
    const Point3 p1 = state_->pending ? state_->pending_p1 : p0;
    state_->pending = false;
    const bool globe = state_->options->globe != nullptr;
    if (sameBits(placement, p0)) {
      state_->identity[kept] = state_->identity[profile.v0()];
      state_->grid[kept] = state_->grid[profile.v0()];
      if (globe) state_->ecef[kept] = state_->ecef[profile.v0()];
    } else if (sameBits(placement, p1)) {
      state_->identity[kept] = state_->identity[profile.v1()];
      state_->grid[kept] = state_->grid[profile.v1()];
      if (globe) state_->ecef[kept] = state_->ecef[profile.v1()];
    } else {
      state_->grid[kept] = state_->toGrid(placement);  // moved: keeps the identity CGAL kept
      if (globe) {
        const GridPoint& g = state_->grid[kept];
        const bool filtered = g.col == state_->filtered_grid.col && g.row == state_->filtered_grid.row &&
                              g.height_m == state_->filtered_grid.height_m;
        state_->ecef[kept] = filtered ? state_->filtered_ecef : state_->options->globe->place(g);
      }
    }
  }

 private:
  ClusterState* state_;
};

// What one cluster hands to the assembly.
ClusterOutput simplifyOneCluster(const LevelInput& in, const std::vector<std::uint32_t>& class_of_corner,
                                 std::int32_t cluster,
                                 const std::uint32_t* faces_begin, const std::uint32_t* faces_end,
                                 std::vector<std::uint32_t>& local_of_class) {
  ClusterOutput out;
  const TinMesh& mesh = *in.mesh;
  const SimplifyOptions& options = *in.options;
  ClusterState state;
  state.dem = in.dem;
  state.options = &options;

  // Submesh vertices: one per corner class, numbered by first use.
  const std::size_t face_count = static_cast<std::size_t>(faces_end - faces_begin);
  std::vector<std::uint32_t> local_triangles;
  local_triangles.reserve(3 * face_count);
  for (const std::uint32_t* f = faces_begin; f != faces_end; ++f) {
    for (std::uint32_t k = 0; k < 3; ++k) {
      const std::uint32_t corner = 3 * *f + k;
      const std::uint32_t vertex_class = class_of_corner[corner];
      if (local_of_class[vertex_class] == kNone) {
        local_of_class[vertex_class] = static_cast<std::uint32_t>(state.identity.size());
        state.identity.push_back(mesh.triangle_indices[corner]);
      }
      local_triangles.push_back(local_of_class[vertex_class]);
    }
  }
  Mesh submesh;
  submesh.reserve(static_cast<Mesh::size_type>(state.identity.size()),
                  static_cast<Mesh::size_type>(2 * face_count + 2),
                  static_cast<Mesh::size_type>(face_count));
  state.grid.reserve(state.identity.size());
  if (options.globe) {
    state.ecef.reserve(state.identity.size());
    state.filtered_grid = {std::nan(""), std::nan(""), std::nan("")};
  }
  for (const std::uint32_t v : state.identity) {
    const GridPoint& g = mesh.vertices[v];
    state.grid.push_back(g);
    if (options.globe) state.ecef.push_back(options.vertex_ecef[v]);
    submesh.add_vertex(Point3(g.col * options.metres_per_col, -g.row * options.metres_per_row, g.height_m));
  }
  for (std::size_t t = 0; t < face_count; ++t) {
    const auto face = submesh.add_face(VertexIndex(local_triangles[3 * t]), VertexIndex(local_triangles[3 * t + 1]),
                                       VertexIndex(local_triangles[3 * t + 2]));
    if (face == Mesh::null_face()) {
      throw Error(ErrorCode::Internal, "simplifyClusters: cluster " + std::to_string(cluster) +
                                           ": CGAL refused triangle " + std::to_string(faces_begin[t]) +
                                           " although its fans were split into manifold vertices");
    }
  }

  // Locked edges: the submesh's border (cluster borders and the outer border) and constraints.
  LockedMap locked = submesh.add_property_map<Mesh::Edge_index, bool>("e:locked", false).first;
  for (const auto e : submesh.edges()) {
    bool is_locked = submesh.is_border(e);
    if (!is_locked && !in.constrained_keys->empty()) {
      const auto h = submesh.halfedge(e);
      const std::uint64_t key = edgeKey(state.identity[submesh.source(h)], state.identity[submesh.target(h)]);
      is_locked = std::binary_search(in.constrained_keys->begin(), in.constrained_keys->end(), key);
    }
    locked[e] = is_locked;
  }

  if (options.edge_ratio < 1) {
    const TerrainQuadrics quadrics(&state);
    const SMS::Constrained_placement<TerrainQuadrics, LockedMap> placement(locked, quadrics);
    const TerrainFilter filter(&state);
    const SMS::Count_ratio_stop_predicate<Mesh> stop(options.edge_ratio);
    SMS::edge_collapse(submesh, stop,
                       CGAL::parameters::edge_is_constrained_map(locked)
                           .get_cost(quadrics)
                           .get_placement(placement)
                           .filter(filter)
                           .visitor(TrackingVisitor(&state)));
  }

  out.triangles.reserve(3 * submesh.number_of_faces());
  for (const auto f : submesh.faces()) {
    for (const auto v : CGAL::vertices_around_face(submesh.halfedge(f), submesh)) {
      out.triangles.push_back(state.identity[v]);
    }
  }
  for (const auto v : submesh.vertices()) {
    const GridPoint& g = state.grid[v];
    const GridPoint& input = mesh.vertices[state.identity[v]];
    if (g.col != input.col || g.row != input.row || g.height_m != input.height_m) {
      out.moved.emplace_back(state.identity[v], g);
    }
  }
  out.refused_for_error = state.refused_for_error;
  out.refused_for_flip = state.refused_for_flip;
  return out;
}
}  // namespace

std::vector<ClusterOutput> collapseWithCgal(const LevelInput& in) {
  const std::vector<std::uint32_t> class_of_corner = vertexClassOfCorner(*in.mesh, *in.topology, *in.cluster_of_face);
  const std::vector<std::uint32_t>& cluster_start = *in.cluster_start;
  const std::vector<std::uint32_t>& faces_by_cluster = *in.faces_by_cluster;
  const std::size_t clusters = cluster_start.size() - 1;
  // Clusters are independent once their borders are locked: simplify them in parallel, each
  // into its own slot. local_of_class entries are written only for the corner classes of one
  // cluster's triangles, which no other cluster has.
  std::vector<std::uint32_t> local_of_class(in.mesh->triangle_indices.size(), kNone);
  std::vector<ClusterOutput> outputs(clusters);
  forEachClusterLargestFirst(cluster_start, [&](std::uint32_t c) {
    outputs[c] = simplifyOneCluster(in, class_of_corner, static_cast<std::int32_t>(c),
                                    faces_by_cluster.data() + cluster_start[c],
                                    faces_by_cluster.data() + cluster_start[c + 1], local_of_class);
  });
  return outputs;
}

}  // namespace cluster_collapse
}  // namespace terratiles
