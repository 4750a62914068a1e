#include "src/partition/partition_faces.h"

#include <metis.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <random>
#include <string>

#include "src/base/error.h"

namespace terratiles {
namespace {

static_assert(sizeof(idx_t) == sizeof(std::int32_t) || sizeof(idx_t) == sizeof(std::int64_t));

// A component's faces as a graph of its own (local ids), the shape METIS takes.
struct LocalGraph {
  std::vector<std::int32_t> faces;  // local -> global face
  std::vector<idx_t> xadj, adjncy;
};

LocalGraph localGraph(const FaceGraph& graph, const std::vector<std::int32_t>& faces,
                      std::vector<std::int32_t>& local_of_face) {
  LocalGraph local;
  local.faces = faces;
  for (std::size_t i = 0; i < faces.size(); ++i) local_of_face[static_cast<std::size_t>(faces[i])] = static_cast<std::int32_t>(i);
  local.xadj.reserve(faces.size() + 1);
  local.xadj.push_back(0);
  for (const std::int32_t face : faces) {
    const auto t = static_cast<std::size_t>(face);
    for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
      local.adjncy.push_back(local_of_face[static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)])]);
    }
    local.xadj.push_back(static_cast<idx_t>(local.adjncy.size()));
  }
  return local;
}

void metisParts(LocalGraph& local, std::int32_t parts, std::uint32_t seed, std::vector<std::int32_t>& part_of_local) {
  idx_t vertices = static_cast<idx_t>(local.faces.size());
  idx_t constraints = 1, nparts = parts, objective = 0;
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_OBJTYPE] = METIS_OBJTYPE_CUT;
  options[METIS_OPTION_CONTIG] = 1;
  options[METIS_OPTION_NUMBERING] = 0;
  options[METIS_OPTION_SEED] = static_cast<idx_t>(seed);
  std::vector<idx_t> part(local.faces.size(), 0);
  const int status = METIS_PartGraphKway(&vertices, &constraints, local.xadj.data(), local.adjncy.data(),
                                         nullptr, nullptr, nullptr, &nparts, nullptr, nullptr, options,
                                         &objective, part.data());
  if (status != METIS_OK) {
    throw Error(ErrorCode::Internal, "METIS_PartGraphKway failed with status " + std::to_string(status) +
                                         " on " + std::to_string(vertices) + " faces into " +
                                         std::to_string(parts) + " parts");
  }
  part_of_local.assign(part.begin(), part.end());
}

// Random contiguous growth (paper fig 40's control): `parts` distinct random seed faces, then
// repeatedly a random cluster that can still grow takes the oldest face of its frontier.
void randomParts(const FaceGraph& graph, const LocalGraph& local, std::int32_t parts, std::mt19937& random,
                 const std::vector<std::int32_t>& local_of_face, std::vector<std::int32_t>& part_of_local) {
  const std::size_t n = local.faces.size();
  part_of_local.assign(n, -1);
  std::vector<std::int32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::int32_t>(i);
  for (std::size_t i = 0; i < static_cast<std::size_t>(parts); ++i) {  // partial Fisher-Yates
    std::uniform_int_distribution<std::size_t> pick(i, n - 1);
    std::swap(order[i], order[pick(random)]);
  }
  std::vector<std::deque<std::int32_t>> frontier(static_cast<std::size_t>(parts));
  for (std::int32_t p = 0; p < parts; ++p) {
    part_of_local[static_cast<std::size_t>(order[static_cast<std::size_t>(p)])] = p;
    frontier[static_cast<std::size_t>(p)].push_back(order[static_cast<std::size_t>(p)]);
  }
  std::vector<std::int32_t> growing(static_cast<std::size_t>(parts));
  for (std::int32_t p = 0; p < parts; ++p) growing[static_cast<std::size_t>(p)] = p;
  while (!growing.empty()) {
    std::uniform_int_distribution<std::size_t> pick(0, growing.size() - 1);
    const std::size_t g = pick(random);
    const std::int32_t p = growing[g];
    auto& queue = frontier[static_cast<std::size_t>(p)];
    bool grew = false;
    while (!queue.empty() && !grew) {
      const std::int32_t local_face = queue.front();
      const auto t = static_cast<std::size_t>(local.faces[static_cast<std::size_t>(local_face)]);
      for (std::int32_t k = graph.offsets[t]; k < graph.offsets[t + 1]; ++k) {
        const std::int32_t other = local_of_face[static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(k)])];
        if (part_of_local[static_cast<std::size_t>(other)] < 0) {
          part_of_local[static_cast<std::size_t>(other)] = p;
          queue.push_back(other);
          grew = true;
          break;
        }
      }
      if (!grew) queue.pop_front();  // no free neighbour left: this face is interior
    }
    if (!grew) {
      growing[g] = growing.back();
      growing.pop_back();
    }
  }
}

}  // namespace

FacePartition partitionFaces(const FaceGraph& graph, const PartitionOptions& options) {
  if (options.clusters < 1) {
    throw Error(ErrorCode::Usage, "the number of clusters is " + std::to_string(options.clusters) +
                                      "; expected at least 1");
  }
  const std::size_t face_count = graph.faceCount();
  FacePartition result;
  result.cluster_of_face.assign(face_count, -1);
  if (face_count == 0) return result;
  std::vector<std::int32_t> component_of_face;
  const std::int32_t components = faceComponents(graph, component_of_face);
  std::vector<std::vector<std::int32_t>> faces_of(static_cast<std::size_t>(components));
  for (std::size_t t = 0; t < face_count; ++t) {
    faces_of[static_cast<std::size_t>(component_of_face[t])].push_back(static_cast<std::int32_t>(t));
  }
  std::mt19937 random(options.seed);
  std::vector<std::int32_t> local_of_face(face_count, -1), part_of_local;
  std::int32_t next_id = 0;
  for (const std::vector<std::int32_t>& faces : faces_of) {
    const double share = static_cast<double>(options.clusters) * static_cast<double>(faces.size()) /
                         static_cast<double>(face_count);
    const auto parts = static_cast<std::int32_t>(std::clamp<double>(std::round(share), 1.0, static_cast<double>(faces.size())));
    LocalGraph local = localGraph(graph, faces, local_of_face);
    if (parts == 1) {
      part_of_local.assign(faces.size(), 0);
    } else if (options.method == Partitioner::Metis) {
      metisParts(local, parts, options.seed, part_of_local);
    } else {
      randomParts(graph, local, parts, random, local_of_face, part_of_local);
    }
    // Dense ids in order of first appearance within the component, so ids never skip.
    std::vector<std::int32_t> id_of_part(static_cast<std::size_t>(parts), -1);
    for (std::size_t i = 0; i < faces.size(); ++i) {
      std::int32_t& id = id_of_part[static_cast<std::size_t>(part_of_local[i])];
      if (id < 0) id = next_id++;
      result.cluster_of_face[static_cast<std::size_t>(faces[i])] = id;
    }
  }
  result.cluster_count = next_id;
  return result;
}

std::size_t edgeCut(const FaceGraph& graph, const std::vector<std::int32_t>& cluster_of_face) {
  std::size_t cut = 0;
  for (std::size_t t = 0; t < graph.faceCount(); ++t) {
    for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
      const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
      if (other > t && cluster_of_face[other] != cluster_of_face[t]) ++cut;
    }
  }
  return cut;
}

}  // namespace terratiles
