// Method `auto`: the cheapest method and knobs predicted to meet `bake.tolerance` (the relative
// RMSE of the cloud's own light) on this scene, from the cost and error model of auto_model.h
// and what auto_measure.h measures of the scene. A run resolves an auto shot into the chosen
// method's shot before anything is baked (core/job's runShot and the dry-run plan), so the
// chosen method's cache entries are shared with shots that name it.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/methods/auto_measure.h"
#include "core/methods/auto_model.h"
#include "core/methods/method.h"

namespace cloudbake {

const BakeMethod& autoMethod();

/// True for a shot whose bake.method is "auto".
bool isAutoShot(const ShotSpec& shot);

struct AutoOptions {
  int threads = 0;
  MethodLimits limits;  ///< candidates beyond them are not chosen
  int max_samples = 0;  ///< most bake.samples this server allows (0: 1e6)
  std::string source = "shot.json";
  std::function<bool(double fraction)> progress;  ///< of the pilot; false: Cancelled
};

/// What `auto` chose and why.
struct AutoChoice {
  ShotSpec shot;  ///< the shot with the chosen method, knobs and samples
  double tolerance = 0;
  AutoCandidate chosen;
  std::vector<AutoCandidate> considered;  ///< every candidate, the chosen first
  SceneTraits traits;
  PilotMeasure pilot;
  /// What the choice changes of the shot beyond its method (outputs.vdb_voxel_size, which a
  /// light bake's bake.vdb does not use: it is the bake's lattice).
  std::vector<std::string> notes;

  /// Dry-run lines: the choice, its predicted error and cost, and the runners-up.
  std::vector<std::string> planLines() const;
  /// The record written beside the outputs as auto.json (docs/outputs.md).
  nlohmann::json toJson() const;
};

/// Chooses for `shot` (method auto) on `scene` (density built; unused for a sequence, whose
/// frames only `precomputed` renders). InputError naming /bake/tolerance when no method is
/// predicted to meet it within the limits, with the best predicted error.
AutoChoice chooseAuto(const ShotSpec& shot, const Scene& scene, const AutoOptions& options);

/// The choice's one-line summary for EXR headers and logs.
std::string autoSummary(const AutoChoice& choice);

}  // namespace cloudbake
