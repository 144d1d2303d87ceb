// Method `pathtrace`: the unbiased reference, a volumetric path tracer with delta tracking,
// next-event estimation of the sun and the sky and ratio-tracked shadow rays (Novak et al.
// 2018, "Monte Carlo methods for volumetric light transport simulation"). Every view is traced
// from scratch; with a black sky a view is traced at unit sun irradiance and scaled, so a new
// sun colour recomputes nothing.
#pragma once

#include "core/methods/method.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {

const BakeMethod& pathtraceMethod();

/// The shot's knobs as the path tracer's options.
PathTracerOptions pathTracerOptions(const ShotSpec& shot, int threads);

}  // namespace cloudbake
