#include "src/partition/partition_faces.h"

#include <metis.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <deque>
#include <numeric>
#include <random>
#include <string>

#include "src/base/error.h"
#include "src/partition/huge_pages.h"
#include "src/partition/multilevel_parts.h"

// METIS 5.1 (Debian's libmetis5) draws its random numbers from libc's rand() and reseeds it
// with srand(options[METIS_OPTION_SEED]) at the start of every call. glibc keeps one generator
// for the process, so two METIS calls on two threads interleave their draws and their results
// depend on the timing (measured: two threads partitioning the same grid graph disagree on
// most runs). These definitions replace rand and srand for the whole process (the executable's
// symbols come first in the dynamic linker's lookup, so libmetis binds to them) with one
// generator per thread, each glibc's own algorithm (random_r: TYPE_3, 128 bytes of state,
// seed 1 until srand), so a single thread sees exactly the sequence glibc gives and METIS's
// results do not change. No other code of ours calls rand. detail::metisRandomIsPerThread
// checks that libmetis took them.
namespace {
struct ThreadRandom {
  random_data data{};
  char state[128]{};
  std::uint64_t draws = 0;  // calls of rand on this thread
  ThreadRandom() { initstate_r(1, state, sizeof state, &data); }
};
ThreadRandom& threadRandom() {
  thread_local ThreadRandom random;
  return random;
}
}  // namespace

extern "C" int rand() noexcept {
  ThreadRandom& random = threadRandom();
  ++random.draws;
  std::int32_t value = 0;
  random_r(&random.data, &value);
  return value;
}

extern "C" void srand(unsigned int seed) noexcept { srandom_r(seed, &threadRandom().data); }

namespace terratiles {
namespace {

static_assert(sizeof(idx_t) == sizeof(std::int32_t), "METIS built with 32-bit idx_t expected");

// The faces of one group (a component or a region: every face with the label of `faces`) as a
// graph of its own, local ids being positions in `faces`; edges to other groups are left out.
void pieceGraph(const FaceGraph& graph, std::span<const std::int32_t> faces, std::span<const std::int32_t> label_of_face,
                std::span<const std::int32_t> local_of_face, detail::PieceGraph& piece) {
  const std::int32_t label = label_of_face[static_cast<std::size_t>(faces.front())];
  piece.xadj.resize(faces.size() + 1);
  piece.xadj[0] = 0;
  piece.adjncy.clear();
  piece.adjncy.reserve(3 * faces.size());
  for (std::size_t i = 0; i < faces.size(); ++i) {
    const auto t = static_cast<std::size_t>(faces[i]);
    for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
      const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
      if (label_of_face[other] == label) piece.adjncy.push_back(local_of_face[other]);
    }
    piece.xadj[i + 1] = static_cast<std::int32_t>(piece.adjncy.size());
  }
}

// METIS k-way on the whole piece (the global partition: one call per component).
void metisKway(detail::PieceGraph& piece, std::int32_t parts, std::uint32_t seed, std::vector<std::int32_t>& part) {
  idx_t vertices = static_cast<idx_t>(piece.size());
  idx_t constraints = 1, nparts = parts, objective = 0;
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_OBJTYPE] = METIS_OBJTYPE_CUT;
  options[METIS_OPTION_CONTIG] = 1;
  options[METIS_OPTION_NUMBERING] = 0;
  options[METIS_OPTION_SEED] = static_cast<idx_t>(seed);
  part.assign(piece.size(), 0);
  const int status = METIS_PartGraphKway(&vertices, &constraints, piece.xadj.data(), piece.adjncy.data(), nullptr, nullptr,
                                         nullptr, &nparts, nullptr, nullptr, options, &objective, part.data());
  if (status != METIS_OK) {
    throw Error(ErrorCode::Internal, "METIS_PartGraphKway failed with status " + std::to_string(status) + " on " +
                                         std::to_string(vertices) + " faces into " + std::to_string(parts) + " parts");
  }
}

