#pragma once
// simplifyClusters: one level of the LoD loop's simplification (DESIGN.md 2, step 3c-e; paper
// sections 3.3-3.4): edge collapse inside every cluster of a partitioned TIN, with every
// cluster border, the dataset's outer border and the feature constraints locked.
//
// Two engines do the collapses (SimplifyOptions::simplifier); both keep the rules below.
//
// Simplifier::Native (the default, `--simplifier native`: 1.5-3x faster than CGAL on SRTM; on
// ETOPO5, where the budget refuses about ten collapses for each it accepts, the whole build
// 2.7x Delatin with the tools' default tail stop; tools/bench/README.md has the history): terratiles'
// own edge collapse over flat arrays. A vertex is free when
// none of its edges is locked (a locked edge is on the dataset's outer border, between two
// clusters or a constraint), so a free vertex's star is closed and inside its cluster. A
// collapse removes a free vertex u into a neighbour v: when v is locked, u goes to v (a
// half-edge collapse, v stays where it is); when v is free too, either that, or v moves to the
// edge's quadric optimum (the 3x3 solve of CGAL's placement below, when well conditioned), or,
// only where that does not exist, to the best point of the segment uv. The two triangles of
// edge uv vanish. Costs:
// Garland-Heckbert plane quadrics in metres (unit face normals, as CGAL's), (Q_u + Q_v) at the
// new position. Greedy over all collapses like CGAL's queue of edges: a binary heap holds every
// free vertex at its cheapest collapse not yet refused (ties by vertex order); the vertex on
// top tries that collapse, and when the filter refuses it, its next ones in cost order as long
// as none is dearer than the next vertex's in the heap (then it waits in the heap at that one,
// its untried collapses kept in a pool); the first accepted is applied; the merged vertex and
// its ring are queued again at their new costs, and a vertex whose star a collapse changes
// starts again from its cheapest. (Trying all of a vertex's collapses at once, as before, let
// dear collapses pass cheaper ones elsewhere: up to +11 % geometricError at coarse zooms.) A vertex's triangles are its initial ones (CSR) plus those of
// the vertices it absorbed (a chain), and an edge's quadric optimum is remembered until a
// collapse changes one of its ends, so nothing allocates per collapse: each thread keeps one
// set of arrays for all its clusters.
//
// Simplifier::Cgal (`--simplifier cgal`, the quality reference): each cluster's triangles
// become one CGAL::Surface_mesh (Simple_cartesian<double>, points (col * metres_per_col,
// -row * metres_per_row, height_m): metres in x east, y north and z, so the mesh is
// counter-clockwise seen from above like TinMesh). CGAL's Surface_mesh_simplification::
// edge_collapse simplifies it with Garland-Heckbert plane quadrics, an
// edge_is_constrained_map holding every border edge of the cluster's submesh and every
// constrained edge, and Constrained_placement, so a vertex on a locked edge never moves and a
// chord between two locked vertices is never collapsed (CGAL refuses an edge whose two ends
// both touch a constrained edge); its placement may move a vertex off the lattice.
//
// Both: a cluster stops when its edge count falls below options.edge_ratio of its initial
// count (for CGAL: CGAL 5.5 Count_ratio_stop_predicate, called Edge_count_ratio_stop_predicate
// from CGAL 5.6), or when no collapse is left that the filter accepts. The filter refuses a
// collapse when
//   (a) one of the triangles it creates would be clockwise, or degenerate (twice its area
//       below 1e-9 times its longest edge squared), in the (col, row) plane: the level stays
//       a height field without fold-overs, and covers exactly the same ground; or steeper
//       than 100 (rise over run in metres, about 89.4 degrees): a sliver wall next to a much
//       higher vertex, which turns a quantisation step into a height jump as large as the
//       wall (measured: 490 m on ETOPO5 with the 16 m step of a quarter-world tile); the
//       native engine also refuses slivers (least altitude under 0.05 pixels), which a
//       quantisation step folds over the same way, or
//   (b) one of the triangles it creates is more than options.max_error_m away from a valid
//       DEM pixel it covers (pixel centres at whole (col, row), the inclusion rule and the
//       measure of measureTin: on the globe (options.globe), the triangle as drawn, straight
//       in ECEF, along each pixel's vertical, so long edges over flat ground are refused where
//       their sag would break the budget; without one, linear interpolation; nodata skipped;
//       not tested when the budget is infinite).
// So with a finite budget, every triangle the simplification creates is within the budget
// of the DEM (triangles it does not touch keep the error they had).
//
// CGAL engine: the quadrics are Garland and Heckbert's plane quadrics exactly as CGAL's
// GarlandHeckbert_plane_policies builds them (unit face normals; border edges add a
// perpendicular plane weighted 100), written here on 4x4 doubles because CGAL's class needs
// Eigen. The placement is the quadric optimum when it is well conditioned and lies inside the
// star of the edge seen from above, otherwise the best point of the edge segment that does.
//
// Vertices: a collapse keeps one of its two input vertices (the native engine: v; CGAL
// chooses which; when the new
// point is one end's point, that end's vertex survives). The output holds the surviving input
// vertices in input order, each with its input GridPoint bit for bit unless a collapse moved
// it (then (x / metres_per_col, -y / metres_per_row, z)). A vertex on a locked edge, and so
// every vertex shared by two clusters, never moves and always survives. Input vertices no
// triangle uses are dropped. Triangles: cluster by cluster in cluster id order, each
// cluster's in its own order; counter-clockwise seen from above. The result does not depend
// on the number of threads (clusters are simplified in parallel with TBB, each into its own
// slot, and assembled by vertex index; there is no welding tolerance).
//
// Input: an edge-manifold, consistently oriented TinMesh (vertex-manifold is not needed: a
// vertex where two fans of one cluster touch is on that cluster's border, so locked; CGAL
// splits it inside the cluster's submesh). Throws Error(ErrorCode::Input) with a one-line message when a triangle uses a
// vertex index out of range or the same vertex twice, an edge is in more than two triangles,
// two triangles run an edge in the same direction, cluster_of_face does not hold one id in
// [0, cluster_count) per triangle, or a constrained edge is not an edge of the mesh; throws
// Error(ErrorCode::Usage) for options out of range. Memory: O(triangles) for the topology plus
// one cluster's arrays (native) or Surface_mesh (CGAL) per thread. Time: O(F log F) plus the
// collapses: per cluster O(E log E), and with a finite budget
// O(pixels under the star) per collapse tried.

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

