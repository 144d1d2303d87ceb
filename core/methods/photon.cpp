#include "core/methods/photon.h"

#include <algorithm>

#include "core/error.h"
#include "core/format.h"
#include "core/math/sh_basis.h"
#include "core/methods/common.h"
#include "core/phase/phase_factory.h"

namespace cloudbake {
namespace {

std::vector<Knob> photonKnobs() {
  const PhotonBakeOptions d;
  return {
      stepKnob(),
      filmSpacingKnob(),
      lightResolutionKnob(d.light_resolution, true),
      Knob::integer("photons", 1000, int64_t(1) << 28, d.photons,
                    "photons traced from the sun (and as many from the sky when it is not "
                    "black): the tally's noise falls as 1 / sqrt(photons)"),
      Knob::integer("order", 1, kMaxShDegree, d.order,
                    "highest spherical-harmonic degree of the tallied radiance: (order + 1)^2 "
                    "coefficients per voxel and colour channel"),
      Knob::integer("tally_resolution", 0, 1024, d.tally_resolution,
                    "voxels along the longest side of the tallies' lattice (0: the bake's "
                    "lattice itself); the scattered light is smooth, so a coarser lattice "
                    "than the transmittance's gathers more photons per voxel"),
      Knob::integer("zonal_order", 0, kMaxZonalDegree, d.zonal_order,
                    "highest degree of the extra zonal terms of the sunlight's tally about the "
                    "sun's axis, where its forward peak lies (0: none; else above order): "
                    "zonal_order - order coefficients more per voxel and colour channel"),
  };
}

// A sky that is not uniform is baked by its shape (PhotonBakeOptions::sky_shape), so the light
// key must hold it: one test for both.
bool bakesSkyShape(const ShotSpec& shot) {
  return needsSky(shot) && shot.lighting.sky.type != Sky::Type::kConstant;
}

class PhotonMethod final : public BakeMethod {
 public:
  PhotonMethod() {
    info_.name = "photon";
    info_.summary =
        "multiply scattered light traced as photons from the sun and the sky, tallied per voxel "
        "in spherical harmonics by the track-length estimator; exact single scattering and a "
        "Funk-Hecke convolution with the phase at render time (converges to the reference as "
        "photons, order and resolution grow)";
    info_.citation =
        "Jensen and Christensen 1998, \"Efficient simulation of light transport in scenes with "
        "participating media using photon maps\" (SIGGRAPH); Evans 1998, \"The spherical "
        "harmonics discrete ordinate method for three-dimensional atmospheric radiative "
        "transfer\" (J. Atmos. Sci. 55), for radiance fields in spherical harmonics; Wiscombe "
        "1977, "
        "\"The delta-M method\" (J. Atmos. Sci. 34), and Iwabuchi and Suzuki 2009, truncation "
        "approximation (JQSRT), for a droplet's forward peak split off";
    // 12 was taken by a commit that was reverted (dc011db: the sky's single scattering from the
    // lattice) and 13 by two (bd0ae60, c0838b0: a sparse film refining its cells), so no cache
    // holds two physics under one number.
    // 14: the sky's single scattering scaled to each point by the lattice's visibility, and
    // split by delta-M.
    info_.version = 14;
    info_.default_samples = 1;
    info_.max_samples = kMaxViewSamples;
    info_.bakes_light = true;
    info_.knobs = photonKnobs();
  }
  const MethodInfo& info() const override { return info_; }

  void validate(const ShotSpec& shot, const std::string& source) const override {
    checkPhaseTable(shot, source, "photon");
    const PhotonBakeOptions o = photonBakeOptions(shot);
    if (o.tally_resolution != 0 && o.tally_resolution < 8) {
      throw InputError(source +
                       ": /bake/tally_resolution: must be 0 (light_resolution) or in "
                       "[8, 1024], got " +
                       std::to_string(o.tally_resolution));
    }
    if (o.zonal_order != 0 && o.zonal_order <= o.order) {
      throw InputError(source + ": /bake/zonal_order: must be 0 (none) or above order " +
                       std::to_string(o.order) + " (the zonal terms add degrees order + 1 .. " +
                       "zonal_order), got " + std::to_string(o.zonal_order));
    }
    // A peak no forward cut removes is refused here, before the job is queued, where the phase
    // is cheap to build (every type but the Lorenz-Mie table, whose peak is forward and is
    // split; the bake checks again).
    if (shot.medium.phase.type != PhaseSpec::Type::kMie) {
      try {
        photonPeakSplit(*makePhaseFunction(shot.medium.phase), o);
      } catch (const InputError& e) {
        throw InputError(source + ": " + e.what());
      }
    }
    checkAnalyticLattice(shot, o.light_resolution, source);
    if (o.tally_resolution > 0) {
      checkAnalyticLattice(shot, o.tally_resolution, source, "/bake/tally_resolution");
    }
  }

