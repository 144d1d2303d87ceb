// Method `auto`: picks the cheapest method and knobs predicted to meet `bake.tolerance`. The
// shot format accepts it so shots can be written ahead; this build refuses to run it.
#pragma once

#include "core/methods/method.h"

namespace cloudbake {

const BakeMethod& autoMethod();

}  // namespace cloudbake
