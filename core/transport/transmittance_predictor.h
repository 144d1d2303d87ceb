// Cheap upper estimates of the transmittance towards the lights, for deciding how many shadow
// rays a collision is worth.
#pragma once

#include <vector>

#include "core/math/vec3.h"
#include "core/volume/majorant_grid.h"

namespace cloudbake {

/// Predicts, for any point of a medium, how much of the sun and of the sky can reach it. Used
/// only to choose how many shadow rays a collision gets (Russian roulette and splitting, which
/// reweight what they keep), never as the estimate itself: a poor prediction costs variance,
/// not bias, as long as every event keeps a chance (predictions are never 0, and the path
/// tracer's roulette keeps at least kPredictedMinSurvival, core/transport/shadow_splitting.h).
///
/// The tracking grid's minorants bound sigma_t from below, so exp(-extinction x the integral of
/// the minorant) along a ray bounds its transmittance from above (and equals it in a
/// homogeneous medium). That is evaluated along the sun direction and along the 6 axis
/// directions from the vertices of a lattice over the grid's box, of about cubic cells, `max_res`
/// along its longest axis; a cell predicts the largest value of its 8 vertices (for the sky, of the
/// 6 directions). Deep inside a thick cloud both are tiny, and the shadow rays from there, which
/// cost most of a path's time and add almost nothing, are mostly rouletted away. Without minorants
/// every prediction is 1.
class TransmittancePredictor {
 public:
  TransmittancePredictor() = default;
  /// `sun_dir`: unit vector towards the sun, or nullptr for no sun; `sky`: predict the sky too.
  TransmittancePredictor(const MajorantGrid& grid, double extinction, const Vec3* sun_dir, bool sky,
                         int max_res = 32);

  /// False when it predicts 1 everywhere (no minorants, or an empty grid).
  bool active() const { return !sun_.empty() || !sky_.empty(); }
  /// Predicted transmittance towards the sun from p, in [0, 1] (1 outside the grid's box).
  double sun(const Vec3& p) const { return at(sun_, p); }
  /// The largest predicted transmittance towards the sky from p, in [0, 1].
  double sky(const Vec3& p) const { return at(sky_, p); }

 private:
  double at(const std::vector<float>& cells, const Vec3& p) const;

  Bounds3 bounds_;
  int n_[3] = {0, 0, 0};
  Vec3 inv_cell_;
  std::vector<float> sun_, sky_;  // per lattice cell, x fastest
};

}  // namespace cloudbake
