#pragma once
// partitionFaces: split a TIN's triangles into clusters (paper 3.3). METIS k-way with the
// edge-cut objective gives compact clusters with short borders, which is what lets the
// simplification inside locked borders reach low errors; `random` (random seeds grown at
// random into contiguous clusters, the control of the paper's fig 40) is there to measure
// that.
//
// Global or by regions. One METIS k-way call over millions of faces for thousands of parts
// costs seconds (Gabon SRTM at --tin-max-error 5: 2.4 M faces into 2400 parts, 9-12 s; its
// cost grows with the parts as well as the faces). Given a region per face (the tile
// neighbourhoods of src/tiling/assign_clusters.h, or square cells of the grid:
// gridCellRegions), every region is partitioned on its own into parts proportional to its
// faces, the regions in parallel: about the same edge cut (the region outlines become
// cluster borders; choose regions whose outlines the caller does not need locked, see
// tileNeighbourhoodRegions) at a fraction of the time.

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
// `options.clusters` proportional to its faces (at least one), and numbers the clusters
// densely: piece by piece in order of each piece's lowest face, and within a piece in order
// of first appearance. So no cluster spans two pieces.
//   region_of_face empty: the pieces are the connected components of the mesh (one METIS call
//     per component, the global partition).
//   region_of_face given (a value >= 0 per face, any numbering): the pieces are the connected
//     parts of each region (faces of one region joined through shared edges). A piece with
//     fewer than half a cluster's faces (faces / clusters) is joined to the neighbouring piece
//     it shares the most edges with (lowest piece on ties), so thin slivers that a region's
//     outline cuts off do not become clusters of their own; a component that small stays one.
// Within a piece METIS is asked for contiguous parts (METIS_OPTION_CONTIG) with the same seed
// for every piece, and the random growth is contiguous by construction (one generator, pieces
// in order); a part METIS leaves empty is dropped. METIS runs on the pieces in parallel (TBB)
// when its random numbers are drawn per thread (metisRandomIsPerThread), else one after the
// other: the result is the same for any thread count.
// Throws Error(Usage) for clusters < 1 or a region_of_face of the wrong size or with a negative
// value, and Error(Internal) if METIS fails.
FacePartition partitionFaces(const FaceGraph& graph, const PartitionOptions& options,
                             std::span<const std::int32_t> region_of_face = {});

// The number of graph edges whose two faces are in different clusters (METIS's edge cut).
std::size_t edgeCut(const FaceGraph& graph, const std::vector<std::int32_t>& cluster_of_face);

// Regions for partitionFaces: the square cell of side cell_px grid pixels (cells start at
// origin_px, in columns and rows) that holds each face's centroid, as a region id per face.
// Throws Error(Usage) unless cell_px > 0 and finite.
std::vector<std::int32_t> gridCellRegions(const TinMesh& mesh, double cell_px, std::array<double, 2> origin_px);

namespace detail {
// True when libmetis draws its random numbers (libc's rand, which METIS 5.1 reseeds with
// srand at every call) from the calling thread's own generator: partition_faces.cpp replaces
// rand and srand for the process with per-thread generators that give the same sequences as
// glibc's, so concurrent METIS calls are each as deterministic as a single one. Checked once,
// by watching a METIS call draw from this thread's generator.
bool metisRandomIsPerThread();
}  // namespace detail

}  // namespace terratiles
