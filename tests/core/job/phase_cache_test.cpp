// The server's in-memory cache of phase functions and the dry-run line of a Lorenz-Mie table.
#include "core/job/phase_cache.h"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <string>

#include "core/error.h"

namespace cloudbake {
namespace {

PhaseSpec mie(double reff, double veff) {
  PhaseSpec s;
  s.type = PhaseSpec::Type::kMie;
  s.effective_radius_um = reff;
  s.effective_variance = veff;
  return s;
}

TEST(PhaseCache, KeyCoversEveryFieldThatChangesTheFunction) {
  const PhaseSpec a = mie(10, 0.1);
  PhaseSpec b = a;
  EXPECT_EQ(phaseKey(a), phaseKey(b));
  b.effective_variance = 0.1000000000000001;  // printed exactly, so a different key
  EXPECT_NE(phaseKey(a), phaseKey(b));
  b = a;
  b.mie_ratio = 0.5;
  EXPECT_NE(phaseKey(a), phaseKey(b));
  b = a;
  b.type = PhaseSpec::Type::kHenyeyGreenstein;
  EXPECT_NE(phaseKey(a), phaseKey(b));
}

TEST(PhaseCache, BuildsOnceAndSharesTheTable) {
  PhaseCache cache;
  bool cached = true;
  const auto first = cachedPhase(mie(5, 0.1), &cache, &cached);
  EXPECT_FALSE(cached);
  const auto second = cachedPhase(mie(5, 0.1), &cache, &cached);
  EXPECT_TRUE(cached);
  EXPECT_EQ(first.get(), second.get());
  EXPECT_EQ(cache.builds(), 1u);
  EXPECT_EQ(cache.hits(), 1u);
  // Without a cache each call builds.
  const auto third = cachedPhase(mie(5, 0.1), nullptr, &cached);
  EXPECT_FALSE(cached);
  EXPECT_NE(third.get(), first.get());
  // A failed build is not remembered: the error comes back on each try.
  EXPECT_THROW(cachedPhase(mie(500, 0.1), &cache), InputError);
  EXPECT_THROW(cachedPhase(mie(500, 0.1), &cache), InputError);
  EXPECT_FALSE(cache.contains(phaseKey(mie(500, 0.1))));
}

TEST(PhaseCache, LeastRecentlyUsedEntryGoesFirst) {
  MemoryCache<int> cache(2);
  std::atomic<int> builds{0};
  auto get = [&](const std::string& k) { return cache.getOrBuild(k, [&] { return ++builds; }); };
  EXPECT_EQ(get("a"), 1);
  EXPECT_EQ(get("b"), 2);
  EXPECT_EQ(get("a"), 1);  // a is now the most recent
  EXPECT_EQ(get("c"), 3);  // evicts b
  EXPECT_TRUE(cache.contains("a"));
  EXPECT_FALSE(cache.contains("b"));
  EXPECT_EQ(get("b"), 4);
}

TEST(PhaseCache, DryRunLineForMieTablesOnly) {
  PhaseSpec hg;
  hg.type = PhaseSpec::Type::kHenyeyGreenstein;
  hg.g = 0.8;
  EXPECT_EQ(phasePlanLine(hg, nullptr, 2), "");
  PhaseCache cache;
  const std::string before = phasePlanLine(mie(50, 0.499), &cache, 2);
  EXPECT_NE(before.find("built in about"), std::string::npos) << before;
  EXPECT_NE(before.find("r_eff 50"), std::string::npos) << before;
  cachedPhase(mie(2, 0.1), &cache);
  const std::string after = phasePlanLine(mie(2, 0.1), &cache, 2);
  EXPECT_NE(after.find("in this server's memory"), std::string::npos) << after;
}

}  // namespace
}  // namespace cloudbake
