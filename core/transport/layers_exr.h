// Writing path-traced render layers as one multi-layer EXR (the contract of docs/DESIGN.md).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/io/exr_io.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {

/// The layers in file order: the cloud element unprefixed (R, G, B, A: premultiplied, RGB =
/// sun + sky, A = coverage), `background` (what is seen through the cloud), `beauty` (the two
/// added), then `sun`, `sky`, `single`, `multiple` (each R, G, B). Images are copied.
std::vector<ExrLayer> renderLayersToExr(const RenderLayers& layers);
/// The same, moving the images.
std::vector<ExrLayer> renderLayersToExr(RenderLayers&& layers);

/// The header attribute naming a view's layers in file order, "cloud" for the unprefixed one
/// (outputs.exr_layers may leave any out).
inline constexpr const char* kExrLayersAttribute = "cloudbake:layers";

/// The layer of `exr` that holds the beauty: "beauty" in views of this layout (which may have
/// left it out: see kExrLayersAttribute), "" (unprefixed) in older views and other renderers'
/// files.
std::string beautyLayerName(const ExrContents& exr);

/// Their names in file order ("" first).
const std::vector<std::string>& renderLayerNames();

/// Reads those layers back in file order (a cached view); InputError naming the path when one
/// is missing.
std::vector<ExrLayer> readRenderLayersExr(const std::string& path);

/// Multiplies the RGB channels by the sun irradiance per channel (alpha untouched): a render
/// at unit irradiance becomes one at `e`.
void scaleRgb(Image& image, const Rgb& e);

/// Writes `layers` to `path` atomically (FLOAT, ZIP; see writeExr), with `attributes` as string
/// header attributes. Throws InputError naming the path on failure.
void writeRenderLayers(const std::string& path, const RenderLayers& layers,
                       const std::map<std::string, std::string>& attributes = {});

}  // namespace cloudbake
