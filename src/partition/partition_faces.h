#pragma once
// partitionFaces: split a TIN's triangles into clusters (paper 3.3). METIS k-way with the
// edge-cut objective gives compact clusters with short borders, which is what lets the
// simplification inside locked borders reach low errors; `random` (random seeds grown at
// random into contiguous clusters, the control of the paper's fig 40) is there to measure
// that.
//
// Global or by regions. One METIS k-way call over millions of faces for thousands of parts
// costs seconds (SRTM Gabon at --tin-max-error 5: 2.4 M faces into 4608 parts, 6.5-10 s; k-way's
// cost grows with the parts as well as the faces). Given a region per face (the tile
// neighbourhoods of src/tiling/assign_clusters.h, or square cells of the grid:
// gridCellRegions, clusterCellRegions), every region is partitioned on its own, the regions
// in parallel, by METIS on a coarsened graph refined back to the faces
// (src/partition/multilevel_parts.h). Measured on Gabon, level by level: edge cut 3-10 % above
// one global k-way call (the region outlines are cluster borders too; choose regions whose
// outlines the caller does not need locked, see tileNeighbourhoodRegions), at a tenth of the
// time on one thread.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "src/partition/face_graph.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

enum class Partitioner { Metis, Random };

struct PartitionOptions {
  Partitioner method = Partitioner::Metis;
  std::int32_t clusters = 8;  // wanted; the result may have fewer when there are fewer faces
  std::uint32_t seed = 1;     // METIS's and the random partitioner's seed: same seed, same result
};

struct FacePartition {
  std::vector<std::int32_t> cluster_of_face;  // 0 .. cluster_count - 1, every id used
  std::int32_t cluster_count = 0;
};

// Splits the faces into pieces, partitions every piece on its own into a share of
// `options.clusters` proportional to its faces (rounded, at least one), so no cluster spans two
// pieces, and numbers the clusters densely.
//   region_of_face empty (global): the pieces are the connected components of the mesh. METIS
//     k-way (METIS_OPTION_CONTIG) runs once per component; ids component by component (in
//     order of each one's lowest face), within one in order of first appearance. The random
//     growth is contiguous by construction (one generator, components in order).
//   region_of_face given (a value >= 0 per face, any numbering; regional): the pieces are the
//     connected parts of each region (faces of one region joined through shared edges). A
//     piece with at least half a cluster's faces (faces / clusters) is partitioned by
//     multilevelParts (METIS recursive bisection of the coarsened piece, refined; contiguous
//     parts), or grown at random (one generator, regions in order, pieces in order of their
//     lowest face); a smaller piece (a sliver that a region outline cuts off) is attached
//     afterwards, whole, to the neighbouring cluster it shares the most edges with (lowest
//     provisional id on ties), and one with no neighbour (a small component) is a cluster of
//     its own. Ids in order of each cluster's first face.
// Every METIS call gets options.seed. A part METIS leaves empty is dropped. The regions are
// partitioned in parallel (TBB) when METIS draws its random numbers per thread
// (detail::metisRandomIsPerThread), else one after the other (as the components are): the
// result is the same for any thread count. Throws Error(Usage) for clusters < 1 or a region_of_face of the wrong size or
// with a negative value, and Error(Internal) if METIS fails.
FacePartition partitionFaces(const FaceGraph& graph, const PartitionOptions& options,
                             std::span<const std::int32_t> region_of_face = {});

// True when every cluster id in [0, cluster_count) is used and each cluster's faces form one
// connected piece through shared edges (what partitionFaces promises for METIS and random
// growth on a mesh whose components each get their own clusters).
bool clustersAreContiguous(const FaceGraph& graph, const FacePartition& partition);

// The number of graph edges whose two faces are in different clusters (METIS's edge cut).
std::size_t edgeCut(const FaceGraph& graph, const std::vector<std::int32_t>& cluster_of_face);

// Regions for partitionFaces: the square cell of side cell_px grid pixels (cells start at
// origin_px, in columns and rows) that holds each face's centroid, as a region id per face.
// Throws Error(Usage) unless cell_px > 0 and finite.
std::vector<std::int32_t> gridCellRegions(const TinMesh& mesh, double cell_px, std::array<double, 2> origin_px);

// gridCellRegions with cells sized to hold about region_clusters of the mesh's `clusters`
// clusters each (by the area of the vertices' bounding box), starting at its corner, or half a
// cell before it when `offset` (so the cell outlines of two successive levels differ). None
// (empty: partition globally) when region_clusters <= 0 or clusters <= region_clusters.
std::vector<std::int32_t> clusterCellRegions(const TinMesh& mesh, std::int32_t clusters, std::int32_t region_clusters,
                                             bool offset);

namespace detail {
// True when libmetis draws its random numbers (libc's rand, which METIS 5.1 reseeds with
// srand at every call) from the calling thread's own generator: partition_faces.cpp replaces
// rand and srand for the process with per-thread generators that give the same sequences as
// glibc's, so concurrent METIS calls are each as deterministic as a single one. Checked once,
// by watching a METIS call draw from this thread's generator.
bool metisRandomIsPerThread();
}  // namespace detail

}  // namespace terratiles
