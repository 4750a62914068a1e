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

// The faces of one piece as a graph of its own (local ids: positions in `faces`).
void pieceGraph(const FaceGraph& graph, std::span<const std::int32_t> faces, const std::vector<std::int32_t>& piece_of_face,
                const std::vector<std::int32_t>& local_of_face, detail::PieceGraph& piece) {
  const auto piece_id = piece_of_face[static_cast<std::size_t>(faces.front())];
  piece.xadj.resize(faces.size() + 1);
  piece.xadj[0] = 0;
  piece.adjncy.clear();
  piece.adjncy.reserve(3 * faces.size());
  for (std::size_t i = 0; i < faces.size(); ++i) {
    const auto t = static_cast<std::size_t>(faces[i]);
    for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
      const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
      if (piece_of_face[other] == piece_id) piece.adjncy.push_back(local_of_face[other]);  // not across pieces
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

// Pieces: faces joined through shared edges (and, with regions, of one region), numbered in
// order of their lowest face. Returns the piece count.
std::int32_t connectedPieces(const FaceGraph& graph, std::span<const std::int32_t> region_of_face,
                             std::vector<std::int32_t>& piece_of_face) {
  const std::size_t face_count = graph.faceCount();
  detail::assignOnHugePages(piece_of_face, face_count, -1);
  std::int32_t pieces = 0;
  std::vector<std::int32_t> stack;
  for (std::size_t start = 0; start < face_count; ++start) {
    if (piece_of_face[start] >= 0) continue;
    piece_of_face[start] = pieces;
    stack.push_back(static_cast<std::int32_t>(start));
    while (!stack.empty()) {
      const auto t = static_cast<std::size_t>(stack.back());
      stack.pop_back();
      for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
        const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
        if (piece_of_face[other] < 0 && (region_of_face.empty() || region_of_face[other] == region_of_face[t])) {
          piece_of_face[other] = pieces;
          stack.push_back(static_cast<std::int32_t>(other));
        }
      }
    }
    ++pieces;
  }
  return pieces;
}

// Faces grouped by piece (each group in face order) as CSR, and each face's position in its
// group.
void facesByPiece(const std::vector<std::int32_t>& piece_of_face, std::int32_t pieces, std::vector<std::int32_t>& first,
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

// Joins every piece smaller than min_faces to the neighbouring piece it shares the most edges
// with (lowest piece on ties), then renumbers the pieces in order of their lowest face.
std::int32_t joinSmallPieces(const FaceGraph& graph, std::size_t min_faces, std::int32_t pieces,
                             std::vector<std::int32_t>& piece_of_face) {
  std::vector<std::int32_t> size(static_cast<std::size_t>(pieces), 0);
  for (const std::int32_t p : piece_of_face) ++size[static_cast<std::size_t>(p)];
  // The faces of the small pieces only, grouped by piece.
  std::vector<std::int32_t> small_first(static_cast<std::size_t>(pieces) + 1, 0);
  for (std::size_t p = 0; p < size.size(); ++p) {
    small_first[p + 1] = small_first[p] + (static_cast<std::size_t>(size[p]) < min_faces ? size[p] : 0);
  }
  if (small_first.back() == 0) return pieces;
  std::vector<std::int32_t> small_faces(static_cast<std::size_t>(small_first.back()));
  {
    std::vector<std::int32_t> fill(small_first.begin(), small_first.end() - 1);
    for (std::size_t t = 0; t < piece_of_face.size(); ++t) {
      const auto p = static_cast<std::size_t>(piece_of_face[t]);
      if (static_cast<std::size_t>(size[p]) < min_faces) small_faces[static_cast<std::size_t>(fill[p]++)] = static_cast<std::int32_t>(t);
    }
  }
  std::vector<std::int32_t> parent(static_cast<std::size_t>(pieces));
  std::iota(parent.begin(), parent.end(), 0);
  const auto root = [&](std::int32_t p) {
    while (parent[static_cast<std::size_t>(p)] != p) {
      p = parent[static_cast<std::size_t>(p)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(p)])];
    }
    return p;
  };
  std::vector<std::int32_t> shared(static_cast<std::size_t>(pieces), 0), touched;
  bool joined = false;
  for (std::int32_t p = 0; p < pieces; ++p) {
    const auto begin = static_cast<std::size_t>(small_first[static_cast<std::size_t>(p)]);
    const auto end = static_cast<std::size_t>(small_first[static_cast<std::size_t>(p) + 1]);
    if (begin == end) continue;
    for (std::size_t i = begin; i < end; ++i) {
      const auto t = static_cast<std::size_t>(small_faces[i]);
      for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
        const std::int32_t q = piece_of_face[static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)])];
        if (q == p) continue;
        if (shared[static_cast<std::size_t>(q)]++ == 0) touched.push_back(q);
      }
    }
    std::int32_t best = -1;
    for (const std::int32_t q : touched) {
      if (best < 0 || shared[static_cast<std::size_t>(q)] > shared[static_cast<std::size_t>(best)] ||
          (shared[static_cast<std::size_t>(q)] == shared[static_cast<std::size_t>(best)] && q < best)) {
        best = q;
      }
    }
    for (const std::int32_t q : touched) shared[static_cast<std::size_t>(q)] = 0;
    touched.clear();
    if (best < 0) continue;  // a component of its own
    const std::int32_t a = root(p), b = root(best);
    if (a != b) parent[static_cast<std::size_t>(std::max(a, b))] = std::min(a, b);
    joined = true;
  }
  if (!joined) return pieces;
  std::vector<std::int32_t> renumbered(static_cast<std::size_t>(pieces), -1);
  std::int32_t count = 0;
  for (std::int32_t& p : piece_of_face) {
    std::int32_t& id = renumbered[static_cast<std::size_t>(root(p))];
    if (id < 0) id = count++;
    p = id;
  }
  return count;
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

