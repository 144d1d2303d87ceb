#include "core/io/exr_io.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfMatrixAttribute.h>
#include <ImfOutputFile.h>
#include <ImfStdIO.h>
#include <ImfStringAttribute.h>
#include <ImfTestFile.h>
#include <ImfThreading.h>
#include <openexr.h>
#include <tbb/info.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/io/file_sync.h"

namespace cloudbake {
namespace {

// Reading refuses images beyond this many pixels, so a corrupt header cannot make us allocate
// gigabytes (2^26, 8192^2, is the largest view a server allows: --max-image-pixels).
constexpr long long kMaxPixels = 1ll << 26;
// Channel values read at most (512 MiB of floats): beyond any view this product writes (its
// server's limit is 2^22 pixels a view) and far below what a corrupt header could ask for.
constexpr long long kMaxValues = 1ll << 27;
// Data windows past this many pixels a side are refused by OpenEXR itself, before it sizes its
// line-offset tables from them.
constexpr int kMaxSide = 1 << 15;

// Bytes Imf::Header reads for a predefined attribute type of fixed layout; -1 for the types
// whose declared size it uses (string, vectors, unknown types: allocated at that size).
long long fixedExrAttributeSize(const std::string& type) {
  static const std::map<std::string, long long> kSizes = {{"box2i", 16},
                                                          {"box2f", 16},
                                                          {"compression", 1},
                                                          {"lineOrder", 1},
                                                          {"float", 4},
                                                          {"double", 8},
                                                          {"int", 4},
                                                          {"v2i", 8},
                                                          {"v2f", 8},
                                                          {"v2d", 16},
                                                          {"v3i", 12},
                                                          {"v3f", 12},
                                                          {"v3d", 24},
                                                          {"m33f", 36},
                                                          {"m33d", 72},
                                                          {"m44f", 64},
                                                          {"m44d", 128},
                                                          {"tiledesc", 9},
                                                          {"envmap", 1},
                                                          {"keycode", 28},
                                                          {"timecode", 8},
                                                          {"rational", 8},
                                                          {"chromaticities", 32},
                                                          {"deepImageState", 1}};
  const auto it = kSizes.find(type);
  return it == kSizes.end() ? -1 : it->second;
}

// OpenEXR allocates an attribute's declared size before reading it: a fuzzed header asked for
// 1.7 GB. Walk every header (all parts of a multi-part file) and refuse a size the file cannot
// hold, or a header that does not end before the file does.
void checkExrHeaderSizes(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  const long long file_size = static_cast<long long>(in.tellg());
  unsigned char head[8] = {};
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(head), 8)) throw InputError(path + ": truncated EXR");
  const bool multipart = (head[5] & 0x10) != 0;              // version flags, bit 12
  const size_t max_name = (head[5] & 0x04) != 0 ? 255 : 31;  // bit 10: long names
  // As OpenEXR reads a name: up to max_name characters and a terminating NUL, stopping at the
  // NUL; so a name without one ends where OpenEXR's does.
  // Channel names may be 255 characters whatever the flag says (Imf::ChannelList's reader).
  auto readName = [&](std::string* s, size_t max = 0) {
    s->clear();
    for (size_t n = 0; n <= (max ? max : max_name); ++n) {
      const int c = in.get();
      if (c == EOF) throw InputError(path + ": EXR header is truncated");
      if (c == 0) return;
      s->push_back(char(c));
    }
  };
  for (int part = 0;; ++part) {
    std::string name, type;
    for (readName(&name); !name.empty(); readName(&name)) {
      readName(&type);
      unsigned char b[4];
      if (!in.read(reinterpret_cast<char*>(b), 4)) throw InputError(path + ": truncated EXR");
      long long size = static_cast<int32_t>(uint32_t(b[0]) | uint32_t(b[1]) << 8 |
                                            uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24);
      // Imf::Header reads a known type by its own layout, whatever the declared size says: go
      // where it goes, so the next attribute is the one it reads next.
      if (type == "chlist") {
        std::string channel;
        for (readName(&channel, 255); !channel.empty(); readName(&channel, 255)) {
          in.seekg(16, in.cur);
        }
        continue;
      }
      const long long fixed = fixedExrAttributeSize(type);
      if (fixed >= 0) size = fixed;
      if (type == "preview") {  // width and height, then width x height RGBA bytes
        unsigned char wh[8];
        if (!in.read(reinterpret_cast<char*>(wh), 8)) throw InputError(path + ": truncated EXR");
        const auto u32 = [&](int o) {
          return uint32_t(wh[o]) | uint32_t(wh[o + 1]) << 8 | uint32_t(wh[o + 2]) << 16 |
                 uint32_t(wh[o + 3]) << 24;
        };
        size = static_cast<long long>(u32(0)) * u32(4) * 4;
      }
      if (size < 0 || size > file_size - static_cast<long long>(in.tellg())) {
        throw InputError(path + ": EXR attribute '" + name + "' claims " + std::to_string(size) +
                         " bytes, more than the file holds");
      }
      in.seekg(size, std::ios::cur);
    }
    if (!multipart || in.peek() == 0 || part > 100000) return;
  }
}

