// simplifyClusters' default engine: edge collapses over flat arrays, in passes (see
// simplify_clusters.h, Simplifier::Native).

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <functional>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <utility>

#include "src/geo/dem_on_globe.h"
#include "src/simplify/cluster_collapse.h"

namespace terratiles {
namespace cluster_collapse {
namespace {

// Vertices on a locked edge: the dataset's outer border, a border between two clusters or a
// constraint. Every other vertex has a closed star inside one cluster.
std::vector<std::uint8_t> lockedVertices(const LevelInput& in) {
  const TinMesh& mesh = *in.mesh;
  const std::vector<std::uint32_t>& opposite = in.topology->opposite_corner;
  const std::vector<std::int32_t>& cluster_of_face = *in.cluster_of_face;
  const std::vector<std::uint64_t>& constrained = *in.constrained_keys;
  std::vector<std::uint8_t> locked(mesh.vertices.size(), 0);
  const auto corners = static_cast<std::uint32_t>(mesh.triangle_indices.size());
  for (std::uint32_t c = 0; c < corners; ++c) {
    const std::uint32_t o = opposite[c];
    const std::uint32_t u = mesh.triangle_indices[c], v = mesh.triangle_indices[nextCorner(c)];
    const bool is_locked = o == kNone || cluster_of_face[c / 3] != cluster_of_face[o / 3] ||
                           (!constrained.empty() && std::binary_search(constrained.begin(), constrained.end(), edgeKey(u, v)));
    if (is_locked) locked[u] = locked[v] = 1;
  }
  return locked;
}

constexpr std::size_t kNoPixel = std::numeric_limits<std::size_t>::max();
// A quadric optimum closer than this to an end of its edge, in columns and in rows, is that
// end (see quadricOptimum).
constexpr double kEndSnapPx = 0.01;

// A collapse of the vertex under way, u: u goes to v, and v stays or moves.
struct Collapse {
  double cost = 0;
  std::uint32_t v = kNone;
  bool moves = false;    // both ends free: v moves to `placed` (the quadric optimum)
  bool on_edge = false;  // moves to the segment's least point instead (segmentOptimum)
  GridPoint placed;
  bool operator<(const Collapse& other) const {
    return cost != other.cost ? cost < other.cost : v != other.v ? v < other.v : moves < other.moves;
  }
};

// A collapse of a refused vertex u not tried yet (ClusterArrays::waiting): its cost, for the
// order, and which it is (UntriedCollapse's placement). Where v would go is computed again
// when it is tried, the same bits: nothing it depends on (the quadrics and places of u and
// v) changes while u waits, since a collapse that changes u or v, or u's star, queues u
// afresh and drops its list. 16 bytes instead of a Collapse's 40: at ETOPO5's coarse levels
// the lists held up to 110 MB per thread.
struct WaitingCollapse {
  double cost = 0;
  std::uint32_t v = kNone;
  std::uint8_t placement = UntriedCollapse::kStays;
};

std::uint8_t placementOf(const Collapse& c) {
  return c.on_edge ? UntriedCollapse::kOnEdge : c.moves ? UntriedCollapse::kOptimum : UntriedCollapse::kStays;
}

// One thread's arrays, reused for every cluster it simplifies.
struct ClusterArrays {
  std::vector<std::uint32_t> local_of_vertex;  // per input vertex: its local index, or kNone
  std::vector<std::uint32_t> identity;         // per local vertex: the input vertex
  std::vector<GridPoint> grid;
  std::vector<EcefPoint> ecef;
  std::vector<std::array<double, 3>> metres;   // x east, y north, z up, from the cluster's first vertex
  std::vector<Quadric> quadric;
  std::vector<std::uint8_t> locked, removed;
  std::vector<std::size_t> broken_pixel;  // per local vertex: the last pixel beyond the budget of one of its collapses
  std::vector<std::uint32_t> corners;          // 3 local vertices per local triangle
  std::vector<std::uint8_t> alive;             // per local triangle
  // Per local vertex: the triangles it was in at the start (CSR). A vertex's triangles now are
  // those of the vertices it absorbed too: `absorbed_next` chains them from the vertex itself
  // (kNone ends a chain, `absorbed_last` is its last link).
  std::vector<std::uint32_t> star_start, star, star_fill;
  std::vector<std::uint32_t> absorbed_next, absorbed_last;
  // Per local vertex: its cheapest collapse (the queue's key is its cost; v = kNone: none
  // known), kept so that a collapse next to it recomputes only the collapses it changes, and
  // tried first when the vertex comes out of the queue.
  std::vector<Collapse> best;
  // A vertex the filter refused since its star last changed (`refused` 1) waits in the queue
  // at its next collapse: its collapses not tried yet, from the cheapest, are
  // waiting[waiting_next[u] .. waiting_end[u]) (a pool for the cluster, compacted as it grows;
  // a list is dropped when the star changes).
  std::vector<std::uint8_t> refused;
  std::vector<WaitingCollapse> waiting;
  std::vector<std::uint32_t> waiting_next, waiting_end;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> live_lists;  // compactWaiting's (start, vertex)
  // The queue: a binary heap of free vertices by (best_cost, vertex), and each vertex's place
  // in it (kNone: not queued).
  struct QueueEntry {
    double cost;
    std::uint32_t vertex;
  };
  std::vector<QueueEntry> heap;
  std::vector<std::uint32_t> heap_place;
  std::vector<std::uint32_t> u_triangles, u_ring, v_triangles, v_ring, around;
  std::vector<Collapse> targets;  // the collapses of the vertex under way
  // Points placed on the globe, by their grid point's bits (direct-mapped): a vertex refused
  // for its budget is tried again at the same optimum after every collapse next to it, and
  // placing a point (CRS, geoid, ECEF) costs more than the rest of a try.
  struct PlacedPoint {
    GridPoint grid{std::numeric_limits<double>::quiet_NaN(), 0, 0};
    EcefPoint ecef;
  };
  std::vector<PlacedPoint> placed_points = std::vector<PlacedPoint>(65536);
  // Quadric optima of edges between free vertices, by the edge's ends and when they last
  // changed (changed_at; direct-mapped): an edge's optimum (the same from either end: Q_u +
  // Q_v has the same bits as Q_v + Q_u) is asked for by both ends when they are queued, and
  // again whenever a collapse next to an end queues it again, but changes only when a
  // collapse changes an end (a collapse into v gives v a new quadric, and may move it).
  // `generation` tells the clusters (and a split cluster's two runs) apart.
  struct EdgeOptimum {
    std::uint32_t lo = kNone, hi = kNone, lo_changed_at = 0, hi_changed_at = 0, generation = 0;
    bool moves = false;  // false: no optimum (ill-conditioned, or at an end)
    double cost = 0;
    GridPoint placed;
  };
  std::vector<EdgeOptimum> edge_optima = std::vector<EdgeOptimum>(16384);
  std::uint32_t generation = 0;
  // Collapses the filter refused, by (u, v, placement) (direct-mapped): the new triangle that
  // failed, made from `triangle` of u's star (or v's, when v moves), and the count of
  // collapses applied then. As long as neither end nor any corner of that triangle has changed
  // since (changed_at), the collapse makes the same triangle and fails again: a vertex
  // queued again after a collapse next to it skips its refused collapses that collapse did
  // not touch.
  struct Refusal {
    std::uint32_t u = kNone, v_and_placement = 0, triangle = 0, applied = 0, generation = 0;
    bool for_error = false;
  };
  std::vector<Refusal> refusals = std::vector<Refusal>(16384);
  // The tail stop (SimplifyOptions::tail_stop): the try count at each of the last
  // tail_stop.applied applied collapses, a ring by collapse number.
  std::vector<std::uint64_t> tries_at_applied;
  std::vector<std::uint32_t> changed_at;  // per local vertex: the count of collapses applied when its quadric or place last changed (0: never)
};

// How a cluster is loaded besides its faces: for a part of a split cluster, and for the whole
// of it after its parts.
struct ClusterSetup {
  const GridPoint* origin = nullptr;  // of the metres frame (default: the first face's first vertex)
  double edge_ratio = 0;              // the stop rule's ratio (0: SimplifyOptions::edge_ratio)
  std::size_t initial_edges = 0;      // the stop rule's initial count (0: the cluster's own)
  const std::vector<Quadric>* quadrics = nullptr;  // per input vertex, instead of its faces' planes
  bool keep_quadrics = false;         // hand every survivor's quadric (and the refused vertices) to the output
  // Per input vertex, kNone or an index into `untried_start`: the filter refused the vertex in
  // its part and its star has not changed since (nor has any neighbour been freed). It starts
  // as refused here, waiting at the collapses it had not tried yet
  // (untried[untried_start[i] .. untried_start[i + 1]), `into` an input vertex): the filter
  // would refuse the others again.
  const std::vector<std::uint32_t>* refused_in_part = nullptr;
  const std::vector<std::uint32_t>* untried_start = nullptr;
  const std::vector<UntriedCollapse>* untried = nullptr;
};

class ClusterCollapser {
 public:
  ClusterCollapser(const LevelInput& in, const std::vector<std::uint8_t>& locked_vertex, ClusterArrays& arrays)
      : in_(in), options_(*in.options), locked_vertex_(locked_vertex), a_(arrays) {}

