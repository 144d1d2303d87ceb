#include "core/methods/pointcloud.h"

#include "core/error.h"
#include "core/format.h"
#include "core/methods/common.h"

namespace cloudbake {
namespace {

std::vector<Knob> pointcloudKnobs() {
  const PointcloudOptions d;
  return {
      stepKnob(),
      filmSpacingKnob(),
      lightResolutionKnob(d.light_resolution, true),
      Knob::integer("points", 64, int64_t(1) << 24, d.points,
                    "points inside the volume (density-weighted): the quality knob"),
      Knob::integer("passes", 1, 1000, d.passes, "maximum scattering passes"),
      Knob::number("radius", 0, 1e12, std::nullopt, "world units",
                   "neighbourhood cut-off; larger than the volume's diagonal is an error")
          .derivedDefault("3x the mean point spacing"),
      Knob::choice("rule", {"normalized", "paper"}, "normalized",
                   "energy-normalised transfer, or Reimschuessel's Eq. 1-5 as written"),
      Knob::boolean("output_mapping", d.output_mapping,
                    "`paper` rule only: Reimschuessel's Eq. 2, Co = 1 - exp(-Ci)"),
      Knob::boolean("tail", d.tail,
                    "add the geometric tail of the orders after the last pass; false shows "
                    "exactly `passes` orders (a pass-by-pass sequence)"),
      Knob::number("tolerance", 0, 1, d.tolerance, "",
                   "stop when a pass changes the result by less than this (relative)"),
  };
}

class PointcloudMethod final : public BakeMethod {
 public:
  PointcloudMethod() {
    info_.name = "pointcloud";
    info_.summary =
        "multiple scattering between points inside the cloud, pass by pass, with a Mie/isotropic "
        "ratio per point (Reimschuessel 2011)";
    info_.citation =
        "Reimschuessel 2011, \"Rendering Realistic Cloud Effects for Computer Generated Films\" "
        "(BYU thesis)";
    // 11: the geometric tail of the orders not computed takes each channel's own ratio.
    // 12: the sky's single scattering weights the phase function, as single's 7 does.
    // 13 was taken by the reverted bd0ae60 and c0838b0 (a sparse film refining its cells).
    // 14: a backward peak sees the medium behind a camera inside the lattice as single's 9.
    info_.version = 14;
    info_.default_samples = 1;
    info_.max_samples = kMaxViewSamples;
    info_.bakes_light = true;
    info_.knobs = pointcloudKnobs();
  }
  const MethodInfo& info() const override { return info_; }

  void validate(const ShotSpec& shot, const std::string& source) const override {
    checkPhaseTable(shot, source, "pointcloud");
    const KnobValues& k = shot.bake.knobs;
    if (k.boolean("output_mapping") && k.choice("rule") != "paper") {
      throw InputError(source +
                       ": /bake/output_mapping: Eq. 2's output mapping applies to rule 'paper' "
                       "only (the normalised rule keeps radiometric units)");
    }
    checkAnalyticLattice(shot, pointcloudOptions(shot).light_resolution, source);
  }

  nlohmann::json keyMaterial(const ShotSpec& shot, const nlohmann::json& canonical) const override {
    return wholeMediumLightKey(*this, shot, canonical);
  }

  MethodPlan plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                  const std::function<bool(const std::string&)>& lookup) const override {
    const PointcloudOptions o = pointcloudOptions(shot);
    std::vector<std::string> lines = lightBakePlanLines(shot, o.light_resolution);
    lines.push_back("multiple scattering: " + std::to_string(o.points) + " points, up to " +
                    std::to_string(o.passes) + " passes (stop below a relative change of " +
                    shortNumber(o.tolerance) + "), rule " + shot.bake.knobs.choice("rule"));
    return lightBakePlan(shot, keys, lookup, std::move(lines));
  }

  void checkLimits(const ShotSpec& shot, const MethodLimits& limits,
                   const std::string& source) const override {
    const PointcloudOptions o = pointcloudOptions(shot);
    checkLatticeVoxels(o.light_resolution, 1, "a bake lattice", limits, source);
    checkPointCount(o.points, "/bake/points", limits, source);
  }

  void run(MethodRun& run) const override {
    const PointcloudOptions o = pointcloudOptions(run.shot());
    // Measured on the Perlin example: 0.4 us per point and pass (the sky's passes as many).
    LightBakeWork work;
    work.bake_seconds =
        latticeSeconds(o.light_resolution) + 4e-7 * double(o.points) * o.passes * (o.sky ? 2 : 1);
    work.view_seconds_per_ray = 1.7e-6;
    work.light_resolution = o.light_resolution;
    runLightBake(
        run,
        [&](const Medium& medium, const Vec3& sun, const BakeProgressFn& progress) {
          return bakePointcloud(medium, sun, o, progress, nullptr);
        },
        work);
  }

 private:
  MethodInfo info_;
};

}  // namespace

const BakeMethod& pointcloudMethod() {
  static const PointcloudMethod kMethod;
  return kMethod;
}

PointcloudOptions pointcloudOptions(const ShotSpec& shot) {
  const KnobValues& k = shot.bake.knobs;
  PointcloudOptions o;
  o.points = int(k.integer("points"));
  o.passes = int(k.integer("passes"));
  o.radius = k.optionalNumber("radius").value_or(0.0);
  o.tolerance = k.number("tolerance");
  o.rule = k.choice("rule") == "paper" ? PointcloudOptions::Rule::kPaper
                                       : PointcloudOptions::Rule::kNormalized;
  o.output_mapping = k.boolean("output_mapping");
  o.tail = k.boolean("tail");
  o.light_resolution = int(k.integer("light_resolution"));
  o.step = k.optionalNumber("step").value_or(0.0);
  o.sky = needsSky(shot);
  o.seed = shot.bake.seed;
  return o;
}

}  // namespace cloudbake
