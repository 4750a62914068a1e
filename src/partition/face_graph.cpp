#include "src/partition/face_graph.h"

#include <algorithm>
#include <string>

#include "src/base/error.h"

namespace terratiles {

FaceGraph buildFaceGraph(const TinMesh& mesh) {
  TERRATILES_ASSERT(mesh.triangle_indices.size() % 3 == 0);
  const std::size_t face_count = mesh.triangleCount();
  TERRATILES_ASSERT(face_count < static_cast<std::size_t>(INT32_MAX / 3));
  // One record per triangle side, keyed by the undirected edge; sorting brings the two sides
  // of an interior edge together.
  struct Side {
    std::uint64_t key;   // (min vertex << 32) | max vertex
    std::int32_t side;   // 3 * t + k
  };
  std::vector<Side> sides(3 * face_count);
  const auto& idx = mesh.triangle_indices;
  for (std::size_t s = 0; s < sides.size(); ++s) {
    const std::uint32_t from = idx[s], to = idx[s % 3 == 2 ? s - 2 : s + 1];
    if (from == to) {
      throw Error(ErrorCode::Input, "triangle " + std::to_string(s / 3) + " repeats vertex " +
                                        std::to_string(from) + "; expected three distinct corners");
    }
    const std::uint64_t lo = std::min(from, to), hi = std::max(from, to);
    sides[s] = {(lo << 32) | hi, static_cast<std::int32_t>(s)};
  }
  std::sort(sides.begin(), sides.end(),
            [](const Side& a, const Side& b) { return a.key < b.key || (a.key == b.key && a.side < b.side); });

  FaceGraph graph;
  graph.across.assign(3 * face_count, kNoFace);
  for (std::size_t i = 0; i < sides.size();) {
    std::size_t j = i + 1;
    while (j < sides.size() && sides[j].key == sides[i].key) ++j;
    const std::string edge = std::to_string(sides[i].key >> 32) + "-" + std::to_string(sides[i].key & 0xffffffffu);
    if (j - i > 2) {
      throw Error(ErrorCode::Input, "edge " + edge + " is shared by " + std::to_string(j - i) +
                                        " triangles; expected a manifold TIN (at most two per edge)");
    }
    if (j - i == 2) {
      const std::int32_t a = sides[i].side, b = sides[i + 1].side;
      if (idx[static_cast<std::size_t>(a)] == idx[static_cast<std::size_t>(b)]) {
        throw Error(ErrorCode::Input, "edge " + edge + " is run in the same direction by triangles " +
                                          std::to_string(a / 3) + " and " + std::to_string(b / 3) +
                                          "; expected consistently oriented triangles");
      }
      graph.across[static_cast<std::size_t>(a)] = b / 3;
      graph.across[static_cast<std::size_t>(b)] = a / 3;
    }
    i = j;
  }
  graph.offsets.resize(face_count + 1, 0);
  graph.neighbours.reserve(graph.across.size());
  for (std::size_t t = 0; t < face_count; ++t) {
    for (std::size_t k = 0; k < 3; ++k) {
      if (graph.across[3 * t + k] != kNoFace) graph.neighbours.push_back(graph.across[3 * t + k]);
    }
    graph.offsets[t + 1] = static_cast<std::int32_t>(graph.neighbours.size());
  }
  return graph;
}

std::int32_t faceComponents(const FaceGraph& graph, std::vector<std::int32_t>& component_of_face) {
  const std::size_t face_count = graph.faceCount();
  component_of_face.assign(face_count, -1);
  std::int32_t components = 0;
  std::vector<std::int32_t> stack;
  for (std::size_t start = 0; start < face_count; ++start) {
    if (component_of_face[start] >= 0) continue;
    component_of_face[start] = components;
    stack.push_back(static_cast<std::int32_t>(start));
    while (!stack.empty()) {
      const auto t = static_cast<std::size_t>(stack.back());
      stack.pop_back();
      for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
        const std::int32_t other = graph.neighbours[static_cast<std::size_t>(n)];
        if (component_of_face[static_cast<std::size_t>(other)] < 0) {
          component_of_face[static_cast<std::size_t>(other)] = components;
          stack.push_back(other);
        }
      }
    }
    ++components;
  }
  return components;
}

}  // namespace terratiles
