#include "core/transport/scene.h"

#include <cmath>

#include "core/error.h"
#include "core/format.h"

namespace cloudbake {

void validateMediumOptics(const Medium& m) {
  if (!m.phase) throw InputError("medium.phase: no phase function given");
  if (!std::isfinite(m.extinction) || m.extinction < 0) {
    throw InputError("medium.extinction: must be finite and >= 0, got " + str(m.extinction));
  }
  for (int c = 0; c < 3; ++c) {
    if (!(m.albedo[c] >= 0 && m.albedo[c] <= 1)) {  // also rejects NaN
      throw InputError("medium.albedo: each channel must be in [0, 1], got " + str(m.albedo));
    }
  }
}

}  // namespace cloudbake