// Allocations of OpenEXR's C core while it parses a header: a header needs kilobytes, so a
// request past this is a corrupt size, refused instead of granted.
constexpr size_t kMaxHeaderAllocation = size_t(64) << 20;
void* boundedAlloc(size_t n) { return n > kMaxHeaderAllocation ? nullptr : std::malloc(n); }
void quietErrors(exr_const_context_t, exr_result_t, const char*) {}

// The header as OpenEXR's C core reads it, with every allocation bounded and the image limits
// set: it validates attribute sizes and the data window before Imf::InputFile (which has no
// such bound) sees the file.
void checkExrHeaderWithCore(const std::string& path) {
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.alloc_fn = boundedAlloc;
  init.free_fn = std::free;
  init.error_handler_fn = quietErrors;
  init.max_image_width = init.max_image_height = kMaxSide;
  init.max_tile_width = init.max_tile_height = kMaxSide;
  exr_context_t ctx = nullptr;
  const exr_result_t rv = exr_start_read(&ctx, path.c_str(), &init);
  if (ctx) exr_finish(&ctx);
  if (rv != EXR_ERR_SUCCESS) {
    throw InputError(path + ": not a readable OpenEXR file (" + exr_get_default_error_message(rv) +
                     ")");
  }
}

std::vector<std::string> channelNamesFor(int channels) {
  switch (channels) {
    case 1:
      return {"Y"};
    case 3:
      return {"R", "G", "B"};
    case 4:
      return {"R", "G", "B", "A"};
    default:
      return {};
  }
}

// Sort key that puts R, G, B, A, Y first (in that order), then everything else by name.
std::pair<int, std::string> channelOrder(const std::string& base) {
  static const char* kKnown[] = {"R", "G", "B", "A", "Y"};
  for (int i = 0; i < 5; ++i) {
    if (base == kKnown[i]) return {i, ""};
  }
  return {5, base};
}

constexpr int kZipLevel = 1;

Imf::Compression toImf(ExrCompression c) {
  switch (c) {
    case ExrCompression::kNone:
      return Imf::NO_COMPRESSION;
    case ExrCompression::kRle:
      return Imf::RLE_COMPRESSION;
    case ExrCompression::kZips:
      return Imf::ZIPS_COMPRESSION;
    case ExrCompression::kZip:
      return Imf::ZIP_COMPRESSION;
    case ExrCompression::kPiz:
      return Imf::PIZ_COMPRESSION;
  }
  throw InputError("EXR compression " + std::to_string(int(c)) + " is not one of " +
                   exrCompressionNamesList());
}

// Before Imf::InputFile sizes anything from an untrusted header (the fuzzing section of
// docs/api.md).
void checkExrHeader(const std::string& path) {
  // isOpenExrFile only checks the magic number; it gives a clearer message than the library's
  // for the common "not an EXR at all / does not exist" cases.
  // A FIFO would block the open, a device never end: regular files only.
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (std::filesystem::exists(st) && !std::filesystem::is_regular_file(st)) {
    throw InputError(path + ": not a regular file");
  }
  if (FILE* f = std::fopen(path.c_str(), "rb")) {
    std::fclose(f);
  } else if (errno == ENOENT) {
    throw MissingFileError(path + ": file not found");  // exit code 3, as for shots' files
  } else {
    throw InputError(path + ": cannot open EXR file (" + std::strerror(errno) + ")");
  }
  if (!Imf::isOpenExrFile(path.c_str())) throw InputError(path + ": not an OpenEXR file");
  checkExrHeaderSizes(path);
  checkExrHeaderWithCore(path);
  Imf::Header::setMaxImageSize(kMaxSide, kMaxSide);
  Imf::Header::setMaxTileSize(kMaxSide, kMaxSide);
}