  ClusterOutput simplify(std::int32_t cluster, const std::uint32_t* faces_begin, const std::uint32_t* faces_end,
                         const ClusterSetup& setup = {}) {
    edge_ratio_ = setup.edge_ratio > 0 ? setup.edge_ratio : options_.edge_ratio;
    setup_ = &setup;
    load(cluster, faces_begin, faces_end, setup);
    ClusterOutput out;
    const bool collapsed = edge_ratio_ < 1;
    if (collapsed) collapse(out);
    out.triangles.reserve(3 * live_triangles_);
    const std::size_t triangles = a_.alive.size();
    for (std::size_t t = 0; t < triangles; ++t) {
      if (!a_.alive[t]) continue;
      for (std::size_t k = 0; k < 3; ++k) out.triangles.push_back(a_.identity[a_.corners[3 * t + k]]);
    }
    const TinMesh& mesh = *in_.mesh;
    for (std::size_t l = 0; l < a_.identity.size(); ++l) {
      const GridPoint& g = a_.grid[l];
      const GridPoint& input = mesh.vertices[a_.identity[l]];
      if (g.col != input.col || g.row != input.row || g.height_m != input.height_m) {
        out.moved.emplace_back(a_.identity[l], g);
      }
    }
    if (setup.keep_quadrics) {
      for (std::size_t l = 0; l < a_.identity.size(); ++l) {
        if (a_.removed[l]) continue;
        out.quadrics.emplace_back(a_.identity[l], a_.quadric[l]);
        if (!collapsed || a_.locked[l] || !a_.refused[l]) continue;
        out.refused_vertices.push_back(a_.identity[l]);
        out.untried_start.push_back(static_cast<std::uint32_t>(out.untried.size()));
        for (std::uint32_t i = a_.waiting_next[l]; i < a_.waiting_end[l]; ++i) {
          const WaitingCollapse& c = a_.waiting[i];
          out.untried.push_back({a_.identity[c.v], c.placement});
        }
      }
      out.untried_start.push_back(static_cast<std::uint32_t>(out.untried.size()));
    }
    for (const std::uint32_t v : a_.identity) a_.local_of_vertex[v] = kNone;
    setup_ = nullptr;
    return out;
  }

 private:
  void load(std::int32_t cluster, const std::uint32_t* faces_begin, const std::uint32_t* faces_end,
            const ClusterSetup& setup) {
    const TinMesh& mesh = *in_.mesh;
    const std::vector<std::uint32_t>& opposite = in_.topology->opposite_corner;
    const std::vector<std::int32_t>& cluster_of_face = *in_.cluster_of_face;
    a_.identity.clear();
    a_.corners.clear();
    std::size_t border_halfedges = 0;
    for (const std::uint32_t* f = faces_begin; f != faces_end; ++f) {
      for (std::uint32_t k = 0; k < 3; ++k) {
        const std::uint32_t corner = 3 * *f + k;
        const std::uint32_t v = mesh.triangle_indices[corner];
        if (a_.local_of_vertex[v] == kNone) {
          a_.local_of_vertex[v] = static_cast<std::uint32_t>(a_.identity.size());
          a_.identity.push_back(v);
        }
        a_.corners.push_back(a_.local_of_vertex[v]);
        const std::uint32_t o = opposite[corner];
        if (o == kNone || cluster_of_face[o / 3] != cluster) ++border_halfedges;
      }
    }
    const std::size_t vertices = a_.identity.size(), triangles = a_.corners.size() / 3;
    live_triangles_ = triangles;
    edges_ = (a_.corners.size() + border_halfedges) / 2;
    initial_edges_ = setup.initial_edges > 0 ? setup.initial_edges : edges_;
    a_.alive.assign(triangles, 1);
    a_.removed.assign(vertices, 0);
    a_.grid.resize(vertices);
    a_.metres.resize(vertices);
    a_.locked.resize(vertices);
    a_.quadric.assign(vertices, Quadric{});
    if (options_.globe) a_.ecef.resize(vertices);
    origin_ = setup.origin ? *setup.origin : mesh.vertices[a_.identity[0]];
    const GridPoint& origin = origin_;
    for (std::size_t l = 0; l < vertices; ++l) {
      const std::uint32_t v = a_.identity[l];
      const GridPoint& g = mesh.vertices[v];
      a_.grid[l] = g;
      a_.metres[l] = {(g.col - origin.col) * options_.metres_per_col, -(g.row - origin.row) * options_.metres_per_row,
                      g.height_m - origin.height_m};
      a_.locked[l] = locked_vertex_[v];
      if (options_.globe) a_.ecef[l] = options_.vertex_ecef[v];
    }
    if (setup.quadrics) {
      for (std::size_t l = 0; l < vertices; ++l) a_.quadric[l] = (*setup.quadrics)[a_.identity[l]];
      return;
    }
    // Plane quadrics with unit normals (as CGAL's GarlandHeckbert_plane_policies); a border
    // needs no plane of its own since its vertices never move.
    for (std::size_t t = 0; t < triangles; ++t) {
      const auto& p = a_.metres[a_.corners[3 * t]];
      const auto& q = a_.metres[a_.corners[3 * t + 1]];
      const auto& r = a_.metres[a_.corners[3 * t + 2]];
      const double ux = q[0] - p[0], uy = q[1] - p[1], uz = q[2] - p[2];
      const double vx = r[0] - p[0], vy = r[1] - p[1], vz = r[2] - p[2];
      double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      const double length = std::sqrt(nx * nx + ny * ny + nz * nz);
      if (length != 0) {
        nx /= length;
        ny /= length;
        nz /= length;
      }
      const Quadric plane = planeQuadric(nx, ny, nz, p[0], p[1], p[2]);
      for (std::size_t k = 0; k < 3; ++k) addTo(a_.quadric[a_.corners[3 * t + k]], plane);
    }
  }

  // The stop rule of CGAL's Count_ratio_stop_predicate: collapse while edges / initial >= ratio.
  bool wantsMore() const {
    return static_cast<double>(edges_) >= edge_ratio_ * static_cast<double>(initial_edges_);
  }

  std::array<double, 3> metresOf(const GridPoint& g) const {
    return {(g.col - origin_.col) * options_.metres_per_col, -(g.row - origin_.row) * options_.metres_per_row,
            g.height_m - origin_.height_m};
  }

