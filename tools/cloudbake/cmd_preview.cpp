// `cloudbake preview`: an sRGB PNG of any layer of any EXR (a view of this tool, of the server,
// or of another renderer), to look at a result without re-rendering it.
#include <cmath>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "common/cli_number.h"
#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/io/png_writer.h"
#include "core/transport/layers_exr.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {

// The layer to show, by its name in the file: the one asked for ("cloud" is the unprefixed
// element), else the beauty.
std::string pickLayer(const ExrContents& exr, const std::string& layer, const std::string& path) {
  const std::string name = layer.empty() ? beautyLayerName(exr) : layer == "cloud" ? "" : layer;
  auto it = exr.layers.find(name);
  if (it == exr.layers.end() || it->second.channels < 3) {
    std::string have;
    for (const auto& [n, image] : exr.layers) {
      if (image.channels >= 3) have += (have.empty() ? "" : ", ") + (n.empty() ? "cloud" : n);
    }
    if (layer.empty()) {  // no --layer given: the file has no beauty to show
      throw InputError(path + ": no RGB beauty layer to preview (RGB layers: " +
                       (have.empty() ? std::string("none") : have) + "; choose one with --layer)");
    }
    throw InputError("--layer: " + path + " has no RGB layer '" + layer +
                     "' (it has: " + (have.empty() ? std::string("none") : have) + ")");
  }
  return name;
}

// A non-finite pixel is the input's fault: named by the EXR and its layer, before the PNG.
void checkFinite(const Image& image, const std::string& path, const std::string& layer) {
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      for (int c = 0; c < image.channels; ++c) {
        if (!std::isfinite(image.at(x, y)[c])) {
          throw InputError(path + ": layer '" + layer + "' has a non-finite pixel at (" +
                           std::to_string(x) + ", " + std::to_string(y) + "): nothing to preview");
        }
      }
    }
  }
}

}  // namespace

void addPreviewCommand(CLI::App& app, int* exit_code) {
  struct Options {
    std::string exr, out, layer;
    double exposure = 0;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "preview",
      "Write an sRGB PNG preview of an EXR's layer (default: the beauty); prints "
      "{\"png\",\"layer\",\"exposure\"} as one JSON line");
  cmd->add_option("exr", opt->exr,
                  "the EXR (any view this tool or the server wrote, or another "
                  "renderer's)")
      ->required();
  cmd->add_option("--out", opt->out, "PNG file to write")->required();
  cmd->add_option("--layer", opt->layer,
                  "layer to show: beauty (default), cloud (the premultiplied element), "
                  "background, sun, sky, single, multiple");
  cmd->add_option("--exposure", opt->exposure,
                  "radiance multiplier (default: auto, the 99th percentile of luminance at 0.8), "
                  "so previews of different files compare")
      ->check(numberIn(0, 1e12, true));
  // numberIn checks what was typed; 0, the default (auto), is never typed.
  cmd->callback([opt, exit_code] {
    const ExrContents exr = readExr(opt->exr);
    const std::string name = pickLayer(exr, opt->layer, opt->exr);
    checkFinite(exr.layers.at(name), opt->exr, name.empty() ? "cloud" : name);
    const double exposure = writePreviewPng(opt->out, exr.layers.at(name), opt->exposure);
    const std::string layer = opt->layer.empty() ? "beauty" : opt->layer;
    std::printf(
        "%s\n",
        nlohmann::json{{"png", opt->out}, {"layer", layer}, {"exposure", exposure}}.dump().c_str());
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
