// A float image with a fixed number of channels, stored row-major from the top-left pixel.
#pragma once

#include <vector>

namespace cloudbake {

/// Linear float image. Pixel (x, y) with y = 0 the top row; channels interleaved.
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> data;

  Image() = default;
  Image(int w, int h, int c) : width(w), height(h), channels(c), data(size_t(w) * h * c, 0.f) {}
  float* at(int x, int y) { return &data[(size_t(y) * width + x) * channels]; }
  const float* at(int x, int y) const { return &data[(size_t(y) * width + x) * channels]; }
};

}  // namespace cloudbake