  Quadric combined(std::uint32_t u, std::uint32_t v) const {
    Quadric sum = a_.quadric[u];
    addTo(sum, a_.quadric[v]);
    return sum;
  }


  // u -> v with v moved to g, at the cost of the edge's quadric q there.
  Collapse movedTo(const Quadric& q, std::uint32_t v, const GridPoint& g) const {
    const auto m = metresOf(g);
    return {std::max(0.0, evaluate(q, m[0], m[1], m[2])), v, true, false, g};
  }

  // Both ends free: the point of segment uv where the edge's quadric is least (CGAL's
  // fallback placement when the optimum is unusable), strictly between the ends; none
  // (moves false) otherwise.
  Collapse segmentOptimum(const Quadric& q, std::uint32_t u, std::uint32_t v) const {
    const auto& p0 = a_.metres[v];
    const auto& p1 = a_.metres[u];
    const std::optional<double> t = segmentMinimum(q, p0, {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]});
    if (!t) return {};
    const GridPoint& g0 = a_.grid[v];
    const GridPoint& g1 = a_.grid[u];
    Collapse on_edge = movedTo(q, v, {g0.col + *t * (g1.col - g0.col), g0.row + *t * (g1.row - g0.row),
                                      g0.height_m + *t * (g1.height_m - g0.height_m)});
    on_edge.on_edge = true;
    return on_edge;
  }

  // quadricOptimum(q, u, v), remembered for the edge uv until a collapse changes u or v.
  // q: the edge's quadric, or nullptr to sum it only when the optimum is not remembered.
  Collapse cachedOptimum(const Quadric* q, std::uint32_t u, std::uint32_t v) {
    const std::uint32_t lo = std::min(u, v), hi = std::max(u, v);
    const std::uint64_t hash = (std::uint64_t{lo} * 0x9E3779B97F4A7C15ull) ^ (std::uint64_t{hi} * 0xC2B2AE3D27D4EB4Full);
    ClusterArrays::EdgeOptimum& entry = a_.edge_optima[(hash >> 32) & (a_.edge_optima.size() - 1)];
    if (entry.lo != lo || entry.hi != hi || entry.lo_changed_at != a_.changed_at[lo] ||
        entry.hi_changed_at != a_.changed_at[hi] ||
        entry.generation != a_.generation) {
      const Collapse optimum = quadricOptimum(q ? *q : combined(u, v), u, v);
      entry = {lo, hi, a_.changed_at[lo], a_.changed_at[hi], a_.generation, optimum.moves, optimum.cost, optimum.placed};
    }
    Collapse collapse;
    if (entry.moves) collapse = {entry.cost, v, true, false, entry.placed};
    return collapse;
  }

  // Both ends free: the edge's quadric optimum (CGAL's Garland-Heckbert placement) with its
  // cost; none (moves false) when the 3x3 system is ill-conditioned or the optimum is an end.
  Collapse quadricOptimum(const Quadric& q, std::uint32_t u, std::uint32_t v) const {
    std::array<double, 3> optimum;
    if (!quadricMinimum(q, optimum)) return {};
    const GridPoint g{optimum[0] / options_.metres_per_col + origin_.col,
                      -optimum[1] / options_.metres_per_row + origin_.row, optimum[2] + origin_.height_m};
    if (!(std::isfinite(g.col) && std::isfinite(g.row) && std::isfinite(g.height_m))) return {};
    // An optimum at an end, or within kEndSnapPx of one in the grid (the rounding of a
    // quadric whose least point is that end), is no move: the collapse into the end covers
    // it. A vertex nudged a thousandth of a pixel off the lattice turns the triangles of
    // lattice points it was collinear with into slivers as tall as the terrain between them,
    // which the quantisation of the tiles folds over (measured on ETOPO5: a 4.6 m wide sliver
    // 324 m high drawn 262 m off the DEM at a 40 m budget).
    for (const std::uint32_t end : {u, v}) {
      if (std::fabs(a_.grid[end].col - g.col) < kEndSnapPx && std::fabs(a_.grid[end].row - g.row) < kEndSnapPx) return {};
    }
    return movedTo(q, v, g);
  }

  // The vertex after u in triangle t (u's ring, counter-clockwise).
  std::uint32_t after(std::uint32_t t, std::uint32_t u) const {
    const std::uint32_t* c = &a_.corners[3 * t];
    return c[0] == u ? c[1] : c[1] == u ? c[2] : c[0];
  }

  void buildStars() {
    const std::size_t vertices = a_.identity.size(), triangles = a_.alive.size();
    a_.star_start.assign(vertices + 1, 0);
    for (std::size_t t = 0; t < triangles; ++t) {
      if (!a_.alive[t]) continue;
      for (std::size_t k = 0; k < 3; ++k) ++a_.star_start[a_.corners[3 * t + k] + 1];
    }
    for (std::size_t v = 0; v < vertices; ++v) a_.star_start[v + 1] += a_.star_start[v];
    a_.star.resize(a_.star_start[vertices]);
    a_.star_fill.assign(a_.star_start.begin(), a_.star_start.end() - 1);
    for (std::size_t t = 0; t < triangles; ++t) {
      if (!a_.alive[t]) continue;
      for (std::size_t k = 0; k < 3; ++k) a_.star[a_.star_fill[a_.corners[3 * t + k]]++] = static_cast<std::uint32_t>(t);
    }
  }

  // u's alive triangles and its ring (the vertex after u in each). Each alive triangle holding u
  // holds exactly one vertex of u's chain (two would have made it vanish when they merged).
  // On the way the chain forgets what it no longer holds (the same triangles in the same order
  // next time, fewer entries to pass): each owner's list keeps its alive triangles holding u at
  // its front (star_fill ends it), and an owner left with none leaves the chain.
  void gatherStar(std::uint32_t u, std::vector<std::uint32_t>& triangles, std::vector<std::uint32_t>& ring) {
    triangles.clear();
    ring.clear();
    if (a_.removed[u]) return;  // no triangle holds it (and its chain is another vertex's now)
    std::uint32_t previous = kNone;
    for (std::uint32_t owner = u; owner != kNone;) {
      const std::uint32_t next = a_.absorbed_next[owner];
      std::uint32_t kept = a_.star_start[owner];
      for (std::uint32_t i = a_.star_start[owner]; i < a_.star_fill[owner]; ++i) {
        const std::uint32_t t = a_.star[i];
        const std::uint32_t* c = &a_.corners[3 * t];
        if (!a_.alive[t] || (c[0] != u && c[1] != u && c[2] != u)) continue;
        a_.star[kept++] = t;
        triangles.push_back(t);
        ring.push_back(after(t, u));
      }
      a_.star_fill[owner] = kept;
      if (kept == a_.star_start[owner] && previous != kNone) {
        a_.absorbed_next[previous] = next;  // owner != u: it leaves u's chain
        if (next == kNone) a_.absorbed_last[u] = previous;
      } else {
        previous = owner;
      }
      owner = next;
    }
  }

