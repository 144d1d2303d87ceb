#include "core/transport/layers_exr.h"

namespace cloudbake {

std::vector<ExrLayer> renderLayersToExr(const RenderLayers& layers) {
  return {{"", layers.beauty},
          {"sun", layers.sun},
          {"sky", layers.sky},
          {"single", layers.single},
          {"multiple", layers.multiple}};
}

void writeRenderLayers(const std::string& path, const RenderLayers& layers,
                       const std::map<std::string, std::string>& attributes) {
  writeExr(path, renderLayersToExr(layers), attributes);
}

}  // namespace cloudbake
