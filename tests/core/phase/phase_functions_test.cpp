// Analytic phase functions: normalisation, sampling vs pdf, mean cosine, and input validation.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "core/error.h"
#include "core/phase/draine.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"
#include "core/phase/mie_approx.h"
#include "core/phase/mie_isotropic_blend.h"
#include "core/phase/phase_factory.h"
#include "phase_test_util.h"

namespace cloudbake {
namespace {

using testing::chiSquareTest;
using testing::integrateCos;
using testing::sphereIntegral;

double numericalMeanCosine(const PhaseFunction& p, int c) {
  return 2.0 * kPi * integrateCos([&](double mu) { return mu * p.eval(mu)[c]; });
}

void expectValidPhase(const PhaseFunction& p, double norm_tol, double mean_tol) {
  SCOPED_TRACE(p.describe());
  const Rgb integral = sphereIntegral(p);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(integral[c], 1.0, norm_tol) << "channel " << c;
    EXPECT_NEAR(p.meanCosine()[c], numericalMeanCosine(p, c), mean_tol) << "channel " << c;
  }
  // Grey functions sample exactly their value.
  for (double mu : {-1.0, -0.3, 0.0, 0.5, 0.99, 1.0}) {
    EXPECT_NEAR(p.pdf(mu), average(p.eval(mu)), 1e-12 * p.pdf(mu)) << "mu = " << mu;
  }
  const auto chi = chiSquareTest(p, 400000, 12345);
  EXPECT_LT(chi.chi2, chi.critical) << "dof " << chi.dof;
  EXPECT_GE(chi.dof, 10);
  // Samples stay in [-1, 1] even at the ends of [0, 1).
  for (double u : {0.0, 1e-17, 0.5, std::nextafter(1.0, 0.0)}) {
    const double mu = p.sampleCosTheta(u);
    EXPECT_TRUE(mu >= -1.0 && mu <= 1.0) << "u = " << u << " mu = " << mu;
  }
}

// A sampler that is slightly off (g = 0.76 samples, g = 0.75 pdf) must fail the chi-square test,
// otherwise the test above could not catch a wrong sampler.
class MismatchedHg final : public PhaseFunction {
 public:
  Rgb eval(double mu) const override { return Rgb(hgEval(0.75, mu)); }
  double pdf(double mu) const override { return hgEval(0.75, mu); }
  double sampleCosTheta(double u) const override { return hgSampleCosTheta(0.76, u); }
  Rgb meanCosine() const override { return Rgb(0.75); }
  std::string describe() const override { return "mismatched"; }
};

TEST(ChiSquare, DetectsASlightlyWrongSampler) {
  const auto chi = chiSquareTest(MismatchedHg(), 400000, 12345);
  EXPECT_GT(chi.chi2, chi.critical);
  const auto ok = chiSquareTest(HenyeyGreensteinPhase(0.75), 400000, 12345);
  EXPECT_LT(ok.chi2, ok.critical);
}

TEST(Isotropic, IsNormalisedAndSampledExactly) {
  IsotropicPhase p;
  expectValidPhase(p, 1e-12, 1e-12);
  EXPECT_DOUBLE_EQ(p.eval(0.3).x, 1.0 / (4.0 * kPi));
  EXPECT_FALSE(p.chromatic());
}

class HenyeyGreenstein : public ::testing::TestWithParam<double> {};

TEST_P(HenyeyGreenstein, IsNormalisedSampledAndHasMeanCosineG) {
  const double g = GetParam();
  HenyeyGreensteinPhase p(g);
  expectValidPhase(p, 1e-9, 1e-9);
  EXPECT_EQ(p.meanCosine().x, g);
  EXPECT_NEAR(numericalMeanCosine(p, 0), g, 1e-9);
}

INSTANTIATE_TEST_SUITE_P(Asymmetries, HenyeyGreenstein,
                         ::testing::Values(-0.999, -0.5, 0.0, 0.75, 0.999));

// At the largest |g| a shot may give, the peak is still resolved: the value at the peak is the
// closed form's, (1 + g) / (4 pi (1 - g)^2), to a part in 1e3, and every value is finite and
// positive. Past it, 1 + g^2 - 2 g cos_theta rounds to zero or below (NaN pixels at 1 - 1e-9).
TEST(HenyeyGreenstein, HoldsItsPeakUpToTheLargestAsymmetryAllowed) {
  for (double g : {kMaxHgAsymmetry, -kMaxHgAsymmetry}) {
    const HenyeyGreensteinPhase hg(g);
    const double peak_mu = g > 0 ? 1.0 : -1.0;
    const double exact = (1 + std::abs(g)) / (4 * kPi * (1 - std::abs(g)) * (1 - std::abs(g)));
    EXPECT_NEAR(hg.pdf(peak_mu) / exact, 1.0, 1e-3) << g;
    for (double u : {0.0, 1e-9, 0.5, 1 - 1e-9}) {
      const double mu = hg.sampleCosTheta(u);
      ASSERT_TRUE(std::isfinite(hg.pdf(mu)) && hg.pdf(mu) > 0) << g << " " << u;
    }
  }
  EXPECT_THROW(HenyeyGreensteinPhase(std::nextafter(kMaxHgAsymmetry, 1.0)), InputError);
}

TEST(HenyeyGreensteinSampling, MatchesTextbookInverseAndIsUniformAtZero) {
  // The cancellation-free form equals the textbook formula where that one is well conditioned.
  for (double g : {-0.7, 0.3, 0.9}) {
    for (double u : {0.01, 0.3, 0.77, 0.999}) {
      const double s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
      const double textbook = (1.0 + g * g - s * s) / (2.0 * g);
      EXPECT_NEAR(hgSampleCosTheta(g, u), textbook, 1e-12);
    }
  }
  EXPECT_DOUBLE_EQ(hgSampleCosTheta(0.0, 0.25), -0.5);
  EXPECT_DOUBLE_EQ(hgSampleCosTheta(0.999, 1.0), 1.0);
  EXPECT_DOUBLE_EQ(hgSampleCosTheta(-0.999, 0.0), -1.0);
  // Tiny g: continuous with the isotropic limit.
  EXPECT_NEAR(hgSampleCosTheta(1e-12, 0.75), 0.5, 1e-11);
}

TEST(Draine, ClosedFormCdfAgreesWithQuadratureAtTheSwitch) {
  // draineCdf switches from quadrature to the closed form at |g| = 0.1; both must agree.
  for (double alpha : {0.0, 1.0, 25.0}) {
    for (double mu : {-0.9, -0.2, 0.4, 0.95}) {
      const double below = draineCdf(0.0999999999, alpha, mu);
      const double above = draineCdf(0.1, alpha, mu);
      EXPECT_NEAR(below, above, 1e-8) << "alpha " << alpha << " mu " << mu;
      const double nb = draineCdf(-0.0999999999, alpha, mu);
      const double na = draineCdf(-0.1, alpha, mu);
      EXPECT_NEAR(nb, na, 1e-8) << "alpha " << alpha << " mu " << mu;
    }
  }
  // CDF against independent quadrature of the density.
  for (double g : {-0.6, 0.05, 0.55, 0.9}) {
    for (double mu : {-0.5, 0.0, 0.8}) {
      double ref = 0.0;
      const auto pts = testing::clusteredBreakpoints(0.7, 1e-10);
      for (size_t i = 0; i + 1 < pts.size(); ++i) {
        const double lo = pts[i], hi = std::min(pts[i + 1], mu);
        if (hi <= lo) break;
        ref += 2.0 * kPi *
               testing::gaussLegendre([&](double m) { return draineEval(g, 20.0, m); }, lo, hi);
      }
      EXPECT_NEAR(draineCdf(g, 20.0, mu), ref, 1e-10) << "g " << g << " mu " << mu;
    }
  }
}

TEST(Draine, SamplingInvertsTheCdf) {
  for (double g : {-0.5, 0.0, 0.05, 0.6}) {
    for (double u : {1e-6, 0.1, 0.5, 0.9, 0.999999}) {
      const double mu = draineSampleCosTheta(g, 17.0, u);
      EXPECT_NEAR(draineCdf(g, 17.0, mu), u, 1e-12) << "g " << g << " u " << u;
    }
  }
  expectValidPhase(DrainePhase(0.6, 20.0), 1e-9, 1e-9);
  expectValidPhase(DrainePhase(0.0, 5.0), 1e-9, 1e-9);
}

class MieApprox : public ::testing::TestWithParam<double> {};

TEST_P(MieApprox, IsNormalisedAndSampled) {
  MieApproxPhase p(GetParam());
  expectValidPhase(p, 1e-8, 1e-8);
  // Strongly forward, as cloud droplets are.
  EXPECT_GT(p.meanCosine().x, 0.75);
  EXPECT_GT(p.eval(1.0).x, 100.0 * p.eval(0.0).x);
}

INSTANTIATE_TEST_SUITE_P(Diameters, MieApprox, ::testing::Values(5.0, 20.0, 50.0));

TEST(MieApproxParams, MatchThePaperFits) {
  // Values of the paper's formulas evaluated independently at d = 20 um.
  const MieApproxParams p = mieApproxParams(20.0);
  EXPECT_NEAR(p.g_hg, std::exp(-0.0990567 / 18.32846), 1e-15);
  EXPECT_NEAR(p.g_hg, 0.9946100, 1e-6);
  EXPECT_NEAR(p.g_d, 0.5937906, 1e-6);
  EXPECT_NEAR(p.alpha, 27.113694, 1e-5);
  EXPECT_NEAR(p.w_d, 0.4981595, 1e-6);
}

TEST(MieIsotropicBlendTest, BlendIsNormalisedAndSampled) {
  auto hg = std::make_shared<HenyeyGreensteinPhase>(0.9);
  MieIsotropicBlend p(hg, 0.3);
  expectValidPhase(p, 1e-9, 1e-9);
  EXPECT_NEAR(p.meanCosine().x, 0.27, 1e-12);
  EXPECT_NEAR(p.eval(0.2).x, 0.3 * hgEval(0.9, 0.2) + 0.7 * kInv4Pi, 1e-15);
  // R = 0 and R = 1 are the two ends.
  EXPECT_DOUBLE_EQ(MieIsotropicBlend(hg, 0.0).eval(1.0).x, kInv4Pi);
  EXPECT_DOUBLE_EQ(MieIsotropicBlend(hg, 1.0).eval(1.0).x, hg->eval(1.0).x);
  expectValidPhase(MieIsotropicBlend(std::make_shared<MieApproxPhase>(20.0), 0.3), 1e-8, 1e-8);
}

TEST(PhaseFactory, ParsesEveryForm) {
  PhaseSpec s = parsePhaseSpec("isotropic");
  EXPECT_EQ(s.type, PhaseSpec::Type::kIsotropic);
  s = parsePhaseSpec("hg:g=0.75");
  EXPECT_EQ(s.type, PhaseSpec::Type::kHenyeyGreenstein);
  EXPECT_EQ(s.g, 0.75);
  s = parsePhaseSpec("mie_approx:d=20");
  EXPECT_EQ(s.type, PhaseSpec::Type::kMieApprox);
  EXPECT_EQ(s.diameter_um, 20.0);
  s = parsePhaseSpec("mie:reff=12,veff=0.2");
  EXPECT_EQ(s.type, PhaseSpec::Type::kMie);
  EXPECT_EQ(s.effective_radius_um, 12.0);
  EXPECT_EQ(s.effective_variance, 0.2);
  s = parsePhaseSpec("mie");
  EXPECT_EQ(s.effective_radius_um, 10.0);
  EXPECT_EQ(s.effective_variance, 0.1);
  s = parsePhaseSpec("hg:g=-0.5,ratio=0.3");
  EXPECT_EQ(s.mie_ratio, 0.3);
  EXPECT_EQ(s.g, -0.5);

  auto p = makePhaseFunction(parsePhaseSpec("hg:g=0.75"));
  EXPECT_EQ(p->describe(), "hg(g=0.75)");
  p = makePhaseFunction(parsePhaseSpec("mie_approx:d=20,ratio=0.5"));
  EXPECT_NEAR(p->eval(-1.0).x, 0.5 * MieApproxPhase(20.0).eval(-1.0).x + 0.5 * kInv4Pi, 1e-15);
  EXPECT_EQ(makePhaseFunction(PhaseSpec{})->describe(), "isotropic");
}

void expectInputError(const std::string& spec_text, const std::string& needle) {
  try {
    makePhaseFunction(parsePhaseSpec(spec_text));
    ADD_FAILURE() << "no error for '" << spec_text << "'";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos)
        << "'" << spec_text << "' -> " << e.what();
  }
}