  // The queue's order: cheapest collapse first, ties by vertex. The heap holds each vertex's
  // cost beside it, so sifting reads the heap alone.
  using QueueEntry = ClusterArrays::QueueEntry;
  static bool before(const QueueEntry& p, const QueueEntry& q) {
    return p.cost != q.cost ? p.cost < q.cost : p.vertex < q.vertex;
  }
  void heapSet(std::size_t place, const QueueEntry& entry) {
    a_.heap[place] = entry;
    a_.heap_place[entry.vertex] = static_cast<std::uint32_t>(place);
  }
  void siftUp(std::size_t place) {
    const QueueEntry entry = a_.heap[place];
    while (place > 0) {
      const std::size_t parent = (place - 1) / 2;
      if (!before(entry, a_.heap[parent])) break;
      heapSet(place, a_.heap[parent]);
      place = parent;
    }
    heapSet(place, entry);
  }
  void siftDown(std::size_t place) {
    const QueueEntry entry = a_.heap[place];
    const std::size_t size = a_.heap.size();
    for (;;) {
      std::size_t child = 2 * place + 1;
      if (child >= size) break;
      if (child + 1 < size && before(a_.heap[child + 1], a_.heap[child])) ++child;
      if (!before(a_.heap[child], entry)) break;
      heapSet(place, a_.heap[child]);
      place = child;
    }
    heapSet(place, entry);
  }
  // u's cheapest collapse changed: (re)place it in the queue.
  void queueAt(std::uint32_t u, const Collapse& cheapest) {
    a_.best[u] = cheapest;
    const std::uint32_t place = a_.heap_place[u];
    if (place == kNone) {
      a_.heap.push_back({cheapest.cost, u});
      siftUp(a_.heap.size() - 1);
      return;
    }
    const double old = a_.heap[place].cost;
    a_.heap[place].cost = cheapest.cost;
    if (cheapest.cost <= old) {
      siftUp(place);
    } else {
      siftDown(place);
    }
  }
  std::uint32_t popCheapest() {
    const std::uint32_t u = a_.heap.front().vertex;
    a_.heap_place[u] = kNone;
    const QueueEntry last = a_.heap.back();
    a_.heap.pop_back();
    if (!a_.heap.empty()) {
      a_.heap[0] = last;
      siftDown(0);
    }
    return u;
  }

  // u -> v, v where it is.
  Collapse stays(const Quadric& q, std::uint32_t v) const {
    const auto& p = a_.metres[v];
    return {std::max(0.0, evaluate(q, p[0], p[1], p[2])), v, false, false, a_.grid[v]};
  }

  // The collapses of u into its neighbour v, passed to add: u -> v (v stays where it is),
  // and with v free too, v moved to the edge's quadric optimum or, only where that does not
  // exist, to the best point of the segment uv (CGAL's placement and its fallback). The
  // segment's point costs at least the optimum (the quadric's least value); trying it too when
  // the filter refuses the optimum made ETOPO5's levels 39 % slower for 0-1 % fewer triangles.
  template <typename Add>
  void collapsesInto(std::uint32_t u, std::uint32_t v, Add&& add) {
    const Quadric q = combined(u, v);
    add(stays(q, v));
    if (a_.locked[v]) return;
    const Collapse moved = cachedOptimum(&q, u, v);
    if (moved.moves) {
      add(moved);
      return;
    }
    const Collapse on_edge = segmentOptimum(q, u, v);
    if (on_edge.moves) add(on_edge);
  }

  // Queues u (free, not removed) at its cheapest collapse, superseding its earlier place.
  // `gathered`: u's star is in u_triangles and u_ring already.
  void enqueue(std::uint32_t u, bool gathered = false) {
    if (a_.locked[u] || a_.removed[u]) return;
    a_.refused[u] = 0;  // its star changed: every collapse may be accepted now
    if (!gathered) gatherStar(u, a_.u_triangles, a_.u_ring);
    Collapse cheapest;
    cheapest.cost = std::numeric_limits<double>::infinity();
    for (const std::uint32_t v : a_.u_ring) {
      collapsesInto(u, v, [&](const Collapse& c) {
        if (c < cheapest) cheapest = c;
      });
    }
    if (cheapest.v == kNone) return;
    queueAt(u, cheapest);
  }

  // w was next to u or v when u collapsed into v: only its collapses into v changed (and
  // those into u are gone), so unless its cheapest went to u or v, the new cheapest is the
  // cheaper of that and its collapses into v now. Queued again in any case (a vertex the
  // filter refused comes back when its star changes).
  void requeueNextTo(std::uint32_t w, std::uint32_t u, std::uint32_t v) {
    if (a_.locked[w] || a_.removed[w]) return;
    const std::uint32_t target = a_.best[w].v;
    if (target == kNone || target == u || target == v || a_.refused[w]) {
      enqueue(w);
      return;
    }
    Collapse cheapest = a_.best[w];
    collapsesInto(w, v, [&](const Collapse& c) {
      if (c < cheapest) cheapest = c;
    });
    queueAt(w, cheapest);
  }

  // Greedy, as CGAL's edge_collapse: always the cheapest queued vertex next; a vertex the
  // filter refused every way comes back when a collapse changes its star.
  void collapse(ClusterOutput& out) {
    const std::size_t vertices = a_.identity.size();
    buildStars();
    a_.absorbed_next.assign(vertices, kNone);
    a_.absorbed_last.resize(vertices);
    for (std::uint32_t v = 0; v < vertices; ++v) a_.absorbed_last[v] = v;
    a_.removed.assign(vertices, 0);
    a_.broken_pixel.assign(vertices, kNoPixel);
    a_.changed_at.assign(vertices, 0);
    applied_ = 0;
    if (++a_.generation == 0) {  // wrapped: forget every entry
      a_.edge_optima.assign(a_.edge_optima.size(), ClusterArrays::EdgeOptimum{});
      a_.refusals.assign(a_.refusals.size(), ClusterArrays::Refusal{});
      a_.generation = 1;
    }
    a_.best.assign(vertices, Collapse{});
    a_.refused.assign(vertices, 0);
    a_.waiting_next.resize(vertices);
    a_.waiting_end.resize(vertices);
    a_.waiting.clear();
    a_.heap.clear();
    a_.heap_place.assign(vertices, kNone);
    for (std::uint32_t u = 0; u < vertices; ++u) {
      if (a_.star_start[u] == a_.star_start[u + 1]) continue;
      if (setup_->refused_in_part) {
        const std::uint32_t i = (*setup_->refused_in_part)[a_.identity[u]];
        if (i != kNone) {
          waitAtUntried(u, (*setup_->untried_start)[i], (*setup_->untried_start)[i + 1]);
          continue;
        }
      }
      enqueue(u);
    }
    tries_ = 0;
    a_.tries_at_applied.assign(options_.tail_stop.on() ? options_.tail_stop.applied : 0, 0);
    while (wantsMore() && !a_.heap.empty() && !stalled()) tryCollapse(popCheapest(), out);
  }

  // The tail stop: fewer than tail_stop.applied of the run's last tail_stop.tries tries were
  // applied (while the run has applied fewer, its start counts as the missing ones).
  bool stalled() const {
    const std::size_t k = a_.tries_at_applied.size();
    if (k == 0) return false;
    const std::uint64_t kth_last = applied_ < k ? 0 : a_.tries_at_applied[(applied_ + 1) % k];
    return tries_ - kth_last >= options_.tail_stop.tries;
  }

  // u starts as the filter left it in its part (ClusterSetup::refused_in_part): refused,
  // waiting at the collapses it had not tried, untried[begin .. end).
  void waitAtUntried(std::uint32_t u, std::uint32_t begin, std::uint32_t end) {
    a_.refused[u] = 1;
    a_.waiting_next[u] = static_cast<std::uint32_t>(a_.waiting.size());
    for (std::uint32_t i = begin; i < end; ++i) {
      const UntriedCollapse& c = (*setup_->untried)[i];
      const std::uint32_t v = a_.local_of_vertex[c.into];
      a_.waiting.push_back({collapseOf(u, v, c.placement).cost, v, c.placement});
    }
    a_.waiting_end[u] = static_cast<std::uint32_t>(a_.waiting.size());
    if (begin < end) queueAt(u, queuedAt(a_.waiting[a_.waiting_next[u]]));
  }

