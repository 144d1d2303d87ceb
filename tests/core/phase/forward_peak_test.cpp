// The forward peak split off a phase function: where it is cut, and that peak + rest is p.
#include "core/phase/forward_peak.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/math/sh_basis.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/mie_table.h"
#include "phase_test_util.h"

namespace cloudbake {
namespace {

using testing::integrateCos;

// 2 pi integral of part(mu)[c] P_l(mu) over [-1, 1], by the tests' own quadrature, with the cut
// as a breakpoint (the rest has a kink there).
double legendreMoment(const std::function<Rgb(double)>& part, int c, int l, double cos_cut) {
  std::vector<double> p(size_t(l) + 1);
  return 2 * kPi *
         integrateCos(
             [&](double mu) {
               legendreP(l, mu, p.data());
               return part(mu)[c] * p[size_t(l)];
             },
             {cos_cut});
}

TEST(ForwardPeak, ASmoothPhaseIsNotSplit) {
  bool found = false;
  const ForwardPeak split = splitForwardPeak(HenyeyGreensteinPhase(0.85), 24, 0.1, 30, &found);
  EXPECT_TRUE(found);
  EXPECT_FALSE(split.active());
  EXPECT_EQ(split.peak(0.9999, Rgb(100.0)), Rgb(0.0));
}

TEST(ForwardPeak, ADropletsPeakIsCutWhereTheRestFallsUnderTheBound) {
  const MieTablePhase mie;
  bool found = false;
  const ForwardPeak split = splitForwardPeak(mie, 24, 0.1, 30, &found);
  ASSERT_TRUE(found);
  ASSERT_TRUE(split.active());
  const double cut_deg = std::acos(split.cos_cut) * 180 / kPi;
  // The diffraction peak of 10 um droplets is a few degrees wide.
  EXPECT_GT(cut_deg, 0.5);
  EXPECT_LT(cut_deg, 30);
  auto peak = [&](double mu) { return split.peak(mu, mie.eval(mu)); };
  auto rest = [&](double mu) { return mie.eval(mu) - peak(mu); };
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(split.p_cut[c], mie.eval(split.cos_cut)[c], 1e-12);
    // The fraction is the peak's integral, and most of the droplet's p_24 went with it.
    const double f = legendreMoment(peak, c, 0, split.cos_cut);
    EXPECT_NEAR(split.fraction[c], f, 2e-3 * f) << c;
    EXPECT_GT(f, 0.05);
    EXPECT_LT(f, 0.9);
    const double rest0 = legendreMoment(rest, c, 0, split.cos_cut);
    EXPECT_NEAR(rest0, 1 - f, 2e-3);
    EXPECT_LE(std::abs(legendreMoment(rest, c, 24, split.cos_cut) / rest0), 0.1 + 2e-3) << c;
  }
  // Both parts are non-negative and sum to p; the peak vanishes outside the cut.
  for (double theta = 0; theta <= 180; theta += 0.05) {
    const double mu = std::cos(theta * kPi / 180);
    const Rgb p = mie.eval(mu), pk = peak(mu);
    for (int c = 0; c < 3; ++c) {
      EXPECT_GE(pk[c], 0);
      EXPECT_GE(p[c] - pk[c], 0);
      if (mu <= split.cos_cut) {
        EXPECT_EQ(pk[c], 0);
      }
    }
  }
  // A narrower cut would leave the rest above the bound: the cut is the narrowest (to the
  // search's stride).
  bool found_tighter = false;
  const ForwardPeak tighter = splitForwardPeak(mie, 24, 0.2, 30, &found_tighter);
  EXPECT_TRUE(found_tighter);
  EXPECT_GT(tighter.cos_cut, split.cos_cut);
}

// The grid the split integrates on holds a droplet's peak and HG's up to g = 0.9995; past that
// its integral of the phase drifts from 1 (photonPeakSplit refuses such phases).
TEST(ForwardPeak, TheGridResolvesDropletsButNotTheNarrowestHgPeaks) {
  for (double g : {0.0, 0.85, 0.999, 0.9995}) {
    EXPECT_NEAR(phaseIntegralOnPeakGrid(HenyeyGreensteinPhase(g)).x, 1.0, 0.005) << g;
  }
  const Rgb droplets = phaseIntegralOnPeakGrid(MieTablePhase());  // r_eff 10 um, v_eff 0.1
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(droplets[c], 1.0, 2e-4) << c;
  for (double g : {0.9999, 0.99999, kMaxHgAsymmetry}) {
    EXPECT_GT(std::abs(phaseIntegralOnPeakGrid(HenyeyGreensteinPhase(g)).x - 1), 0.05) << g;
  }
}

// The split reports the same integral, so photon need not integrate the phase twice.
TEST(ForwardPeak, TheSplitCarriesThePhasesIntegralOnItsGrid) {
  for (double g : {0.85, 0.9999}) {
    bool found = false;
    const HenyeyGreensteinPhase hg(g);
    const ForwardPeak split = splitForwardPeak(hg, 24, 0.1, 30, &found);
    EXPECT_NEAR(split.integral.x, phaseIntegralOnPeakGrid(hg).x, 1e-12) << g;
  }
}

TEST(ForwardPeak, ABackwardPeakCannotBeCut) {
  bool found = true;
  splitForwardPeak(HenyeyGreensteinPhase(-0.99), 24, 0.1, 30, &found);
  EXPECT_FALSE(found);
}

}  // namespace
}  // namespace cloudbake
