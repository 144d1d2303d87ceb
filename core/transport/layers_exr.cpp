#include "core/transport/layers_exr.h"

#include "core/error.h"

namespace cloudbake {

std::vector<ExrLayer> renderLayersToExr(const RenderLayers& layers) {
  return {{"", layers.beauty},
          {"sun", layers.sun},
          {"sky", layers.sky},
          {"single", layers.single},
          {"multiple", layers.multiple}};
}

std::vector<ExrLayer> renderLayersToExr(RenderLayers&& layers) {
  return {{"", std::move(layers.beauty)},
          {"sun", std::move(layers.sun)},
          {"sky", std::move(layers.sky)},
          {"single", std::move(layers.single)},
          {"multiple", std::move(layers.multiple)}};
}

std::vector<ExrLayer> readRenderLayersExr(const std::string& path) {
  ExrContents contents = readExr(path);
  std::vector<ExrLayer> layers;
  for (const char* name : {"", "sun", "sky", "single", "multiple"}) {
    auto it = contents.layers.find(name);
    if (it == contents.layers.end()) {
      throw InputError(path + ": lacks render layer '" + std::string(name) + "'");
    }
    layers.push_back({name, std::move(it->second)});
  }
  return layers;
}

void scaleRgb(Image& image, const Rgb& e) {
  const double s[3] = {e.x, e.y, e.z};
  for (size_t i = 0; i < image.data.size(); ++i) {
    const int c = int(i % size_t(image.channels));
    if (c < 3) image.data[i] = float(image.data[i] * s[c]);
  }
}

void writeRenderLayers(const std::string& path, const RenderLayers& layers,
                       const std::map<std::string, std::string>& attributes) {
  writeExr(path, renderLayersToExr(layers), attributes);
}

}  // namespace cloudbake