  nlohmann::json keyMaterial(const ShotSpec& shot, const nlohmann::json& canonical) const override {
    // The photons scatter with the albedo and the phase: the whole medium is baked.
    nlohmann::json key = wholeMediumLightKey(*this, shot, canonical);
    if (bakesSkyShape(shot)) key["light"]["sky_shape"] = canonical["lighting"]["sky"];
    // A black sun's bake traces no sun photons: it cannot serve a shot whose sun shines.
    if (!needsSun(shot)) key["light"]["sun"] = "black";
    return key;
  }

  MethodPlan plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                  const std::function<bool(const std::string&)>& lookup) const override {
    const PhotonBakeOptions o = photonBakeOptions(shot);
    std::vector<std::string> lines = lightBakePlanLines(shot, o.light_resolution);
    lines.push_back(
        "multiple scattering: " +
        (o.sun ? std::to_string(o.photons) + " sun photons" : "no sun photons (a black sun)") +
        (o.sky ? (o.sun ? " and as many" : ", " + std::to_string(o.photons)) +
                     " sky photons (their unscattered light too: the sky's single scattering)"
               : "") +
        ", tallied on a lattice of " +
        std::to_string(o.tally_resolution > 0 ? o.tally_resolution : o.light_resolution) +
        " voxels along the longest side in spherical harmonics to degree " +
        std::to_string(o.order) + " (" + std::to_string(shCount(o.order)) +
        " coefficients per voxel)" +
        (o.sun && o.zonal_order > o.order
             ? ", and the sunlight's in zonal terms about the sun's axis "
               "to degree " +
                   std::to_string(o.zonal_order)
             : std::string()));
    return lightBakePlan(shot, keys, lookup, std::move(lines));
  }

  void checkLimits(const ShotSpec& shot, const MethodLimits& limits,
                   const std::string& source) const override {
    const PhotonBakeOptions o = photonBakeOptions(shot);
    // Per voxel: the fixed-point counts (two floats' worth each) and the stored floats, RGB,
    // per coefficient and per tally, plus the lattice's own grids.
    const double sky_tallies = o.sky ? 2 : 0;  // sky scattered and unscattered
    const double zonal = std::max(0, o.zonal_order - o.order);
    // The bake's lattice: density, transmittance to the sun, Cd (RGB) and, under a sky, its
    // visibility, the visibility's first moment while the bake runs (RGB) and the sky's single
    // scattering's scale.
    checkLatticeVoxels(o.light_resolution, o.sky ? 10 : 6, "a photon bake lattice", limits, source);
    checkLatticeVoxels(
        o.tally_resolution > 0 ? o.tally_resolution : o.light_resolution,
        ((1 + sky_tallies) * shCount(o.order) + zonal) * 3 * 3 + 1,  // + recordErrors' density
        "a photon tally lattice of " + std::to_string(shCount(o.order)) +
            " spherical-harmonic coefficients (/bake/order " + std::to_string(o.order) + ")",
        limits, source,
        o.tally_resolution > 0 ? "/bake/tally_resolution" : "/bake/light_resolution");
  }

  void run(MethodRun& run) const override {
    PhotonBakeOptions o = photonBakeOptions(run.shot());
    if (bakesSkyShape(run.shot())) o.sky_shape = &run.lights().sky;
    // Measured on the Perlin example: 3.7 us per photon (its tallies included; 5.7 before
    // version 4 summed each photon's segments per voxel); a view's ray as auto's model prices it.
    LightBakeWork work;
    work.bake_seconds = latticeSeconds(o.light_resolution) +
                        3.7e-6 * double(o.photons) * ((o.sky ? 1 : 0) + (o.sun ? 1 : 0));
    work.view_seconds_per_ray = photonFieldViewSecondsPerRay(o.light_resolution);
    work.light_resolution = o.light_resolution;
    runLightBake(
        run,
        [&](const Medium& medium, const Vec3& sun, const BakeProgressFn& progress) {
          return bakePhoton(medium, sun, o, progress);
        },
        work);
  }

 private:
  MethodInfo info_;
};

}  // namespace

double photonFieldViewSecondsPerRay(int light_resolution) {
  return 1.5e-6 * std::max(0.5, light_resolution / 128.0);
}

const BakeMethod& photonMethod() {
  static const PhotonMethod kMethod;
  return kMethod;
}

PhotonBakeOptions photonBakeOptions(const ShotSpec& shot) {
  const KnobValues& k = shot.bake.knobs;
  PhotonBakeOptions o;
  o.light_resolution = int(k.integer("light_resolution"));
  o.photons = k.integer("photons");
  o.order = int(k.integer("order"));
  o.zonal_order = int(k.integer("zonal_order"));
  o.tally_resolution = int(k.integer("tally_resolution"));
  o.step = k.optionalNumber("step").value_or(0.0);
  o.sky = needsSky(shot);
  o.sun = needsSun(shot);
  o.seed = shot.bake.seed;
  return o;
}

}  // namespace cloudbake
