// FirstTouchAllocator: vectors that use it behave as std::vector<float> does (zeros from value
// initialisation, copies, growth) on either side of the size from which pages are touched in
// parallel, also when allocated inside a parallel loop, and an impossible size fails clearly.
#include "core/math/first_touch_allocator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <new>
#include <vector>

#include "core/math/parallel.h"

namespace cloudbake {
namespace {

size_t countNonZero(const FirstTouchFloats& v) {
  return size_t(std::count_if(v.begin(), v.end(), [](float x) { return x != 0.f; }));
}

TEST(FirstTouchAllocator, ValueInitialisedVectorsHoldZerosAtEverySize) {
  const size_t threshold = kFirstTouchBytes / sizeof(float);
  for (size_t n : {size_t(0), size_t(1), size_t(1000), threshold - 1, threshold, threshold + 1,
                   size_t(3) << 20}) {
    const FirstTouchFloats v(n);
    ASSERT_EQ(v.size(), n);
    EXPECT_EQ(countNonZero(v), 0u) << n;
    FirstTouchFloats w;
    w.assign(n, 0.f);
    EXPECT_EQ(countNonZero(w), 0u) << n;
  }
}

TEST(FirstTouchAllocator, KeepsValuesThroughCopiesGrowthAndSwaps) {
  const size_t n = (kFirstTouchBytes / sizeof(float)) * 3 + 17;
  FirstTouchFloats v(n);
  for (size_t i = 0; i < n; ++i) v[i] = float(i % 977);
  const std::vector<float> expected(v.begin(), v.end());

  FirstTouchFloats copy = v;
  EXPECT_TRUE(std::equal(copy.begin(), copy.end(), expected.begin(), expected.end()));
  copy.resize(2 * n);  // growth reallocates: the old values move, the new ones are zero
  EXPECT_TRUE(std::equal(copy.begin(), copy.begin() + long(n), expected.begin()));
  EXPECT_EQ(size_t(std::count(copy.begin() + long(n), copy.end(), 0.f)), n);

  FirstTouchFloats other(5, 1.f);
  other.swap(v);
  EXPECT_EQ(other.size(), n);
  EXPECT_EQ(v.size(), 5u);
  EXPECT_TRUE(std::equal(other.begin(), other.end(), expected.begin(), expected.end()));
  EXPECT_EQ(FirstTouchAllocator<float>(), FirstTouchAllocator<double>());
}

TEST(FirstTouchAllocator, WorksInsideAParallelLoop) {
  const size_t n = (kFirstTouchBytes / sizeof(float)) * 2;
  std::vector<size_t> wrong(8, 1);
  parallelFor(0, 8, [&](int64_t k) {
    FirstTouchFloats v(n, float(k));
    wrong[size_t(k)] =
        size_t(std::count_if(v.begin(), v.end(), [&](float x) { return x != float(k); }));
  });
  for (size_t w : wrong) EXPECT_EQ(w, 0u);
}

TEST(FirstTouchAllocator, ImpossibleSizeThrowsBadAlloc) {
  FirstTouchAllocator<double> a;
  EXPECT_THROW(a.allocate(std::numeric_limits<size_t>::max() / 4), std::bad_alloc);
  EXPECT_THROW(a.allocate(std::numeric_limits<size_t>::max() / 16), std::bad_alloc);
}

}  // namespace
}  // namespace cloudbake
