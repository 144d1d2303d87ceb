// The one parallel loop (core/math/parallel.h): coverage of the range, per-chunk bodies,
// cancellation and its polls; and the shared small helpers (luminance, sqrt(4 pi), str()).
#include "core/math/parallel.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

#include "core/format.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/vec3.h"

namespace cloudbake {
namespace {

TEST(ParallelFor, VisitsEveryIndexOnceInEitherBodyForm) {
  for (int64_t grain : {int64_t(1), int64_t(7), kCheapIterationGrain}) {
    std::vector<std::atomic<int>> per_index(10000);
    parallelFor(3, 10000, [&](int64_t i) { ++per_index[size_t(i)]; }, {grain});
    std::vector<std::atomic<int>> per_chunk(10000);
    std::atomic<int64_t> chunks{0};
    parallelFor(3, 10000,
                [&](int64_t lo, int64_t hi) {
                  EXPECT_LT(lo, hi);
                  ++chunks;
                  for (int64_t i = lo; i < hi; ++i) ++per_chunk[size_t(i)];
                },
                {grain});
    for (int64_t i = 0; i < 10000; ++i) {
      ASSERT_EQ(per_index[size_t(i)].load(), i >= 3 ? 1 : 0) << i;
      ASSERT_EQ(per_chunk[size_t(i)].load(), i >= 3 ? 1 : 0) << i;
    }
    EXPECT_GE(chunks.load(), 1);
  }
  int calls = 0;
  parallelFor(5, 5, [&](int64_t) { ++calls; });
  parallelFor(5, 2, [&](int64_t) { ++calls; });
  EXPECT_EQ(calls, 0);
}

TEST(ParallelFor, ChunksAreAtMostTheGrainWhenCancellable) {
  ParallelOptions o;
  o.grain = 16;
  o.cancelled = [](double) { return false; };
  std::atomic<int64_t> largest{0};
  parallelFor(
      0, 5000,
      [&](int64_t lo, int64_t hi) {
        int64_t seen = largest.load();
        while (hi - lo > seen && !largest.compare_exchange_weak(seen, hi - lo)) {
        }
      },
      o);
  EXPECT_LE(largest.load(), 16);
}

TEST(ParallelFor, PollsAreSerialisedAndMonotone) {
  std::vector<double> fractions;  // not thread-safe on purpose: polls never overlap
  ParallelOptions o;
  o.cancelled = [&](double f) {
    fractions.push_back(f);
    return false;
  };
  parallelFor(
      0, 2000, [](int64_t) { std::this_thread::sleep_for(std::chrono::microseconds(200)); }, o);
  // About every 10 ms of the loop's 400 ms of sleeping, shared by the threads.
  ASSERT_GE(fractions.size(), 2u);
  EXPECT_EQ(fractions.front(), 0.0);
  EXPECT_LT(fractions.back(), 1.0);
  for (size_t i = 1; i < fractions.size(); ++i) EXPECT_GE(fractions[i], fractions[i - 1]);
}

TEST(ParallelFor, StopSkipsTheRestAndThrowsCancelled) {
  std::atomic<int64_t> done{0};
  ParallelOptions o;
  o.cancelled = [&](double) { return done.load() >= 10; };
  o.cancelled_message = "loop stopped";
  try {
    parallelFor(
        0, 100000,
        [&](int64_t) {
          std::this_thread::sleep_for(std::chrono::microseconds(100));
          ++done;
        },
        o);
    FAIL() << "no Cancelled";
  } catch (const Cancelled& e) {
    EXPECT_STREQ(e.what(), "loop stopped");
  }
  EXPECT_LT(done.load(), 100000);
  // Asked to stop before any work: nothing runs.
  done = 0;
  o.cancelled = [](double) { return true; };
  EXPECT_THROW(parallelFor(
                   0, 1000, [&](int64_t) { ++done; }, o),
               Cancelled);
  EXPECT_EQ(done.load(), 0);
}

TEST(ParallelFor, ExceptionsOfTheBodyPropagate) {
  EXPECT_THROW(parallelFor(0, 100,
                           [](int64_t i) {
                             if (i == 42) throw InputError("bad index");
                           }),
               InputError);
}

TEST(ParallelFor, SameResultsOnOneThread) {
  auto run = [] {
    std::vector<double> out(50000);
    parallelFor(0, int64_t(out.size()), [&](size_t i) { out[i] = std::sin(double(i)) * 1e-3; },
                {kCheapIterationGrain});
    return out;
  };
  const std::vector<double> many = run();
  tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  EXPECT_EQ(run(), many);
}

TEST(SharedHelpers, LuminanceSqrt4PiAndNumbers) {
  EXPECT_EQ(luminance(Rgb(1, 0, 0)), 0.2126);
  EXPECT_EQ(luminance(Rgb(0.5, 0.25, 2)), 0.2126 * 0.5 + 0.7152 * 0.25 + 0.0722 * 2);
  EXPECT_EQ(kSqrt4Pi, std::sqrt(4 * kPi));
  // As an iostream prints them by default: integers in full, %g with 6 digits.
  EXPECT_EQ(str(16777217), "16777217");
  EXPECT_EQ(str(uint64_t(12345678901234ull)), "12345678901234");
  EXPECT_EQ(str(1.5), "1.5");
  EXPECT_EQ(str(4e8), "4e+08");
  EXPECT_EQ(str(0.1234567891), "0.123457");
  EXPECT_EQ(str(0.1234567891, 9), "0.123456789");
  EXPECT_EQ(str(Vec3(1, -2.5, 1e-7)), "[1, -2.5, 1e-07]");
}

}  // namespace
}  // namespace cloudbake
