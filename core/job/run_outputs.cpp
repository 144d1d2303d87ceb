#include "core/job/run_outputs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "core/io/png_writer.h"
#include "core/job/sha256.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
uint8_t srgbByte(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255.0));
}

// Preview only: exposure puts the 99th percentile of luminance at 0.8, then sRGB encoding (as
// `cloudbake render --png`). The EXR stays the authoritative, unexposed radiance.
void writePreviewPng(const std::string& path, const Image& beauty, double fixed_exposure) {
  std::vector<double> lum;
  lum.reserve(size_t(beauty.width) * beauty.height);
  for (int y = 0; y < beauty.height; ++y) {
    for (int x = 0; x < beauty.width; ++x) {
      const float* p = beauty.at(x, y);
      lum.push_back(luminance(Rgb(p[0], p[1], p[2])));
    }
  }
  const size_t k = std::min(lum.size() - 1, size_t(0.99 * double(lum.size())));
  std::nth_element(lum.begin(), lum.begin() + std::ptrdiff_t(k), lum.end());
  const double exposure = fixed_exposure > 0                    ? fixed_exposure
                          : lum[k] > 0 && std::isfinite(lum[k]) ? 0.8 / lum[k]
                                                                : 1.0;
  std::vector<uint8_t> px(size_t(beauty.width) * beauty.height * 3);
  for (int y = 0; y < beauty.height; ++y) {
    for (int x = 0; x < beauty.width; ++x) {
      const float* p = beauty.at(x, y);
      for (int c = 0; c < 3; ++c) {
        px[(size_t(y) * beauty.width + x) * 3 + c] = srgbByte(exposure * p[c]);
      }
    }
  }
  writePng(path, beauty.width, beauty.height, 3, px);
}

}  // namespace

OutputFile describeOutput(const std::string& out_dir, const std::string& name) {
  OutputFile f;
  f.name = name;
  f.path = (fs::path(out_dir) / name).string();
  f.size = fs::file_size(f.path);
  f.sha256 = sha256File(f.path);
  return f;
}

void addPreview(const RunOptions& opt, const std::string& stem, const std::string& exr_path,
                RunResult& result) {
  const std::string png_name = stem + ".png";
  // The beauty (the cloud over what is seen through it), not the cloud element alone.
  ExrContents exr = readExr(exr_path);
  auto beauty = exr.layers.find("beauty");
  writePreviewPng((fs::path(opt.out_dir) / png_name).string(),
                  beauty != exr.layers.end() ? beauty->second : readExrRgb(exr_path),
                  opt.png_exposure);
  result.files.push_back(describeOutput(opt.out_dir, png_name));
}

}  // namespace cloudbake
