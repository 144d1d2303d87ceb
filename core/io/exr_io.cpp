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
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/io/file_sync.h"

namespace cloudbake {
namespace {

// Reading refuses images beyond this many pixels, so a corrupt header cannot make us allocate
// gigabytes (16384^2 is the largest render; maps are far smaller).
constexpr long long kMaxPixels = 1ll << 28;

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

std::string uniqueTempPath(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  std::ostringstream os;
  os << path << ".tmp." << ::getpid() << "." << counter++;
  return os.str();
}

}  // namespace

void writeExr(const std::string& path, const std::vector<ExrLayer>& layers,
              const std::map<std::string, std::string>& attributes,
              const std::map<std::string, ExrMatrix>& matrices) {
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

  Imf::Header header(width, height);
  header.compression() = Imf::ZIP_COMPRESSION;
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

  const std::string tmp = uniqueTempPath(path);
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

ExrContents readExr(const std::string& path) {
  // isOpenExrFile only checks the magic number; it gives a clearer message than the library's
  // for the common "not an EXR at all / does not exist" cases.
  if (FILE* f = std::fopen(path.c_str(), "rb")) {
    std::fclose(f);
  } else if (errno == ENOENT) {
    throw MissingFileError(path + ": file not found");  // exit code 3, as for shots' files
  } else {
    throw InputError(path + ": cannot open EXR file (" + std::strerror(errno) + ")");
  }
  if (!Imf::isOpenExrFile(path.c_str())) throw InputError(path + ": not an OpenEXR file");

  ExrContents out;
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i dw = header.dataWindow();
    const long long w = static_cast<long long>(dw.max.x) - dw.min.x + 1;
    const long long h = static_cast<long long>(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w * h > kMaxPixels) {
      throw InputError(path + ": EXR data window is empty or larger than 2^28 pixels");
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
    if (total_channels * w * h > 4 * kMaxPixels) {
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
