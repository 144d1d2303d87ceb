// What runShot and its method runners share to write a run's files: EXR layers, PNG previews,
// output descriptions, and short numbers for progress lines. Internal to core/job.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include "core/format.h"
#include "core/io/exr_io.h"
#include "core/job/run_shot.h"
#include "core/transport/layers_exr.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {

/// Name, path, size and SHA-256 of out_dir/name.
OutputFile describeOutput(const std::string& out_dir, const std::string& name);

/// DIR/<stem>.png beside an EXR (a display preview of the view's `beauty`, written to the EXR
/// or not; the EXR is the product): exposure puts the 99th percentile of luminance at 0.8
/// unless opt.png_exposure is set, then sRGB.
void addPreview(const RunOptions& opt, const std::string& stem, const Image& beauty,
                RunResult& result);

}  // namespace cloudbake
