// What runShot and its method runners share to write a run's files: EXR layers, PNG previews,
// output descriptions, and short numbers for progress lines. Internal to core/job.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include "core/io/exr_io.h"
#include "core/job/run_shot.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {

/// A number with `digits` decimals, for progress messages ("2.58 s" rather than "2.581958 s").
std::string fixed(double value, int digits);

double secondsSince(std::chrono::steady_clock::time_point since);

/// A number in %g form ("0.05", "1e+06"), for plan and progress lines.
std::string shortNumber(double value);

/// Multiplies the RGB channels of a layer by the sun irradiance (alpha untouched).
void scaleRgb(Image& image, const Rgb& e);

/// The EXR layers of a render: beauty unprefixed, then sun, sky, single, multiple.
std::vector<ExrLayer> toExrLayers(RenderLayers&& layers);

/// Reads those layers back (a cached view); std::runtime_error when one is missing.
std::vector<ExrLayer> readLayers(const std::string& path);

/// Name, path, size and SHA-256 of out_dir/name.
OutputFile describeOutput(const std::string& out_dir, const std::string& name);

/// DIR/<stem>.png beside an EXR (a display preview; the EXR is the product): exposure puts the
/// 99th percentile of luminance at 0.8 unless opt.png_exposure is set, then sRGB.
void addPreview(const RunOptions& opt, const std::string& stem, const std::string& exr_path,
                RunResult& result);

}  // namespace cloudbake
