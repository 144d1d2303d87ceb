#include "core/phase/forward_peak.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "core/math/sh_basis.h"

namespace cloudbake {

Rgb ForwardPeak::peak(double mu, const Rgb& p_mu) const {
  if (!(mu > cos_cut)) return Rgb(0.0);
  return Rgb(std::max(0.0, p_mu.x - p_cut.x), std::max(0.0, p_mu.y - p_cut.y),
             std::max(0.0, p_mu.z - p_cut.z));
}

namespace {

constexpr int kSteps = kPeakGridSteps;
// Cuts tried: every this many steps (0.045 degrees).
constexpr int kCutStride = 5;

struct ThetaGrid {
  std::vector<double> mu, weight, p_top;  // cos theta, 2 pi sin theta dtheta, P_degree(mu)
  std::vector<Rgb> p;                     // the phase
};

ThetaGrid sampleTheta(const PhaseFunction& phase, int degree) {
  ThetaGrid g;
  const double dtheta = kPi / kSteps;
  std::vector<double> legendre(size_t(degree) + 1);
  for (int k = 0; k < kSteps; ++k) {
    const double theta = (k + 0.5) * dtheta;
    g.mu.push_back(std::cos(theta));
    g.weight.push_back(2 * kPi * std::sin(theta) * dtheta);
    g.p.push_back(phase.eval(g.mu.back()));
    legendreP(degree, g.mu.back(), legendre.data());
    g.p_top.push_back(legendre[size_t(degree)]);
  }
  return g;
}

// The largest |rest_degree / rest_0| over channels for the cut at the start of step `cut`.
double restRatio(const ThetaGrid& g, const Rgb& p_l0, const Rgb& p_top, int cut, Rgb* p_cut,
                 Rgb* fraction, const PhaseFunction& phase) {
  const double cos_cut = std::cos(cut * kPi / kSteps);
  *p_cut = phase.eval(cos_cut);
  Rgb f(0.0), peak_top(0.0);
  for (int k = 0; k < cut; ++k) {
    for (int c = 0; c < 3; ++c) {
      const double e = std::max(0.0, g.p[size_t(k)][c] - (*p_cut)[c]) * g.weight[size_t(k)];
      f[c] += e;
      peak_top[c] += e * g.p_top[size_t(k)];
    }
  }
  *fraction = f;
  double worst = 0;
  for (int c = 0; c < 3; ++c) {
    const double rest0 = p_l0[c] - f[c];
    if (!(rest0 > 0)) return INFINITY;
    worst = std::max(worst, std::abs((p_top[c] - peak_top[c]) / rest0));
  }
  return worst;
}

}  // namespace

ForwardPeak splitForwardPeak(const PhaseFunction& phase, int degree, double max_legendre,
                             double max_angle_deg, bool* found) {
  const ThetaGrid g = sampleTheta(phase, degree);
  Rgb p_l0(0.0), p_top(0.0);
  for (size_t k = 0; k < g.mu.size(); ++k) {
    p_l0 += g.p[k] * g.weight[k];
    p_top += g.p[k] * (g.weight[k] * g.p_top[k]);
  }
  ForwardPeak split;
  split.integral = p_l0;
  *found = true;
  double worst = 0;
  for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(p_top[c] / p_l0[c]));
  if (worst <= max_legendre) return split;
  const int last = std::min(kSteps, int(std::ceil(max_angle_deg / 180.0 * kSteps)));
  for (int cut = kCutStride; cut <= last; cut += kCutStride) {
    Rgb p_cut, fraction;
    const double ratio = restRatio(g, p_l0, p_top, cut, &p_cut, &fraction, phase);
    split.cos_cut = std::cos(cut * kPi / kSteps);
    split.p_cut = p_cut;
    split.fraction = fraction;
    if (ratio <= max_legendre) return split;
  }
  *found = false;
  return split;
}

Rgb phaseIntegralOnPeakGrid(const PhaseFunction& phase) {
  const double dtheta = kPi / kSteps;
  Rgb sum(0.0);
  for (int k = 0; k < kSteps; ++k) {
    const double theta = (k + 0.5) * dtheta;
    sum += phase.eval(std::cos(theta)) * (2 * kPi * std::sin(theta) * dtheta);
  }
  return sum;
}

// Nodes across the cone in angle and in azimuth: the cone is a few degrees at most, so 32 x 16
// nodes resolve it to about a tenth of a degree.
constexpr int kConeNodes = 32;
constexpr int kAzimuthNodes = 16;

PeakKernel::PeakKernel(const ForwardPeak& split, const std::function<Rgb(double)>& p) {
  const double cut = std::acos(std::clamp(split.cos_cut, -1.0, 1.0));
  const Rgb p_cut = p(split.cos_cut);
  const double dtheta = cut / kConeNodes, dphi = kPi / kAzimuthNodes;
  Rgb sum(0.0);
  for (int k = 0; k < kConeNodes; ++k) {
    const double t = (k + 0.5) * dtheta;
    const Rgb pt = p(std::cos(t));
    Rgb q;
    for (int c = 0; c < 3; ++c) q[c] = std::max(0.0, pt[c] - p_cut[c]);
    const Rgb w = q * (std::sin(t) * dtheta * dphi);
    if (!(w.x > 0 || w.y > 0 || w.z > 0)) continue;
    nodes_.push_back({std::cos(t), std::sin(t), w});
    sum += w * double(kAzimuthNodes);
  }
  // The fraction on a finer grid than the nodes (the peak's mass lies in its first tenth of a
  // degree), as splitForwardPeak measures it.
  const int steps = std::max(1, int(std::ceil(cut / (kPi / kSteps))));
  const double h = cut / steps;
  for (int k = 0; k < steps; ++k) {
    const double t = (k + 0.5) * h;
    const Rgb pt = p(std::cos(t));
    for (int c = 0; c < 3; ++c) {
      fraction_[c] += std::max(0.0, pt[c] - p_cut[c]) * 2 * kPi * std::sin(t) * h;
    }
  }
  for (Node& n : nodes_) {
    for (int c = 0; c < 3; ++c) n.weight[c] = sum[c] > 0 ? n.weight[c] / sum[c] : 0.0;
  }
  for (int j = 0; j < kAzimuthNodes; ++j) cos_phi_.push_back(std::cos((j + 0.5) * dphi));
}

}  // namespace cloudbake
