#pragma once
// multilevelParts: METIS on a coarsened graph, refined back down to the faces (an internal
// step of partitionFaces by regions; src/partition/partition_faces.h).
//
// METIS k-way spends most of its time, for many parts, on a fixed cost: its initial
// partitioning runs 4-5 recursive bisections of a graph it first coarsens to 30 vertices per
// part, whatever the input size (measured on Gabon's 2.4 M faces in regions of 64 parts:
// k-way on the faces 1.3 s per level, on 32x coarsened groups still 0.9 s). Here the piece is
// coarsened first by greedy heavy-edge matching (METIS's own scheme, deterministic, in vertex
// order) to about 8 vertices per part, METIS_PartGraphRecursive (edge-cut objective, one
// cut) splits that small weighted graph, and the parts are projected back level by level,
// each level refined by moving vertices that share more edge weight with a neighbouring part
// than with their own (within METIS's 3 % balance), as METIS's own uncoarsening does. On the
// faces the parts are made connected and smoothed without ever disconnecting one. Measured
// on Gabon, level 0: edge cut within 1 % of k-way on the same regions, at a sixth of the time.

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