  // u's collapse into v with that placement (UntriedCollapse's), as collapsesInto makes it.
  Collapse collapseOf(std::uint32_t u, std::uint32_t v, std::uint8_t placement) {
    if (placement == UntriedCollapse::kOptimum) return cachedOptimum(nullptr, u, v);
    const Quadric q = combined(u, v);
    return placement == UntriedCollapse::kStays ? stays(q, v) : segmentOptimum(q, u, v);
  }
  // The same for a waiting collapse, whose cost is known: v staying where it is needs no sum.
  Collapse collapseOf(std::uint32_t u, const WaitingCollapse& w) {
    if (w.placement == UntriedCollapse::kStays) return {w.cost, w.v, false, false, a_.grid[w.v]};
    return collapseOf(u, w.v, w.placement);
  }

  // A refused vertex's place in the queue: the cost and target of its next collapse (the
  // queue and requeueNextTo read no more of a refused vertex's best).
  static Collapse queuedAt(const WaitingCollapse& w) {
    Collapse c;
    c.cost = w.cost;
    c.v = w.v;
    c.moves = w.placement != UntriedCollapse::kStays;
    c.on_edge = w.placement == UntriedCollapse::kOnEdge;
    return c;
  }

  // Tries u's collapses from the cheapest (the one it was queued at, then the others in order)
  // and applies the first the filter accepts, as long as it is not dearer than the next
  // vertex's in the queue: then u waits in the queue at that collapse (greedy over all
  // collapses, as CGAL's queue of edges, not only over vertices).
  bool tryCollapse(std::uint32_t u, ClusterOutput& out) {
    gatherStar(u, a_.u_triangles, a_.u_ring);
    if (!a_.refused[u]) {
      const Collapse first = a_.best[u];
      if (accepts(u, first, out)) return true;
      a_.targets.clear();
      for (const std::uint32_t v : a_.u_ring) {
        collapsesInto(u, v, [&](const Collapse& c) {
          if (first < c || c < first) a_.targets.push_back(c);
        });
      }
      std::sort(a_.targets.begin(), a_.targets.end());
      if (a_.waiting.size() + a_.targets.size() > a_.waiting.capacity()) compactWaiting();
      a_.refused[u] = 1;
      a_.waiting_next[u] = static_cast<std::uint32_t>(a_.waiting.size());
      for (const Collapse& c : a_.targets) a_.waiting.push_back({c.cost, c.v, placementOf(c)});
      a_.waiting_end[u] = static_cast<std::uint32_t>(a_.waiting.size());
    }
    while (a_.waiting_next[u] < a_.waiting_end[u]) {
      const WaitingCollapse waiting = a_.waiting[a_.waiting_next[u]];
      if (!a_.heap.empty()) {
        const std::uint32_t next = a_.heap.front().vertex;
        const double next_cost = a_.heap.front().cost;
        if (waiting.cost > next_cost || (waiting.cost == next_cost && next < u)) {
          queueAt(u, queuedAt(waiting));
          return false;
        }
      }
      ++a_.waiting_next[u];
      if (accepts(u, collapseOf(u, waiting), out)) return true;
    }
    return false;  // not queued again until a collapse changes its star
  }

  // The waiting lists still in use, moved down to the front of the pool in their order (in
  // place: each moves to or below where it is); the pool doubles when they fill more than
  // half of it.
  void compactWaiting() {
    a_.live_lists.clear();
    const auto vertices = static_cast<std::uint32_t>(a_.refused.size());
    for (std::uint32_t u = 0; u < vertices; ++u) {
      if (!a_.refused[u] || a_.removed[u] || a_.waiting_next[u] == a_.waiting_end[u]) {
        a_.waiting_next[u] = a_.waiting_end[u] = 0;
        continue;
      }
      a_.live_lists.emplace_back(a_.waiting_next[u], u);
    }
    std::sort(a_.live_lists.begin(), a_.live_lists.end());
    std::uint32_t kept = 0;
    for (const auto& [begin, u] : a_.live_lists) {
      const std::uint32_t end = a_.waiting_end[u];
      if (begin != kept) std::copy(a_.waiting.begin() + begin, a_.waiting.begin() + end, a_.waiting.begin() + kept);
      a_.waiting_next[u] = kept;
      kept += end - begin;
      a_.waiting_end[u] = kept;
    }
    a_.waiting.resize(kept);
    const std::size_t wanted = std::max<std::size_t>(4096, 2 * (a_.waiting.size() + a_.targets.size()));
    if (a_.waiting.capacity() < wanted) a_.waiting.reserve(wanted);
  }

  ClusterArrays::Refusal& refusalOf(std::uint32_t u, std::uint32_t v_and_placement) {
    const std::uint64_t hash =
        (std::uint64_t{u} * 0x9E3779B97F4A7C15ull) ^ (std::uint64_t{v_and_placement} * 0xC2B2AE3D27D4EB4Full);
    return a_.refusals[(hash >> 32) & (a_.refusals.size() - 1)];
  }
  static std::uint32_t vAndPlacement(const Collapse& c) { return (c.v << 2) | placementOf(c); }
  // The filter refused this collapse before and it would make the same failing triangle now.
  bool refusedAgain(const ClusterArrays::Refusal& r, std::uint32_t u, std::uint32_t v_and_placement) const {
    if (r.u != u || r.v_and_placement != v_and_placement || r.generation != a_.generation) return false;
    const std::uint32_t v = v_and_placement >> 2;
    if (a_.changed_at[u] > r.applied || a_.changed_at[v] > r.applied || !a_.alive[r.triangle]) return false;
    const std::uint32_t* c = &a_.corners[3 * r.triangle];
    return a_.changed_at[c[0]] <= r.applied && a_.changed_at[c[1]] <= r.applied && a_.changed_at[c[2]] <= r.applied;
  }
  void rememberRefusal(ClusterArrays::Refusal& r, std::uint32_t u, std::uint32_t v_and_placement, bool for_error) {
    r = {u, v_and_placement, failed_triangle_, applied_, a_.generation, for_error};
  }

  // Applies the collapse of u when the filter accepts it. Needs u's star gathered.
  bool accepts(std::uint32_t u, const Collapse& collapse, ClusterOutput& out) {
    ++tries_;
    const std::uint32_t v = collapse.v;
    const std::uint32_t v_and_placement = vAndPlacement(collapse);
    ClusterArrays::Refusal& refusal = refusalOf(u, v_and_placement);
    if (refusedAgain(refusal, u, v_and_placement)) {
      ++(refusal.for_error ? out.refused_for_error : out.refused_for_flip);
      return false;
    }
    // The placed point's slot is almost never in the cache (3 MB, read at random): fetch it
    // while the star and the fold-over tests run.
    if (options_.globe && collapse.moves) {
      const char* slot = reinterpret_cast<const char*>(&placedPointSlot(collapse.placed));
      __builtin_prefetch(slot);
      __builtin_prefetch(slot + sizeof(ClusterArrays::PlacedPoint) - 1);  // it may span two lines
    }
    const GridPoint& placed = collapse.placed;
    const bool budgeted = std::isfinite(options_.max_error_m);
    // Most tries fail at the pixel that broke u's last try (see withinBudget): a collapse
    // where v stays needs neither v's star nor a new place for that test, so it runs first.
    if (!collapse.moves && budgeted && breaksAtRememberedPixel(u, v, false, placed, a_.ecef[v])) {
      rememberRefusal(refusal, u, v_and_placement, true);
      ++out.refused_for_error;
      return false;
    }
    gatherStar(v, a_.v_triangles, a_.v_ring);
    if (!keepsHeightField(u, v, collapse.moves, placed)) {
      rememberRefusal(refusal, u, v_and_placement, false);
      ++out.refused_for_flip;
      return false;
    }
    // A moved vertex is placed on the globe exactly as the pipeline will place it.
    const EcefPoint placed_ecef = !options_.globe ? EcefPoint{} : collapse.moves ? placeOnGlobe(placed) : a_.ecef[v];
    if (budgeted && ((collapse.moves && breaksAtRememberedPixel(u, v, true, placed, placed_ecef)) ||
                     !withinBudget(u, v, collapse.moves, placed, placed_ecef))) {
      rememberRefusal(refusal, u, v_and_placement, true);
      ++out.refused_for_error;
      return false;
    }
    if (!linkIsTwoVertices(u)) {
      ++out.refused_for_flip;
      return false;
    }
    apply(u, v, collapse.moves, placed, placed_ecef);
    return true;
  }

