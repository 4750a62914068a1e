#include "src/partition/multilevel_parts.h"

#include <metis.h>

#include <algorithm>
#include <span>
#include <string>

#include "src/base/error.h"

namespace terratiles::detail {
namespace {

static_assert(sizeof(idx_t) == sizeof(std::int32_t), "METIS built with 32-bit idx_t expected");

using Level = MultilevelScratch::Level;

// A level as coarsen and refineParts read it: the piece itself (weights 1) or a coarsened one.
struct LevelView {
  std::span<const std::int32_t> xadj, adjncy, adjwgt, vwgt;
  std::size_t size() const { return xadj.size() - 1; }
};

LevelView viewOf(const Level& level) { return {level.xadj, level.adjncy, level.adjwgt, level.vwgt}; }

// One level of coarsening: a greedy heavy-edge matching in vertex order (each unmatched
// vertex takes the unmatched neighbour it shares the heaviest edge with; ties: the lighter
// neighbour, then the lower id), then every vertex left single joins the group of the
// neighbour it shares the heaviest edge with (ties: the lighter group, then the lower id), so
// but for isolated vertices every group holds two or more. No group outweighs max_weight.
// Groups are connected, numbered as they form. Fills coarse_of and `coarse`. O(E).
void coarsen(const LevelView& fine, std::int32_t max_weight, std::vector<std::int32_t>& coarse_of, Level& coarse,
             MultilevelScratch& scratch) {
  const std::size_t n = fine.size();
  coarse_of.assign(n, -1);
  std::vector<std::int32_t>& group_weight = coarse.vwgt;
  group_weight.clear();
  std::vector<std::int32_t>& first_member = scratch.first_member;  // members as linked lists
  std::vector<std::int32_t>& next_member = scratch.next_member;
  first_member.clear();
  next_member.assign(n, -1);
  for (std::size_t u = 0; u < n; ++u) {
    if (coarse_of[u] >= 0) continue;
    const std::int32_t weight_u = fine.vwgt[u];
    std::int32_t best = -1, best_edge = 0, best_weight = 0;
    for (std::int32_t e = fine.xadj[u]; e < fine.xadj[u + 1]; ++e) {
      const std::int32_t v = fine.adjncy[static_cast<std::size_t>(e)];
      if (coarse_of[static_cast<std::size_t>(v)] >= 0) continue;
      const std::int32_t weight_v = fine.vwgt[static_cast<std::size_t>(v)];
      if (weight_u + weight_v > max_weight) continue;
      const std::int32_t edge = fine.adjwgt[static_cast<std::size_t>(e)];
      if (best < 0 || edge > best_edge || (edge == best_edge && (weight_v < best_weight || (weight_v == best_weight && v < best)))) {
        best = v;
        best_edge = edge;
        best_weight = weight_v;
      }
    }
    if (best < 0) continue;  // left single for now
    const auto group = static_cast<std::int32_t>(group_weight.size());
    coarse_of[u] = coarse_of[static_cast<std::size_t>(best)] = group;
    group_weight.push_back(weight_u + best_weight);
    first_member.push_back(static_cast<std::int32_t>(u));
    next_member[u] = best;
  }
  for (std::size_t u = 0; u < n; ++u) {
    if (coarse_of[u] >= 0) continue;
    const std::int32_t weight_u = fine.vwgt[u];
    std::int32_t best = -1, best_edge = 0;
    for (std::int32_t e = fine.xadj[u]; e < fine.xadj[u + 1]; ++e) {
      const std::int32_t g = coarse_of[static_cast<std::size_t>(fine.adjncy[static_cast<std::size_t>(e)])];
      if (g < 0 || group_weight[static_cast<std::size_t>(g)] + weight_u > max_weight) continue;
      const std::int32_t edge = fine.adjwgt[static_cast<std::size_t>(e)];
      const std::int32_t gw = group_weight[static_cast<std::size_t>(g)];
      if (best < 0 || edge > best_edge ||
          (edge == best_edge && (gw < group_weight[static_cast<std::size_t>(best)] ||
                                 (gw == group_weight[static_cast<std::size_t>(best)] && g < best)))) {
        best = g;
        best_edge = edge;
      }
    }
    if (best < 0) {  // alone: a group of its own
      best = static_cast<std::int32_t>(group_weight.size());
      group_weight.push_back(0);
      first_member.push_back(static_cast<std::int32_t>(u));
    } else {
      next_member[u] = next_member[static_cast<std::size_t>(first_member[static_cast<std::size_t>(best)])];
      next_member[static_cast<std::size_t>(first_member[static_cast<std::size_t>(best)])] = static_cast<std::int32_t>(u);
    }
    coarse_of[u] = best;
    group_weight[static_cast<std::size_t>(best)] += weight_u;
  }
  // Each group's edges: the members' edges to other groups, merged through `slot`.
  const std::size_t groups = group_weight.size();
  coarse.xadj.resize(groups + 1);
  coarse.xadj[0] = 0;
  coarse.adjncy.resize(fine.adjncy.size());  // an upper bound, trimmed below
  coarse.adjwgt.resize(fine.adjncy.size());
  std::vector<std::int32_t>& slot = scratch.slot;
  slot.assign(groups, -1);
  std::int32_t end = 0;
  for (std::size_t g = 0; g < groups; ++g) {
    const std::int32_t row = end;
    for (std::int32_t u = first_member[g]; u >= 0; u = next_member[static_cast<std::size_t>(u)]) {
      for (std::int32_t e = fine.xadj[static_cast<std::size_t>(u)]; e < fine.xadj[static_cast<std::size_t>(u) + 1]; ++e) {
        const std::int32_t h = coarse_of[static_cast<std::size_t>(fine.adjncy[static_cast<std::size_t>(e)])];
        if (static_cast<std::size_t>(h) == g) continue;
        std::int32_t& at = slot[static_cast<std::size_t>(h)];
        if (at < 0) {
          at = end++;
          coarse.adjncy[static_cast<std::size_t>(at)] = h;
          coarse.adjwgt[static_cast<std::size_t>(at)] = 0;
        }
        coarse.adjwgt[static_cast<std::size_t>(at)] += fine.adjwgt[static_cast<std::size_t>(e)];
      }
    }
    for (std::int32_t e = row; e < end; ++e) slot[static_cast<std::size_t>(coarse.adjncy[static_cast<std::size_t>(e)])] = -1;
    coarse.xadj[g + 1] = end;
  }
  coarse.adjncy.resize(static_cast<std::size_t>(end));
  coarse.adjwgt.resize(static_cast<std::size_t>(end));
}

// Greedy refinement of the parts of a weighted level: a vertex moves to the neighbouring part
// it shares the most edge weight with when that is more than it shares with its own part (the
// cut falls), the other part stays within max_part_weight and its own part keeps some weight.
// Two sweeps in vertex order at most. May disconnect a part (joinOrphans mends that).
void refineParts(const LevelView& level, std::int32_t parts, std::int64_t max_part_weight, std::vector<std::int32_t>& part,
                 MultilevelScratch& scratch) {
  const std::size_t n = level.size();
  std::vector<std::int64_t>& weight = scratch.weight;
  weight.assign(static_cast<std::size_t>(parts), 0);
  for (std::size_t u = 0; u < n; ++u) weight[static_cast<std::size_t>(part[u])] += level.vwgt[u];
  std::vector<std::int64_t>& shared = scratch.shared;
  shared.assign(static_cast<std::size_t>(parts), 0);
  std::vector<std::int32_t>& touched = scratch.stack;
  for (int sweep = 0; sweep < 2; ++sweep) {
    bool moved = false;
    for (std::size_t u = 0; u < n; ++u) {
      const std::int32_t own = part[u];
      bool boundary = false;
      for (std::int32_t e = level.xadj[u]; e < level.xadj[u + 1]; ++e) {
        boundary |= part[static_cast<std::size_t>(level.adjncy[static_cast<std::size_t>(e)])] != own;
      }
      if (!boundary) continue;
      touched.clear();
      for (std::int32_t e = level.xadj[u]; e < level.xadj[u + 1]; ++e) {
        const std::int32_t q = part[static_cast<std::size_t>(level.adjncy[static_cast<std::size_t>(e)])];
        if (shared[static_cast<std::size_t>(q)] == 0) touched.push_back(q);
        shared[static_cast<std::size_t>(q)] += level.adjwgt[static_cast<std::size_t>(e)];
      }
      std::int32_t best = -1;
      for (const std::int32_t q : touched) {
        if (q == own || weight[static_cast<std::size_t>(q)] + level.vwgt[u] > max_part_weight) continue;
        if (best < 0 || shared[static_cast<std::size_t>(q)] > shared[static_cast<std::size_t>(best)] ||
            (shared[static_cast<std::size_t>(q)] == shared[static_cast<std::size_t>(best)] && q < best)) {
          best = q;
        }
      }
      if (best >= 0 && shared[static_cast<std::size_t>(best)] > shared[static_cast<std::size_t>(own)] &&
          weight[static_cast<std::size_t>(own)] > level.vwgt[u]) {
        weight[static_cast<std::size_t>(own)] -= level.vwgt[u];
        weight[static_cast<std::size_t>(best)] += level.vwgt[u];
        part[u] = best;
        moved = true;
      }
      for (const std::int32_t q : touched) shared[static_cast<std::size_t>(q)] = 0;
    }
    if (!moved) break;
  }
}

// Makes every part of the faces connected: each part keeps its largest connected set of faces
// (the first on ties); every other set of its faces (an orphan) goes whole to the part whose
// kept faces it shares the most edges with (lowest part on ties), orphans in order of their
// first face, again until none is left (an orphan that touches only other orphans waits for
// a later round). The piece is connected, so this ends, and a part never empties.
void joinOrphans(const PieceGraph& piece, std::int32_t parts, std::vector<std::int32_t>& part, MultilevelScratch& scratch) {
  const std::size_t n = piece.size();
  std::vector<std::int32_t>& set_of = scratch.ids;
  set_of.assign(n, -1);
  std::vector<std::int32_t>& stack = scratch.stack;
  std::vector<std::int32_t>& set_first = scratch.first_member;  // a face of each set
  std::vector<std::int64_t>& set_size = scratch.weight;
  set_first.clear();
  set_size.clear();
  for (std::size_t start = 0; start < n; ++start) {
    if (set_of[start] >= 0) continue;
    const auto id = static_cast<std::int32_t>(set_first.size());
    set_first.push_back(static_cast<std::int32_t>(start));
    set_size.push_back(0);
    set_of[start] = id;
    stack.assign(1, static_cast<std::int32_t>(start));
    while (!stack.empty()) {
      const auto u = static_cast<std::size_t>(stack.back());
      stack.pop_back();
      ++set_size.back();
      for (std::int32_t e = piece.xadj[u]; e < piece.xadj[u + 1]; ++e) {
        const auto v = static_cast<std::size_t>(piece.adjncy[static_cast<std::size_t>(e)]);
        if (set_of[v] < 0 && part[v] == part[u]) {
          set_of[v] = id;
          stack.push_back(static_cast<std::int32_t>(v));
        }
      }
    }
  }
  const std::size_t sets = set_first.size();
  std::vector<std::int32_t> kept(static_cast<std::size_t>(parts), -1);
  std::size_t parts_used = 0;
  for (std::size_t set = 0; set < sets; ++set) {
    std::int32_t& k = kept[static_cast<std::size_t>(part[static_cast<std::size_t>(set_first[set])])];
    if (k < 0) ++parts_used;
    if (k < 0 || set_size[set] > set_size[static_cast<std::size_t>(k)]) k = static_cast<std::int32_t>(set);
  }
  if (sets == parts_used) return;  // one set per part: all connected
  std::vector<std::uint8_t> settled(sets, 0);
  for (const std::int32_t k : kept) {
    if (k >= 0) settled[static_cast<std::size_t>(k)] = 1;
  }
  // The faces of each set, in face order.
  std::vector<std::int32_t> first(sets + 1, 0), faces(n);
  for (std::size_t u = 0; u < n; ++u) ++first[static_cast<std::size_t>(set_of[u]) + 1];
  for (std::size_t set = 0; set < sets; ++set) first[set + 1] += first[set];
  {
    std::vector<std::int32_t> fill(first.begin(), first.end() - 1);
    for (std::size_t u = 0; u < n; ++u) faces[static_cast<std::size_t>(fill[static_cast<std::size_t>(set_of[u])]++)] = static_cast<std::int32_t>(u);
  }
  std::vector<std::int64_t> shared(static_cast<std::size_t>(parts), 0);
  std::vector<std::int32_t> touched;
  for (bool left = true; left;) {
    left = false;
    for (std::size_t set = 0; set < sets; ++set) {
      if (settled[set]) continue;
      for (std::int32_t i = first[set]; i < first[set + 1]; ++i) {
        const auto u = static_cast<std::size_t>(faces[static_cast<std::size_t>(i)]);
        for (std::int32_t e = piece.xadj[u]; e < piece.xadj[u + 1]; ++e) {
          const auto v = static_cast<std::size_t>(piece.adjncy[static_cast<std::size_t>(e)]);
          if (!settled[static_cast<std::size_t>(set_of[v])]) continue;
          const std::int32_t q = part[v];
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
      if (best < 0) {
        left = true;
        continue;
      }
      for (std::int32_t i = first[set]; i < first[set + 1]; ++i) part[static_cast<std::size_t>(faces[static_cast<std::size_t>(i)])] = best;
      settled[set] = 1;
    }
  }
}

// Smoothing of connected parts of the faces: a face with exactly one neighbour in its own
// part and two or more in another part moves there: the cut loses an edge or more, its own
// part stays connected (the face is a leaf of it) and keeps a face, and the other part stays
// connected; unless that part would outweigh max_part_faces. One sweep in face order, then
// the neighbours of the faces that moved, in the order they were queued, until nothing moves
// (every move lowers the cut, so this ends).
void smoothParts(const PieceGraph& piece, std::int32_t parts, std::int64_t max_part_faces, std::vector<std::int32_t>& part,
                 MultilevelScratch& scratch) {
  const std::size_t n = piece.size();
  std::vector<std::int64_t>& size = scratch.weight;
  size.assign(static_cast<std::size_t>(parts), 0);
  for (std::size_t u = 0; u < n; ++u) ++size[static_cast<std::size_t>(part[u])];
  std::vector<std::int32_t>& queue = scratch.stack;  // faces to look at again
  std::vector<std::int32_t>& queued = scratch.ids;   // 1 while in the queue
  queue.clear();
  queued.assign(n, 0);
  const auto tryMove = [&](std::size_t u) {
    const std::int32_t own = part[u];
    std::int32_t other[3], count[3], kinds = 0, own_count = 0;
    for (std::int32_t e = piece.xadj[u]; e < piece.xadj[u + 1]; ++e) {
      const std::int32_t q = part[static_cast<std::size_t>(piece.adjncy[static_cast<std::size_t>(e)])];
      if (q == own) {
        ++own_count;
        continue;
      }
      std::int32_t k = 0;
      while (k < kinds && other[k] != q) ++k;
      if (k == kinds) {
        if (kinds == 3) continue;  // a triangle has three sides
        other[kinds] = q;
        count[kinds++] = 0;
      }
      ++count[k];
    }
    if (own_count != 1) return;  // 0: the part's only face; 2 or more: nothing to gain
    for (std::int32_t k = 0; k < kinds; ++k) {
      const auto q = static_cast<std::size_t>(other[k]);
      if (count[k] >= 2 && size[q] < max_part_faces) {
        --size[static_cast<std::size_t>(own)];
        ++size[q];
        part[u] = other[k];
        for (std::int32_t e = piece.xadj[u]; e < piece.xadj[u + 1]; ++e) {
          const auto v = static_cast<std::size_t>(piece.adjncy[static_cast<std::size_t>(e)]);
          if (!queued[v]) {
            queued[v] = 1;
            queue.push_back(static_cast<std::int32_t>(v));
          }
        }
        return;
      }
    }
  };
  for (std::size_t u = 0; u < n; ++u) tryMove(u);
  for (std::size_t i = 0; i < queue.size(); ++i) {
    const auto u = static_cast<std::size_t>(queue[i]);
    queued[u] = 0;
    tryMove(u);
  }
}

}  // namespace

void multilevelParts(const PieceGraph& piece, std::int32_t parts, std::uint32_t seed, std::vector<std::int32_t>& part,
                     MultilevelScratch& scratch) {
  const std::size_t n = piece.size();
  TERRATILES_ASSERT(parts >= 1 && static_cast<std::size_t>(parts) <= n);
  // Groups up to a quarter of a part, so METIS can still balance the parts; coarsening ends at
  // about 8 vertices per part, or when a level shrinks the graph by less than a tenth.
  const auto max_group = static_cast<std::int32_t>(std::max<std::size_t>(2, n / static_cast<std::size_t>(parts) / 4));
  const std::size_t target = 8 * static_cast<std::size_t>(parts);
  std::vector<Level>& levels = scratch.levels;
  if (levels.empty()) levels.resize(1);
  if (scratch.ones.size() < piece.adjncy.size()) scratch.ones.assign(piece.adjncy.size(), 1);
  const std::span<const std::int32_t> ones(scratch.ones);
  const auto view = [&](std::size_t level) {
    return level == 0 ? LevelView{piece.xadj, piece.adjncy, ones.first(piece.adjncy.size()), ones.first(n)} : viewOf(levels[level]);
  };
  std::size_t depth = 0;  // the coarsest level built
  while (view(depth).size() > target) {
    if (levels.size() < depth + 2) levels.resize(depth + 2);
    coarsen(view(depth), max_group, levels[depth].coarse_of, levels[depth + 1], scratch);
    if (levels[depth + 1].size() * 10 > view(depth).size() * 9) break;
    ++depth;
  }
  if (depth == 0) {  // too small to coarsen: METIS on the faces
    levels[0].xadj = piece.xadj;
    levels[0].adjncy = piece.adjncy;
    levels[0].adjwgt.assign(piece.adjncy.size(), 1);
    levels[0].vwgt.assign(n, 1);
  }
  Level& coarsest = levels[depth];
  const std::size_t coarse_n = coarsest.size();
  part.assign(coarse_n, 0);
  if (parts > 1) {
    idx_t vertices = static_cast<idx_t>(coarse_n), constraints = 1, nparts = parts, objective = 0;
    idx_t options[METIS_NOPTIONS];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_OBJTYPE] = METIS_OBJTYPE_CUT;
    options[METIS_OPTION_NUMBERING] = 0;
    options[METIS_OPTION_SEED] = static_cast<idx_t>(seed);
    const int status = METIS_PartGraphRecursive(&vertices, &constraints, coarsest.xadj.data(), coarsest.adjncy.data(),
                                                coarsest.vwgt.data(), nullptr, coarsest.adjwgt.data(), &nparts, nullptr,
                                                nullptr, options, &objective, part.data());
    if (status != METIS_OK) {
      throw Error(ErrorCode::Internal, "METIS_PartGraphRecursive failed with status " + std::to_string(status) + " on " +
                                           std::to_string(vertices) + " groups of " + std::to_string(n) + " faces into " +
                                           std::to_string(parts) + " parts");
    }
  }
  // The balance METIS reached, or its k-way tolerance (3 %) when that is looser.
  std::int64_t max_weight = (static_cast<std::int64_t>(n) * 103 + parts * 100 - 1) / (std::int64_t{parts} * 100);
  {
    std::vector<std::int64_t>& weight = scratch.weight;
    weight.assign(static_cast<std::size_t>(parts), 0);
    for (std::size_t u = 0; u < coarse_n; ++u) weight[static_cast<std::size_t>(part[u])] += coarsest.vwgt[u];
    max_weight = std::max(max_weight, *std::max_element(weight.begin(), weight.end()));
  }
  std::vector<std::int32_t>& finer = scratch.part_work;
  for (std::size_t level = depth; level-- > 0;) {
    const std::vector<std::int32_t>& coarse_of = levels[level].coarse_of;
    finer.resize(coarse_of.size());
    for (std::size_t u = 0; u < coarse_of.size(); ++u) finer[u] = part[static_cast<std::size_t>(coarse_of[u])];
    part.swap(finer);
    if (level > 0) refineParts(view(level), parts, max_weight, part, scratch);
  }
  joinOrphans(piece, parts, part, scratch);
  smoothParts(piece, parts, max_weight, part, scratch);
}

}  // namespace terratiles::detail
