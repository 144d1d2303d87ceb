// PNG output for previews and plots (8 bits per channel).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cloudbake {

/// Writes an 8-bit PNG with libpng's simplified API. `pixels` is row-major from the top row,
/// `channels` interleaved: 1 (grey), 3 (RGB) or 4 (RGBA), values already display-encoded (sRGB).
/// Throws InputError naming `path` on bad dimensions or when the file cannot be written.
void writePng(const std::string& path, int width, int height, int channels,
              const std::vector<uint8_t>& pixels);

}  // namespace cloudbake
