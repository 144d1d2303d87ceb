// Reading and writing multi-layer OpenEXR images (OpenEXR headers stay in exr_io.cpp).
#pragma once

#include <array>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "core/io/exr_compression.h"
#include "core/io/image.h"

namespace cloudbake {

/// One layer of an EXR file: `name` is the channel prefix ("sun" gives sun.R, sun.G, sun.B);
/// the empty name is the unprefixed beauty layer (R, G, B, A). The image's channel count picks
/// the channel names: 1 -> Y, 3 -> R,G,B, 4 -> R,G,B,A (other counts are rejected).
struct ExrLayer {
  std::string name;
  Image image;
};

/// Everything readExr() found in a file.
/// An M44f header attribute, m[4 * row + column], in Imath's row-vector convention
/// (p' = p M: translation in the last row).
using ExrMatrix = std::array<float, 16>;

struct ExrContents {
  int width = 0, height = 0;
  /// Layers by prefix ("" = unprefixed). Channels are ordered R, G, B, A, then Y, then any
  /// other channel names alphabetically; channel_names gives the order per layer.
  std::map<std::string, Image> layers;
  std::map<std::string, std::vector<std::string>> channel_names;
  /// String-valued header attributes (e.g. "cloudbake:version").
  std::map<std::string, std::string> attributes;
  /// 4x4 float matrix attributes (e.g. "worldToCamera"), row-major as Imath stores them.
  std::map<std::string, ExrMatrix> matrices;
};

/// Writes a single-part scanline EXR with FLOAT pixels, compressed losslessly with `compression`
/// (ZIP unless given; the pixels read back the same whatever it is). All layers must have
/// the same, non-zero size and distinct names. `attributes` are stored as string attributes, plus
/// "cloudbake:version" (set automatically unless given). The write is atomic: the file is written
/// next to `path` under a temporary name and renamed over `path`, so readers never see a partial
/// image. Throws InputError (naming `path`) when the layers are invalid or the file cannot be
/// written.
void writeExr(const std::string& path, const std::vector<ExrLayer>& layers,
              const std::map<std::string, std::string>& attributes = {},
              const std::map<std::string, ExrMatrix>& matrices = {},
              ExrCompression compression = ExrCompression::kZip);

/// Sets the threads OpenEXR compresses and decompresses an image's line blocks on; 0 means
/// all cores (TBB's default concurrency), as `--threads 0` does. Without a call OpenEXR does
/// it on the calling thread alone: a quarter of a 640x480 view's run. The pool is OpenEXR's and
/// process-wide, so only an executable's main or command calls this, never a library; the bytes
/// written do not depend on it. Throws InputError for a count outside [0, 4096].
void setExrThreads(int threads);

/// Reads every channel of an EXR (any pixel type, converted to float; the data window is read
/// as a whole, top row first). Throws InputError naming `path` for a missing, truncated or
/// corrupt file, or an image larger than 2^28 pixels.
ExrContents readExr(const std::string& path);

/// Reads the unprefixed R, G, B channels as a 3-channel image (lat-long sky maps). A file with
/// only Y gives grey RGB. Throws InputError if neither R,G,B nor Y exists.
Image readExrRgb(const std::string& path);

}  // namespace cloudbake
