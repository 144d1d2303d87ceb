#include "core/methods/auto.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "core/format.h"
#include "core/methods/precomputed.h"
#include "core/methods/registry.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {
namespace {

// docs/methods.md's trade table: `precomputed` measured 0.34-0.43 relative RMSE on the three
// scenes; it is what animates, so a sequence is its or nobody's.
constexpr double kPrecomputedError = 0.45;

class AutoMethod final : public BakeMethod {
 public:
  AutoMethod() {
    info_.name = "auto";
    info_.summary =
        "the cheapest method and knobs predicted to meet bake.tolerance on this scene, from a "
        "cost and error model fitted to the measured trade curves and a short pilot render "
        "(the choice, its prediction and the bake's own error estimate go to auto.json)";
    info_.citation =
        "cloudbake's own measured trade curves (2026; docs/methods.md, \"Method auto\"): the "
        "model and its fit; the methods it chooses cite their papers";
    // 12: a sequence's choice, `precomputed`, walks with future costs (its version 10).
    // 13: photon rungs whose tally voxels are optically thick are not candidates.
    // 14: its choice `single` scatters the sky with the phase function (single 7).
    // 15 was taken by the reverted bd0ae60 and c0838b0 (a sparse film refining its cells).
    // 16: its choice `single` is version 9.
    // 17: before a photon rung is chosen, small bakes measure its angular truncation.
    // 18: its choice `photon` is version 14 (the check's small bakes too), and photon's
    // seconds are those the check's small bakes took.
    // 19: a hard surface's rim on the lattice is part of single's and photon's predictions.
    // 20: so is any cloud's, in the share of the views against the sun beyond the bench's.
    info_.version = 20;
    info_.default_samples = 1;
    info_.animates = true;
    info_.knobs = {
        Knob::integer("max_depth", 1, 1000000, PathTracerOptions{}.max_depth,
                      "scattering events per path, in the pilot and should the choice be "
                      "`pathtrace`"),
        Knob::number("tolerance", 0, 1, std::nullopt, "",
                     "relative RMSE of the cloud's own light (the scattered layers, background "
                     "excluded) the choice must meet")
            .exclusiveMax()
            .isRequired(),
    };
  }
  const MethodInfo& info() const override { return info_; }

  // A run resolves the shot first (chooseAuto): what these see of an auto shot is a bug.
  MethodPlan plan(const ShotSpec&, const ShotCacheKeys&,
                  const std::function<bool(const std::string&)>&) const override {
    throw InternalError("method auto is planned through its choice (chooseAuto)");
  }
  void run(MethodRun&) const override {
    throw InternalError("method auto runs through its choice (chooseAuto)");
  }

