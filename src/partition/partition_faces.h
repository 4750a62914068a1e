#pragma once
// partitionFaces: split a TIN's triangles into clusters (paper 3.3). METIS k-way with the
// edge-cut objective gives compact clusters with short borders, which is what lets the
// simplification inside locked borders reach low errors; `random` (random seeds grown at
// random into contiguous clusters, the control of the paper's fig 40) is there to measure
// that.

#include <cstdint>
#include <vector>

#include "src/partition/face_graph.h"

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

// Each connected component of the mesh gets a share of the clusters proportional to its faces
// (at least one), so no cluster spans two components. Within a component, METIS is asked for
// contiguous parts (METIS_OPTION_CONTIG), and the random growth is contiguous by
// construction; a part METIS still leaves empty is dropped and ids are renumbered densely.
// Throws Error(Usage) for clusters < 1 and Error(Internal) if METIS fails.
FacePartition partitionFaces(const FaceGraph& graph, const PartitionOptions& options);

// The number of graph edges whose two faces are in different clusters (METIS's edge cut).
std::size_t edgeCut(const FaceGraph& graph, const std::vector<std::int32_t>& cluster_of_face);

}  // namespace terratiles
