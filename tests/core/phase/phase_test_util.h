// Quadrature and chi-square helpers shared by the phase-function tests.
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "core/math/rng.h"
#include "core/math/vec3.h"
#include "core/phase/phase_function.h"
#include "tests/chi_square_util.h"

namespace cloudbake::testing {

/// Breakpoints in cos(theta) clustered geometrically towards both poles, where peaked phase
/// functions (HG at |g| = 0.999, the Mie diffraction peak) put their mass.
inline std::vector<double> clusteredBreakpoints(double ratio, double smallest) {
  std::vector<double> b{-1.0, 1.0};
  for (double d = 1.0; d > smallest; d *= ratio) {
    b.push_back(1.0 - d);
    b.push_back(-1.0 + d);
  }
  std::sort(b.begin(), b.end());
  b.erase(std::unique(b.begin(), b.end()), b.end());
  return b;
}

/// 20-point Gauss-Legendre on [lo, hi] (nodes by Newton iteration, independent of the library).
inline double gaussLegendre(const std::function<double(double)>& f, double lo, double hi) {
  static const auto table = [] {
    constexpr int n = 20;
    std::vector<std::pair<double, double>> xw;
    for (int i = 0; i < n; ++i) {
      double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), dp = 1.0;
      for (int it = 0; it < 100; ++it) {
        double p0 = 1.0, p1 = z;
        for (int k = 2; k <= n; ++k) {
          const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
          p0 = p1;
          p1 = p2;
        }
        dp = n * (z * p1 - p0) / (z * z - 1.0);
        const double dz = p1 / dp;
        z -= dz;
        if (std::abs(dz) < 1e-16) break;
      }
      xw.emplace_back(z, 2.0 / ((1.0 - z * z) * dp * dp));
    }
    return xw;
  }();
  const double half = 0.5 * (hi - lo), mid = 0.5 * (hi + lo);
  double sum = 0.0;
  for (const auto& [x, w] : table) sum += w * f(mid + half * x);
  return sum * half;
}

/// Integral of f(mu) over [-1, 1] on the clustered breakpoints plus `extra` ones (e.g. the
/// nodes of a tabulated function, so kinks fall on interval ends).
inline double integrateCos(const std::function<double(double)>& f,
                           const std::vector<double>& extra = {}) {
  std::vector<double> b = clusteredBreakpoints(0.8, 1e-13);
  for (double e : extra) {
    if (e > -1.0 && e < 1.0) b.push_back(e);
  }
  std::sort(b.begin(), b.end());
  b.erase(std::unique(b.begin(), b.end()), b.end());
  double sum = 0.0;
  for (size_t i = 0; i + 1 < b.size(); ++i) {
    if (b[i + 1] > b[i]) sum += gaussLegendre(f, b[i], b[i + 1]);
  }
  return sum;
}

/// Per-channel sphere integral 2 pi int p dmu.
inline Rgb sphereIntegral(const PhaseFunction& p, const std::vector<double>& extra = {}) {
  Rgb r;
  for (int c = 0; c < 3; ++c) {
    r[c] = 2.0 * kPi * integrateCos([&](double mu) { return p.eval(mu)[c]; }, extra);
  }
  return r;
}

using testing_util::chiSquareCritical;

struct ChiSquareResult {
  double chi2 = 0;
  int dof = 0;
  double critical = 0;
};

/// Draws `n` samples of sampleCosTheta() from a fixed-seed stream, bins them in cos(theta) on
/// clustered bins, and compares against the bin probabilities 2 pi int pdf dmu from independent
/// quadrature. Bins with expected count < 5 are merged with their neighbours. Critical value at
/// significance 1e-4 (z = 3.719).
inline ChiSquareResult chiSquareTest(const PhaseFunction& p, int n, uint64_t seed,
                                     const std::vector<double>& extra = {}) {
  std::vector<double> edges = clusteredBreakpoints(0.6, 1e-9);
  for (int i = 1; i < 40; ++i) edges.push_back(-1.0 + 2.0 * i / 40.0);
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  const size_t nb = edges.size() - 1;
  std::vector<double> observed(nb, 0.0), expected(nb, 0.0);
  Rng rng(seed, 7);
  for (int i = 0; i < n; ++i) {
    const double mu = p.sampleCosTheta(rng.uniform());
    size_t b =
        static_cast<size_t>(std::upper_bound(edges.begin(), edges.end(), mu) - edges.begin());
    b = std::min(std::max<size_t>(b, 1), nb) - 1;
    observed[b] += 1.0;
  }
  std::vector<double> sub_extra;
  for (size_t b = 0; b < nb; ++b) {
    sub_extra.clear();
    for (double e : extra) {
      if (e > edges[b] && e < edges[b + 1]) sub_extra.push_back(e);
    }
    std::vector<double> pts{edges[b]};
    pts.insert(pts.end(), sub_extra.begin(), sub_extra.end());
    pts.push_back(edges[b + 1]);
    double prob = 0.0;
    for (size_t i = 0; i + 1 < pts.size(); ++i) {
      prob += 2.0 * kPi * gaussLegendre([&](double mu) { return p.pdf(mu); }, pts[i], pts[i + 1]);
    }
    expected[b] = prob * n;
  }
  // Merge consecutive bins until each cell expects >= 5 samples; a short tail joins the last cell.
  std::vector<std::pair<double, double>> cells;  // (observed, expected)
  double obs_acc = 0.0, exp_acc = 0.0;
  for (size_t b = 0; b < nb; ++b) {
    obs_acc += observed[b];
    exp_acc += expected[b];
    if (exp_acc >= 5.0) {
      cells.emplace_back(obs_acc, exp_acc);
      obs_acc = exp_acc = 0.0;
    }
  }
  if (!cells.empty()) {
    cells.back().first += obs_acc;
    cells.back().second += exp_acc;
  }
  ChiSquareResult r;
  for (const auto& [o, e] : cells) r.chi2 += (o - e) * (o - e) / e;
  const int n_cells = static_cast<int>(cells.size());
  r.dof = n_cells - 1;
  r.critical = chiSquareCritical(r.dof, 3.719);
  return r;
}

}  // namespace cloudbake::testing
