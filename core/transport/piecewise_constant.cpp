#include "core/transport/piecewise_constant.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace cloudbake {

PiecewiseConstant1D::PiecewiseConstant1D(std::vector<double> f) : f_(std::move(f)) {
  if (f_.empty()) throw std::invalid_argument("PiecewiseConstant1D: no bins");
  const size_t n = f_.size();
  cdf_.assign(n + 1, 0.0);
  for (size_t i = 0; i < n; ++i) cdf_[i + 1] = cdf_[i] + f_[i] / double(n);
  integral_ = cdf_[n];
  if (integral_ > 0) {
    for (size_t i = 1; i <= n; ++i) cdf_[i] /= integral_;
  } else {
    for (size_t i = 1; i <= n; ++i) cdf_[i] = double(i) / double(n);
  }
  cdf_[n] = 1.0;
}

double PiecewiseConstant1D::sample(double u, double* pdf, int* bin) const {
  const int n = size();
  // Last index with cdf_[i] <= u, skipping zero-width bins.
  int i = static_cast<int>(std::upper_bound(cdf_.begin(), cdf_.end(), u) - cdf_.begin()) - 1;
  i = std::clamp(i, 0, n - 1);
  const double width = cdf_[i + 1] - cdf_[i];
  double du = width > 0 ? (u - cdf_[i]) / width : 0.5;
  du = std::clamp(du, 0.0, 1.0);
  if (bin) *bin = i;
  if (pdf) *pdf = width * n;
  // Stay strictly below 1 so the caller's bin lookup agrees with `bin`.
  return std::min((i + du) / n, std::nextafter(1.0, 0.0));
}

double PiecewiseConstant1D::pdf(double x) const {
  const int n = size();
  const int i = std::clamp(static_cast<int>(x * n), 0, n - 1);
  return (cdf_[i + 1] - cdf_[i]) * n;
}

namespace {
std::vector<double> rowMeans(const std::vector<double>& f, int nu, int nv) {
  if (nu < 1 || nv < 1 || f.size() != size_t(nu) * nv) {
    throw std::invalid_argument("PiecewiseConstant2D: table size does not match nu x nv");
  }
  std::vector<double> m(nv, 0.0);
  for (int v = 0; v < nv; ++v) {
    double s = 0;
    for (int u = 0; u < nu; ++u) s += f[size_t(v) * nu + u];
    m[v] = s / nu;
  }
  return m;
}
}  // namespace

PiecewiseConstant2D::PiecewiseConstant2D(const std::vector<double>& f, int nu, int nv)
    : marginal_(rowMeans(f, nu, nv)) {
  conditional_.reserve(nv);
  for (int v = 0; v < nv; ++v) {
    conditional_.emplace_back(
        std::vector<double>(f.begin() + size_t(v) * nu, f.begin() + size_t(v + 1) * nu));
  }
}

void PiecewiseConstant2D::sample(double u1, double u2, double* u, double* v, double* pdf) const {
  double pdf_v, pdf_u;
  int row;
  *v = marginal_.sample(u2, &pdf_v, &row);
  *u = conditional_[row].sample(u1, &pdf_u, nullptr);
  *pdf = pdf_v * pdf_u;
}

double PiecewiseConstant2D::pdf(double u, double v) const {
  const int nv = marginal_.size();
  const int row = std::clamp(static_cast<int>(v * nv), 0, nv - 1);
  return marginal_.pdf(v) * conditional_[row].pdf(u);
}

}  // namespace cloudbake