// The header of a written EXR: its compression, this build's version and the caller's
// attributes.
Imf::Header exrHeader(const std::string& path, int width, int height,
                      const std::map<std::string, std::string>& attributes,
                      const std::map<std::string, ExrMatrix>& matrices,
                      ExrCompression compression) {
  Imf::Header header(width, height);
  header.compression() = toImf(compression);
  // Deflate's fastest level: the bench's six 640x480 views wrote 1.19x faster than at OpenEXR's
  // default of 4 (up to 1.6x on one), for files 0-2 % larger (docs/methods.md, "Writing the
  // views"). The pixels are the same.
  header.zipCompressionLevel() = kZipLevel;
  header.insert("cloudbake:version", Imf::StringAttribute(CLOUDBAKE_VERSION));
  for (const auto& [key, value] : attributes) {
    if (key.empty()) throw InputError(path + ": empty attribute name");
    header.insert(key, Imf::StringAttribute(value));
  }
  for (const auto& [key, m] : matrices) {
    if (key.empty()) throw InputError(path + ": empty attribute name");
    header.insert(
        key, Imf::M44fAttribute(Imath::M44f(m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8],
                                            m[9], m[10], m[11], m[12], m[13], m[14], m[15])));
  }
  return header;
}

}  // namespace

void writeExr(const std::string& path, const std::vector<ExrLayer>& layers,
              const std::map<std::string, std::string>& attributes,
              const std::map<std::string, ExrMatrix>& matrices, ExrCompression compression) {
  if (layers.empty()) throw InputError(path + ": no layers to write");
  const int width = layers.front().image.width, height = layers.front().image.height;
  if (width <= 0 || height <= 0) throw InputError(path + ": image has zero size");
  std::set<std::string> seen;
  for (const ExrLayer& layer : layers) {
    const Image& im = layer.image;
    if (im.width != width || im.height != height) {
      throw InputError(path + ": layer '" + layer.name + "' has a different size than the first");
    }
    if (channelNamesFor(im.channels).empty()) {
      throw InputError(path + ": layer '" + layer.name + "' has " + std::to_string(im.channels) +
                       " channels (1, 3 or 4 supported)");
    }
    if (im.data.size() != size_t(width) * height * im.channels) {
      throw InputError(path + ": layer '" + layer.name + "' pixel buffer has the wrong size");
    }
    if (layer.name.find('.') != std::string::npos || !seen.insert(layer.name).second) {
      throw InputError(path + ": layer name '" + layer.name + "' is duplicated or contains '.'");
    }
  }

  Imf::Header header = exrHeader(path, width, height, attributes, matrices, compression);
  Imf::FrameBuffer fb;
  for (const ExrLayer& layer : layers) {
    const Image& im = layer.image;
    const std::vector<std::string> names = channelNamesFor(im.channels);
    const size_t xstride = sizeof(float) * im.channels;
    for (int c = 0; c < im.channels; ++c) {
      const std::string name = layer.name.empty() ? names[c] : layer.name + "." + names[c];
      header.channels().insert(name, Imf::Channel(Imf::FLOAT));
      // OpenEXR's slice API takes a non-const pointer even for writing.
      char* base = reinterpret_cast<char*>(const_cast<float*>(im.data.data())) + sizeof(float) * c;
      fb.insert(name, Imf::Slice(Imf::FLOAT, base, xstride, xstride * width));
    }
  }

  const std::string tmp = temporaryNameFor(path);
  try {
    // Our own stream, checked at the end: OpenEXR closes its own file stream unchecked in a
    // destructor, so a full disk could cut the last buffered bytes off a file reported
    // written. (No exception mask: the destructor that writes the line offsets must not throw.)
    std::ofstream os(tmp, std::ios::out | std::ios::binary | std::ios::trunc);
    if (!os) throw std::runtime_error(std::string("cannot create: ") + std::strerror(errno));
    {
      Imf::StdOFStream stream(os, tmp.c_str());
      Imf::OutputFile file(stream, header);
      file.setFrameBuffer(fb);
      file.writePixels(height);
    }
    os.close();
    if (os.fail()) throw std::runtime_error(std::string("write failed: ") + std::strerror(errno));
    syncFile(tmp);
  } catch (const StorageFullError&) {
    std::remove(tmp.c_str());
    throw;
  } catch (const std::exception& e) {
    const int err = errno;
    std::remove(tmp.c_str());
    throwIfNoSpace(err, path + ": cannot write EXR: " + e.what());
    throw InputError(path + ": cannot write EXR: " + e.what());
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw InputError(path + ": cannot move the finished EXR into place");
  }
}