class DemOnGlobe;

enum class Simplifier {
  Native,  // terratiles' own edge collapse over flat arrays (the default, fast)
  Cgal,    // CGAL's Surface_mesh_simplification::edge_collapse per cluster (the reference)
};

// "native" or "cgal", as --simplifier takes it.
inline const char* simplifierName(Simplifier simplifier) { return simplifier == Simplifier::Cgal ? "cgal" : "native"; }

// The tail stop: a cluster's run also stops when fewer than `applied` of its last `tries`
// collapse tries were applied (tries = 0: off). Where the budget binds, a level's last few per
// cent of collapses take about half of its tries (every change nearby makes each refused
// vertex try again); the stop leaves those triangles in the level. The budget still holds for
// every collapse applied; the result still does not depend on the number of threads.
struct TailStop {
  std::uint32_t tries = 0;
  std::uint32_t applied = 0;
  bool on() const { return tries > 0 && applied > 0; }
};

// The tools' default (`build`, `levels`; a library caller's SimplifyOptions and LevelOptions
// default to off, the full greedy run): measured in tools/bench/README.md.
inline constexpr TailStop kDefaultTailStop{1000, 5};

// "off", or "TRIES,APPLIED" (as --tail-stop takes it).
std::string tailStopName(const TailStop& stop);
// Parses --tail-stop's value: "off" or "TRIES,APPLIED", 1 <= APPLIED <= TRIES, APPLIED <= 4096.
// Throws Error(ErrorCode::Usage) naming the option otherwise.
TailStop parseTailStop(std::string_view text);

struct SimplifyOptions {
  Simplifier simplifier = Simplifier::Native;
  // Each cluster stops when its edge count falls below this fraction of its initial count
  // (paper 3.4: 50 %). In (0, 1]; 1 leaves the mesh as it is.
  double edge_ratio = 0.5;
  // Level error budget, metres: a collapse is refused if any triangle it creates would be
  // more than this above or below a valid DEM pixel it covers. >= 0; infinity: no test.
  double max_error_m = std::numeric_limits<double>::infinity();
  // Ground size of one grid unit along columns and rows, metres (> 0), so the quadrics see
  // metres in x, y and z. For a projected CRS in metres, the pixel size; for degrees, the
  // pixel size times the metres per degree at the DEM's latitude.
  double metres_per_col = 1;
  double metres_per_row = 1;
  // The budget on the globe (the DEM's DemOnGlobe) with every input vertex's ECEF position
  // (globe->place of mesh.vertices); a vertex a collapse moves is placed by globe->place.
  // nullptr: the budget is measured in the grid frame.
  const DemOnGlobe* globe = nullptr;
  std::span<const EcefPoint> vertex_ecef;
  TailStop tail_stop;  // native engine only
};

struct ClusterSimplification {
  // The coarser level: the surviving input vertices in input order, and nothing else.
  TinMesh mesh;
  // Per input vertex: its index in mesh.vertices, or kRemovedVertex.
  std::vector<std::uint32_t> new_index_of_vertex;
  // Per output triangle: the cluster it was simplified in (its borders are the input's
  // cluster borders, so a fixed-border scheme can keep the partition).
  std::vector<std::int32_t> cluster_of_face;
  // Collapses the filter refused (statistics; a refused edge is tried again when a
  // neighbouring collapse changes its star): (b) above the error budget, (a) fold-over or a
  // face steeper than 100 (rise over run, about 89.4 degrees).
  std::size_t refused_for_error = 0;
  std::size_t refused_for_flip = 0;
  // The input mesh's edges, each counted once (an edge-manifold mesh: its corners plus its
  // border sides, over two), from the topology the simplification builds anyway.
  std::size_t input_edges = 0;
};

inline constexpr std::uint32_t kRemovedVertex = 0xffffffff;

// dem: the source DEM, for the error budget (read only). mesh: the level to simplify, in the
// DEM's grid frame. cluster_of_face: one cluster id per triangle, in [0, cluster_count);
// clusters may be empty, disconnected or touch themselves at a vertex. constrained_edges:
// extra locked edges (feature constraints) as pairs of vertex indices, either order; may be
// empty.
ClusterSimplification simplifyClusters(const DemGrid& dem, const TinMesh& mesh,
                                       const std::vector<std::int32_t>& cluster_of_face,
                                       std::int32_t cluster_count,
                                       const std::vector<std::array<std::uint32_t, 2>>& constrained_edges,
                                       const SimplifyOptions& options);

}  // namespace terratiles
