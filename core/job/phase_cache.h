// In-memory cache of built phase functions, so the jobs of one server build a Lorenz-Mie table
// (seconds for large droplets) once, and the dry-run line that says what building one costs.
#pragma once

#include <memory>
#include <string>

#include "core/job/memory_cache.h"
#include "core/phase/phase_factory.h"

namespace cloudbake {

/// Keeps the `capacity` most recently used phase functions by phaseKey; see MemoryCache.
class PhaseCache : public MemoryCache<std::shared_ptr<const PhaseFunction>> {
 public:
  using MemoryCache<std::shared_ptr<const PhaseFunction>>::MemoryCache;
};

/// Every field of `spec` that changes the function, its numbers printed exactly (%.17g).
std::string phaseKey(const PhaseSpec& spec);

/// The phase function of `spec`: from `cache` when there is one (built into it when absent),
/// else built. `was_cached` (optional) says which. `keep_going`: as for makePhaseFunction; a
/// build cancelled so is not kept, and a caller that was waiting for it builds it itself.
std::shared_ptr<const PhaseFunction> cachedPhase(const PhaseSpec& spec, PhaseCache* cache,
                                                 bool* was_cached = nullptr,
                                                 const std::function<bool()>& keep_going = {});

/// A dry run's line for a Lorenz-Mie table ("" for analytic phase functions): its predicted build
/// time on `threads` cores, or that this server holds it already.
std::string phasePlanLine(const PhaseSpec& spec, const PhaseCache* cache, int threads);

}  // namespace cloudbake
