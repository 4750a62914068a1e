#pragma once
// Large arrays on transparent huge pages.
//
// On this project's build VM the kernel takes about 7 us to fault in each fresh 4 KB page
// (measured: first touch of 64 MB 0.44 s, again 0.003 s; with MADV_HUGEPAGE 0.009 s), so
// filling a fresh array of a few hundred MB costs more than the work done in it. glibc returns
// freed blocks above its mmap threshold to the kernel, so every level's arrays are fresh
// again. reserveOnHugePages reserves a vector's capacity and asks the kernel (madvise
// MADV_HUGEPAGE, honoured when /sys/kernel/mm/transparent_hugepage/enabled is "madvise" or
// "always") to back the 2 MB-aligned interior of the block with huge pages when it is first
// touched. Smaller requests, and kernels that refuse, are left as they are: only the speed
// depends on it.

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace terratiles::detail {

inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

// Reserves capacity for `count` elements and advises huge pages for it when the block is at
// least 8 MB. Call before the elements are written (resize, assign, push_back).
template <typename T>
void reserveOnHugePages(std::vector<T>& values, std::size_t count) {
  if (count <= values.capacity()) return;
  values.reserve(count);
  const std::size_t bytes = count * sizeof(T);
  if (bytes < 4 * kHugePageBytes) return;
  const auto begin = reinterpret_cast<std::uintptr_t>(values.data());
  const std::uintptr_t first = (begin + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
  const std::uintptr_t last = (begin + bytes) & ~(kHugePageBytes - 1);
  if (last > first) madvise(reinterpret_cast<void*>(first), last - first, MADV_HUGEPAGE);
}

// resize after reserveOnHugePages: the new elements are written on huge pages.
template <typename T>
void resizeOnHugePages(std::vector<T>& values, std::size_t count, const T& value = T()) {
  reserveOnHugePages(values, count);
  values.resize(count, value);
}

// assign after reserveOnHugePages.
template <typename T>
void assignOnHugePages(std::vector<T>& values, std::size_t count, const T& value) {
  if (count > values.capacity()) {
    values.clear();
    values.shrink_to_fit();  // a fresh block: the old elements need not be kept
    reserveOnHugePages(values, count);
  }
  values.assign(count, value);
}

}  // namespace terratiles::detail
