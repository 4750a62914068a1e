#pragma once
// FaceGraph: the face dual graph of a TIN, the graph METIS partitions (paper 3.3): a node per
// triangle, an edge between two triangles that share a mesh edge. Stored twice: per triangle
// side (which triangle lies across each side, for border tests) and as CSR (xadj/adjncy, the
// layout METIS takes).

#include <cstdint>
#include <vector>

#include "src/tin/tin_mesh.h"

namespace terratiles {

inline constexpr std::int32_t kNoFace = -1;

struct FaceGraph {
  // across[3 * t + k]: the triangle on the other side of side k of triangle t (side k runs
  // from corner k to corner (k + 1) % 3), or kNoFace on the mesh's outer border.
  std::vector<std::int32_t> across;
  // CSR: the neighbours of t are neighbours[offsets[t] .. offsets[t + 1]), in side order.
  std::vector<std::int32_t> offsets;
  std::vector<std::int32_t> neighbours;

  std::size_t faceCount() const { return offsets.empty() ? 0 : offsets.size() - 1; }
};

// Builds the graph of `mesh`. Throws Error(Input) naming the edge when the mesh is not an
// oriented edge-manifold: an edge used by more than two triangles, or by two triangles that
// run it in the same direction (inconsistent orientation), or a degenerate triangle (a
// repeated corner). O(T) and parallel (TBB) for a valid mesh: each side finds its twin among
// the sides leaving its far vertex (per-vertex lists), and every twin is checked to point
// back; any doubt goes to a sort of all sides (O(T log T)), which names the first fault in
// edge order. The result is the same either way (a valid mesh's twins are unique).
FaceGraph buildFaceGraph(const TinMesh& mesh);
// The same into `graph`, reusing its arrays' memory (a level loop keeps one graph: the next
// level's arrays are smaller and need no fresh pages).
void buildFaceGraph(const TinMesh& mesh, FaceGraph& graph);

// The connected components of the graph (through shared edges): a component id per face,
// numbered 0.. in order of each component's lowest face; returns the number of components.
std::int32_t faceComponents(const FaceGraph& graph, std::vector<std::int32_t>& component_of_face);

}  // namespace terratiles
