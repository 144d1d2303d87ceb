#include "core/volume/analytic.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "core/error.h"

namespace cloudbake {
namespace {

void checkDensity(double density, const char* what) {
  if (!std::isfinite(density) || density < 0) {
    std::ostringstream os;
    os << what << ": density must be finite and >= 0, got " << density;
    throw InputError(os.str());
  }
}

class BoxLookup final : public DensityField::Lookup {
 public:
  BoxLookup(const Bounds3& b, double d) : box_(b), density_(d) {}
  double density(const Vec3& p) override { return box_.contains(p) ? density_ : 0.0; }

 private:
  Bounds3 box_;
  double density_;
};

class SphereLookup final : public DensityField::Lookup {
 public:
  SphereLookup(const Vec3& c, double r, double d) : center_(c), r2_(r * r), density_(d) {}
  double density(const Vec3& p) override {
    const Vec3 v = p - center_;
    return dot(v, v) <= r2_ ? density_ : 0.0;
  }

 private:
  Vec3 center_;
  double r2_, density_;
};

}  // namespace

BoxDensity::BoxDensity(const Vec3& min, const Vec3& max, double density) : density_(density) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(min[a]) || !std::isfinite(max[a]) || !(min[a] < max[a])) {
      throw InputError("box: min must be finite and strictly less than max on every axis");
    }
  }
  checkDensity(density, "box");
  box_.min = min;
  box_.max = max;
  majorants_ = MajorantGrid::uniform(box_, static_cast<float>(density));
  tracking_ = std::make_shared<const MajorantGrid>(box_, 1, 1, 1,
                                                   std::vector<float>{static_cast<float>(density)},
                                                   std::vector<float>{static_cast<float>(density)});
}

std::unique_ptr<DensityField::Lookup> BoxDensity::lookup() const {
  return std::make_unique<BoxLookup>(box_, density_);
}

std::optional<double> BoxDensity::cellMean(const Bounds3& cell) const {
  double share = 1;
  for (int a = 0; a < 3; ++a) {
    const double width = cell.max[a] - cell.min[a];
    if (!(width > 0)) return std::nullopt;  // a degenerate cell: sampled as a point
    const double inside = std::min(cell.max[a], box_.max[a]) - std::max(cell.min[a], box_.min[a]);
    share *= std::clamp(inside / width, 0.0, 1.0);
  }
  return density_ * share;
}

double BoxDensity::featureSize() const {
  const Vec3 e = box_.extent();
  return std::min(e.x, std::min(e.y, e.z)) / 32.0;
}

std::string BoxDensity::describe() const {
  std::ostringstream os;
  os << "box [" << box_.min.x << "," << box_.min.y << "," << box_.min.z << "]-[" << box_.max.x
     << "," << box_.max.y << "," << box_.max.z << "] density " << density_;
  return os.str();
}

SphereDensity::SphereDensity(const Vec3& center, double radius, double density)
    : center_(center), radius_(radius), density_(density) {
  if (!isFinite(center)) throw InputError("sphere: center must be finite");
  if (!std::isfinite(radius) || !(radius > 0)) {
    throw InputError("sphere: radius must be finite and > 0");
  }
  checkDensity(density, "sphere");
  // A single cell would make every ray through the empty corners of the bounding box pay for
  // null collisions at the full density (about 1e6 per unit length at extinction 1e6). Cells
  // that do not touch the sphere get majorant 0, so tracking skips them outright.
  constexpr int kCells = 8;
  const Bounds3 b = bounds();
  const double cell = 2.0 * radius_ / kCells;
  std::vector<float> maxima(kCells * kCells * kCells, 0.f);
  for (int z = 0; z < kCells; ++z) {
    for (int y = 0; y < kCells; ++y) {
      for (int x = 0; x < kCells; ++x) {
        // Squared distance from the centre to the closest point of the cell.
        double d2 = 0;
        const int idx[3] = {x, y, z};
        for (int a = 0; a < 3; ++a) {
          const double lo = b.min[a] + idx[a] * cell, hi = lo + cell;
          const double c = center_[a];
          const double d = c < lo ? lo - c : (c > hi ? c - hi : 0.0);
          d2 += d * d;
        }
        if (d2 <= radius_ * radius_) {
          maxima[(static_cast<size_t>(z) * kCells + y) * kCells + x] = static_cast<float>(density);
        }
      }
    }
  }
  majorants_ = MajorantGrid(b, kCells, kCells, kCells, std::move(maxima));
}

bool SphereDensity::supportInterval(const Ray& ray, double tmin, double tmax, double* t0,
                                    double* t1) const {
  // |o + t d - c|^2 = r^2 with |d| = 1: t = -b -+ sqrt(b^2 - (|o - c|^2 - r^2)), b = d.(o - c).
  // The roots are widened by a relative 1e-9 so that points on the surface stay inside.
  const Vec3 oc = ray.o - center_;
  const double b = dot(ray.d, oc);
  const double disc = b * b - (dot(oc, oc) - radius_ * radius_);
  if (!(disc >= 0)) return false;
  const double h = std::sqrt(disc);
  const double pad = 1e-9 * (radius_ + std::abs(b));
  *t0 = std::max(tmin, -b - h - pad);
  *t1 = std::min(tmax, -b + h + pad);
  return *t1 > *t0;
}

Bounds3 SphereDensity::bounds() const {
  Bounds3 b;
  b.min = center_ - Vec3(radius_);
  b.max = center_ + Vec3(radius_);
  return b;
}

std::unique_ptr<DensityField::Lookup> SphereDensity::lookup() const {
  return std::make_unique<SphereLookup>(center_, radius_, density_);
}

std::string SphereDensity::describe() const {
  std::ostringstream os;
  os << "sphere center [" << center_.x << "," << center_.y << "," << center_.z << "] radius "
     << radius_ << " density " << density_;
  return os.str();
}

}  // namespace cloudbake
