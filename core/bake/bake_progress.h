// Progress and cancellation for bake methods.
#pragma once

#include <functional>
#include <string>

namespace cloudbake {

/// Called from the top-level loop of a bake with the fraction done in [0, 1] and a short stage
/// name ("lattice", "sun transmittance", "pass 3/8", ...). Return false to cancel: the bake then
/// throws Cancelled within about a second of work.
using BakeProgressFn = std::function<bool(double fraction, const std::string& stage)>;

}  // namespace cloudbake