 private:
  MethodInfo info_;
};

ShotSpec resolvedShot(const ShotSpec& shot, const AutoCandidate& c) {
  ShotSpec out = shot;
  const BakeMethod* method = findMethod(c.method);
  if (!method) throw InternalError("auto: no method '" + c.method + "'");
  out.bake.method = c.method;
  out.bake.samples = c.samples;
  out.bake.knobs = KnobValues(method->info().knobs);
  for (const auto& [key, value] : c.knobs) out.bake.knobs.set(key, value);
  if (c.method == "pathtrace") {
    out.bake.knobs.set("max_depth", shot.bake.knobs.integer("max_depth"));
  }
  // A light bake's bake.vdb is its lattice (the shot parser refuses the key for it).
  if (method->info().bakes_light) out.outputs.vdb_voxel_size = 0;
  return out;
}

// The candidate's shot passes its method's checks and this server's limits.
bool withinLimits(const ShotSpec& shot, const AutoOptions& o) {
  try {
    const BakeMethod& m = methodOf(shot);
    m.validate(shot, o.source);
    m.checkLimits(shot, o.limits, o.source);
    return true;
  } catch (const InputError&) {
    return false;
  }
}

// The model's candidates for `choice`'s traits and pilot that pass their checks and the
// server's limits, best first.
std::vector<AutoCandidate> consideredCandidates(const ShotSpec& shot, const AutoChoice& choice,
                                                const AutoOptions& o) {
  std::vector<AutoCandidate> out;
  for (const AutoCandidate& c :
       autoCandidates(choice.traits, choice.pilot, choice.tolerance, o.max_samples)) {
    if (withinLimits(resolvedShot(shot, c), o)) out.push_back(c);
  }
  return out;
}

// photon's bound rests on the bench scenes: before a photon rung is chosen, small bakes measure
// its angular truncation at each order the rungs use (measurePhotonTruncation), and the
// candidates are predicted again with it. A small bake the scene refuses rules photon out.
void checkPhotonChoice(const ShotSpec& shot, const Scene& scene, const PilotOptions& po,
                       const AutoOptions& o, AutoChoice* choice) {
  const std::vector<AutoCandidate>& c = choice->considered;
  if (c.empty() || c.front().method != "photon" || !(c.front().error <= choice->tolerance) ||
      !choice->pilot.photon_check.empty() || choice->pilot.photon_check_failed) {
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<int> orders;
  for (const PhotonRung& r : photonRungs()) {
    if (std::find(orders.begin(), orders.end(), r.order) == orders.end()) {
      orders.push_back(r.order);
    }
  }
  try {
    choice->pilot.photon_check = measurePhotonTruncation(shot, scene, po, choice->pilot, orders,
                                                         &choice->pilot.photon_seconds);
    for (const auto& [order, value] : choice->pilot.photon_check) {
      if (!std::isfinite(value)) {
        choice->pilot.photon_check_failed = true;
        choice->notes.push_back("photon's check measured no finite truncation at order " +
                                std::to_string(order) + ", so photon is not chosen");
      }
    }
  } catch (const InputError& e) {
    choice->pilot.photon_check_failed = true;
    choice->notes.push_back(std::string("photon's check bake failed, so photon is not chosen: ") +
                            e.what());
  }
  choice->pilot.photon_check_seconds = secondsSince(t0);
  choice->considered = consideredCandidates(shot, *choice, o);
}

std::string percent(double x) { return fixed(100 * x, x < 0.1 ? 1 : 0) + " %"; }

std::string describe(const AutoCandidate& c) {
  std::string s = c.method;
  for (const auto& [k, v] : c.knobs) s += " " + k + "=" + std::to_string(v);
  return s + " samples=" + std::to_string(c.samples);
}

AutoChoice chooseSequence(const ShotSpec& shot, double tolerance, const AutoOptions& o) {
  if (tolerance < kPrecomputedError) {
    throw InputError(o.source + ": /bake/tolerance: " + exactNumber(tolerance) +
                     " cannot be met for an animated volume: only `precomputed` renders "
                     "sequences, and its error is about " +
                     percent(kPrecomputedError) + " (docs/methods.md); ask for at least " +
                     exactNumber(kPrecomputedError));
  }
  AutoChoice choice;
  choice.tolerance = tolerance;
  choice.traits.sequence = true;
  choice.chosen.method = "precomputed";
  choice.chosen.error = kPrecomputedError;
  choice.chosen.why = "only precomputed renders animated volumes";
  choice.considered = {choice.chosen};
  choice.shot = shot;
  choice.shot.bake.method = "precomputed";
  choice.shot.bake.knobs = KnobValues(precomputedMethod().info().knobs);
  choice.shot.bake.samples = precomputedMethod().info().default_samples;
  return choice;
}

// {"3": 0.51, "4": 0.27}, by order: JSON objects' keys are strings.
nlohmann::json byOrderJson(const std::map<int, double>& by_order) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [order, value] : by_order) j[std::to_string(order)] = value;
  return j;
}

