#pragma once
// What the two edge-collapse engines behind simplifyClusters share (internal to
// src/simplify): the level's input topology, the rules a collapse must keep (a height field
// without fold-overs or walls, the error budget as measureTin measures it) and what one
// cluster hands to the assembly. simplifyClusters (simplify_clusters.cpp) validates the input,
// builds the topology and assembles; cgal_edge_collapse.cpp and native_edge_collapse.cpp
// simplify the clusters.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

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
  // The corners leaving each vertex, in corner order: leaving[leaving_start[v] ..
  // leaving_start[v + 1]) (corner c runs from its vertex to the next corner's).
  std::vector<std::uint32_t> leaving_start, leaving;
};

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
struct ClusterOutput {
  std::vector<std::uint32_t> triangles;                    // input vertex indices, 3 per triangle
  std::vector<std::pair<std::uint32_t, GridPoint>> moved;  // surviving vertices that moved
  std::size_t refused_for_error = 0;
  std::size_t refused_for_flip = 0;
};

// A symmetric 4x4 quadric (Garland and Heckbert): xx xy xz xw yy yz yw zz zw ww.
using Quadric = std::array<double, 10>;

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
bool quadricMinimum(const Quadric& q, std::array<double, 3>& point);

// Where the quadric is least along p0 + t d (CGAL's construct_optimal_point_singular): t when
// the quadric curves upward along d and t lies strictly inside (0, 1); nullopt otherwise.
std::optional<double> segmentMinimum(const Quadric& q, const std::array<double, 3>& p0,
                                     const std::array<double, 3>& d);

// Counter-clockwise seen from above and not degenerate: twice the area in (col, row) above
// 1e-9 times the longest edge squared, so the sign is stable under rounding whatever vertex a
// reader starts at.
bool isUpwardTriangle(const GridPoint& a, const GridPoint& b, const GridPoint& c);

// A face steeper than this (rise over run, about 89.4 degrees) is a wall no terrain level
// needs: simplification only makes one when it pulls a vertex next to a much higher or lower
// one (a sliver), and such a face turns a quantisation step of the vertices into a height
// jump as large as the wall.
inline constexpr double kMaxSlope = 100;

// Whether the triangle rises more than max_slope (rise over run in metres) anywhere, or is
// vertical or degenerate: its gradient's squared length against max_slope^2, without a root or
// a division.
bool isSteeperThan(const GridPoint& a, const GridPoint& b, const GridPoint& c, double metres_per_col,
                   double metres_per_row, double max_slope);

// True when some valid DEM pixel the triangle covers is more than budget_m away from it: the
// pixel inclusion and measure of measureTin (in the grid frame, or on the globe with the
// corners' ECEF positions), so measureTin confirms the budget.
bool exceedsBudget(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c, double budget_m);
// violating_pixel: when not null and the budget is exceeded, the first pixel found beyond it.
bool exceedsBudgetOnGlobe(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                          const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double budget_m,
                          std::size_t* violating_pixel = nullptr);
// Whether `pixel` (valid, inside the triangle in the grid) is beyond the budget: a pixel that
// broke the budget of a vertex's earlier collapses, tested first (exceedsBudgetOnGlobe would
// find it too).
bool exceedsBudgetAtPixel(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                          const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double budget_m,
                          std::size_t pixel);

// The engines: one ClusterOutput per cluster id (empty for an empty cluster).
std::vector<ClusterOutput> collapseWithCgal(const LevelInput& level);
std::vector<ClusterOutput> collapseNatively(const LevelInput& level);

}  // namespace cluster_collapse
}  // namespace terratiles
