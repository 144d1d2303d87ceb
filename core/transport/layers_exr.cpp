#include "core/transport/layers_exr.h"

#include "core/error.h"

namespace cloudbake {

namespace {

// The cloud as a compositing element: premultiplied RGBA, RGB the light the cloud sends towards
// the camera (sun + sky layers), A its coverage. `over` a plate of the background reproduces the
// beauty; the beauty itself (cloud plus background seen through it) was written here before,
// which an `over` in Nuke, Houdini or Blender counted twice.
Image cloudElement(const RenderLayers& layers) {
  Image cloud = layers.beauty;
  const size_t n = size_t(cloud.width) * cloud.height;
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c) {
      cloud.data[4 * p + c] = layers.sun.data[3 * p + c] + layers.sky.data[3 * p + c];
    }
  }
  return cloud;
}

// The beauty's RGB alone (its alpha is the cloud element's).
Image beautyRgb(const RenderLayers& layers) {
  const Image& b = layers.beauty;
  Image rgb(b.width, b.height, 3);
  for (size_t p = 0; p < size_t(b.width) * b.height; ++p) {
    for (int c = 0; c < 3; ++c) rgb.data[3 * p + c] = b.data[4 * p + c];
  }
  return rgb;
}

}  // namespace

std::string beautyLayerName(const ExrContents& exr) {
  const bool layered = exr.layers.count("beauty") || exr.attributes.count(kExrLayersAttribute);
  return layered ? "beauty" : "";
}

const std::vector<std::string>& renderLayerNames() {
  static const std::vector<std::string> kNames = {"",    "background", "beauty",  "sun",
                                                  "sky", "single",     "multiple"};
  return kNames;
}

std::vector<ExrLayer> renderLayersToExr(const RenderLayers& layers) {
  return {{"", cloudElement(layers)},    {"background", layers.background},
          {"beauty", beautyRgb(layers)}, {"sun", layers.sun},
          {"sky", layers.sky},           {"single", layers.single},
          {"multiple", layers.multiple}};
}

std::vector<ExrLayer> renderLayersToExr(RenderLayers&& layers) {
  Image cloud = cloudElement(layers);
  Image beauty = beautyRgb(layers);
  return {{"", std::move(cloud)},
          {"background", std::move(layers.background)},
          {"beauty", std::move(beauty)},
          {"sun", std::move(layers.sun)},
          {"sky", std::move(layers.sky)},
          {"single", std::move(layers.single)},
          {"multiple", std::move(layers.multiple)}};
}

std::vector<ExrLayer> readRenderLayersExr(const std::string& path) {
  ExrContents contents = readExr(path);
  std::vector<ExrLayer> layers;
  for (const std::string& name : renderLayerNames()) {
    auto it = contents.layers.find(name);
    if (it == contents.layers.end()) {
      throw InputError(path + ": lacks render layer '" + name + "'");
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
