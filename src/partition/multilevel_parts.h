#pragma once
// multilevelParts: METIS on a coarsened graph, refined back down to the faces (an internal
// step of partitionFaces by regions; src/partition/partition_faces.h).
//
// METIS k-way spends most of its time, for many parts, on a fixed cost: its initial
// partitioning runs 4-5 recursive bisections of a graph it first coarsens to 30 vertices per
// part, whatever the input size (measured on SRTM Gabon's 2.4 M faces in regions of 64 parts:
// k-way on the faces 2.5-3.0 s per level on one core, on the same regions coarsened 32x still
// 1.9 s). Here the piece is coarsened first by greedy heavy-edge matching (METIS's own scheme,
// deterministic, in vertex order; a group never outweighs a quarter of a part) to about 8
// vertices per part, METIS_PartGraphRecursive (edge-cut objective, METIS's defaults) splits
// that small weighted graph, and the parts are projected back level by level, each level
// refined by moving vertices that share more edge weight with a neighbouring part than with
// their own (within METIS's 3 % balance or the balance it reached), as METIS's own
// uncoarsening does. On the faces every part is made connected (orphaned pieces join the
// neighbouring part they share the most edges with) and smoothed without ever disconnecting
// one. Measured on the same Gabon regions: edge cut 140 k against k-way's 139 k (+0.8 %), in
// 0.7-0.9 s instead of 2.5-3.0 s.

#include <cstdint>
#include <vector>

namespace terratiles::detail {

// A connected piece of the face graph in METIS's CSR layout (local ids 0..n-1).
struct PieceGraph {
  std::vector<std::int32_t> xadj{0}, adjncy;
  std::size_t size() const { return xadj.size() - 1; }
};

struct MultilevelScratch;  // memory reused between calls on one thread

// Splits `piece` (connected, at least `parts` faces) into at most `parts` contiguous parts of
// about equal size with few cut edges: part[v] in 0..parts-1 for every vertex. METIS's seed is
// `seed`. Deterministic: the same input gives the same parts on any thread. Throws
// Error(Internal) if METIS fails.
void multilevelParts(const PieceGraph& piece, std::int32_t parts, std::uint32_t seed, std::vector<std::int32_t>& part,
                     MultilevelScratch& scratch);

// Scratch for multilevelParts; one per thread.
struct MultilevelScratch {
  struct Level {  // a coarsened graph with vertex and edge weights
    std::vector<std::int32_t> xadj, adjncy, adjwgt, vwgt;
    std::vector<std::int32_t> coarse_of;  // this level's vertex -> the next coarser level's
    std::size_t size() const { return xadj.empty() ? 0 : xadj.size() - 1; }
  };
  std::vector<Level> levels;  // levels[0]: the piece's own coarsening map; weights 1
  std::vector<std::int32_t> ones, next_member, first_member, slot, part_work, ids, stack;
  std::vector<std::int64_t> weight, shared;
};

}  // namespace terratiles::detail
