#include "core/methods/single.h"

#include "core/methods/common.h"

namespace cloudbake {
namespace {

class SingleMethod final : public BakeMethod {
 public:
  SingleMethod() {
    info_.name = "single";
    info_.summary =
        "single scattering from a transmittance-to-sun lattice and sky visibility; no multiple "
        "scattering (slsdo 2010)";
    info_.citation =
        "slsdo 2010, \"Volumetric Clouds: a volume renderer that utilizes ray casting and ray "
        "marching through a 3D voxel grid\"";
    // 7: the sky's single scattering weights the phase function (sky_visibility_vector and
    // its forward peak; it had been the ambient term L_mean Vsky).
    // 8 was taken by the reverted bd0ae60 and c0838b0 (a sparse film refining its cells).
    // 9: a backward peak sees the medium behind a camera inside the lattice through
    //    marchTransmittance (the views' own march before: within 1e-5).
    info_.version = 9;
    info_.default_samples = 1;
    info_.max_samples = kMaxViewSamples;
    info_.bakes_light = true;
    info_.knobs = {stepKnob(), filmSpacingKnob(),
                   lightResolutionKnob(SingleBakeOptions{}.light_resolution, true)};
  }
  const MethodInfo& info() const override { return info_; }

  nlohmann::json keyMaterial(const ShotSpec& shot, const nlohmann::json& canonical) const override {
    // Albedo and phase are applied when a view is rendered, so only extinction is baked.
    return {{"light",
             {{"extinction", canonical["medium"]["extinction"]},
              {"sky", needsSky(shot)},
              {"knobs", bakeKnobMaterial(*this, shot)}}}};
  }

  void validate(const ShotSpec& shot, const std::string& source) const override {
    checkPhaseTable(shot, source, "single");
    checkAnalyticLattice(shot, singleBakeOptions(shot).light_resolution, source);
  }

  MethodPlan plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                  const std::function<bool(const std::string&)>& lookup) const override {
    const SingleBakeOptions o = singleBakeOptions(shot);
    std::vector<std::string> lines = lightBakePlanLines(shot, o.light_resolution);
    lines.push_back("multiple scattering: not modelled by method single");
    return lightBakePlan(shot, keys, lookup, std::move(lines));
  }

  void checkLimits(const ShotSpec& shot, const MethodLimits& limits,
                   const std::string& source) const override {
    checkLatticeVoxels(singleBakeOptions(shot).light_resolution, 1, "a bake lattice", limits,
                       source);
  }

  void run(MethodRun& run) const override {
    const SingleBakeOptions o = singleBakeOptions(run.shot());
    // Measured on the Perlin example (cloudbake render --stats-json).
    LightBakeWork work;
    work.bake_seconds = latticeSeconds(o.light_resolution);
    work.view_seconds_per_ray = 1.3e-6;
    work.light_resolution = o.light_resolution;
    runLightBake(
        run,
        [&](const Medium& medium, const Vec3& sun, const BakeProgressFn& progress) {
          return bakeSingle(medium, sun, o, progress);
        },
        work);
  }

 private:
  MethodInfo info_;
};

}  // namespace

const BakeMethod& singleMethod() {
  static const SingleMethod kMethod;
  return kMethod;
}

SingleBakeOptions singleBakeOptions(const ShotSpec& shot) {
  const KnobValues& k = shot.bake.knobs;
  SingleBakeOptions o;
  o.light_resolution = int(k.integer("light_resolution"));
  o.step = k.optionalNumber("step").value_or(0.0);
  o.sky = needsSky(shot);
  return o;
}

}  // namespace cloudbake
