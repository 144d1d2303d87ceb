#include "core/phase/draine.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/phase/henyey_greenstein.h"

namespace cloudbake {
namespace {

// Nodes and weights of 32-point Gauss-Legendre quadrature on [-1, 1], computed once by Newton
// iteration on P_32 (Golub-Welsch is overkill at this size).
struct GaussLegendre32 {
  double x[32], w[32];
  GaussLegendre32() {
    constexpr int n = 32;
    for (int i = 0; i < n; ++i) {
      double z = std::cos(kPi * (i + 0.75) / (n + 0.5));
      double dp = 1.0;
      for (int iter = 0; iter < 100; ++iter) {
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
      x[i] = z;
      w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
    }
  }
};

const GaussLegendre32& gaussLegendre32() {
  static const GaussLegendre32 table;
  return table;
}

// Unnormalised integrand in mu: (1 + alpha mu^2) (1 + g^2 - 2 g mu)^(-3/2).
double draineKernel(double g, double alpha, double mu) {
  const double s = 1.0 + g * g - 2.0 * g * mu;
  return (1.0 + alpha * mu * mu) / (s * std::sqrt(s));
}

// Integral of draineKernel over [-1, mu].
double draineKernelIntegral(double g, double alpha, double mu) {
  if (std::abs(g) >= 0.1) {
    // Substituting s = 1 + g^2 - 2 g mu turns the integrand into a polynomial in s times s^-3/2.
    const double a = 1.0 + g * g;
    const double k = alpha / (4.0 * g * g);
    auto antiderivative = [&](double s) {
      const double rs = std::sqrt(s);
      return -2.0 * (1.0 + k * a * a) / rs - 4.0 * k * a * rs + (2.0 / 3.0) * k * s * rs;
    };
    const double s0 = (1.0 + g) * (1.0 + g);
    const double s1 = std::max(a - 2.0 * g * mu, 0.0);
    return (antiderivative(s0) - antiderivative(s1)) / (2.0 * g);
  }
  const GaussLegendre32& gl = gaussLegendre32();
  const double half = 0.5 * (mu + 1.0), mid = 0.5 * (mu - 1.0);
  double sum = 0.0;
  for (int i = 0; i < 32; ++i) sum += gl.w[i] * draineKernel(g, alpha, mid + half * gl.x[i]);
  return sum * half;
}

}  // namespace

double draineEval(double g, double alpha, double cos_theta) {
  const double norm = (1.0 - g * g) / (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0);
  return kInv4Pi * norm * draineKernel(g, alpha, cos_theta);
}

double draineCdf(double g, double alpha, double cos_theta) {
  const double mu = std::clamp(cos_theta, -1.0, 1.0);
  // The full integral is known exactly: 2 (1 + alpha (1 + 2 g^2) / 3) / (1 - g^2).
  const double total = 2.0 * (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0) / (1.0 - g * g);
  return std::clamp(draineKernelIntegral(g, alpha, mu) / total, 0.0, 1.0);
}

double draineSampleCosTheta(double g, double alpha, double u) {
  // The HG inverse with the same g is a close first guess; Newton on the CDF with a bisection
  // bracket never leaves [-1, 1] and converges quadratically once near the root.
  double lo = -1.0, hi = 1.0;
  double mu = hgSampleCosTheta(g, u);
  for (int iter = 0; iter < 100; ++iter) {
    const double f = draineCdf(g, alpha, mu) - u;
    if (f < 0.0)
      lo = mu;
    else
      hi = mu;
    const double dens = 2.0 * kPi * draineEval(g, alpha, mu);
    double next = mu - f / dens;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - mu) <= 1e-15 * (1.0 + std::abs(mu)) || hi - lo <= 1e-15) {
      mu = next;
      break;
    }
    mu = next;
  }
  return std::clamp(mu, -1.0, 1.0);
}

double draineMeanCosine(double g, double alpha) {
  return (g + alpha * (3.0 * g + 2.0 * g * g * g) / 5.0) /
         (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0);
}

DrainePhase::DrainePhase(double g, double alpha) : g_(g), alpha_(alpha) {
  if (!std::isfinite(g) || !(g > -1.0 && g < 1.0)) {
    std::ostringstream os;
    os << "draine.g: must be in (-1, 1), got " << g;
    throw InputError(os.str());
  }
  if (!std::isfinite(alpha) || alpha < 0.0) {
    std::ostringstream os;
    os << "draine.alpha: must be finite and >= 0, got " << alpha;
    throw InputError(os.str());
  }
}

std::string DrainePhase::describe() const {
  std::ostringstream os;
  os << "draine(g=" << g_ << ",alpha=" << alpha_ << ")";
  return os.str();
}

}  // namespace cloudbake