TEST(PhaseFactory, BadInputsThrowInputErrorNamingTheField) {
  expectInputError("hg:g=1.5", "phase.g: must be in [-0.999999, 0.999999], got 1.5");
  expectInputError("hg:g=-1", "phase.g");
  expectInputError("hg:g=0.9999999", "phase.g");
  expectInputError("hg:g=-0.9999999", "phase.g");
  expectInputError("hg:g=nan", "phase.g");
  expectInputError("hg:g=0.5x", "phase.g");
  expectInputError("hg", "phase.g");
  expectInputError("hg:g=0.1,g=0.2", "phase.g");
  expectInputError("hg:q=0.1", "phase.q");
  expectInputError("mie_approx:d=4", "phase.d");
  expectInputError("mie_approx:d=51", "phase.d");
  expectInputError("mie:reff=0.5", "phase.reff");
  expectInputError("mie:reff=100", "phase.reff");
  expectInputError("mie:veff=0", "phase.veff");
  expectInputError("mie:veff=0.5", "phase.veff");
  expectInputError("mie:veff=-1", "phase.veff");
  expectInputError("hg:g=0.5,ratio=1.2", "phase.ratio");
  expectInputError("hg:g=0.5,ratio=-0.1", "phase.ratio");
  expectInputError("rayleigh", "unknown phase function 'rayleigh'");
  expectInputError("hg:", "empty parameter list");
  expectInputError("hg:g", "key=value");
  expectInputError("hg:g=0.5,", "trailing");
  EXPECT_THROW(HenyeyGreensteinPhase(1.0), InputError);
  EXPECT_THROW(DrainePhase(0.5, -1.0), InputError);
  EXPECT_THROW(MieIsotropicBlend(nullptr, 0.5), InputError);
  PhaseSpec bad;
  bad.type = PhaseSpec::Type::kHenyeyGreenstein;
  bad.g = std::nan("");
  EXPECT_THROW(makePhaseFunction(bad), InputError);
}

}  // namespace
}  // namespace cloudbake