// "0.00, 2.15" per view, or "not measured".
std::string aureoleList(const std::vector<double>& a) {
  if (a.empty()) return "not measured";
  std::string s;
  for (double v : a) s += (s.empty() ? "" : ", ") + fixed(v, 2);
  return s;
}

}  // namespace

const BakeMethod& autoMethod() {
  static const AutoMethod kMethod;
  return kMethod;
}

bool isAutoShot(const ShotSpec& shot) { return shot.bake.method == "auto"; }

AutoChoice chooseAuto(const ShotSpec& shot, const Scene& scene, const AutoOptions& o) {
  const double tolerance = shot.bake.knobs.number("tolerance");
  if (std::holds_alternative<SequenceVolumeSpec>(shot.volume)) {
    return chooseSequence(shot, tolerance, o);
  }
  AutoChoice choice;
  choice.tolerance = tolerance;
  choice.traits = measureSceneTraits(shot, scene);
  PilotOptions po;
  po.threads = o.threads;
  po.max_depth = int(shot.bake.knobs.integer("max_depth"));
  po.progress = o.progress;
  // A droplet's spike makes the path tracer's noise heavy-tailed: a short pilot may miss the
  // rare large samples and read the noise low, so peaky phases get 4x the pilot's paths.
  if (choice.traits.phase_spikiness > kHeavyTailSpikiness) po.samples = 32;
  if (choice.traits.pixels > 0) {
    choice.pilot = runPilot(scene, po);
  } else {
    // No views: the product is bake.vdb, whose views come later. Nothing measures how much of
    // the light is multiply scattered, so single is not trusted with it.
    choice.pilot.multiple_fraction = 1;
    choice.pilot.multiple_rms = 1;
    // Nor whether they look towards the sun: photon's droplet error is taken as the worst
    // measured there.
    choice.pilot.aureole = {kAureoleWorst};
  }
  choice.considered = consideredCandidates(shot, choice, o);
  checkPhotonChoice(shot, scene, po, o, &choice);
  if (choice.considered.empty() || !(choice.considered.front().error <= tolerance)) {
    std::string best = "none within this server's limits";
    if (!choice.considered.empty()) {
      const AutoCandidate& b = choice.considered.front();
      best =
          "the best predicted is " + describe(b) + " at " + percent(b.error) + " (" + b.why + ")";
    }
    throw InputError(o.source + ": /bake/tolerance: no method is predicted to meet " +
                     exactNumber(tolerance) + " on this scene within this server's limits; " +
                     best);
  }
  choice.chosen = choice.considered.front();
  choice.shot = resolvedShot(shot, choice.chosen);
  if (shot.outputs.vdb && shot.outputs.vdb_voxel_size > 0 &&
      choice.shot.outputs.vdb_voxel_size == 0) {
    // The key is required of an analytic volume in case the path tracer is chosen.
    choice.notes.push_back("outputs.vdb_voxel_size " + exactNumber(shot.outputs.vdb_voxel_size) +
                           " is not used: " + choice.chosen.method +
                           "'s bake.vdb is its bake lattice (light_resolution " +
                           std::to_string(choice.shot.bake.knobs.integer("light_resolution")) +
                           ")");
  }
  return choice;
}

