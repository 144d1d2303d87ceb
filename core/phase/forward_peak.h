// A phase function's forward peak split off at a cone, for methods that expand scattered light
// in spherical harmonics (method photon).
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "core/phase/phase_function.h"

namespace cloudbake {

/// p = peak + rest per channel, with a cut at scattering angle theta_c (cos_cut = cos theta_c):
///   peak(mu) = max(0, p(mu) - p(cos_cut))  for mu > cos_cut, else 0;
///   rest(mu) = p(mu) - peak(mu)            (p clipped to its value at the cut inside the cone).
/// Both are non-negative and rest is as smooth as p outside the cone, so light that has scattered
/// through `rest` keeps few spherical-harmonic degrees, while light scattered only through the
/// narrow `peak` travels within theta_c of its first direction. This is the truncation
/// approximation of Monte Carlo radiative transfer (Iwabuchi and Suzuki 2009, JQSRT), the
/// sampled counterpart of delta-M (Wiscombe 1977).
struct ForwardPeak {
  double cos_cut = 1;  ///< 1: nothing split off (peak = 0)
  Rgb p_cut{0.0};      ///< p(cos_cut) per channel, sr^-1
  Rgb fraction{0.0};   ///< the integral of peak over the sphere per channel: its share of p
  /// p's own integral over the sphere per channel on the grid the split integrates on (see
  /// phaseIntegralOnPeakGrid): 1 where the grid resolves the peak.
  Rgb integral{1.0};

  bool active() const { return cos_cut < 1; }
  /// peak(mu) given p(mu) = p_mu, per channel, sr^-1.
  Rgb peak(double mu, const Rgb& p_mu) const;
};

/// The narrowest cut for which the normalised Legendre coefficient of `rest` at `degree`,
/// rest_degree / rest_0 (rest_l = 2 pi integral of rest(mu) P_l(mu) dmu), is at most
/// `max_legendre` in absolute value in every channel: none (cos_cut = 1) when p itself satisfies
/// it, else cuts up to `max_angle_deg`. *found is false when no cut up to that angle does (a peak
/// elsewhere, such as a backward one); the widest cut tried is returned then. The result's
/// `integral` is set in every case.
ForwardPeak splitForwardPeak(const PhaseFunction& phase, int degree, double max_legendre,
                             double max_angle_deg, bool* found);

/// Midpoints in theta over [0, pi] of the grid splitForwardPeak and PeakKernel integrate on: as
/// fine as the Legendre coefficients of method photon (a droplet's forward peak is about a
/// degree wide, 110 steps).
constexpr int kPeakGridSteps = 20000;

/// The phase's integral over the sphere per channel on the grid of scattering angles that
/// splitForwardPeak and PeakKernel integrate on (midpoints 0.009 degrees apart): 1 for a
/// normalised phase whose forward peak the grid resolves. A narrower peak reads otherwise (HG
/// g = 0.9995: 1.004; 0.9999: 1.12; 0.99999: 0.31), and so does every integral of it there.
Rgb phaseIntegralOnPeakGrid(const PhaseFunction& phase);

/// The normalised shape of `split`'s peak, q = peak / its integral per channel, as a kernel on
/// the sphere: light scattered once through the peak spreads over the cone about its former
/// direction as q. Convolving a phase with it (and with itself for light scattered through the
/// peak again) smooths the sharp features of p, its forward peak and the glory, that a view
/// would otherwise see as if that light still travelled along its first direction.
class PeakKernel {
 public:
  /// `p`: the phase (any fast form of it, such as a table); `split` must be active.
  PeakKernel(const ForwardPeak& split, const std::function<Rgb(double)>& p);
  /// The peak's integral per channel (its share of scattering), by the kernel's quadrature.
  const Rgb& fraction() const { return fraction_; }
  /// Integral of q(w') f(w' . w) dw' over the cone about the axis, for w at cos theta from it.
  /// `f`: any callable Rgb(double); inlined here, since a view's droplet peak calls it about
  /// four million times (PhotonPeakLight).
  template <typename F>
  Rgb convolve(F&& f, double cos_theta) const;

 private:
  struct Node {
    double cos_t, sin_t;  // the angle from the peak's axis
    Rgb weight;           // q sin dtheta dphi, normalised over all nodes
  };
  std::vector<Node> nodes_;
  std::vector<double> cos_phi_;  // azimuths over [0, pi] (the integrand is even in phi)
  Rgb fraction_{0.0};
};

// Implementation.

template <typename F>
Rgb PeakKernel::convolve(F&& f, double cos_theta) const {
  if (nodes_.empty()) return f(cos_theta);
  const double c = std::clamp(cos_theta, -1.0, 1.0);
  const double s = std::sqrt(std::max(0.0, 1 - c * c));
  Rgb out(0.0);
  for (const Node& n : nodes_) {
    Rgb ring(0.0);
    for (double cp : cos_phi_) ring += f(c * n.cos_t + s * n.sin_t * cp);
    out += n.weight * ring;
  }
  return out;
}

}  // namespace cloudbake
