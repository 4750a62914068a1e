#pragma once
// buildLevels: the cluster LoD loop (DESIGN.md 2 step 3; paper sections 3.3-3.4, 4, 5.3.1).
//
// Level 0 is the finest TIN. Each coarser level is made from the one before it: partition
// its triangles into clusters (METIS on the face dual graph, or random growth for
// experiments), lock every cluster border, the outer border and the feature constraints,
// simplify inside every cluster (edge collapse, in parallel: LevelOptions::simplifier) to about `level_ratio` of
// its edges or until the next collapse would exceed the level's error budget, and merge the
// clusters by index. Re-partitioning every level moves the locked borders, so no border
// stays locked for ever (paper figs 4, 42, 43); `repartition = false` keeps the first
// partition's borders instead, for comparison.
//
// Every level's vertical error is measured against the DEM on every pixel (measureTin; on the
// globe, the level as drawn), and
// after every level the loop checks (paper algorithm 2) that every constrained edge still
// exists; a lost constraint is an Error(Internal), never silently accepted.

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "src/base/progress.h"
#include "src/dem/dem_grid.h"
#include "src/partition/partition_faces.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tin/measure_tin.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

struct LevelOptions {
  Partitioner partitioner = Partitioner::Metis;
  // Clusters per level: ceil(triangles / cluster_triangles) (paper 3.5 sizes them from the
  // tiles of the zoom: about four per tile; the tiling stage passes clusters_per_level).
  std::int32_t cluster_triangles = 2048;
  // When not empty, clusters_per_level[l] clusters split level l (instead of the above).
  std::vector<std::int32_t> clusters_per_level;
  // How METIS sees a level (partitionFaces, src/partition/partition_faces.h):
  //  - partition_regions set: by the regions it returns for the level's mesh and index, each
  //    region on its own, in parallel (the tiling stage: tile neighbourhoods, whose outlines
  //    its regroup_clusters joins away);
  //  - else region_clusters > 0 and the level wants more clusters than that: by square cells
  //    of the grid, each about region_clusters clusters' worth of the mesh's bounding box, on
  //    every other level offset by half a cell (so the cell outlines, which stay locked as
  //    cluster borders of that level, move from level to level as the borders of a
  //    re-partition do);
  //  - else globally: one METIS k-way call per connected component (the paper's method as
  //    written; seconds per level for thousands of clusters over millions of faces).
  std::int32_t region_clusters = 0;
  std::function<std::vector<std::int32_t>(const TinMesh&, std::size_t)> partition_regions;
  // The edge-collapse engine: CGAL's edge collapse (the default, the quality reference) or
  // native (terratiles' own over flat arrays, faster; simplify_clusters.h).
  Simplifier simplifier = Simplifier::Native;
  TailStop tail_stop;  // the native engine's (SimplifyOptions::tail_stop)
  // Target edge ratio of one simplification (paper: 0.5).
  double level_ratio = 0.5;
  // Error budget of level l (l >= 1): first_budget_m * level_error_growth^(l - 1); 0 or
  // infinity: no budget (the ratio alone decides).
  double first_budget_m = 0;
  double level_error_growth = 2;
  // Levels to build after the finest. 0: until a simplification keeps more than
  // level_ratio + 0.1 of the edges without being held back by the budget (or, held back,
  // keeps more than 90 % of the triangles): that level is dropped, since locked edges (outer
  // border, constraints) dominate it; or after the level simplified as one cluster.
  std::int32_t coarser_levels = 0;
  std::uint32_t seed = 1;
  // When set, regroups each level's partition before it is simplified (clusters with the same
  // id are simplified as one, so the borders between them are not locked): the tiling
  // stage joins clusters whose borders no tile outline will follow (paper fig 34).
  // Arguments: the level's mesh, its index, the METIS partition.
  std::function<FacePartition(const TinMesh&, std::size_t, const FacePartition&)> regroup_clusters;
  // false: fixed borders, the scheme the paper compares against (fig 42): the finest level's
  // partition is kept at every level (each simplified triangle stays in its cluster).
  bool repartition = true;
  // The DEM on the globe: every level is measured, and simplified under its budget, as drawn
  // (straight triangles in ECEF, errors along each pixel's vertical; DemOnGlobe). nullptr: in
  // the grid frame, heights interpolated linearly.
  const DemOnGlobe* globe = nullptr;
  // Measure every level against the DEM on every pixel (Level::error, which `levels` reports).
  // false: only place its vertices on the globe (the build measures its tiles instead, as
  // drawn and after quantisation: a second measure of every level would only cost time).
  bool measure = true;
};

struct Level {
  TinMesh mesh;
  // The partition that split this level to build the next coarser one (empty on the
  // coarsest level).
  FacePartition partition;
  // The finer level's partition carried over to this level's faces: every face lies inside
  // one cluster of the finer level, whose outline this level keeps (empty on level 0).
  FacePartition inherited_partition;
  // Per vertex of this level: its index in the next coarser level, or kRemovedVertex.
  std::vector<std::uint32_t> index_in_coarser;
  TinErrorStatistics error;  // measured against the DEM (LevelOptions::measure)
  std::size_t edge_count = 0;
  double budget_m = 0;  // the error budget this level was simplified under (0: none)
  std::size_t refused_for_error = 0, refused_for_flip = 0;
};

// Ground metres per grid unit along columns and rows: the pixel size for a projected CRS in
// metres (or other linear units, converted), for a geographic CRS the pixel size in degrees
// times the metres per degree at the DEM's centre latitude (WGS84).
std::array<double, 2> groundMetresPerPixel(const DemGrid& dem);

// The undirected edges of a mesh, as sorted (low << 32 | high) keys.
std::vector<std::uint64_t> meshEdgeKeys(const TinMesh& mesh);
// How many they are (meshEdgeKeys(mesh).size()), in linear time: each vertex's edges leaving
// it, an edge counted at its lower end when it leaves from there, else at its upper end.
std::size_t meshEdgeCount(const TinMesh& mesh);

// Feature constraints as the paper made them (4.2): `count` random connected sets of up to
// `set_faces` triangles (grown breadth-first from random seed triangles), every edge of them
// locked. Deterministic for a seed.
std::vector<std::array<std::uint32_t, 2>> randomFaceSetConstraints(const TinMesh& mesh, std::size_t count,
                                                                   std::size_t set_faces, std::uint32_t seed);

// finest: level 0, in the DEM's grid frame. constraints: locked edges of level 0 as vertex
// pairs (kept at every level). Throws Error(Input) for a non-manifold TIN, Error(Usage) for
// options out of range, Error(Internal) if a constraint is lost.
std::vector<Level> buildLevels(const DemGrid& dem, TinMesh finest, const LevelOptions& options,
                               std::vector<std::array<std::uint32_t, 2>> constraints, Progress& progress);

}  // namespace terratiles
