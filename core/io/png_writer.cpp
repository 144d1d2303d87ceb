#include "core/io/png_writer.h"

#include <png.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "core/error.h"

namespace cloudbake {

void writePng(const std::string& path, int width, int height, int channels,
              const std::vector<uint8_t>& pixels) {
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535) {
    throw InputError(path + ": PNG size must be in 1..65535 pixels, got " + std::to_string(width) +
                     "x" + std::to_string(height));
  }
  if (channels != 1 && channels != 3 && channels != 4) {
    throw InputError(path + ": PNG needs 1, 3 or 4 channels, got " + std::to_string(channels));
  }
  if (pixels.size() != static_cast<size_t>(width) * height * channels) {
    throw InputError(path + ": PNG pixel buffer has " + std::to_string(pixels.size()) +
                     " bytes, expected " +
                     std::to_string(static_cast<size_t>(width) * height * channels));
  }
  // The simplified API reports errors through the struct instead of longjmp, which keeps
  // C++ objects out of libpng's setjmp/longjmp error path.
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width);
  image.height = static_cast<png_uint_32>(height);
  image.format =
      channels == 1 ? PNG_FORMAT_GRAY : (channels == 3 ? PNG_FORMAT_RGB : PNG_FORMAT_RGBA);
  const int ok = png_image_write_to_file(&image, path.c_str(), 0, pixels.data(),
                                         static_cast<png_int_32>(width * channels), nullptr);
  if (!ok) {
    const int err = errno;
    const std::string message = image.message;
    png_image_free(&image);
    throwIfNoSpace(err, path + ": cannot write PNG: " + message);
    throw InputError(path + ": cannot write PNG: " + message);
  }
  png_image_free(&image);
}

namespace {

uint8_t srgbByte(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255.0));
}

double luminanceOf(const float* p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

}  // namespace

double writePreviewPng(const std::string& path, const Image& image, double exposure) {
  if (image.channels < 3 || image.width < 1 || image.height < 1) {
    throw InputError(path + ": a preview needs an RGB image, got " +
                     std::to_string(image.channels) + " channel(s)");
  }
  const size_t n = size_t(image.width) * image.height;
  // A NaN would break the exposure's ordering (nth_element) and map to an arbitrary byte.
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(image.data[p * image.channels + c])) {
        throw InputError(path + ": cannot preview an image with a non-finite pixel at (" +
                         std::to_string(p % size_t(image.width)) + ", " +
                         std::to_string(p / size_t(image.width)) + ")");
      }
    }
  }
  if (!(exposure > 0)) {
    std::vector<double> lum(n);
    for (size_t p = 0; p < n; ++p) lum[p] = luminanceOf(&image.data[p * image.channels]);
    const size_t k = std::min(n - 1, size_t(0.99 * double(n)));
    std::nth_element(lum.begin(), lum.begin() + std::ptrdiff_t(k), lum.end());
    exposure = lum[k] > 0 && std::isfinite(lum[k]) ? 0.8 / lum[k] : 1.0;
  }
  std::vector<uint8_t> px(n * 3);
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c)
      px[p * 3 + c] = srgbByte(exposure * image.data[p * image.channels + c]);
  }
  writePng(path, image.width, image.height, 3, px);
  return exposure;
}

}  // namespace cloudbake
