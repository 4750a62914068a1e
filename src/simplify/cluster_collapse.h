#pragma once
// What the two edge-collapse engines behind simplifyClusters share (internal to
// src/simplify): the level's input topology, the rules a collapse must keep (a height field
// without fold-overs or walls, the error budget as measureTin measures it) and what one
// cluster hands to the assembly. simplifyClusters (simplify_clusters.cpp) validates the input,
// builds the topology and assembles; cgal_edge_collapse.cpp and native_edge_collapse.cpp
// simplify the clusters.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include "src/base/largest_first.h"
#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

class DemOnGlobe;

namespace cluster_collapse {

inline constexpr std::uint32_t kNone = 0xffffffff;

inline std::uint64_t edgeKey(std::uint32_t u, std::uint32_t v) {
  return (std::uint64_t{u < v ? u : v} << 32) | (u < v ? v : u);
}

// Corner 3t + k is triangle t's vertex k and the edge from it to vertex (k + 1) % 3.
inline std::uint32_t nextCorner(std::uint32_t corner) { return corner % 3 == 2 ? corner - 2 : corner + 1; }

struct InputTopology {
  std::vector<std::uint32_t> opposite_corner;   // per corner: the other triangle's corner of that edge, or kNone
};

// Every corner's opposite. Throws Error(Input) for an edge in more than two triangles or run
// twice in the same direction.
InputTopology buildTopology(const TinMesh& mesh);

// The level to simplify, as simplifyClusters prepared it.
struct LevelInput {
  const DemGrid* dem = nullptr;
  const TinMesh* mesh = nullptr;
  const SimplifyOptions* options = nullptr;
  const InputTopology* topology = nullptr;
  const std::vector<std::int32_t>* cluster_of_face = nullptr;
  const std::vector<std::uint64_t>* constrained_keys = nullptr;  // sorted, unique
  // The faces of cluster c, in input order: faces_by_cluster[cluster_start[c] .. cluster_start[c + 1]).
  const std::vector<std::uint32_t>* cluster_start = nullptr;
  const std::vector<std::uint32_t>* faces_by_cluster = nullptr;
};

// What one cluster hands to the assembly.
// A symmetric 4x4 quadric (Garland and Heckbert): xx xy xz xw yy yz yw zz zw ww.
using Quadric = std::array<double, 10>;

// A collapse of a vertex into its neighbour `into` (an input vertex), as the native engine
// computes it again from the two ends (their quadrics and places): `into` stays where it is,
// or moves to the edge's quadric optimum or to the least point of the segment.
struct UntriedCollapse {
  enum : std::uint8_t { kStays, kOptimum, kOnEdge };
  std::uint32_t into = kNone;
  std::uint8_t placement = kStays;
};

struct ClusterOutput {
  std::vector<std::uint32_t> triangles;                    // input vertex indices, 3 per triangle
  std::vector<std::pair<std::uint32_t, GridPoint>> moved;  // surviving vertices that moved
  // The native engine, for a part of a split cluster: every surviving vertex's quadric.
  std::vector<std::pair<std::uint32_t, Quadric>> quadrics;
  // The native engine, for a part of a split cluster: the surviving free vertices the filter
  // refused since their star last changed (input vertex indices), each with the collapses it
  // has not tried yet, cheapest first (none: it refused every way):
  // untried[untried_start[i] .. untried_start[i + 1]) are refused_vertices[i]'s.
  std::vector<std::uint32_t> refused_vertices;
  std::vector<std::uint32_t> untried_start;
  std::vector<UntriedCollapse> untried;
  std::size_t refused_for_error = 0;
  std::size_t refused_for_flip = 0;
};

// The plane with unit normal n through point p, as a quadric: its value at a point is the
// squared distance to the plane.
inline Quadric planeQuadric(double nx, double ny, double nz, double px, double py, double pz) {
  const double d = -(nx * px + ny * py + nz * pz);
  return {nx * nx, nx * ny, nx * nz, nx * d, ny * ny, ny * nz, ny * d, nz * nz, nz * d, d * d};
}

inline void addTo(Quadric& sum, const Quadric& q, double weight = 1) {
  for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += weight * q[i];
}

inline double evaluate(const Quadric& q, double x, double y, double z) {
  return q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x + q[4] * y * y +
         2 * q[5] * y * z + 2 * q[6] * y + q[7] * z * z + 2 * q[8] * z + q[9];
}

// Where the quadric is least (Garland and Heckbert's optimal placement): A x = -b with A its
// upper 3x3 block, by Cramer's rule. False when the system is ill-conditioned (|det| at most
// 1e-12 trace^3), where the optimum would run far away over nearly flat ground.
inline bool quadricMinimum(const Quadric& q, std::array<double, 3>& point) {
  const double a00 = q[0], a01 = q[1], a02 = q[2], a11 = q[4], a12 = q[5], a22 = q[7];
  const double b0 = -q[3], b1 = -q[6], b2 = -q[8];
  const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
  const double det = a00 * c00 + a01 * c01 + a02 * c02;
  const double trace = a00 + a11 + a22;
  if (!(std::fabs(det) > 1e-12 * trace * trace * trace)) return false;
  const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
  point = {(c00 * b0 + c01 * b1 + c02 * b2) / det, (c01 * b0 + c11 * b1 + c12 * b2) / det,
           (c02 * b0 + c12 * b1 + c22 * b2) / det};
  return true;
}

// Where the quadric is least along p0 + t d (CGAL's construct_optimal_point_singular): t when
// the quadric curves upward along d and t lies strictly inside (0, 1); nullopt otherwise.
inline std::optional<double> segmentMinimum(const Quadric& q, const std::array<double, 3>& p0,
                                            const std::array<double, 3>& d) {
  const double qa = q[0] * d[0] * d[0] + 2 * q[1] * d[0] * d[1] + 2 * q[2] * d[0] * d[2] + q[4] * d[1] * d[1] +
                    2 * q[5] * d[1] * d[2] + q[7] * d[2] * d[2];  // (d, 0)^T Q (d, 0)
  const double qb = 2 * (q[0] * p0[0] * d[0] + q[1] * (p0[0] * d[1] + p0[1] * d[0]) +
                         q[2] * (p0[0] * d[2] + p0[2] * d[0]) + q[4] * p0[1] * d[1] +
                         q[5] * (p0[1] * d[2] + p0[2] * d[1]) + q[7] * p0[2] * d[2] + q[3] * d[0] +
                         q[6] * d[1] + q[8] * d[2]);  // 2 (p0, 1)^T Q (d, 0)
  if (!(qa > 0)) return std::nullopt;
  const double t = -qb / (2 * qa);
  if (!(t > 0 && t < 1)) return std::nullopt;
  return t;
}

// Twice the signed area in (col, row); negative means counter-clockwise seen from above.
inline double signedArea2(const GridPoint& a, const GridPoint& b, const GridPoint& c) {
  return (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
}

// Counter-clockwise seen from above and not degenerate: twice the area in (col, row) above
// 1e-9 times the longest edge squared, so the sign is stable under rounding whatever vertex a
// reader starts at.
inline bool isUpwardTriangle(const GridPoint& a, const GridPoint& b, const GridPoint& c) {
  auto squared = [](const GridPoint& p, const GridPoint& q) {
    return (p.col - q.col) * (p.col - q.col) + (p.row - q.row) * (p.row - q.row);
  };
  const double longest2 = std::max({squared(a, b), squared(b, c), squared(c, a)});
  return signedArea2(a, b, c) < -1e-9 * longest2;
}

// A face steeper than this (rise over run, about 89.4 degrees) is a wall no terrain level
// needs: simplification only makes one when it pulls a vertex next to a much higher or lower
// one (a sliver), and such a face turns a quantisation step of the vertices into a height
// jump as large as the wall.
inline constexpr double kMaxSlope = 100;

// Whether the triangle rises more than max_slope (rise over run in metres) anywhere, or is
// vertical or degenerate: its gradient's squared length against max_slope^2, without a root or
// a division.
inline bool isSteeperThan(const GridPoint& a, const GridPoint& b, const GridPoint& c, double metres_per_col,
                          double metres_per_row, double max_slope) {
  const double ux = (b.col - a.col) * metres_per_col, uy = (b.row - a.row) * metres_per_row;
  const double vx = (c.col - a.col) * metres_per_col, vy = (c.row - a.row) * metres_per_row;
  const double det = ux * vy - uy * vx;
  if (det == 0) return true;
  const double dz1 = b.height_m - a.height_m, dz2 = c.height_m - a.height_m;
  const double gx = dz1 * vy - dz2 * uy, gy = dz2 * ux - dz1 * vx;  // the gradient times det
  return gx * gx + gy * gy > max_slope * max_slope * det * det;
}

// A sliver: its least altitude in the grid under kSliverAltitudePx. A quantisation step of
// the tiles, a few metres on a zoom of the globe, can fold it over and show the terrain it
// spans as a wall, so the native engine makes none. (A slope limit of 4 on slivers let
// ETOPO5's zoom 4 draw a sliver 145 m off the DEM at a 20 m budget, 0.0085 pixels wide between
// two lattice points and a vertex the quadric had moved; with no slope limit at all ETOPO5's
// coarse zooms drew 4.6 m wide slivers 324 m high.)
inline constexpr double kSliverAltitudePx = 0.05;
inline bool isSliver(const GridPoint& a, const GridPoint& b, const GridPoint& c) {
  auto squared = [](const GridPoint& p, const GridPoint& q) {
    return (p.col - q.col) * (p.col - q.col) + (p.row - q.row) * (p.row - q.row);
  };
  const double longest2 = std::max({squared(a, b), squared(b, c), squared(c, a)});
  const double area2 = signedArea2(a, b, c);
  // altitude = |area2| / longest < kSliverAltitudePx, without the root
  return area2 * area2 < kSliverAltitudePx * kSliverAltitudePx * longest2;
}

// True when some valid DEM pixel the triangle covers is more than budget_m away from it: the
// pixel inclusion and measure of measureTin (in the grid frame, or on the globe with the
// corners' ECEF positions), so measureTin confirms the budget.
bool exceedsBudget(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c, double budget_m);
// violating_pixel: when not null and the budget is exceeded, the first pixel found beyond it.
// On the globe (budget_scan.cpp): forEachCoveredPixelOnGlobe's scan, on the columns of each
// row that can be visited and four at a time with AVX2; the same verdict and first pixel.
bool exceedsBudgetOnGlobe(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                          const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double budget_m,
                          std::size_t* violating_pixel = nullptr);
// Whether `pixel` (valid, inside the triangle in the grid) is beyond the budget: a pixel that
// broke the budget of a vertex's earlier collapses, tested first (exceedsBudgetOnGlobe would
// find it too).
bool exceedsBudgetAtPixel(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                          const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double budget_m,
                          std::size_t pixel);

// Runs simplify(c) for every non-empty cluster c, largest first, each thread taking the next
// cluster as it finishes one: at a coarse level a few large clusters would otherwise leave a
// core idle at the end. (Where each cluster's result goes does not depend on the order.)
template <typename Simplify>
void forEachClusterLargestFirst(const std::vector<std::uint32_t>& cluster_start, Simplify&& simplify) {
  std::vector<std::size_t> order;
  for (std::uint32_t c = 0; c + 1 < cluster_start.size(); ++c) {
    if (cluster_start[c] != cluster_start[c + 1]) order.push_back(c);
  }
  const auto size = [&](std::size_t c) { return cluster_start[c + 1] - cluster_start[c]; };
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return size(a) > size(b); });
  forEachLargestFirst(order, [&](std::size_t c) { simplify(static_cast<std::uint32_t>(c)); });
}

// The engines: one ClusterOutput per cluster id (empty for an empty cluster).
std::vector<ClusterOutput> collapseWithCgal(const LevelInput& level);
std::vector<ClusterOutput> collapseNatively(const LevelInput& level);

}  // namespace cluster_collapse
}  // namespace terratiles
