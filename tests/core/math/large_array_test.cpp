// LargeArray: sizes, alignment (2 MiB for large arrays, so huge pages can back them), the values
// written, and a clear failure for an impossible size.
#include "core/math/large_array.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <new>
#include <utility>

namespace cloudbake {
namespace {

TEST(LargeArray, EmptySmallAndLarge) {
  const LargeArray<float> none;
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.data(), nullptr);
  const LargeArray<float> zero(0);
  EXPECT_TRUE(zero.empty());

  LargeArray<float> small(100);
  ASSERT_EQ(small.size(), 100u);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(small.data()) % alignof(std::max_align_t), 0u);
  for (size_t i = 0; i < small.size(); ++i) small[i] = float(i);
  EXPECT_EQ(small[99], 99.f);

  const size_t n = size_t(5) << 20;  // 20 MiB of floats
  LargeArray<float> large(n);
  ASSERT_EQ(large.size(), n);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(large.data()) % (size_t(2) << 20), 0u);
  for (size_t i = 0; i < n; ++i) large[i] = float(i % 1000);
  size_t wrong = 0;
  for (size_t i = 0; i < n; ++i) wrong += large[i] != float(i % 1000);
  EXPECT_EQ(wrong, 0u);

  LargeArray<float> moved = std::move(large);
  EXPECT_EQ(moved.size(), n);
  EXPECT_EQ(moved[1001], 1.f);
  EXPECT_TRUE(large.empty());  // NOLINT(bugprone-use-after-move): a moved-from array is empty
  EXPECT_EQ(large.data(), nullptr);
}

TEST(LargeArray, ImpossibleSizeThrowsBadAlloc) {
  EXPECT_THROW(LargeArray<double>(size_t(-1) / 4), std::bad_alloc);
}

}  // namespace
}  // namespace cloudbake