FacePartition partitionFaces(const FaceGraph& graph, const PartitionOptions& options,
                             std::span<const std::int32_t> region_of_face) {
  if (options.clusters < 1) {
    throw Error(ErrorCode::Usage, "the number of clusters is " + std::to_string(options.clusters) +
                                      "; expected at least 1");
  }
  const std::size_t face_count = graph.faceCount();
  const bool regional = !region_of_face.empty();
  if (regional) {
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
  FacePartition result;
  if (face_count == 0) return result;
  std::vector<std::int32_t> piece_of_face;
  std::int32_t pieces = connectedPieces(graph, region_of_face, piece_of_face);
  if (regional) {
    const double faces_per_cluster = static_cast<double>(face_count) / static_cast<double>(options.clusters);
    pieces = joinSmallPieces(graph, static_cast<std::size_t>(std::ceil(faces_per_cluster / 2)), pieces, piece_of_face);
  }
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
  if (options.method == Partitioner::Random) {
    std::mt19937 random(options.seed);  // one generator, pieces in order
    detail::PieceGraph piece;
    std::vector<std::int32_t> part;
    for (std::size_t p = 0; p < parts_of.size(); ++p) {
      if (parts_of[p] == 1) continue;
      pieceGraph(graph, facesOf(p), piece_of_face, local_of_face, piece);
      randomParts(piece, parts_of[p], random, part);
      scatter(p, part);
    }
  } else {
    // Largest pieces first, so the last tasks are short.
    std::vector<std::int32_t> order;
    for (std::size_t p = 0; p < parts_of.size(); ++p) {
      if (parts_of[p] > 1) order.push_back(static_cast<std::int32_t>(p));
    }
    std::stable_sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) {
      return facesOf(static_cast<std::size_t>(a)).size() > facesOf(static_cast<std::size_t>(b)).size();
    });
    struct Work {
      detail::PieceGraph piece;
      std::vector<std::int32_t> part;
      detail::MultilevelScratch scratch;
    };
    tbb::enumerable_thread_specific<Work> work;
    const auto partitionPiece = [&](std::size_t i) {
      const auto p = static_cast<std::size_t>(order[i]);
      Work& mine = work.local();
      pieceGraph(graph, facesOf(p), piece_of_face, local_of_face, mine.piece);
      if (regional) {
        detail::multilevelParts(mine.piece, parts_of[p], options.seed, mine.part, mine.scratch);
      } else {
        metisKway(mine.piece, parts_of[p], options.seed, mine.part);
      }
      scatter(p, mine.part);
    };
    if (order.size() > 1 && detail::metisRandomIsPerThread()) {
      tbb::parallel_for(std::size_t{0}, order.size(), partitionPiece, tbb::simple_partitioner());
    } else {
      for (std::size_t i = 0; i < order.size(); ++i) partitionPiece(i);
    }
  }

  // Dense ids: piece by piece, in order of first appearance within the piece; a part left
  // empty gets none.
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

}  // namespace terratiles
