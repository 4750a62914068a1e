#pragma once
// forEachLargestFirst: runs independent jobs of very different sizes (the tiles of a zoom, the
// clusters of a level: from a few hundred triangles to a hundred thousand) on TBB's threads so that the largest
// start first and the small ones fill in at the end: every free thread takes the next job of
// `order`, a greedy schedule that leaves at most one small job's time idle at the end, where
// a split of the index range can leave a thread idle for a large job's whole time.

#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <span>

namespace terratiles {

// Calls work(order[k]) once for every k, in parallel. `order`: job indices, largest first.
// An exception from a job stops the taking of further jobs and is rethrown.
template <typename Work>
void forEachLargestFirst(std::span<const std::size_t> order, Work&& work) {
  if (order.empty()) return;
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  const auto slots = static_cast<int>(
      std::min<std::size_t>(order.size(), static_cast<std::size_t>(tbb::this_task_arena::max_concurrency())));
  tbb::parallel_for(
      0, slots,
      [&](int) {
        for (std::size_t k = next.fetch_add(1); k < order.size() && !failed.load(); k = next.fetch_add(1)) {
          try {
            work(order[k]);
          } catch (...) {
            failed = true;
            throw;
          }
        }
      },
      tbb::simple_partitioner());
}

}  // namespace terratiles
