// PNG output for previews and plots (8 bits per channel).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/io/image.h"

namespace cloudbake {

/// Writes an 8-bit PNG with libpng's simplified API. `pixels` is row-major from the top row,
/// `channels` interleaved: 1 (grey), 3 (RGB) or 4 (RGBA), values already display-encoded (sRGB).
/// Throws InputError naming `path` on bad dimensions or when the file cannot be written.
void writePng(const std::string& path, int width, int height, int channels,
              const std::vector<uint8_t>& pixels);

/// A display preview of linear radiance (the first three channels of `image`): multiplied by
/// `exposure`, or (exposure <= 0) by what puts the 99th percentile of luminance at 0.8, then
/// sRGB-encoded into an 8-bit RGB PNG. Returns the exposure used. The EXR stays the product.
double writePreviewPng(const std::string& path, const Image& image, double exposure = 0);

}  // namespace cloudbake