std::vector<std::string> AutoChoice::planLines() const {
  std::vector<std::string> lines;
  lines.push_back("auto: chose " + describe(chosen) + " for a tolerance of " + percent(tolerance) +
                  ": predicted error " + percent(chosen.error) + ", " + fixed(chosen.seconds, 1) +
                  " s (" + chosen.why + ")");
  if (!traits.sequence) {
    lines.push_back("auto: measured " +
                    (pilot.samples > 0 ? "a pilot of " + std::to_string(pilot.pixels) +
                                             " pixels x " + std::to_string(pilot.samples) +
                                             " paths x 2 seeds in " + fixed(pilot.seconds, 2) + " s"
                                       : std::string("no views to pilot")) +
                    "; albedo " + fixed(traits.albedo, 3) + ", phase spikiness " +
                    fixed(traits.phase_spikiness, 1) +
                    (traits.peak_split ? " (photon splits its forward peak off)" : "") +
                    ", optical thickness of a 1/128 voxel " + fixed(traits.tau_voxel_128, 3) +
                    ", " + fixed(100 * traits.hard_surface, 0) + " % of its surface hard, " +
                    fixed(traits.thinnest_voxels_128, 1) +
                    " such voxels across the cloud's thinnest side" +
                    ", the views' aureole brightness " + aureoleList(pilot.aureole));
  }
  if (!pilot.photon_check.empty()) {
    std::string s;
    for (const auto& [order, bias] : pilot.photon_check) {
      s += (s.empty() ? "" : ", ") + std::string("order ") + std::to_string(order) + " " +
           percent(bias);
    }
    lines.push_back(std::string("auto: photon's angular truncation, small bakes at each order ") +
                    "and the next (relative RMS on tiles of " + std::to_string(kPilotTile) + "x" +
                    std::to_string(kPilotTile) + " pixels): " + s + ", measured in " +
                    fixed(pilot.photon_check_seconds, 2) + " s");
  }
  for (const std::string& note : notes) lines.push_back("auto: " + note);
  for (size_t i = 1; i < considered.size() && i < 4; ++i) {
    const AutoCandidate& c = considered[i];
    lines.push_back("auto: also considered " + describe(c) + ": " + percent(c.error) + ", " +
                    fixed(c.seconds, 1) + " s");
  }
  return lines;
}

nlohmann::json AutoChoice::toJson() const {
  auto candidate = [](const AutoCandidate& c) {
    nlohmann::json knobs = nlohmann::json::object();
    for (const auto& [k, v] : c.knobs) knobs[k] = v;
    return nlohmann::json{{"method", c.method},
                          {"knobs", knobs},
                          {"samples", c.samples},
                          {"predicted_error", c.error},
                          {"predicted_seconds", c.seconds},
                          {"why", c.why}};
  };
  nlohmann::json considered_json = nlohmann::json::array();
  for (const AutoCandidate& c : considered) considered_json.push_back(candidate(c));
  return {{"tolerance", tolerance},
          {"chosen", candidate(chosen)},
          {"notes", notes},
          {"considered", considered_json},
          {"traits",
           {{"albedo", traits.albedo},
            {"phase_spikiness", traits.phase_spikiness},
            {"peak_split", traits.peak_split},
            {"photon_refuses", traits.photon_refuses},
            {"sun", traits.sun},
            {"sky", traits.sky},
            {"tau_voxel_128", traits.tau_voxel_128},
            {"hard_surface", traits.hard_surface},
            {"sunward_views", traits.sunward_views},
            {"thinnest_voxels_128", traits.thinnest_voxels_128},
            {"views", traits.views},
            {"pixels", traits.pixels},
            {"write_seconds_per_pixel", traits.write_seconds_per_pixel},
            {"frames", traits.frames}}},
          {"pilot",
           {{"noise_1spp", pilot.noise_1spp},
            {"seconds_per_sample", pilot.seconds_per_sample},
            {"multiple_fraction", pilot.multiple_fraction},
            {"multiple_rms", pilot.multiple_rms},
            {"cloud_fraction", pilot.cloud_fraction},
            {"aureole", pilot.aureole},
            {"samples", pilot.samples},
            {"pixels", pilot.pixels},
            {"seconds", pilot.seconds},
            {"photon_check", byOrderJson(pilot.photon_check)},
            {"photon_check_failed", pilot.photon_check_failed},
            {"photon_check_seconds", pilot.photon_check_seconds},
            {"photon_seconds_per_photon", byOrderJson(pilot.photon_seconds)}}}};
}

std::string autoSummary(const AutoChoice& c) {
  return describe(c.chosen) + " for tolerance " + exactNumber(c.tolerance) + ", predicted " +
         exactNumber(c.chosen.error);
}

}  // namespace cloudbake
