#include "src/partition/face_graph.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <string>

#include "src/base/error.h"
#include "src/partition/huge_pages.h"

namespace terratiles {
namespace {

constexpr std::size_t kFaceBlock = 16384;  // faces per parallel task

// The checking path: one record per triangle side keyed by the undirected edge; sorting
// brings the sides of an edge together, so every way a mesh can fail to be an oriented
// edge-manifold is found and named in edge order. O(T log T). The fast path below hands a
// mesh to this one as soon as it sees anything wrong, so the messages do not depend on the
// path.
FaceGraph sortedFaceGraph(const TinMesh& mesh) {
  const std::size_t face_count = mesh.triangleCount();
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
    if (j - i > 2 || (j - i == 2 && idx[static_cast<std::size_t>(sides[i].side)] == idx[static_cast<std::size_t>(sides[i + 1].side)])) {
      const std::string edge = std::to_string(sides[i].key >> 32) + "-" + std::to_string(sides[i].key & 0xffffffffu);
      if (j - i > 2) {
        throw Error(ErrorCode::Input, "edge " + edge + " is shared by " + std::to_string(j - i) +
                                          " triangles; expected a manifold TIN (at most two per edge)");
      }
      throw Error(ErrorCode::Input, "edge " + edge + " is run in the same direction by triangles " +
                                        std::to_string(sides[i].side / 3) + " and " + std::to_string(sides[i + 1].side / 3) +
                                        "; expected consistently oriented triangles");
    }
    if (j - i == 2) {
      const std::int32_t a = sides[i].side, b = sides[i + 1].side;
      graph.across[static_cast<std::size_t>(a)] = b / 3;
      graph.across[static_cast<std::size_t>(b)] = a / 3;
    }
    i = j;
  }
  return graph;
}

// The fast path, O(T): the corners at each vertex as a linked list (head per vertex, next per
// side: one pass in side order). Around vertex v every triangle has one side leaving v
// (v -> x) and one arriving (y -> v); the side v -> x's twin is the side x -> v of the
// triangle around v whose arriving side starts at x. So each vertex's list is walked once and
// matched within itself (a few entries), in parallel over vertices, and each side is set by
// its first vertex. Returns false (leaving `across` unspecified) when the mesh is not an
// oriented edge-manifold: a repeated corner, or two sides leaving (or arriving at) a vertex
// from the same other vertex (two triangles that run one edge the same way; an edge of three
// or more triangles always has two such sides). head and next are scratch (the caller's, so
// their memory is reused).
bool linkedAcross(const TinMesh& mesh, std::vector<std::int32_t>& across, std::vector<std::int32_t>& head,
                  std::vector<std::int32_t>& next) {
  const std::size_t vertex_count = mesh.vertices.size();
  const auto& idx = mesh.triangle_indices;
  detail::assignOnHugePages(head, vertex_count, -1);
  detail::resizeOnHugePages(next, idx.size());
  for (std::size_t s = 0; s < idx.size(); ++s) {
    if (idx[s] >= vertex_count) return false;  // the checking path names it as best it can
    next[s] = head[idx[s]];
    head[idx[s]] = static_cast<std::int32_t>(s);
  }
  detail::resizeOnHugePages(across, idx.size());
  std::atomic<bool> manifold{true};
  constexpr std::size_t kVertexBlock = 8192;
  tbb::parallel_for(std::size_t{0}, (vertex_count + kVertexBlock - 1) / kVertexBlock, [&](std::size_t block) {
    struct Corner {
      std::uint32_t out, in;  // the far vertex of the leaving and of the arriving side
      std::int32_t side;      // the leaving side
    };
    std::vector<Corner> corners;
    const std::size_t end = std::min(vertex_count, (block + 1) * kVertexBlock);
    for (std::size_t v = block * kVertexBlock; v < end; ++v) {
      corners.clear();
      for (std::int32_t i = head[v]; i >= 0; i = next[static_cast<std::size_t>(i)]) {
        const auto side = static_cast<std::size_t>(i);
        const std::size_t base = side - side % 3, k = side % 3;
        corners.push_back({idx[base + (k + 1) % 3], idx[base + (k + 2) % 3], i});
        if (corners.back().out == v || corners.back().in == v) {
          manifold.store(false, std::memory_order_relaxed);
          return;
        }
      }
      for (std::size_t j = 0; j < corners.size(); ++j) {
        std::int32_t twin = kNoFace;
        for (std::size_t k = 0; k < corners.size(); ++k) {
          if (k != j && (corners[k].out == corners[j].out || corners[k].in == corners[j].in)) {
            manifold.store(false, std::memory_order_relaxed);
            return;
          }
          if (corners[k].in == corners[j].out) twin = corners[k].side / 3;
        }
        across[static_cast<std::size_t>(corners[j].side)] = twin;
      }
    }
  });
  return manifold.load();
}

}  // namespace

FaceGraph buildFaceGraph(const TinMesh& mesh) {
  FaceGraph graph;
  buildFaceGraph(mesh, graph);
  return graph;
}

void buildFaceGraph(const TinMesh& mesh, FaceGraph& graph) {
  TERRATILES_ASSERT(mesh.triangle_indices.size() % 3 == 0);
  const std::size_t face_count = mesh.triangleCount();
  TERRATILES_ASSERT(face_count < static_cast<std::size_t>(INT32_MAX / 3));
  // offsets and neighbours serve as the lists' scratch before they are filled.
  if (!linkedAcross(mesh, graph.across, graph.offsets, graph.neighbours)) {
    graph = sortedFaceGraph(mesh);  // throws, naming the fault
  }
  // CSR in side order: per block, the neighbours counted, then offsets by a prefix over
  // faces, then filled.
  detail::resizeOnHugePages(graph.offsets, face_count + 1);
  graph.offsets[0] = 0;
  const std::size_t blocks = (face_count + kFaceBlock - 1) / kFaceBlock;
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t block) {
    const std::size_t end = std::min(face_count, (block + 1) * kFaceBlock);
    for (std::size_t t = block * kFaceBlock; t < end; ++t) {
      std::int32_t n = 0;
      for (std::size_t k = 0; k < 3; ++k) n += graph.across[3 * t + k] != kNoFace;
      graph.offsets[t + 1] = n;
    }
  });
  for (std::size_t t = 0; t < face_count; ++t) graph.offsets[t + 1] += graph.offsets[t];
  graph.offsets.resize(face_count + 1);
  detail::resizeOnHugePages(graph.neighbours, static_cast<std::size_t>(graph.offsets[face_count]));
  graph.neighbours.resize(static_cast<std::size_t>(graph.offsets[face_count]));
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t block) {
    const std::size_t end = std::min(face_count, (block + 1) * kFaceBlock);
    for (std::size_t t = block * kFaceBlock; t < end; ++t) {
      auto out = static_cast<std::size_t>(graph.offsets[t]);
      for (std::size_t k = 0; k < 3; ++k) {
        if (graph.across[3 * t + k] != kNoFace) graph.neighbours[out++] = graph.across[3 * t + k];
      }
    }
  });
}

std::int32_t faceComponents(const FaceGraph& graph, std::vector<std::int32_t>& component_of_face) {
  const std::size_t face_count = graph.faceCount();
  detail::assignOnHugePages(component_of_face, face_count, -1);
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