void setExrThreads(int threads) {
  if (threads < 0 || threads > 4096) {
    throw InputError("EXR threads: must be in [0, 4096], got " + std::to_string(threads));
  }
  Imf::setGlobalThreadCount(threads > 0 ? threads : tbb::info::default_concurrency());
}

ExrContents readExr(const std::string& path) {
  checkExrHeader(path);

  ExrContents out;
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i dw = header.dataWindow();
    const long long w = static_cast<long long>(dw.max.x) - dw.min.x + 1;
    const long long h = static_cast<long long>(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w * h > kMaxPixels) {
      throw InputError(path + ": EXR data window is empty or larger than 2^26 pixels");
    }
    out.width = static_cast<int>(w);
    out.height = static_cast<int>(h);

    for (auto it = header.begin(); it != header.end(); ++it) {
      if (const auto* m = dynamic_cast<const Imf::M44fAttribute*>(&it.attribute())) {
        ExrMatrix& to = out.matrices[it.name()];
        for (int k = 0; k < 16; ++k) to[size_t(k)] = m->value()[k / 4][k % 4];
      }
      if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute())) {
        out.attributes[it.name()] = s->value();
      }
    }

    // Group channels by layer prefix (everything before the last '.').
    std::map<std::string, std::vector<std::string>> bases;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
      const std::string full = it.name();
      const size_t dot = full.rfind('.');
      const std::string layer = dot == std::string::npos ? "" : full.substr(0, dot);
      bases[layer].push_back(dot == std::string::npos ? full : full.substr(dot + 1));
    }
    long long total_channels = 0;
    for (const auto& entry : bases) total_channels += static_cast<long long>(entry.second.size());
    if (total_channels * w * h > kMaxValues) {
      throw InputError(path + ": EXR has too many channels x pixels to read");
    }

    Imf::FrameBuffer fb;
    for (auto& [layer, names] : bases) {
      std::sort(names.begin(), names.end(), [](const std::string& a, const std::string& b) {
        return channelOrder(a) < channelOrder(b);
      });
      Image im(out.width, out.height, static_cast<int>(names.size()));
      out.layers[layer] = std::move(im);
      out.channel_names[layer] = names;
    }
    for (auto& [layer, im] : out.layers) {
      const auto& names = out.channel_names[layer];
      const size_t xstride = sizeof(float) * im.channels;
      const size_t ystride = xstride * im.width;
      for (size_t c = 0; c < names.size(); ++c) {
        const std::string full = layer.empty() ? names[c] : layer + "." + names[c];
        // Point the slice so that pixel (dw.min.x, dw.min.y) lands at the buffer's start.
        char* base = reinterpret_cast<char*>(im.data.data()) + sizeof(float) * c -
                     static_cast<ptrdiff_t>(dw.min.x) * static_cast<ptrdiff_t>(xstride) -
                     static_cast<ptrdiff_t>(dw.min.y) * static_cast<ptrdiff_t>(ystride);
        fb.insert(full, Imf::Slice(Imf::FLOAT, base, xstride, ystride, 1, 1, 0.0));
      }
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path + ": corrupt or unreadable EXR: " + e.what());
  }
  return out;
}

Image readExrRgb(const std::string& path) {
  ExrContents contents = readExr(path);
  auto it = contents.layers.find("");
  if (it == contents.layers.end()) {
    throw InputError(path + ": EXR has no unprefixed R,G,B (or Y) channels");
  }
  const Image& src = it->second;
  const std::vector<std::string>& names = contents.channel_names[""];
  auto find = [&](const char* n) {
    const auto p = std::find(names.begin(), names.end(), n);
    return p == names.end() ? -1 : static_cast<int>(p - names.begin());
  };
  int idx[3] = {find("R"), find("G"), find("B")};
  if (idx[0] < 0 || idx[1] < 0 || idx[2] < 0) {
    const int y = find("Y");
    if (y < 0) throw InputError(path + ": EXR has no unprefixed R,G,B (or Y) channels");
    idx[0] = idx[1] = idx[2] = y;
  }
  Image rgb(src.width, src.height, 3);
  for (int y = 0; y < src.height; ++y) {
    for (int x = 0; x < src.width; ++x) {
      const float* s = src.at(x, y);
      float* d = rgb.at(x, y);
      for (int c = 0; c < 3; ++c) d[c] = s[idx[c]];
    }
  }
  return rgb;
}

}  // namespace cloudbake