  // The link condition of an interior edge: u and v share exactly the two vertices opposite
  // edge uv. (A planar collapse that keeps every triangle upward implies it; this keeps the
  // mesh manifold whatever rounding does.) Needs v_ring gathered.
  bool linkIsTwoVertices(std::uint32_t u) const {
    std::size_t shared = 0;
    for (const std::uint32_t w : a_.v_ring) {
      if (w != u && std::find(a_.u_ring.begin(), a_.u_ring.end(), w) != a_.u_ring.end()) ++shared;
    }
    return shared == 2;
  }

  // Every triangle the collapse makes, as (p, q, r) where kPlaced stands for the merged
  // vertex: u's star without the two triangles of edge uv, u replaced; with `moves`, also v's
  // star without them (v moves). Needs u_triangles and v_triangles gathered.
  static constexpr std::uint32_t kPlaced = kNone - 1;
  // On failure the triangle of the star it came from is failed_triangle_.
  template <typename Test>
  bool allNewTriangles(std::uint32_t u, std::uint32_t v, bool moves, Test&& test) const {
    for (const std::uint32_t t : a_.u_triangles) {
      const std::uint32_t* c = &a_.corners[3 * t];
      if (c[0] == v || c[1] == v || c[2] == v) continue;
      if (!test(c[0] == u ? kPlaced : c[0], c[1] == u ? kPlaced : c[1], c[2] == u ? kPlaced : c[2])) {
        failed_triangle_ = t;
        return false;
      }
    }
    if (!moves) return true;
    for (const std::uint32_t t : a_.v_triangles) {
      const std::uint32_t* c = &a_.corners[3 * t];
      if (c[0] == u || c[1] == u || c[2] == u) continue;
      if (!test(c[0] == v ? kPlaced : c[0], c[1] == v ? kPlaced : c[1], c[2] == v ? kPlaced : c[2])) {
        failed_triangle_ = t;
        return false;
      }
    }
    return true;
  }

  bool keepsHeightField(std::uint32_t u, std::uint32_t v, bool moves, const GridPoint& placed) const {
    const auto at = [&](std::uint32_t w) -> const GridPoint& { return w == kPlaced ? placed : a_.grid[w]; };
    return allNewTriangles(u, v, moves, [&](std::uint32_t p, std::uint32_t q, std::uint32_t r) {
      return isUpwardTriangle(at(p), at(q), at(r)) &&
             !isSteeperThan(at(p), at(q), at(r), options_.metres_per_col, options_.metres_per_row, kMaxSlope) &&
             !isSliver(at(p), at(q), at(r));
    });
  }

  ClusterArrays::PlacedPoint& placedPointSlot(const GridPoint& g) {
    std::uint64_t bits[3];
    std::memcpy(bits, &g, sizeof bits);
    std::uint64_t hash = (bits[0] * 0x9E3779B97F4A7C15ull) ^ (bits[1] * 0xC2B2AE3D27D4EB4Full) ^ (bits[2] * 0x165667B19E3779F9ull);
    hash ^= hash >> 29;
    return a_.placed_points[hash & (a_.placed_points.size() - 1)];
  }

  EcefPoint placeOnGlobe(const GridPoint& g) {
    ClusterArrays::PlacedPoint& entry = placedPointSlot(g);
    if (std::memcmp(&entry.grid, &g, sizeof g) != 0) {
      entry.grid = g;
      entry.ecef = options_.globe->place(g);
    }
    return entry.ecef;
  }

  // The budget, first at the pixel that broke one of u's collapses before (it usually breaks
  // the next try too): true when a new triangle is beyond the budget there.
  bool breaksAtRememberedPixel(std::uint32_t u, std::uint32_t v, bool moves, const GridPoint& placed,
                               const EcefPoint& placed_ecef) const {
    const DemOnGlobe* globe = options_.globe;
    const std::size_t remembered = a_.broken_pixel[u];
    if (!globe || remembered == kNoPixel) return false;
    const auto at = [&](std::uint32_t w) -> const GridPoint& { return w == kPlaced ? placed : a_.grid[w]; };
    const auto ecefAt = [&](std::uint32_t w) -> const EcefPoint& { return w == kPlaced ? placed_ecef : a_.ecef[w]; };
    return !allNewTriangles(u, v, moves, [&](std::uint32_t p, std::uint32_t q, std::uint32_t r) {
      return !exceedsBudgetAtPixel(*globe, at(p), at(q), at(r), ecefAt(p), ecefAt(q), ecefAt(r), options_.max_error_m,
                                   remembered);
    });
  }

  // The budget at every pixel the new triangles cover (the remembered one was tested first).
  bool withinBudget(std::uint32_t u, std::uint32_t v, bool moves, const GridPoint& placed,
                    const EcefPoint& placed_ecef) {
    const double budget_m = options_.max_error_m;
    const DemOnGlobe* globe = options_.globe;
    const auto at = [&](std::uint32_t w) -> const GridPoint& { return w == kPlaced ? placed : a_.grid[w]; };
    const auto ecefAt = [&](std::uint32_t w) -> const EcefPoint& { return w == kPlaced ? placed_ecef : a_.ecef[w]; };
    if (!globe) {
      return allNewTriangles(u, v, moves, [&](std::uint32_t p, std::uint32_t q, std::uint32_t r) {
        return !exceedsBudget(*in_.dem, at(p), at(q), at(r), budget_m);
      });
    }
    std::size_t& remembered = a_.broken_pixel[u];
    return allNewTriangles(u, v, moves, [&](std::uint32_t p, std::uint32_t q, std::uint32_t r) {
      return !exceedsBudgetOnGlobe(*globe, at(p), at(q), at(r), ecefAt(p), ecefAt(q), ecefAt(r), budget_m,
                                   &remembered);
    });
  }

  void apply(std::uint32_t u, std::uint32_t v, bool moves, const GridPoint& placed, const EcefPoint& placed_ecef) {
    for (const std::uint32_t t : a_.u_triangles) {
      std::uint32_t* c = &a_.corners[3 * t];
      if (c[0] == v || c[1] == v || c[2] == v) {
        a_.alive[t] = 0;
        --live_triangles_;
        continue;
      }
      for (std::size_t k = 0; k < 3; ++k) {
        if (c[k] == u) c[k] = v;
      }
    }
    addTo(a_.quadric[v], a_.quadric[u]);
    if (moves) {
      a_.grid[v] = placed;
      a_.metres[v] = metresOf(placed);
      if (options_.globe) a_.ecef[v] = placed_ecef;
    }
    a_.removed[u] = 1;
    a_.changed_at[v] = ++applied_;  // a new quadric, maybe a new place: its edges' optima change
    if (!a_.tries_at_applied.empty()) a_.tries_at_applied[applied_ % a_.tries_at_applied.size()] = tries_;
    a_.absorbed_next[a_.absorbed_last[v]] = u;
    a_.absorbed_last[v] = a_.absorbed_last[u];
    edges_ -= 3;
    // v's star now holds u's: v and every vertex around it have new collapses.
    gatherStar(v, a_.u_triangles, a_.u_ring);  // u's are done with
    a_.around.assign(a_.u_ring.begin(), a_.u_ring.end());  // requeueNextTo reuses the star arrays
    enqueue(v, true);
    for (const std::uint32_t w : a_.around) requeueNextTo(w, u, v);
  }

