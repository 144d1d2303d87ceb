// An allocator for the large vectors a bake or a frame fills in parallel (its light grids, tens
// of MB each): their pages are first touched by the worker threads, not by the one thread that
// constructs the vector. The kernel maps and zeroes a page at its first touch, and a
// std::vector's own zero fill, being serial, made that cost serial: perf put 5.6 % of the bunny
// `pointcloud` bake and 4 % of a `precomputed` frame's lighting at one thread in page faults
// under such fills, time that a second thread could not share.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <vector>

#include "core/math/parallel.h"

namespace cloudbake {

template <class T>
struct FirstTouchAllocator {
  static_assert(alignof(T) <= alignof(std::max_align_t), "malloc's alignment must serve T");
  using value_type = T;

  FirstTouchAllocator() = default;
  template <class U>
  FirstTouchAllocator(const FirstTouchAllocator<U>&) noexcept {}  // NOLINT: as std::allocator

  T* allocate(size_t n);
  void deallocate(T* p, size_t) noexcept { std::free(p); }

  template <class U>
  bool operator==(const FirstTouchAllocator<U>&) const noexcept {
    return true;
  }
  template <class U>
  bool operator!=(const FirstTouchAllocator<U>&) const noexcept {
    return false;
  }
};

/// A vector of floats whose large buffers are first touched in parallel: the light grids of a
/// bake (BakeChannel::data).
using FirstTouchFloats = std::vector<float, FirstTouchAllocator<float>>;

// ---- implementation ----

/// Blocks from this size up are touched in parallel; below it a fault or two is cheaper than
/// scheduling.
constexpr size_t kFirstTouchBytes = size_t(1) << 20;

/// Writes one byte of every 4 KiB page of [p, p + bytes) (bytes > 0), spread over the calling
/// thread's task arena, so the page faults happen there: a byte every 4 KiB from p, and the
/// last, as p need not start a page.
inline void touchPagesInParallel(void* p, size_t bytes) {
  constexpr int64_t kPage = 4096;
  volatile char* const c = static_cast<char*>(p);
  const int64_t last = int64_t(bytes) - 1;
  parallelFor(0, last / kPage + 2, [&](int64_t i) { c[std::min(i * kPage, last)] = 0; },
              {/*grain=*/64});
}

template <class T>
T* FirstTouchAllocator<T>::allocate(size_t n) {
  if (n > size_t(-1) / sizeof(T)) throw std::bad_alloc();
  const size_t bytes = n * sizeof(T);
  void* p = std::malloc(bytes > 0 ? bytes : 1);
  if (!p) throw std::bad_alloc();
  if (bytes < kFirstTouchBytes) return static_cast<T*>(p);
  try {
    touchPagesInParallel(p, bytes);
  } catch (...) {
    std::free(p);
    throw;
  }
  return static_cast<T*>(p);
}

}  // namespace cloudbake
