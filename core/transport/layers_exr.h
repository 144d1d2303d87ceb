// Writing path-traced render layers as one multi-layer EXR (the contract of docs/DESIGN.md).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/io/exr_io.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {

/// The layers in file order: beauty unprefixed (R, G, B, A), then `sun`, `sky`, `single`,
/// `multiple` (each R, G, B). Images are copied.
std::vector<ExrLayer> renderLayersToExr(const RenderLayers& layers);

/// Writes `layers` to `path` atomically (FLOAT, ZIP; see writeExr), with `attributes` as string
/// header attributes. Throws InputError naming the path on failure.
void writeRenderLayers(const std::string& path, const RenderLayers& layers,
                       const std::map<std::string, std::string>& attributes = {});

}  // namespace cloudbake
