#include "core/job/phase_cache.h"

#include <cstdio>

#include "core/format.h"
#include "core/phase/mie_table.h"

namespace cloudbake {

std::string phaseKey(const PhaseSpec& spec) {
  char key[256];
  std::snprintf(key, sizeof key, "type=%d g=%.17g d=%.17g reff=%.17g veff=%.17g ratio=%.17g",
                int(spec.type), spec.g, spec.diameter_um, spec.effective_radius_um,
                spec.effective_variance, spec.mie_ratio);
  return key;
}

std::shared_ptr<const PhaseFunction> cachedPhase(const PhaseSpec& spec, PhaseCache* cache,
                                                 bool* was_cached,
                                                 const std::function<bool()>& keep_going) {
  if (was_cached) *was_cached = false;
  if (!cache) return makePhaseFunction(spec, keep_going);
  return cache->getOrBuild(
      phaseKey(spec), [&] { return makePhaseFunction(spec, keep_going); }, was_cached);
}

std::string phasePlanLine(const PhaseSpec& spec, const PhaseCache* cache, int threads) {
  if (spec.type != PhaseSpec::Type::kMie) return "";
  MieTableOptions o;
  o.effective_radius_um = spec.effective_radius_um;
  o.effective_variance = spec.effective_variance;
  const std::string what = "phase: Lorenz-Mie table (r_eff " + str(o.effective_radius_um) +
                           " um, v_eff " + str(o.effective_variance) + ")";
  if (cache && cache->contains(phaseKey(spec))) return what + ": in this server's memory";
  return what + ": built in about " + fixed(estimateMieTableSeconds(o, threads), 1) +
         " s, then kept in memory for later jobs";
}

}  // namespace cloudbake