// Random contiguous growth (paper fig 40's control): `parts` distinct random seed faces, then
// repeatedly a random cluster that can still grow takes the oldest face of its frontier.
void randomParts(const detail::PieceGraph& piece, std::int32_t parts, std::mt19937& random, std::vector<std::int32_t>& part) {
  const std::size_t n = piece.size();
  part.assign(n, -1);
  std::vector<std::int32_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  for (std::size_t i = 0; i < static_cast<std::size_t>(parts); ++i) {  // partial Fisher-Yates
    std::uniform_int_distribution<std::size_t> pick(i, n - 1);
    std::swap(order[i], order[pick(random)]);
  }
  std::vector<std::deque<std::int32_t>> frontier(static_cast<std::size_t>(parts));
  for (std::int32_t p = 0; p < parts; ++p) {
    part[static_cast<std::size_t>(order[static_cast<std::size_t>(p)])] = p;
    frontier[static_cast<std::size_t>(p)].push_back(order[static_cast<std::size_t>(p)]);
  }
  std::vector<std::int32_t> growing(static_cast<std::size_t>(parts));
  std::iota(growing.begin(), growing.end(), 0);
  while (!growing.empty()) {
    std::uniform_int_distribution<std::size_t> pick(0, growing.size() - 1);
    const std::size_t g = pick(random);
    const std::int32_t p = growing[g];
    auto& queue = frontier[static_cast<std::size_t>(p)];
    bool grew = false;
    while (!queue.empty() && !grew) {
      const auto u = static_cast<std::size_t>(queue.front());
      for (std::int32_t k = piece.xadj[u]; k < piece.xadj[u + 1]; ++k) {
        const std::int32_t other = piece.adjncy[static_cast<std::size_t>(k)];
        if (part[static_cast<std::size_t>(other)] < 0) {
          part[static_cast<std::size_t>(other)] = p;
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

// Faces grouped by piece (each group in face order) as CSR, and each face's position in its
// group.
void facesByPiece(std::span<const std::int32_t> piece_of_face, std::int32_t pieces, std::vector<std::int32_t>& first,
                  std::vector<std::int32_t>& faces, std::vector<std::int32_t>& local_of_face) {
  first.assign(static_cast<std::size_t>(pieces) + 1, 0);
  for (const std::int32_t p : piece_of_face) ++first[static_cast<std::size_t>(p) + 1];
  for (std::size_t p = 0; p < static_cast<std::size_t>(pieces); ++p) first[p + 1] += first[p];
  detail::resizeOnHugePages(faces, piece_of_face.size());
  detail::resizeOnHugePages(local_of_face, piece_of_face.size());
  std::vector<std::int32_t> fill(first.begin(), first.end() - 1);
  for (std::size_t t = 0; t < piece_of_face.size(); ++t) {
    const auto p = static_cast<std::size_t>(piece_of_face[t]);
    local_of_face[t] = fill[p] - first[p];
    faces[static_cast<std::size_t>(fill[p]++)] = static_cast<std::int32_t>(t);
  }
}

}  // namespace

namespace detail {

bool metisRandomIsPerThread() {
  static const bool per_thread = [] {
    // A 4 x 4 grid graph into two parts: METIS draws random numbers for its initial
    // bisection, so this thread's count moves when libmetis calls our rand.
    PieceGraph grid;
    for (std::int32_t y = 0; y < 4; ++y) {
      for (std::int32_t x = 0; x < 4; ++x) {
        if (x > 0) grid.adjncy.push_back(4 * y + x - 1);
        if (x < 3) grid.adjncy.push_back(4 * y + x + 1);
        if (y > 0) grid.adjncy.push_back(4 * (y - 1) + x);
        if (y < 3) grid.adjncy.push_back(4 * (y + 1) + x);
        grid.xadj.push_back(static_cast<std::int32_t>(grid.adjncy.size()));
      }
    }
    std::vector<std::int32_t> parts;
    const std::uint64_t before = threadRandom().draws;
    metisKway(grid, 2, 1, parts);
    return threadRandom().draws > before;
  }();
  return per_thread;
}

}  // namespace detail

namespace {

// partitionFaces over whole components (no regions): one METIS k-way (or random) call per
// connected component, ids component by component.
FacePartition globalPartition(const FaceGraph& graph, const PartitionOptions& options) {
  const std::size_t face_count = graph.faceCount();
  FacePartition result;
  std::vector<std::int32_t> piece_of_face;
  const std::int32_t pieces = faceComponents(graph, piece_of_face);
  std::vector<std::int32_t> first, faces, local_of_face;
  facesByPiece(piece_of_face, pieces, first, faces, local_of_face);
  const auto facesOf = [&](std::size_t p) {
    return std::span<const std::int32_t>(faces).subspan(static_cast<std::size_t>(first[p]),
                                                        static_cast<std::size_t>(first[p + 1] - first[p]));
  };
  std::vector<std::int32_t> parts_of(static_cast<std::size_t>(pieces));
  for (std::size_t p = 0; p < parts_of.size(); ++p) {
    const double share = static_cast<double>(options.clusters) * static_cast<double>(facesOf(p).size()) /
                         static_cast<double>(face_count);
    parts_of[p] = static_cast<std::int32_t>(std::clamp<double>(std::round(share), 1.0, static_cast<double>(facesOf(p).size())));
  }
  // Every face's part within its piece goes into result.cluster_of_face, then is renumbered.
  detail::assignOnHugePages(result.cluster_of_face, face_count, 0);
  const auto scatter = [&](std::size_t p, const std::vector<std::int32_t>& part) {
    const auto piece_faces = facesOf(p);
    for (std::size_t i = 0; i < piece_faces.size(); ++i) result.cluster_of_face[static_cast<std::size_t>(piece_faces[i])] = part[i];
  };
  std::mt19937 random(options.seed);  // one generator, pieces in order
  detail::PieceGraph piece;
  std::vector<std::int32_t> part;
  for (std::size_t p = 0; p < parts_of.size(); ++p) {
    if (parts_of[p] == 1) continue;
    pieceGraph(graph, facesOf(p), piece_of_face, local_of_face, piece);
    if (options.method == Partitioner::Random) {
      randomParts(piece, parts_of[p], random, part);
    } else {
      metisKway(piece, parts_of[p], options.seed, part);
    }
    scatter(p, part);
  }
  // Dense ids: piece by piece, in order of first appearance within the piece.
  std::int32_t next_id = 0;
  std::vector<std::int32_t> id_of_part;
  for (std::size_t p = 0; p < parts_of.size(); ++p) {
    id_of_part.assign(static_cast<std::size_t>(parts_of[p]), -1);
    for (const std::int32_t t : facesOf(p)) {
      std::int32_t& cluster = result.cluster_of_face[static_cast<std::size_t>(t)];
      std::int32_t& id = id_of_part[static_cast<std::size_t>(cluster)];
      if (id < 0) id = next_id++;
      cluster = id;
    }
  }
  result.cluster_count = next_id;
  return result;
}

// partitionFaces by regions. Each region (in parallel for METIS) becomes a graph of its own
// and splits into its connected parts; a part of at least min_faces faces is partitioned on
// its own, a smaller one (a fragment) is attached afterwards, whole, to the neighbouring
// cluster it shares the most edges with. Clusters are numbered at the end in order of their
// first face.
FacePartition regionalPartition(const FaceGraph& graph, const PartitionOptions& options,
                                std::span<const std::int32_t> region_of_face) {
  const std::size_t face_count = graph.faceCount();
  // Region ids as given when they are small enough to count (empty regions cost nothing),
  // otherwise ranked.
  std::span<const std::int32_t> region = region_of_face;
  std::vector<std::int32_t> ranked;
  std::int32_t highest = *std::max_element(region.begin(), region.end());
  if (static_cast<std::size_t>(highest) > 4 * face_count + 64) {
    std::vector<std::int32_t> sorted(region.begin(), region.end());
    std::sort(sorted.begin(), sorted.end());
    sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
    ranked.resize(face_count);
    for (std::size_t t = 0; t < face_count; ++t) {
      ranked[t] = static_cast<std::int32_t>(std::lower_bound(sorted.begin(), sorted.end(), region[t]) - sorted.begin());
    }
    region = ranked;
    highest = static_cast<std::int32_t>(sorted.size()) - 1;
  }
  const auto regions = static_cast<std::size_t>(highest) + 1;
  // The faces of every region in face order, and each face's position in its region.
  std::vector<std::int32_t> region_first, region_faces, local_of_face;
  facesByPiece(region, static_cast<std::int32_t>(regions), region_first, region_faces, local_of_face);
  const double faces_per_cluster = static_cast<double>(face_count) / static_cast<double>(options.clusters);
  const auto min_faces = static_cast<std::size_t>(std::ceil(faces_per_cluster / 2));

  // Per face: its cluster within its piece (made global below), or -1 in a fragment; the
  // fragment's number in fragment_of_face (written for fragment faces only).
  std::vector<std::int32_t> part_of_face, fragment_of_face;
  detail::resizeOnHugePages(part_of_face, face_count);
  detail::resizeOnHugePages(fragment_of_face, face_count);
  struct RegionResult {
    std::vector<std::int32_t> parts;  // per piece of at least min_faces faces: its parts
    std::vector<std::int32_t> fragment_faces, fragment_first{0};  // the fragments' faces
  };
  std::vector<RegionResult> results(regions);
  struct Work {
    detail::PieceGraph graph, piece;  // the region's graph; a piece of it when it has several
    std::vector<std::int32_t> component, piece_of_local, stack, part;
    detail::MultilevelScratch scratch;
  };
  std::mt19937 random(options.seed);  // the random partitioner: one generator, regions in order
  const auto splitRegion = [&](std::size_t r, Work& work) {
    const std::span<const std::int32_t> faces(region_faces.data() + region_first[r],
                                              static_cast<std::size_t>(region_first[r + 1] - region_first[r]));
    if (faces.empty()) return;
    // The region as a graph of its own (local ids: positions in `faces`).
    detail::PieceGraph& local = work.graph;
    pieceGraph(graph, faces, region, local_of_face, local);
    // Its connected pieces, numbered in order of their lowest face.
    std::vector<std::int32_t>& component = work.component;
    component.assign(faces.size(), -1);
    std::int32_t pieces = 0;
    for (std::size_t start = 0; start < faces.size(); ++start) {
      if (component[start] >= 0) continue;
      component[start] = pieces;
      work.stack.assign(1, static_cast<std::int32_t>(start));
      while (!work.stack.empty()) {
        const auto u = static_cast<std::size_t>(work.stack.back());
        work.stack.pop_back();
        for (std::int32_t e = local.xadj[u]; e < local.xadj[u + 1]; ++e) {
          const auto v = static_cast<std::size_t>(local.adjncy[static_cast<std::size_t>(e)]);
          if (component[v] < 0) {
            component[v] = pieces;
            work.stack.push_back(static_cast<std::int32_t>(v));
          }
        }
      }
      ++pieces;
    }
    std::vector<std::int32_t> piece_size(static_cast<std::size_t>(pieces), 0);
    for (const std::int32_t c : component) ++piece_size[static_cast<std::size_t>(c)];
    RegionResult& out = results[r];
    out.parts.clear();
    for (std::int32_t p = 0; p < pieces; ++p) {
      const auto size = static_cast<std::size_t>(piece_size[static_cast<std::size_t>(p)]);
      const bool fragment = size < min_faces;
      // The piece's graph: the region's own when it is the only piece, else its faces'
      // edges renumbered.
      const detail::PieceGraph* piece = &local;
      std::vector<std::int32_t>& members = work.piece_of_local;  // piece -> region local ids
      if (pieces > 1) {
        members.clear();
        for (std::size_t u = 0; u < faces.size(); ++u) {
          if (component[u] == p) members.push_back(static_cast<std::int32_t>(u));
        }
      }
      if (fragment) {
        const auto id = static_cast<std::int32_t>(out.fragment_first.size() - 1);
        for (std::size_t i = 0; i < size; ++i) {
          const auto t = static_cast<std::size_t>(faces[static_cast<std::size_t>(pieces > 1 ? members[i] : static_cast<std::int32_t>(i))]);
          part_of_face[t] = -1;
          fragment_of_face[t] = id;
          out.fragment_faces.push_back(static_cast<std::int32_t>(t));
        }
        out.fragment_first.push_back(static_cast<std::int32_t>(out.fragment_faces.size()));
        continue;
      }
      const double share = static_cast<double>(options.clusters) * static_cast<double>(size) / static_cast<double>(face_count);
      const auto parts = static_cast<std::int32_t>(std::clamp<double>(std::round(share), 1.0, static_cast<double>(size)));
      out.parts.push_back(parts);
      if (pieces > 1 && parts > 1) {
        // Renumber the piece's edges (work.stack: region local id -> piece id).
        std::vector<std::int32_t>& piece_id = work.stack;
        piece_id.assign(faces.size(), -1);
        for (std::size_t i = 0; i < members.size(); ++i) piece_id[static_cast<std::size_t>(members[i])] = static_cast<std::int32_t>(i);
        work.piece.xadj.assign(1, 0);
        work.piece.adjncy.clear();
        for (const std::int32_t u : members) {
          for (std::int32_t e = local.xadj[static_cast<std::size_t>(u)]; e < local.xadj[static_cast<std::size_t>(u) + 1]; ++e) {
            work.piece.adjncy.push_back(piece_id[static_cast<std::size_t>(local.adjncy[static_cast<std::size_t>(e)])]);
          }
          work.piece.xadj.push_back(static_cast<std::int32_t>(work.piece.adjncy.size()));
        }
        piece = &work.piece;
      }
      if (parts == 1) {
        work.part.assign(size, 0);
      } else if (options.method == Partitioner::Random) {
        randomParts(*piece, parts, random, work.part);
      } else {
        detail::multilevelParts(*piece, parts, options.seed, work.part, work.scratch);
      }
      // Parts are numbered within the region for now: this piece's after the pieces before.
      const std::int32_t before = std::accumulate(out.parts.begin(), out.parts.end() - 1, 0);
      for (std::size_t i = 0; i < size; ++i) {
        const std::size_t u = pieces > 1 ? static_cast<std::size_t>(members[i]) : i;
        part_of_face[static_cast<std::size_t>(faces[u])] = before + work.part[i];
      }
    }
  };
  if (options.method == Partitioner::Metis && regions > 1 && detail::metisRandomIsPerThread()) {
    // Largest regions first, so the last tasks are short.
    std::vector<std::int32_t> order(regions);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) {
      return region_first[static_cast<std::size_t>(a) + 1] - region_first[static_cast<std::size_t>(a)] >
             region_first[static_cast<std::size_t>(b) + 1] - region_first[static_cast<std::size_t>(b)];
    });
    tbb::enumerable_thread_specific<Work> work;
    tbb::parallel_for(std::size_t{0}, regions, [&](std::size_t i) { splitRegion(static_cast<std::size_t>(order[i]), work.local()); },
                      tbb::simple_partitioner());
  } else {
    Work work;
    for (std::size_t r = 0; r < regions; ++r) splitRegion(r, work);
  }

  // Provisional cluster ids: each region's parts numbered after the regions before it.
  std::vector<std::int64_t> base(regions + 1, 0);
  for (std::size_t r = 0; r < regions; ++r) {
    base[r + 1] = base[r] + std::accumulate(results[r].parts.begin(), results[r].parts.end(), std::int64_t{0});
  }
  std::int64_t provisional = base[regions];
  TERRATILES_ASSERT(provisional + static_cast<std::int64_t>(face_count) < INT32_MAX);
  constexpr std::size_t kBlock = 16384;
  tbb::parallel_for(std::size_t{0}, (face_count + kBlock - 1) / kBlock, [&](std::size_t b) {
    for (std::size_t t = b * kBlock; t < std::min(face_count, (b + 1) * kBlock); ++t) {
      if (part_of_face[t] >= 0) part_of_face[t] += static_cast<std::int32_t>(base[static_cast<std::size_t>(region[t])]);
    }
  });
  // Fragments, regions in order: each goes whole to the neighbouring cluster it shares the most
  // edges with (lowest id on ties); one that touches only unplaced fragments waits for the next
  // round; one with no neighbour at all (a small component) is a cluster of its own.
  std::vector<std::int32_t> touched;
  for (bool left = true; left;) {
    left = false;
    bool placed = false;
    for (std::size_t r = 0; r < regions; ++r) {
      const RegionResult& result = results[r];
      for (std::size_t f = 0; f + 1 < result.fragment_first.size(); ++f) {
        const auto begin = static_cast<std::size_t>(result.fragment_first[f]);
        const auto end = static_cast<std::size_t>(result.fragment_first[f + 1]);
        if (part_of_face[static_cast<std::size_t>(result.fragment_faces[begin])] >= 0) continue;  // placed
        bool has_neighbour = false;
        touched.clear();
        for (std::size_t i = begin; i < end; ++i) {
          const auto t = static_cast<std::size_t>(result.fragment_faces[i]);
          for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
            const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
            const std::int32_t cluster = part_of_face[other];
            if (cluster < 0 && region[other] == static_cast<std::int32_t>(r) &&
                fragment_of_face[other] == static_cast<std::int32_t>(f)) {
              continue;  // the fragment itself
            }
            has_neighbour = true;
            if (cluster >= 0) touched.push_back(cluster);
          }
        }
        std::int32_t best = -1, best_count = 0;
        std::sort(touched.begin(), touched.end());
        for (std::size_t i = 0; i < touched.size();) {
          std::size_t j = i;
          while (j < touched.size() && touched[j] == touched[i]) ++j;
          if (best < 0 || static_cast<std::int32_t>(j - i) > best_count) {
            best = touched[i];
            best_count = static_cast<std::int32_t>(j - i);
          }
          i = j;
        }
        if (best < 0 && has_neighbour) {
          left = true;
          continue;
        }
        if (best < 0) best = static_cast<std::int32_t>(provisional++);
        for (std::size_t i = begin; i < end; ++i) part_of_face[static_cast<std::size_t>(result.fragment_faces[i])] = best;
        placed = true;
      }
    }
    TERRATILES_ASSERT(!left || placed);  // a connected mesh always has a fragment next to a cluster
  }
  // Dense ids in order of first face.
  FacePartition result;
  std::vector<std::int32_t> id_of(static_cast<std::size_t>(provisional), -1);
  std::int32_t next_id = 0;
  result.cluster_of_face.swap(part_of_face);
  for (std::int32_t& cluster : result.cluster_of_face) {
    std::int32_t& id = id_of[static_cast<std::size_t>(cluster)];
    if (id < 0) id = next_id++;
    cluster = id;
  }
  result.cluster_count = next_id;
  return result;
}

}  // namespace

FacePartition partitionFaces(const FaceGraph& graph, const PartitionOptions& options,
                             std::span<const std::int32_t> region_of_face) {
  if (options.clusters < 1) {
    throw Error(ErrorCode::Usage, "the number of clusters is " + std::to_string(options.clusters) +
                                      "; expected at least 1");
  }
  const std::size_t face_count = graph.faceCount();
  if (!region_of_face.empty()) {
    if (region_of_face.size() != face_count) {
      throw Error(ErrorCode::Usage, "partition regions are given for " + std::to_string(region_of_face.size()) +
                                        " faces; expected one per face (" + std::to_string(face_count) + ")");
    }
    const auto lowest = std::min_element(region_of_face.begin(), region_of_face.end());
    if (*lowest < 0) {
      throw Error(ErrorCode::Usage, "partition region of face " + std::to_string(lowest - region_of_face.begin()) +
                                        " is " + std::to_string(*lowest) + "; expected a region id >= 0");
    }
  }
  if (face_count == 0) return {};
  return region_of_face.empty() ? globalPartition(graph, options) : regionalPartition(graph, options, region_of_face);
}

bool clustersAreContiguous(const FaceGraph& graph, const FacePartition& partition) {
  const std::size_t faces = graph.faceCount();
  if (partition.cluster_of_face.size() != faces || partition.cluster_count < 0) return false;
  std::vector<std::uint8_t> seen(faces, 0), started(static_cast<std::size_t>(partition.cluster_count), 0);
  std::vector<std::size_t> stack;
  for (std::size_t start = 0; start < faces; ++start) {
    if (seen[start]) continue;
    const std::int32_t cluster = partition.cluster_of_face[start];
    if (cluster < 0 || cluster >= partition.cluster_count || started[static_cast<std::size_t>(cluster)]) return false;
    started[static_cast<std::size_t>(cluster)] = 1;
    seen[start] = 1;
    stack.assign(1, start);
    while (!stack.empty()) {
      const std::size_t t = stack.back();
      stack.pop_back();
      for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
        const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
        if (!seen[other] && partition.cluster_of_face[other] == cluster) {
          seen[other] = 1;
          stack.push_back(other);
        }
      }
    }
  }
  return std::all_of(started.begin(), started.end(), [](std::uint8_t s) { return s != 0; });
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

std::vector<std::int32_t> gridCellRegions(const TinMesh& mesh, double cell_px, std::array<double, 2> origin_px) {
  if (!(cell_px > 0) || !std::isfinite(cell_px)) {
    throw Error(ErrorCode::Usage, "partition cells are " + std::to_string(cell_px) + " px wide; expected a width > 0");
  }
  const std::size_t face_count = mesh.triangleCount();
  const auto& idx = mesh.triangle_indices;
  // (row, column) of the cell holding each face's centroid, packed so they sort as pairs.
  const auto cellOf = [&](std::size_t t) {
    const GridPoint &a = mesh.vertices[idx[3 * t]], &b = mesh.vertices[idx[3 * t + 1]], &c = mesh.vertices[idx[3 * t + 2]];
    const auto column = static_cast<std::int64_t>(std::floor(((a.col + b.col + c.col) / 3 - origin_px[0]) / cell_px));
    const auto row = static_cast<std::int64_t>(std::floor(((a.row + b.row + c.row) / 3 - origin_px[1]) / cell_px));
    return static_cast<std::uint64_t>(row + (std::int64_t{1} << 31)) << 32 | static_cast<std::uint64_t>(column + (std::int64_t{1} << 31));
  };
  std::vector<std::uint64_t> cells;
  std::uint64_t last = 0;
  for (std::size_t t = 0; t < face_count; ++t) {
    const std::uint64_t cell = cellOf(t);
    if (t > 0 && cell == last) continue;
    last = cell;
    const auto at = std::lower_bound(cells.begin(), cells.end(), cell);
    if (at == cells.end() || *at != cell) cells.insert(at, cell);
  }
  std::vector<std::int32_t> region(face_count);
  for (std::size_t t = 0; t < face_count; ++t) {
    region[t] = static_cast<std::int32_t>(std::lower_bound(cells.begin(), cells.end(), cellOf(t)) - cells.begin());
  }
  return region;
}

std::vector<std::int32_t> clusterCellRegions(const TinMesh& mesh, std::int32_t clusters, std::int32_t region_clusters,
                                             bool offset) {
  if (region_clusters <= 0 || clusters <= region_clusters || mesh.vertices.empty()) return {};
  double min_col = 1e300, min_row = 1e300, max_col = -1e300, max_row = -1e300;
  for (const GridPoint& v : mesh.vertices) {
    min_col = std::min(min_col, v.col);
    max_col = std::max(max_col, v.col);
    min_row = std::min(min_row, v.row);
    max_row = std::max(max_row, v.row);
  }
  const double area_px = std::max(1.0, (max_col - min_col) * (max_row - min_row));
  const double cell_px = std::sqrt(area_px * region_clusters / clusters);
  const double offset_px = offset ? cell_px / 2 : 0;
  return gridCellRegions(mesh, cell_px, {min_col - offset_px, min_row - offset_px});
}

}  // namespace terratiles
