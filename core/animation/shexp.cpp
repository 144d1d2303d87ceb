#include "core/animation/shexp.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "core/animation/optical_depth_sh.h"
#include "core/error.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/vector_clones.h"
#include "core/math/vector_exp.h"

namespace cloudbake {
namespace {

// GCC's and clang's portable vector extension: 8 doubles, one AVX-512 register (two AVX ones in
// the AVX2 clone, four SSE2 ones in the baseline), with IEEE arithmetic per lane.
typedef double Double8 __attribute__((vector_size(64)));
constexpr int kWidth = 8;
static_assert(kShCoefficients % kWidth == 0, "the sums run eight coefficients a vector");

double hatNorm(const ShCoefficients& g) {
  double s = 0;
  for (int i = 1; i < kShCoefficients; ++i) s += double(g[size_t(i)]) * g[size_t(i)];
  return std::sqrt(s);
}

// Halvings that bring |g^| to at most 1 (scaling and squaring), at most 16.
int squarings(const ShCoefficients& g) {
  const double m = hatNorm(g);
  return m <= 1 ? 0 : std::min(16, int(std::ceil(std::log2(m))));
}

ShCoefficients scaled(const ShCoefficients& g, int k) {
  ShCoefficients out = g;
  const float f = std::ldexp(1.0f, -k);
  for (float& v : out) v *= f;
  return out;
}

// The SH projection of exp(g(w)) by quadrature over the directions of `q`; `transmittance`
// keeps g(w) <= 0 (g = -tau: a transmittance is at most 1). Directions go in blocks of 16, two
// vectors of g(w) summed coefficient by coefficient in registers (every direction's sum still
// in coefficient order), then their exps (vectorExp, a loop that vectorises too: libm's exp, one
// call a direction, was over half of SHEXP's time), then the accumulation by direction, eight
// coefficients a vector, each lane summing in direction order (left to itself GCC vectorised
// that loop across directions instead, as in-order reductions: 1.6x slower). So the result is
// the direction-at-a-time loop's, bit for bit, in every clone: eight lanes a vector rather than
// four took a `precomputed` frame's SHEXP from 0.172-0.174 s to 0.149-0.157 s on this AVX-512
// machine. Directions whose exp underflowed add +-0 to sums that start at +0 and so never become
// -0: they need no test.
CLOUDBAKE_WIDE_VECTOR_CLONES ShCoefficients projectExp(const ShCoefficients& g,
                                                       const ShQuadrature& q, bool transmittance) {
  constexpr size_t kBlock = ShQuadrature::kBlock;
  constexpr int kLanes = int(kBlock / kWidth);
  const size_t n = q.by_direction.size();
  Double8 gi[kShCoefficients];
  for (int i = 0; i < kShCoefficients; ++i) {
    const double v = g[size_t(i)];
    gi[i] = Double8{v, v, v, v, v, v, v, v};
  }
  Double8 acc[kShCoefficients / kWidth] = {};
  for (size_t d0 = 0; d0 < n; d0 += kBlock) {
    Double8 fv[kLanes] = {};
    for (int i = 0; i < kShCoefficients; ++i) {
      const double* y = q.by_coefficient.data() + size_t(i) * q.stride + d0;
      for (int k = 0; k < kLanes; ++k) {
        Double8 yk;
        std::memcpy(&yk, y + kWidth * k, sizeof yk);
        fv[k] += gi[i] * yk;
      }
    }
    double f[kBlock];
    std::memcpy(f, fv, sizeof f);
    for (size_t j = 0; j < kBlock; ++j)
      f[j] = vectorExp(transmittance ? std::min(0.0, f[j]) : f[j]);
    const size_t m = std::min(kBlock, n - d0);
    for (size_t j = 0; j < m; ++j) {
      const double v = f[j];
      const Double8 fj = {v, v, v, v, v, v, v, v};
      const double* y = q.by_direction[d0 + j].data();
      for (int k = 0; k < kShCoefficients / kWidth; ++k) {
        Double8 yk;
        std::memcpy(&yk, y + kWidth * k, sizeof yk);
        acc[k] += fj * yk;
      }
    }
  }
  ShCoefficients out{};
  for (int i = 0; i < kShCoefficients; ++i) {
    out[size_t(i)] = float(acc[i / kWidth][i % kWidth] * 4 * kPi / double(n));
  }
  return out;
}

}  // namespace

ShQuadrature::ShQuadrature(int directions) {
  for (const Vec3& w : sphereDirections(directions)) by_direction.push_back(shBasis(w));
  const size_t n = by_direction.size();
  stride = (n + kBlock - 1) / kBlock * kBlock;
  by_coefficient.assign(stride * kShCoefficients, 0.0);
  for (size_t d = 0; d < n; ++d) {
    for (int i = 0; i < kShCoefficients; ++i) {
      by_coefficient[size_t(i) * stride + d] = by_direction[d][size_t(i)];
    }
  }
}

ShCoefficients shExpReference(const ShCoefficients& g, int directions) {
  return projectExp(g, ShQuadrature(directions), /*transmittance=*/false);
}

ShExp ShExp::fit(const std::vector<ShCoefficients>& samples, int bins, int directions) {
  if (samples.size() < 8) {
    throw InputError("shexp: needs at least 8 sample vectors, got " +
                     std::to_string(samples.size()));
  }
  if (bins < 4 || bins > 4096) {
    throw InputError("shexp: bins must be in [4, 4096], got " + std::to_string(bins));
  }
  ShExp e;
  e.quadrature_ = ShQuadrature(kQuadratureDirections);
  std::vector<ShCoefficients> reduced;
  reduced.reserve(samples.size());
  for (const ShCoefficients& g : samples) {
    for (float v : g) {
      if (!std::isfinite(v)) throw InputError("shexp: a sample vector is not finite");
    }
    reduced.push_back(scaled(g, squarings(g)));
    e.range_ = std::max(e.range_, hatNorm(reduced.back()));
  }
  const double width = e.range_ > 0 ? e.range_ / bins : 1.0;
  // Per bin, minimise sum |a 1 + b g^ - t|^2 with t = reference / exp(g_0 / sqrt(4 pi)). The
  // basis 1 and g^ are orthogonal, so a and b separate.
  std::vector<double> sa(size_t(bins), 0), na(size_t(bins), 0), sb(size_t(bins), 0),
      nb(size_t(bins), 0);
  const ShQuadrature quadrature(directions);  // once for every sample, not once each
  for (const ShCoefficients& g : reduced) {
    const ShCoefficients ref = projectExp(g, quadrature, /*transmittance=*/false);
    const double scale = std::exp(double(g[0]) / kSqrt4Pi);
    const int k = std::min(bins - 1, int(hatNorm(g) / width));
    sa[size_t(k)] += double(ref[0]) / scale * kSqrt4Pi;
    na[size_t(k)] += 4 * kPi;
    for (int i = 1; i < kShCoefficients; ++i) {
      sb[size_t(k)] += double(ref[size_t(i)]) / scale * g[size_t(i)];
      nb[size_t(k)] += double(g[size_t(i)]) * g[size_t(i)];
    }
  }
  e.a_.assign(size_t(bins), std::nan(""));
  e.b_.assign(size_t(bins), std::nan(""));
  for (int k = 0; k < bins; ++k) {
    if (na[size_t(k)] > 0) e.a_[size_t(k)] = sa[size_t(k)] / na[size_t(k)];
    if (nb[size_t(k)] > 0) e.b_[size_t(k)] = sb[size_t(k)] / nb[size_t(k)];
  }
  // At |g^| = 0 the exact answer is a = 1, b = 1 (exp of a constant; first order in g^).
  if (std::isnan(e.a_[0])) e.a_[0] = 1;
  if (std::isnan(e.b_[0])) e.b_[0] = 1;
  for (std::vector<double>* t : {&e.a_, &e.b_}) {
    for (int k = 1; k < bins; ++k) {
      if (std::isnan((*t)[size_t(k)])) (*t)[size_t(k)] = (*t)[size_t(k) - 1];
    }
  }
  return e;
}

ShCoefficients ShExp::projectTransmittance(const ShCoefficients& g) const {
  return projectExp(g, quadrature_, /*transmittance=*/true);
}

ShCoefficients ShExp::operator()(const ShCoefficients& g_in) const {
  const int k = squarings(g_in);
  if (k > 0) return projectTransmittance(g_in);
  const ShCoefficients& g = g_in;
  const int bins = int(a_.size());
  const double width = range_ > 0 ? range_ / bins : 1.0;
  // Linear interpolation between the bin centres, and from the exact values at |g^| = 0 (a = b =
  // 1: the exponential of a constant, and its first-order term) to the first centre.
  const double x = hatNorm(g) / width - 0.5;
  double a, b;
  if (x < 0) {
    const double t = x + 0.5;  // 0 at |g^| = 0, 1 at the first centre
    a = 1 + (a_[0] - 1) * t;
    b = 1 + (b_[0] - 1) * t;
  } else {
    const double xc = std::min(x, double(bins - 1));
    const int k0 = std::min(bins - 1, int(xc)), k1 = std::min(bins - 1, k0 + 1);
    const double t = xc - k0;
    a = a_[size_t(k0)] * (1 - t) + a_[size_t(k1)] * t;
    b = b_[size_t(k0)] * (1 - t) + b_[size_t(k1)] * t;
  }
  const double scale = std::exp(double(g[0]) / kSqrt4Pi);
  ShCoefficients out{};
  out[0] = float(scale * a * kSqrt4Pi);
  for (int i = 1; i < kShCoefficients; ++i) out[size_t(i)] = float(scale * b * g[size_t(i)]);
  return out;
}

ShExp ShExp::fromTables(std::vector<double> a, std::vector<double> b, double range) {
  if (a.size() != b.size() || a.size() < 4 || a.size() > 4096 || !(range >= 0) ||
      !std::isfinite(range)) {
    throw InputError("shexp: tables of " + std::to_string(a.size()) + " and " +
                     std::to_string(b.size()) + " bins over range " + std::to_string(range) +
                     " are not valid");
  }
  for (size_t i = 0; i < a.size(); ++i) {
    if (!std::isfinite(a[i]) || !std::isfinite(b[i])) {
      throw InputError("shexp: table bin " + std::to_string(i) + " is not finite");
    }
  }
  ShExp e;
  e.quadrature_ = ShQuadrature(kQuadratureDirections);
  e.a_ = std::move(a);
  e.b_ = std::move(b);
  e.range_ = range;
  return e;
}

}  // namespace cloudbake
