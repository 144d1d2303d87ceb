#include "core/phase/lorenz_mie.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"

namespace cloudbake {

using Complex = std::complex<double>;

int mieTermCount(double x) {
  return std::max(1, static_cast<int>(std::ceil(x + 4.0 * std::cbrt(x) + 2.0)));
}

Complex normalizeRefractiveIndex(Complex m) {
  if (!std::isfinite(m.real()) || !std::isfinite(m.imag()) || !(m.real() > 0.0)) {
    std::ostringstream os;
    os << "mie.m: refractive index must have a finite real part > 0 and a finite imaginary part, "
       << "got " << m.real() << (m.imag() < 0 ? " - " : " + ") << std::abs(m.imag()) << "i";
    throw InputError(os.str());
  }
  if (std::abs(m) > kMaxRefractiveIndex) {
    std::ostringstream os;
    os << "mie.m: refractive index must have |m| <= " << kMaxRefractiveIndex << ", got |m| "
       << exactNumber(std::abs(m));
    throw InputError(os.str());
  }
  return {m.real(), std::abs(m.imag())};
}

void mieCoefficients(double x, Complex m_in, std::vector<Complex>* a, std::vector<Complex>* b) {
  if (!std::isfinite(x) || !(x >= 1e-8) || x > 1e5) {
    std::ostringstream os;
    os << "mie.x: size parameter must be in [1e-8, 1e5], got " << exactNumber(x);
    throw InputError(os.str());
  }
  const Complex m = normalizeRefractiveIndex(m_in);
  const Complex mx = m * x;
  if (std::abs(mx) > kMaxMieMx) {  // the downward recurrence holds about 1.1 |m x| terms
    std::ostringstream os;
    os << "mie.m: |m| x must be at most " << kMaxMieMx << ", got " << exactNumber(std::abs(mx));
    throw InputError(os.str());
  }
  const int n_stop = mieTermCount(x);
  // Start the downward recurrence far enough above both N and |mx| that the arbitrary start
  // value D = 0 has decayed to rounding level by n = N.
  const double start = std::max<double>(n_stop, std::abs(mx));
  const int n_mx = static_cast<int>(std::ceil(1.1 * start + 4.0 * std::cbrt(start) + 16.0));
  std::vector<Complex> d(n_mx + 1);
  d[n_mx] = 0.0;
  for (int n = n_mx; n >= 1; --n) {
    const Complex r = static_cast<double>(n) / mx;
    d[n - 1] = r - 1.0 / (d[n] + r);
  }

  // D_n(x) of the real argument, for psi_n beyond the turning point (see below).
  std::vector<double> d_real(n_mx + 1);
  d_real[n_mx] = 0.0;
  for (int n = n_mx; n >= 1; --n) {
    const double r = n / x;
    d_real[n - 1] = r - 1.0 / (d_real[n] + r);
  }

  a->assign(n_stop, 0.0);
  b->assign(n_stop, 0.0);
  // Riccati-Bessel psi_n(x) = x j_n(x) and chi_n(x) = -x y_n(x) by upward recurrence; xi = psi - i
  // chi.
  double psi0 = std::cos(x), psi1 = std::sin(x);
  double chi0 = -std::sin(x), chi1 = std::cos(x);
  Complex xi1(psi1, -chi1);
  for (int n = 1; n <= n_stop; ++n) {
    const double fn = (2.0 * n - 1.0) / x;
    // Upward recurrence is stable for psi only while n <= x (oscillatory regime); beyond, psi
    // decays and the recurrence would amplify rounding by chi/psi, so we use the ratio
    // psi_{n-1} / psi_n = D_n(x) + n / x, which has no zeros there (Wiscombe 1980; Cachorro &
    // Salcedo 1991). This keeps tiny x (Rayleigh regime) accurate.
    const double psi = n <= x ? fn * psi1 - psi0 : psi1 / (d_real[n] + n / x);
    const double chi = fn * chi1 - chi0;
    const Complex xi(psi, -chi);
    const double nx = n / x;
    const Complex da = d[n] / m + nx;
    const Complex db = d[n] * m + nx;
    (*a)[n - 1] = (da * psi - psi1) / (da * xi - xi1);
    (*b)[n - 1] = (db * psi - psi1) / (db * xi - xi1);
    psi0 = psi1;
    psi1 = psi;
    chi0 = chi1;
    chi1 = chi;
    xi1 = Complex(psi1, -chi1);
  }
}

MieEfficiencies mieEfficiencies(double x, const std::vector<Complex>& a,
                                const std::vector<Complex>& b) {
  MieEfficiencies r;
  const int n_terms = static_cast<int>(a.size());
  double qext = 0, qsca = 0, gsum = 0;
  Complex back = 0;
  for (int n = 1; n <= n_terms; ++n) {
    const Complex an = a[n - 1], bn = b[n - 1];
    const double w = 2.0 * n + 1.0;
    qext += w * (an.real() + bn.real());
    qsca += w * (std::norm(an) + std::norm(bn));
    back += (n % 2 == 0 ? w : -w) * (an - bn);
    gsum += w / (n * (n + 1.0)) * (an * std::conj(bn)).real();
    if (n < n_terms) {
      const Complex an1 = a[n], bn1 = b[n];
      gsum += n * (n + 2.0) / (n + 1.0) * (an * std::conj(an1) + bn * std::conj(bn1)).real();
    }
  }
  const double x2 = x * x;
  r.qext = 2.0 * qext / x2;
  r.qsca = 2.0 * qsca / x2;
  r.qback = std::norm(back) / x2;
  r.g = qsca > 0 ? 4.0 * gsum / (x2 * r.qsca) : 0.0;
  r.terms = n_terms;
  return r;
}

MieEfficiencies mieEfficiencies(double x, Complex m) {
  std::vector<Complex> a, b;
  mieCoefficients(x, m, &a, &b);
  return mieEfficiencies(x, a, b);
}

void mieAngularFunctions(int n_max, const std::vector<double>& mu, std::vector<double>* pi,
                         std::vector<double>* tau) {
  const size_t nm = mu.size();
  pi->assign(static_cast<size_t>(std::max(n_max, 0)) * nm, 0.0);
  tau->assign(pi->size(), 0.0);
  for (size_t j = 0; j < nm; ++j) {
    double pi_prev = 0.0, pi_cur = 1.0;  // pi_0, pi_1
    for (int n = 1; n <= n_max; ++n) {
      const size_t k = static_cast<size_t>(n - 1) * nm + j;
      (*pi)[k] = pi_cur;
      (*tau)[k] = n * mu[j] * pi_cur - (n + 1.0) * pi_prev;
      const double pi_next = ((2.0 * n + 1.0) * mu[j] * pi_cur - (n + 1.0) * pi_prev) / n;
      pi_prev = pi_cur;
      pi_cur = pi_next;
    }
  }
}

void mieAmplitudes(const std::vector<Complex>& a, const std::vector<Complex>& b,
                   const std::vector<double>& mu, std::vector<Complex>* s1,
                   std::vector<Complex>* s2) {
  const size_t nm = mu.size();
  s1->assign(nm, 0.0);
  s2->assign(nm, 0.0);
  const int n_terms = static_cast<int>(a.size());
  for (size_t j = 0; j < nm; ++j) {
    double pi_prev = 0.0, pi_cur = 1.0;
    Complex sum1 = 0, sum2 = 0;
    for (int n = 1; n <= n_terms; ++n) {
      const double tau = n * mu[j] * pi_cur - (n + 1.0) * pi_prev;
      const double f = (2.0 * n + 1.0) / (n * (n + 1.0));
      const Complex an = a[n - 1] * f, bn = b[n - 1] * f;
      sum1 += an * pi_cur + bn * tau;
      sum2 += an * tau + bn * pi_cur;
      const double pi_next = ((2.0 * n + 1.0) * mu[j] * pi_cur - (n + 1.0) * pi_prev) / n;
      pi_prev = pi_cur;
      pi_cur = pi_next;
    }
    (*s1)[j] = sum1;
    (*s2)[j] = sum2;
  }
}

}  // namespace cloudbake
