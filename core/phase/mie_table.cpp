#include "core/phase/mie_table.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/math/parallel.h"
#include "core/phase/lorenz_mie.h"
#include "core/phase/size_distribution.h"

namespace cloudbake {

using Complex = std::complex<double>;

std::vector<double> mieTableAngleGridDeg() {
  // (end of segment, step) pairs, degrees.
  static constexpr double kSegments[][2] = {{1.0, 0.02},  {5.0, 0.1},    {20.0, 0.25}, {60.0, 0.5},
                                            {125.0, 1.0}, {175.0, 0.25}, {180.0, 0.05}};
  std::vector<double> theta{0.0};
  double start = 0.0;
  for (const auto& seg : kSegments) {
    const int n = static_cast<int>(std::lround((seg[0] - start) / seg[1]));
    for (int i = 1; i <= n; ++i) theta.push_back(start + (seg[0] - start) * i / n);
    start = seg[0];
  }
  return theta;
}

namespace {

// (|S1|^2 + |S2|^2) at every angle for one channel: a row per size parameter xs[k], computed in
// parallel (each row independent, so the result is deterministic).
std::vector<double> scatteredIntensityRows(const std::vector<double>& xs, Complex m,
                                           const std::vector<double>& mu,
                                           const std::function<bool()>& keep_going) {
  const size_t n_mu = mu.size();
  const int n_x = int(xs.size());
  const int n_max = mieTermCount(xs.back() * (1.0 + 1e-9)) + 1;
  std::vector<double> pi_table, tau_table;
  mieAngularFunctions(n_max, mu, &pi_table, &tau_table);
  std::vector<double> rows(static_cast<size_t>(n_x) * n_mu);
  parallelFor(0, n_x, [&](int64_t k0, int64_t k1) {
    std::vector<Complex> a, b;
    std::vector<double> s1r(n_mu), s1i(n_mu), s2r(n_mu), s2i(n_mu);
    for (int k = int(k0); k < k1; ++k) {
      // A row is at most ~10 ms (x ~ 1e4 terms x the angles): checked per row.
      if (keep_going && !keep_going()) throw Cancelled();
      mieCoefficients(xs[size_t(k)], m, &a, &b);
      std::fill(s1r.begin(), s1r.end(), 0.0);
      std::fill(s1i.begin(), s1i.end(), 0.0);
      std::fill(s2r.begin(), s2r.end(), 0.0);
      std::fill(s2i.begin(), s2i.end(), 0.0);
      const int n_terms = std::min(static_cast<int>(a.size()), n_max);
      // Loop over terms outside, angles inside: the inner loop is a vectorisable axpy.
      for (int n = 1; n <= n_terms; ++n) {
        const double f = (2.0 * n + 1.0) / (n * (n + 1.0));
        const double ar = a[n - 1].real() * f, ai = a[n - 1].imag() * f;
        const double br = b[n - 1].real() * f, bi = b[n - 1].imag() * f;
        const double* pi = &pi_table[static_cast<size_t>(n - 1) * n_mu];
        const double* tau = &tau_table[static_cast<size_t>(n - 1) * n_mu];
        for (size_t j = 0; j < n_mu; ++j) {
          s1r[j] += ar * pi[j] + br * tau[j];
          s1i[j] += ai * pi[j] + bi * tau[j];
          s2r[j] += ar * tau[j] + br * pi[j];
          s2i[j] += ai * tau[j] + bi * pi[j];
        }
      }
      double* row = &rows[static_cast<size_t>(k) * n_mu];
      for (size_t j = 0; j < n_mu; ++j) {
        row[j] = s1r[j] * s1r[j] + s1i[j] * s1i[j] + s2r[j] * s2r[j] + s2i[j] * s2i[j];
      }
    }
  });
  return rows;
}

// Size-parameter nodes from x_lo to x_hi: steps of dx up to x = dx / relative, then relative x.
// A row costs about x terms, so uniform steps cost x_hi^2 / (2 dx) terms in all; a heavy-tailed
// distribution (r_eff 50 um, v_eff 0.499, radii to about 1 mm) reached x of 10^4 and minutes
// of build. Growing steps cost about x_hi / relative. They no longer resolve each interference
// ripple at large x, but they need not: n(r) varies over many ripple periods there (its scale
// b = r_eff v_eff is thousands of ripples wide in x), so the ripples average out in the sum
// like a stratified sample.
std::vector<double> sizeParameterNodes(double x_lo, double x_hi, double dx, double relative) {
  std::vector<double> xs{x_lo};
  while (xs.back() < x_hi) {
    const double step = std::max(dx, relative * xs.back());
    xs.push_back(xs.back() + step >= x_hi - 0.25 * step ? x_hi : xs.back() + step);
  }
  if (xs.size() < 2) xs.push_back(x_hi + dx);
  return xs;
}

// The sub-band centres of channel c, ascending.
std::vector<double> bandWavelengths(const MieTableOptions& o, int c) {
  const double l0 = o.band_um[size_t(c)][0], l1 = o.band_um[size_t(c)][1];
  const int n_l = o.wavelengths_per_channel;
  std::vector<double> lambda(static_cast<size_t>(n_l));
  for (int i = 0; i < n_l; ++i) lambda[size_t(i)] = l0 + (l1 - l0) * (i + 0.5) / n_l;
  return lambda;
}

// One sweep over x serves every wavelength of a band (same m): x = 2 pi r / lambda over the
// distribution's support.
std::vector<double> channelNodes(const MieTableOptions& o, const GammaSizeDistribution& dist,
                                 const std::vector<double>& lambda) {
  const auto [r_min, r_max] = dist.support();
  const double x_lo = std::max(2.0 * kPi * r_min / lambda.back(), 1e-3);
  const double x_hi = 2.0 * kPi * r_max / lambda.front();
  return sizeParameterNodes(x_lo, x_hi, o.dx, o.relative_dx);
}

void validateOptions(const MieTableOptions& o) {
  for (int c = 0; c < 3; ++c) {
    const double l0 = o.band_um[c][0], l1 = o.band_um[c][1];
    if (!std::isfinite(l0) || !std::isfinite(l1) || !(l0 > 0.0) || !(l1 >= l0) || l1 > 100.0) {
      std::ostringstream os;
      os << "phase.band[" << c << "]: wavelength band must satisfy 0 < lo <= hi <= 100 um, got ["
         << l0 << ", " << l1 << "]";
      throw InputError(os.str());
    }
    normalizeRefractiveIndex(o.refractive_index[c]);
  }
  if (o.wavelengths_per_channel < 1 || o.wavelengths_per_channel > 100) {
    throw InputError("phase.wavelengths_per_channel: must be in [1, 100], got " +
                     std::to_string(o.wavelengths_per_channel));
  }
  if (!std::isfinite(o.dx) || o.dx < 0.01 || o.dx > 2.0) {
    std::ostringstream os;
    os << "phase.dx: size-parameter step must be in [0.01, 2], got " << exactNumber(o.dx);
    throw InputError(os.str());
  }
  if (!std::isfinite(o.relative_dx) || o.relative_dx < 0 || o.relative_dx > 0.1) {
    std::ostringstream os;
    os << "phase.relative_dx: relative size-parameter step must be in [0, 0.1], got "
       << exactNumber(o.relative_dx);
    throw InputError(os.str());
  }
}

}  // namespace

double mieTableWork(const MieTableOptions& o) {
  validateOptions(o);
  const GammaSizeDistribution dist(o.effective_radius_um, o.effective_variance);
  double terms = 0;
  for (int c = 0; c < 3; ++c) {
    for (const double x : channelNodes(o, dist, bandWavelengths(o, c))) terms += mieTermCount(x);
  }
  return terms * double(mieTableAngleGridDeg().size());
}

double estimateMieTableSeconds(const MieTableOptions& o, int threads) {
  // Measured on the reference machine (2 cores of the CI kind; build seconds / mieTableWork for
  // r_eff 1-50 um, v_eff 0.01-0.499 all within 6.1-7.3e-10 on 2 threads): per core,
  constexpr double kSecondsPerTermAngle = 1.3e-9;
  return mieTableWork(o) * kSecondsPerTermAngle / std::max(1, threads);
}

MieTablePhase::MieTablePhase(const MieTableOptions& o, const std::function<bool()>& keep_going) {
  const auto t_start = std::chrono::steady_clock::now();
  validateOptions(o);
  const GammaSizeDistribution dist(o.effective_radius_um, o.effective_variance);
  const std::vector<double> theta = mieTableAngleGridDeg();
  // Nodes ascending in mu = cos(theta), i.e. theta descending.
  mu_.resize(theta.size());
  for (size_t j = 0; j < theta.size(); ++j) {
    const double t = theta[theta.size() - 1 - j];
    mu_[j] = t == 90.0 ? 0.0 : std::cos(t * kPi / 180.0);
  }
  mu_.front() = -1.0;
  mu_.back() = 1.0;
  const size_t n_mu = mu_.size();
  value_.assign(n_mu, Rgb(0.0));

  for (int c = 0; c < 3; ++c) {
    const int n_l = o.wavelengths_per_channel;
    const std::vector<double> lambda = bandWavelengths(o, c);
    const std::vector<double> xs = channelNodes(o, dist, lambda);
    const int n_x = int(xs.size());
    const std::vector<double> rows =
        scatteredIntensityRows(xs, o.refractive_index[c], mu_, keep_going);
    // Scattering-weighted average over wavelengths: n(r) C_sca p = n(r) (|S1|^2+|S2|^2) / (2 k^2)
    // with dr = lambda / (2 pi) dx; trapezoid rule in x over the (uneven) nodes.
    std::vector<double> acc(n_mu, 0.0);
    for (int i = 0; i < n_l; ++i) {
      const double dr_dx = lambda[i] / (2.0 * kPi);
      const double inv_k2 = dr_dx * dr_dx;
      for (int k = 0; k < n_x; ++k) {
        const double r = xs[size_t(k)] * dr_dx;
        const double span = xs[size_t(std::min(k + 1, n_x - 1))] - xs[size_t(std::max(k - 1, 0))];
        const double w = dist.density(r) * dr_dx * 0.5 * span * inv_k2;
        if (w == 0.0) continue;
        const double* row = &rows[static_cast<size_t>(k) * n_mu];
        for (size_t j = 0; j < n_mu; ++j) acc[j] += w * row[j];
      }
    }
    for (size_t j = 0; j < n_mu; ++j) value_[j][c] = acc[j];
  }
  std::ostringstream os;
  os << "mie(reff=" << o.effective_radius_um << "um,veff=" << o.effective_variance << ")";
  description_ = os.str();
  finalize();
  build_seconds_ = secondsSince(t_start);
}

MieTablePhase::MieTablePhase(const std::vector<double>& theta_deg, const std::vector<Rgb>& values) {
  if (theta_deg.size() < 2 || theta_deg.size() != values.size()) {
    throw InputError("phase table: need at least 2 angles and one value per angle");
  }
  if (theta_deg.front() != 0.0 || theta_deg.back() != 180.0) {
    throw InputError("phase table: angles must run from 0 to 180 degrees");
  }
  const size_t n = theta_deg.size();
  mu_.resize(n);
  value_.resize(n);
  for (size_t j = 0; j < n; ++j) {
    const size_t src = n - 1 - j;
    if (j > 0 && !(theta_deg[src] < theta_deg[src + 1])) {
      throw InputError("phase table: angles must be strictly increasing");
    }
    const Rgb& v = values[src];
    if (!isFinite(v) || v.x < 0 || v.y < 0 || v.z < 0) {
      throw InputError("phase table: values must be finite and >= 0");
    }
    mu_[j] = std::cos(theta_deg[src] * kPi / 180.0);
    value_[j] = v;
  }
  mu_.front() = -1.0;
  mu_.back() = 1.0;
  finalize();
}

void MieTablePhase::finalize() {
  const size_t n = mu_.size();
  // Normalise each channel of the piecewise-linear interpolant: 2 pi int p dmu = 1.
  Rgb integral(0.0);
  for (size_t j = 0; j + 1 < n; ++j) {
    integral += (value_[j] + value_[j + 1]) * (0.5 * (mu_[j + 1] - mu_[j]));
  }
  integral *= 2.0 * kPi;
  for (int c = 0; c < 3; ++c) {
    if (!(integral[c] > 0.0) || !std::isfinite(integral[c])) {
      throw InputError("phase table: channel " + std::to_string(c) + " has no positive integral");
    }
  }
  for (auto& v : value_) v = v / integral;
  pdf_.resize(n);
  for (size_t j = 0; j < n; ++j) pdf_[j] = average(value_[j]);
  cdf_.assign(n, 0.0);
  mean_cosine_ = Rgb(0.0);
  for (size_t j = 0; j + 1 < n; ++j) {
    const double h = mu_[j + 1] - mu_[j];
    cdf_[j + 1] = cdf_[j] + 2.0 * kPi * 0.5 * h * (pdf_[j] + pdf_[j + 1]);
    // Exact first moment of the linear interpolant on this segment.
    mean_cosine_ +=
        (value_[j] * (2.0 * mu_[j] + mu_[j + 1]) + value_[j + 1] * (mu_[j] + 2.0 * mu_[j + 1])) *
        (2.0 * kPi * h / 6.0);
  }
  // The channel average of normalised channels is normalised; remove the rounding residue.
  const double total = cdf_.back();
  for (auto& c : cdf_) c /= total;
  for (auto& p : pdf_) p /= total;
}

size_t MieTablePhase::segment(double mu) const {
  // Index j with mu_[j] <= mu <= mu_[j + 1].
  const auto it = std::upper_bound(mu_.begin(), mu_.end(), mu);
  const size_t j = static_cast<size_t>(it - mu_.begin());
  return std::min(std::max<size_t>(j, 1), mu_.size() - 1) - 1;
}

Rgb MieTablePhase::eval(double cos_theta) const {
  const double mu = std::clamp(cos_theta, -1.0, 1.0);
  const size_t j = segment(mu);
  const double t = (mu - mu_[j]) / (mu_[j + 1] - mu_[j]);
  return value_[j] * (1.0 - t) + value_[j + 1] * t;
}

double MieTablePhase::pdf(double cos_theta) const {
  const double mu = std::clamp(cos_theta, -1.0, 1.0);
  const size_t j = segment(mu);
  const double t = (mu - mu_[j]) / (mu_[j + 1] - mu_[j]);
  return pdf_[j] * (1.0 - t) + pdf_[j + 1] * t;
}

double MieTablePhase::sampleCosTheta(double u) const {
  const auto it = std::upper_bound(cdf_.begin(), cdf_.end(), u);
  size_t j = static_cast<size_t>(it - cdf_.begin());
  j = std::min(std::max<size_t>(j, 1), cdf_.size() - 1) - 1;
  // Invert the quadratic CDF of the linear density p0 + (p1 - p0) t / h on [0, h], in a form
  // without cancellation (also when p0 == 0 or p0 == p1).
  const double h = mu_[j + 1] - mu_[j];
  const double p0 = 2.0 * kPi * pdf_[j], p1 = 2.0 * kPi * pdf_[j + 1];
  const double r = std::max(u - cdf_[j], 0.0);
  const double disc = std::max(p0 * p0 + 2.0 * (p1 - p0) * r / h, 0.0);
  const double denom = p0 + std::sqrt(disc);
  const double t = denom > 0.0 ? std::min(2.0 * r / denom, h) : 0.0;
  return std::clamp(mu_[j] + t, -1.0, 1.0);
}

}  // namespace cloudbake
