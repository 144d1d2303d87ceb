// Sun-directional importance sampling: a second technique for the sun's next event at the
// following collision, which draws the next direction from the phase function about the sun.
#pragma once

#include "core/math/vec3.h"
#include "core/phase/phase_function.h"

namespace cloudbake {

/// Relative variance of the sun's next-event weight over uniformly distributed travel
/// directions, V = 4 pi integral(p^2 d omega) - 1 (0 for isotropic, about 21 for HG 0.85 and
/// hundreds to thousands for a droplet's Mie peak): how much a phase function's spike costs a
/// path tracer that samples directions from the phase function alone. Estimated as
/// 4 pi E_p[pdf] - 1 from `n` stratified samples of the phase's own sampler, so a narrow peak
/// is resolved.
double phaseSpikiness(const PhaseFunction& phase, int n = 4096);

/// The lobe probability chosen when a shot does not set one: eps = 0.5 V / (V + 40), so an
/// isotropic phase is never guided, HG 0.5 (V about 1.2) barely (0.015), HG 0.85 (V about 21)
/// at 0.17 and the Mie table (V in the thousands) at almost 0.5. Measured by
/// bench/reference_bench.py (docs/methods.md): in side-lit views the efficiency is flat in eps
/// (HG 0.85: 2.9 at 0.15, 3.1 at 0.34, 2.4 at 0.6; Mie: 1.05 at 0.25, 1.17 at 0.5, 1.04 at 0.75),
/// while in views towards the sun the lobe's walks cost more than they remove for HG, so the
/// rule keeps eps low until the spike is extreme.
double autoSunGuiding(const PhaseFunction& phase);

/// Phase sampling rarely draws a direction inside the phase's forward spike about the sun, yet
/// what follows such a direction is large: the sun's next event there, and in a thick cloud the
/// chains of small-angle scatterings by which most of a forward-peaked medium's sunlight
/// arrives (the light a delta-M scaling would fold into the direct beam). So at a collision,
/// with probability eps_t, a second walk starts along a direction drawn from the phase
/// function about the sun (the backward-tracing mirror of the detector directional importance
/// sampling of Buras & Mayer 2011) and is followed like any path. Both techniques weight all
/// that follows a real collision along their direction by the balance heuristic with the lobe
/// counted as eps_t samples (Veach 1997), p / (p_phase + eps_t p_sun): unbiased, and bounded
/// where the spike is. A walk already travelling into the spike covers it by phase sampling, so
/// eps_t = eps min(1, 1 / (4 pi p(t.s))) falls there and chains towards the sun do not branch
/// again and again. eps = 0 leaves phase sampling alone (weights exactly 1).
class SunGuide {
 public:
  /// Throws InputError unless eps is in [0, 1) and to_sun is a unit vector.
  SunGuide(const PhaseFunction& phase, const Vec3& to_sun, double eps);

  double eps() const { return eps_; }

  /// The lobe probability at a collision reached travelling along `travel`.
  double epsAt(const Vec3& travel) const;

  /// What a direction drawn by phase sampling (with density p_phase, sr^-1) carries, at a
  /// collision of lobe probability eps_t; both from one evaluation of p_sun = p(s.d).
  struct PhaseSampleWeights {
    /// Balance-heuristic weight against the lobe: p_phase / (p_phase + eps_t p_sun); 1 if
    /// eps_t = 0.
    double mis = 1;
    /// How much more a walk along the direction is expected to bring than one whose direction
    /// is random: max(1, 4 pi p_sun), the relative size of the sun's event at its next
    /// collision (for Russian roulette); 1 when guiding is off.
    double importance = 1;
  };
  PhaseSampleWeights phaseSampleWeights(double p_phase, const Vec3& direction, double eps_t) const;

  struct LobeSample {
    Vec3 direction;  ///< unit; density p(dot(to_sun, direction)) sr^-1
    /// Replaces value / pdf x MIS weight / eps_t: f(t.d) / (p(t.d) + eps_t p(s.d)) per channel.
    Rgb weight;
  };
  /// A direction from the lobe about the sun for light travelling along `travel`.
  LobeSample sampleLobe(const Vec3& travel, double eps_t, double u1, double u2) const;

 private:
  const PhaseFunction& phase_;
  Vec3 to_sun_;
  double eps_;
};

}  // namespace cloudbake