  const LevelInput& in_;
  const SimplifyOptions& options_;
  const std::vector<std::uint8_t>& locked_vertex_;
  ClusterArrays& a_;
  std::size_t edges_ = 0, initial_edges_ = 0, live_triangles_ = 0;
  std::uint32_t applied_ = 0;                  // collapses applied in this run
  std::uint64_t tries_ = 0;                    // collapses tried in this run (accepts)
  mutable std::uint32_t failed_triangle_ = 0;  // see allNewTriangles
  double edge_ratio_ = 0.5;
  const ClusterSetup* setup_ = nullptr;
  GridPoint origin_;
};

// Large clusters at coarse levels (a few clusters joined over whole tiles) would leave cores
// idle: a cluster holding more than 1/kSplitShare of the level's faces (and at least
// kMinSplitFaces) is simplified in parts of about 1/(2 kSplitShare) of them, cut by recursive
// bisection of the faces' centroids. The parts run in parallel with the seams between them
// locked, each to kPartSlack more than the cluster's edge ratio; then the whole cluster runs
// again from their result, seams free, with every vertex's accumulated quadric, to the
// cluster's own stop: its greedy order takes the seams' dense collapses first. A vertex away
// from the seams that the filter refused in its part starts the whole run where its part left
// it (refused, waiting at the collapses it had not tried), instead of trying the refused ones
// again. Which clusters split depends on the level alone, not on the threads.
constexpr std::size_t kSplitShare = 8;
constexpr std::size_t kMinSplitFaces = 8192;
constexpr double kPartSlack = 0.05;

// Cuts faces[0 .. count) into `parts` runs of near-equal size, by recursive bisection of
// their centroids (col, row) across the longer side of their box, ties by face index.
void bisectFaces(std::uint32_t* faces, std::size_t count, std::size_t parts,
                 const std::vector<std::array<double, 2>>& centroid, std::vector<std::uint32_t>& part_sizes) {
  if (parts <= 1 || count < 2) {
    part_sizes.push_back(static_cast<std::uint32_t>(count));
    return;
  }
  double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
  for (std::size_t i = 0; i < count; ++i) {
    for (int k = 0; k < 2; ++k) {
      lo[k] = std::min(lo[k], centroid[faces[i]][k]);
      hi[k] = std::max(hi[k], centroid[faces[i]][k]);
    }
  }
  const int axis = hi[0] - lo[0] >= hi[1] - lo[1] ? 0 : 1;
  const std::size_t left_parts = parts / 2;
  const std::size_t left = count * left_parts / parts;
  std::nth_element(faces, faces + left, faces + count, [&](std::uint32_t a, std::uint32_t b) {
    return centroid[a][axis] != centroid[b][axis] ? centroid[a][axis] < centroid[b][axis] : a < b;
  });
  std::sort(faces, faces + left);  // each part's faces in input order
  std::sort(faces + left, faces + count);
  bisectFaces(faces, left, left_parts, centroid, part_sizes);
  bisectFaces(faces + left, count - left, parts - left_parts, centroid, part_sizes);
}

// The edges of a set of faces for the stop rule: every edge once (corners plus the half-edges
// whose other side is not in the set, over two).
std::size_t edgesOf(const LevelInput& in, std::int32_t cluster, const std::uint32_t* begin, const std::uint32_t* end) {
  const std::vector<std::uint32_t>& opposite = in.topology->opposite_corner;
  const std::vector<std::int32_t>& cluster_of_face = *in.cluster_of_face;
  std::size_t corners = 0, border = 0;
  for (const std::uint32_t* f = begin; f != end; ++f) {
    for (std::uint32_t k = 0; k < 3; ++k) {
      const std::uint32_t o = opposite[3 * *f + k];
      ++corners;
      if (o == kNone || cluster_of_face[o / 3] != cluster) ++border;
    }
  }
  return (corners + border) / 2;
}

}  // namespace

std::vector<ClusterOutput> collapseNatively(const LevelInput& in) {
  const std::vector<std::uint8_t> locked = lockedVertices(in);
  const std::vector<std::uint32_t>& cluster_start = *in.cluster_start;
  const std::vector<std::uint32_t>& faces_by_cluster = *in.faces_by_cluster;
  const std::size_t clusters = cluster_start.size() - 1;
  const TinMesh& mesh = *in.mesh;
  const std::size_t vertex_count = mesh.vertices.size();
  tbb::enumerable_thread_specific<ClusterArrays> per_thread([vertex_count] {
    ClusterArrays arrays;
    arrays.local_of_vertex.assign(vertex_count, kNone);
    return arrays;
  });
  std::vector<ClusterOutput> outputs(clusters);

  // Which clusters split, and their parts as units of their own (ids from `clusters` on).
  const std::size_t level_faces = faces_by_cluster.size();
  const std::size_t split_above = std::max(kMinSplitFaces, level_faces / kSplitShare);
  const std::size_t part_faces = std::max<std::size_t>(1, level_faces / (2 * kSplitShare));
  std::vector<std::uint32_t> split;  // cluster ids
  for (std::uint32_t c = 0; c < clusters; ++c) {
    if (cluster_start[c + 1] - cluster_start[c] > split_above) split.push_back(c);
  }
  if (split.empty()) {
    forEachClusterLargestFirst(cluster_start, [&](std::uint32_t c) {
      ClusterCollapser cluster(in, locked, per_thread.local());
      outputs[c] = cluster.simplify(static_cast<std::int32_t>(c), faces_by_cluster.data() + cluster_start[c],
                                    faces_by_cluster.data() + cluster_start[c + 1]);
    });
    return outputs;
  }
  std::vector<std::int32_t> unit_of_face = *in.cluster_of_face;
  std::vector<std::uint32_t> unit_start, unit_faces, unit_cluster;  // units: clusters that stay whole, then parts
  std::vector<std::uint8_t> is_split(clusters, 0);
  for (const std::uint32_t c : split) is_split[c] = 1;
  for (std::uint32_t c = 0; c < clusters; ++c) {
    if (is_split[c]) continue;
    unit_start.push_back(static_cast<std::uint32_t>(unit_faces.size()));
    unit_faces.insert(unit_faces.end(), faces_by_cluster.begin() + cluster_start[c],
                      faces_by_cluster.begin() + cluster_start[c + 1]);
    unit_cluster.push_back(c);
  }
  std::vector<std::array<double, 2>> centroid(mesh.triangleCount());
  std::vector<std::vector<std::uint32_t>> units_of_split(clusters);
  for (const std::uint32_t c : split) {
    std::vector<std::uint32_t> faces(faces_by_cluster.begin() + cluster_start[c], faces_by_cluster.begin() + cluster_start[c + 1]);
    for (const std::uint32_t f : faces) {
      const GridPoint& a = mesh.vertices[mesh.triangle_indices[3 * f]];
      const GridPoint& b = mesh.vertices[mesh.triangle_indices[3 * f + 1]];
      const GridPoint& d = mesh.vertices[mesh.triangle_indices[3 * f + 2]];
      centroid[f] = {a.col + b.col + d.col, a.row + b.row + d.row};
    }
    std::vector<std::uint32_t> sizes;
    bisectFaces(faces.data(), faces.size(), (faces.size() + part_faces - 1) / part_faces, centroid, sizes);
    std::size_t offset = 0;
    for (const std::uint32_t size : sizes) {
      const auto unit = static_cast<std::int32_t>(clusters + unit_start.size());
      units_of_split[c].push_back(static_cast<std::uint32_t>(unit_start.size()));
      unit_start.push_back(static_cast<std::uint32_t>(unit_faces.size()));
      for (std::size_t i = offset; i < offset + size; ++i) {
        unit_faces.push_back(faces[i]);
        unit_of_face[faces[i]] = unit;
      }
      unit_cluster.push_back(c);
      offset += size;
    }
  }
  unit_start.push_back(static_cast<std::uint32_t>(unit_faces.size()));
  centroid = std::vector<std::array<double, 2>>();  // the cuts are made

  // 1. Whole clusters and parts, the seams between parts locked.
  LevelInput units = in;
  units.cluster_of_face = &unit_of_face;
  const std::vector<std::uint8_t> locked_units = lockedVertices(units);
  std::vector<ClusterOutput> unit_outputs(unit_start.size() - 1);
  std::vector<GridPoint> split_origin(clusters);
  for (const std::uint32_t c : split) split_origin[c] = mesh.vertices[mesh.triangle_indices[3 * faces_by_cluster[cluster_start[c]]]];
  forEachClusterLargestFirst(unit_start, [&](std::uint32_t unit) {
    const std::uint32_t c = unit_cluster[unit];
    ClusterCollapser collapser(units, locked_units, per_thread.local());
    const std::uint32_t* begin = unit_faces.data() + unit_start[unit];
    const std::uint32_t* end = unit_faces.data() + unit_start[unit + 1];
    if (!is_split[c]) {
      outputs[c] = collapser.simplify(static_cast<std::int32_t>(c), begin, end);
      return;
    }
    ClusterSetup setup;
    setup.origin = &split_origin[c];
    setup.edge_ratio = std::min(1.0, in.options->edge_ratio + kPartSlack);
    setup.keep_quadrics = true;
    unit_outputs[unit] = collapser.simplify(static_cast<std::int32_t>(clusters + unit), begin, end, setup);
  });

  unit_faces = std::vector<std::uint32_t>();  // the units are simplified (locked_units holds their seams)
  unit_of_face = std::vector<std::int32_t>();

  // 2. Each split cluster whole again, from its parts' result.
  std::vector<std::uint32_t> split_start{0};
  for (const std::uint32_t c : split) split_start.push_back(split_start.back() + cluster_start[c + 1] - cluster_start[c]);
  forEachClusterLargestFirst(split_start, [&](std::uint32_t s) {
    const std::uint32_t c = split[s];
    // The cluster as it is now, as a mesh of its own (vertices in order of first use).
    TinMesh now;
    std::vector<std::uint32_t> identity;  // now's vertex -> level vertex
    std::vector<std::uint32_t> local(vertex_count, kNone);
    std::vector<Quadric> quadric;
    std::vector<std::uint8_t> now_locked;
    ClusterOutput& out = outputs[c];
    std::vector<GridPoint> position_of_moved;
    std::vector<std::uint32_t> moved_local;
    for (const std::uint32_t unit : units_of_split[c]) {
      const ClusterOutput& part = unit_outputs[unit];
      out.refused_for_error += part.refused_for_error;
      out.refused_for_flip += part.refused_for_flip;
      for (const std::uint32_t v : part.triangles) {
        if (local[v] == kNone) {
          local[v] = static_cast<std::uint32_t>(identity.size());
          identity.push_back(v);
          now.vertices.push_back(mesh.vertices[v]);
          quadric.push_back(Quadric{});
          now_locked.push_back(locked[v]);
        }
        now.triangle_indices.push_back(local[v]);
      }
    }
    // The vertices the filter refused in their part, with the collapses they had not tried
    // (their ends as now's vertices).
    std::vector<std::uint32_t> refused_in_part(identity.size(), kNone), untried_start{0};
    std::vector<UntriedCollapse> untried;
    for (const std::uint32_t unit : units_of_split[c]) {
      const ClusterOutput& part = unit_outputs[unit];
      for (const auto& [v, g] : part.moved) {
        if (local[v] != kNone) now.vertices[local[v]] = g;
      }
      for (const auto& [v, q] : part.quadrics) {
        if (local[v] != kNone) addTo(quadric[local[v]], q);
      }
      for (std::size_t i = 0; i < part.refused_vertices.size(); ++i) {
        const std::uint32_t v = part.refused_vertices[i];
        if (local[v] == kNone) continue;
        refused_in_part[local[v]] = static_cast<std::uint32_t>(untried_start.size() - 1);
        for (std::uint32_t j = part.untried_start[i]; j < part.untried_start[i + 1]; ++j) {
          UntriedCollapse collapse = part.untried[j];
          collapse.into = local[collapse.into];
          untried.push_back(collapse);
        }
        untried_start.push_back(static_cast<std::uint32_t>(untried.size()));
      }
    }
    // The parts are read: their memory serves the whole pass.
    for (const std::uint32_t unit : units_of_split[c]) unit_outputs[unit] = ClusterOutput();
    // A vertex next to a seam (locked in the parts, free now) has new collapses: queued afresh.
    for (std::size_t corner = 0; corner < now.triangle_indices.size(); corner += 3) {
      const std::uint32_t* t = &now.triangle_indices[corner];
      const auto seam = [&](std::uint32_t l) { return locked_units[identity[l]] && !locked[identity[l]]; };
      if (seam(t[0]) || seam(t[1]) || seam(t[2])) refused_in_part[t[0]] = refused_in_part[t[1]] = refused_in_part[t[2]] = kNone;
    }
    const InputTopology topology = buildTopology(now);
    std::vector<EcefPoint> ecef;
    SimplifyOptions options = *in.options;
    if (options.globe) {
      ecef.resize(identity.size());
      for (std::size_t l = 0; l < identity.size(); ++l) {
        const GridPoint& g = now.vertices[l];
        const GridPoint& was = mesh.vertices[identity[l]];
        const bool moved = g.col != was.col || g.row != was.row || g.height_m != was.height_m;
        ecef[l] = moved ? options.globe->place(g) : in.options->vertex_ecef[identity[l]];
      }
      options.vertex_ecef = ecef;
    }
    const std::vector<std::int32_t> whole(now.triangleCount(), 0);
    std::vector<std::uint32_t> all_faces(now.triangleCount());
    for (std::uint32_t f = 0; f < all_faces.size(); ++f) all_faces[f] = f;
    const std::vector<std::uint64_t> no_constraints;  // their vertices are locked already
    LevelInput again = in;
    again.mesh = &now;
    again.options = &options;
    again.topology = &topology;
    again.cluster_of_face = &whole;
    again.constrained_keys = &no_constraints;
    ClusterSetup setup;
    setup.origin = &split_origin[c];
    setup.initial_edges = edgesOf(in, static_cast<std::int32_t>(c), faces_by_cluster.data() + cluster_start[c],
                                  faces_by_cluster.data() + cluster_start[c + 1]);
    setup.quadrics = &quadric;
    setup.refused_in_part = &refused_in_part;
    setup.untried_start = &untried_start;
    setup.untried = &untried;
    ClusterCollapser collapser(again, now_locked, per_thread.local());
    ClusterOutput result = collapser.simplify(0, all_faces.data(), all_faces.data() + all_faces.size(), setup);
    out.refused_for_error += result.refused_for_error;
    out.refused_for_flip += result.refused_for_flip;
    out.triangles.reserve(result.triangles.size());
    for (const std::uint32_t l : result.triangles) out.triangles.push_back(identity[l]);
    std::vector<GridPoint> final_position = now.vertices;
    for (const auto& [l, g] : result.moved) final_position[l] = g;
    std::vector<std::uint8_t> survives(identity.size(), 0);
    for (const std::uint32_t l : result.triangles) survives[l] = 1;
    for (std::uint32_t l = 0; l < identity.size(); ++l) {
      const GridPoint& g = final_position[l];
      const GridPoint& was = mesh.vertices[identity[l]];
      if (survives[l] && (g.col != was.col || g.row != was.row || g.height_m != was.height_m)) {
        out.moved.emplace_back(identity[l], g);
      }
    }
  });
  return outputs;
}

}  // namespace cluster_collapse
}  // namespace terratiles
