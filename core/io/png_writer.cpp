#include "core/io/png_writer.h"

#include <png.h>

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
    const std::string message = image.message;
    png_image_free(&image);
    throw InputError(path + ": cannot write PNG: " + message);
  }
  png_image_free(&image);
}

}  // namespace cloudbake
