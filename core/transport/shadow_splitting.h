// How many shadow rays the sun's next event gets at one collision: split where its expected
// contribution is large, roulette where it is small.
#pragma once

#include "core/phase/phase_function.h"

namespace cloudbake {

/// Shadow rays to trace and the weight of each (count 0: rouletted away).
struct ShadowRays {
  int count = 1;
  double weight = 1;
};

/// Below this predicted contribution the sun's next event is rouletted.
constexpr double kShadowRouletteBelow = 0.02;

/// Prediction-based splitting and Russian roulette of the sun's next event (in the spirit of the
/// local-estimate splitting of Buras & Mayer 2011). `predicted` is the event's contribution
/// before transmittance, relative to an isotropic scatter at unit throughput: max over channels
/// of throughput * p(theta_sun) * 4 pi. Above 1 the event is split into min(ceil(predicted),
/// max_rays) rays of weight 1/count, so the transmittance of the collisions that carry the
/// image (the forward peak) is averaged; below kShadowRouletteBelow (0.02) it survives with
/// probability predicted / kShadowRouletteBelow at weight 1/probability, so collisions that
/// add little (backscatter at a forward-peaked phase) skip most of their ratio tracking. Both
/// keep the estimator unbiased. max_rays <= 1 turns splitting off, and the roulette too unless
/// `roulette` (then `predicted` includes a predicted transmittance, so that only collisions the
/// sun cannot reach are rouletted); with both off `u` is unused. u is uniform in [0, 1) and
/// only read for the roulette.
ShadowRays sunShadowRays(double predicted, int max_rays, double u, bool roulette = false,
                         double min_survival = 0);

/// The probability of keeping a next event whose predicted contribution (relative to an
/// isotropic scatter at unit throughput) is `predicted`: 1 at or above kShadowRouletteBelow,
/// else predicted / kShadowRouletteBelow (0 for nothing predicted), and never below
/// `min_survival`.
inline double shadowSurvival(double predicted, double min_survival = 0) {
  const double q = predicted >= kShadowRouletteBelow ? 1.0
                   : predicted > 0                   ? predicted / kShadowRouletteBelow
                                                     : 0.0;
  return q > min_survival ? q : min_survival;
}

/// The least survival of an event rouletted on a predicted transmittance: a prediction is not a
/// bound everywhere (a clear channel between the lattice's vertices), so every event keeps a
/// chance, and a wrong prediction costs at most this factor's inverse in weight.
constexpr double kPredictedMinSurvival = 1e-3;

/// The most shadow rays chosen when a shot does not set it: 8 for phases whose spikiness
/// (phaseSpikiness, core/transport/sun_guiding.h) exceeds 100, like droplets' Mie tables, else 1
/// (off). Measured by bench/reference_bench.py (docs/methods.md): with the sun-guided lobe,
/// splitting raises the efficiency of the Mie scenes (Disney's cloud: 34x -> 42x side-lit,
/// 4.3x -> 6.0x backlit) but costs HG 0.85 views more than it removes (backlit 1.16x -> 0.93x).
int autoSunSplitMax(const PhaseFunction& phase);

}  // namespace cloudbake
