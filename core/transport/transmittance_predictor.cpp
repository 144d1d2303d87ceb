#include "core/transport/transmittance_predictor.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/math/parallel.h"

namespace cloudbake {
namespace {

// Upper bound of the transmittance from p along d: the minorant's optical depth.
double minorantTransmittance(const MajorantGrid& grid, double extinction, const Vec3& p,
                             const Vec3& d) {
  double tau = 0;
  grid.traverseBounds({p, d}, 0, std::numeric_limits<double>::infinity(),
                      [&](double t0, double t1, float /*maj*/, float min) {
                        tau += extinction * double(min) * (t1 - t0);
                        return tau < 50;  // exp(-50): nothing left to predict
                      });
  // Never 0 (the last cell may take tau far past 50, and a float flushes tiny values to 0): a
  // prediction of 0 would roulette away, always, events the light does reach.
  return std::exp(-std::min(tau, 50.0));
}

// Per cell, the largest of its 8 vertices' values.
std::vector<float> cellMaxima(const std::vector<float>& vertex, const int n[3]) {
  const int vx = n[0] + 1, vy = n[1] + 1;
  std::vector<float> cells(static_cast<size_t>(n[0]) * n[1] * n[2]);
  for (int z = 0; z < n[2]; ++z)
    for (int y = 0; y < n[1]; ++y)
      for (int x = 0; x < n[0]; ++x) {
        float m = 0;
        for (int c = 0; c < 8; ++c) {
          const size_t v =
              (size_t(z + ((c >> 2) & 1)) * vy + (y + ((c >> 1) & 1))) * vx + (x + (c & 1));
          m = std::max(m, vertex[v]);
        }
        cells[(size_t(z) * n[1] + y) * n[0] + x] = m;
      }
  return cells;
}

}  // namespace

TransmittancePredictor::TransmittancePredictor(const MajorantGrid& grid, double extinction,
                                               const Vec3* sun_dir, bool sky, int max_res) {
  if (!grid.hasMinorants() || !(extinction > 0) || (!sun_dir && !sky)) return;
  bounds_ = grid.bounds();
  // Cells about cubic, max_res along the longest axis.
  const Vec3 e = bounds_.extent();
  const double longest = std::max(e.x, std::max(e.y, e.z));
  for (int a = 0; a < 3; ++a) {
    n_[a] = std::clamp(int(std::lround(max_res * e[a] / longest)), 1, max_res);
    inv_cell_[a] = e[a] > 0 ? n_[a] / e[a] : 0.0;
  }
  const int vx = n_[0] + 1, vy = n_[1] + 1, vz = n_[2] + 1;
  std::vector<float> sun_v, sky_v;
  if (sun_dir) sun_v.assign(size_t(vx) * vy * vz, 0.f);
  if (sky) sky_v.assign(size_t(vx) * vy * vz, 0.f);
  static const Vec3 kAxes[6] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  const Vec3 ext = e;
  parallelFor(0, vz, [&](size_t z) {
    for (int y = 0; y < vy; ++y)
      for (int x = 0; x < vx; ++x) {
        const Vec3 p = bounds_.min + Vec3(ext.x * x / n_[0], ext.y * y / n_[1], ext.z * z / n_[2]);
        const size_t i = (z * vy + y) * vx + x;
        if (sun_dir) sun_v[i] = float(minorantTransmittance(grid, extinction, p, *sun_dir));
        if (sky) {
          double best = 0;
          for (const Vec3& d : kAxes) {
            best = std::max(best, minorantTransmittance(grid, extinction, p, d));
          }
          sky_v[i] = float(best);
        }
      }
  });
  if (sun_dir) sun_ = cellMaxima(sun_v, n_);
  if (sky) sky_ = cellMaxima(sky_v, n_);
}

double TransmittancePredictor::at(const std::vector<float>& cells, const Vec3& p) const {
  if (cells.empty() || !bounds_.contains(p)) return 1.0;
  int c[3];
  for (int a = 0; a < 3; ++a) {
    c[a] = std::clamp(int((p[a] - bounds_.min[a]) * inv_cell_[a]), 0, n_[a] - 1);
  }
  return cells[(size_t(c[2]) * n_[1] + c[1]) * n_[0] + c[0]];
}

}  // namespace cloudbake
