// `cloudbake render SHOT.json --out DIR [--threads N] [--samples N] [--quiet] [--png]`: renders
// every view of a shot in-process with the reference path tracer (docs/shot-format.md) and
// writes DIR/<view>.exr (beauty + sun, sky, single, multiple layers) and DIR/bake.vdb on request.
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/io/png_writer.h"
#include "core/io/vdb_io.h"
#include "core/shot/scene_builder.h"
#include "core/shot/shot_parser.h"
#include "core/transport/path_tracer.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {
namespace fs = std::filesystem;

struct RenderOptions {
  std::string shot;
  std::string out;
  int threads = 0;
  int samples = -1;  // -1: the shot's bake.samples
  bool quiet = false;
  bool png = false;
};

// Per-view progress on stderr: an updating line on a terminal, one line per 10% otherwise (logs
// and CI capture stay readable).
class ProgressLine {
 public:
  ProgressLine(std::string label, bool quiet)
      : label_(std::move(label)), quiet_(quiet), tty_(isatty(fileno(stderr)) != 0) {}

  void update(double fraction) {
    if (quiet_) return;
    const int percent = static_cast<int>(std::floor(std::clamp(fraction, 0.0, 1.0) * 100.0));
    if (tty_) {
      if (percent == last_) return;
      std::fprintf(stderr, "\r%s: %3d%%", label_.c_str(), percent);
    } else {
      const int decile = percent / 10 * 10;
      if (decile <= last_) return;
      std::fprintf(stderr, "%s: %d%%\n", label_.c_str(), decile);
    }
    std::fflush(stderr);
    last_ = tty_ ? percent : percent / 10 * 10;
  }

  void done(double seconds) {
    if (quiet_) return;
    if (tty_) {
      std::fprintf(stderr, "\r%s: 100%% (%.2f s)\n", label_.c_str(), seconds);
    } else {
      if (last_ < 100) std::fprintf(stderr, "%s: 100%%\n", label_.c_str());
      std::fprintf(stderr, "%s: done in %.2f s\n", label_.c_str(), seconds);
    }
    std::fflush(stderr);
  }

 private:
  std::string label_;
  bool quiet_, tty_;
  int last_ = -1;
};

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

uint8_t srgbByte(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255.0));
}

// Preview only: exposure puts the 99th percentile of luminance at 0.8, then sRGB encoding. The
// EXR stays the authoritative, unexposed radiance.
void writePreviewPng(const std::string& path, const Image& beauty) {
  std::vector<double> lum;
  lum.reserve(size_t(beauty.width) * beauty.height);
  for (int y = 0; y < beauty.height; ++y) {
    for (int x = 0; x < beauty.width; ++x) {
      const float* p = beauty.at(x, y);
      lum.push_back(0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]);
    }
  }
  const size_t k = std::min(lum.size() - 1, size_t(0.99 * double(lum.size())));
  std::nth_element(lum.begin(), lum.begin() + std::ptrdiff_t(k), lum.end());
  const double exposure = lum[k] > 0 && std::isfinite(lum[k]) ? 0.8 / lum[k] : 1.0;
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

// Methods other than the path tracer and animated volumes are later issues; say so plainly.
void checkRenderable(const ShotSpec& shot, const std::string& source) {
  if (shot.bake.method != BakeSpec::Method::kPathtrace) {
    throw InputError(source + ": /bake/method: '" + methodName(shot.bake.method) +
                     "' is not implemented in this version (use 'pathtrace')");
  }
  if (std::holds_alternative<SequenceVolumeSpec>(shot.volume)) {
    throw InputError(source +
                     ": /volume/sequence: animated volumes are not supported by method "
                     "'pathtrace' yet");
  }
}

std::vector<std::string> render(const RenderOptions& opt) {
  if (opt.threads < 0 || opt.threads > 4096) {
    throw InputError("--threads: must be in [0, 4096] (0 = all cores), got " +
                     std::to_string(opt.threads));
  }
  if (opt.samples != -1 && (opt.samples < 1 || opt.samples > 1000000)) {
    throw InputError("--samples: must be in [1, 1000000], got " + std::to_string(opt.samples));
  }
  std::unique_ptr<tbb::global_control> limit;
  if (opt.threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<size_t>(opt.threads));
  }
  const ShotSpec shot = parseShotFile(opt.shot);
  checkRenderable(shot, opt.shot);

  std::error_code ec;
  fs::create_directories(opt.out, ec);
  if (ec || !fs::is_directory(opt.out)) {
    throw InputError("--out: cannot create folder '" + opt.out + "'" +
                     (ec ? ": " + ec.message() : ""));
  }

  const auto t_build = std::chrono::steady_clock::now();
  const Scene scene = buildScene(shot, opt.shot);
  if (!opt.quiet) {
    std::fprintf(stderr, "%s: built %s in %.2f s\n", shot.name.c_str(),
                 scene.medium.density->describe().c_str(), seconds(t_build));
  }

  PathTracerOptions pt;
  pt.samples_per_pixel = opt.samples != -1 ? opt.samples : shot.bake.samples;
  pt.seed = shot.bake.seed;
  if (shot.bake.max_depth) pt.max_depth = *shot.bake.max_depth;
  pt.threads = opt.threads;

  std::vector<std::string> written;
  if (!shot.outputs.exr && !shot.outputs.vdb && !opt.quiet) {
    std::fprintf(stderr, "%s: nothing to write (outputs.exr and outputs.vdb are both false)\n",
                 shot.name.c_str());
  }
  if (shot.outputs.exr) {
    for (const Camera& camera : scene.cameras) {
      ProgressLine line("view '" + camera.name + "' " + std::to_string(camera.width_px) + "x" +
                            std::to_string(camera.height_px) + ", " +
                            std::to_string(pt.samples_per_pixel) + " spp",
                        opt.quiet);
      const auto t0 = std::chrono::steady_clock::now();
      line.update(0.0);
      RenderLayers layers;
      try {
        layers =
            renderPathTraced(scene.medium, scene.sun, scene.sky, camera, pt, [&line](double f) {
              line.update(f);
              return true;
            });
      } catch (const InputError& e) {
        throw InputError(opt.shot + ": view '" + camera.name + "': " + e.what());
      }
      line.done(seconds(t0));
      const std::string path = (fs::path(opt.out) / (camera.name + ".exr")).string();
      const std::map<std::string, std::string> attributes = {
          {"cloudbake:shot", shot.name},
          {"cloudbake:view", camera.name},
          {"cloudbake:method", methodName(shot.bake.method)},
          {"cloudbake:samples", std::to_string(pt.samples_per_pixel)},
          {"cloudbake:seed", std::to_string(pt.seed)},
          {"cloudbake:units", "radiance, units of sun irradiance per sr"}};
      writeExr(path,
               {{"", std::move(layers.beauty)},
                {"sun", std::move(layers.sun)},
                {"sky", std::move(layers.sky)},
                {"single", std::move(layers.single)},
                {"multiple", std::move(layers.multiple)}},
               attributes);
      written.push_back(path);
      if (opt.png) {
        const std::string png = (fs::path(opt.out) / (camera.name + ".png")).string();
        writePreviewPng(png, readExrRgb(path));
        written.push_back(png);
      }
    }
  }
  if (shot.outputs.vdb) {
    const std::string path = (fs::path(opt.out) / "bake.vdb").string();
    VdbWriteOptions vdb;
    vdb.voxel_size = shot.outputs.vdb_voxel_size;
    vdb.file_metadata = {{"cloudbake:shot", shot.name},
                         {"cloudbake:method", methodName(shot.bake.method)},
                         {"cloudbake:volume", scene.medium.density->describe()}};
    writeVdb(path, *scene.medium.density, vdb);
    written.push_back(path);
  }
  return written;
}

}  // namespace

void addRenderCommand(CLI::App& app, int* exit_code) {
  auto opt = std::make_shared<RenderOptions>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Render every view of a shot with the reference path tracer (docs/shot-format.md)");
  cmd->add_option("shot", opt->shot, "shot file (JSON, format v1)")->required();
  cmd->add_option("--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--threads", opt->threads, "worker threads (default 0 = all cores)");
  cmd->add_option("--samples", opt->samples,
                  "samples per pixel, overriding the shot's bake.samples (1..1000000)");
  cmd->add_flag("--quiet", opt->quiet, "no progress on stderr");
  cmd->add_flag("--png", opt->png,
                "also write an auto-exposed sRGB preview DIR/<view>.png beside each EXR");
  cmd->callback([opt, exit_code] {
    // Exit codes are decided here rather than in main() because a missing file (3) is an
    // InputError (2) to everything else.
    try {
      for (const std::string& path : render(*opt)) std::cout << path << "\n";
      std::cout.flush();
      *exit_code = kOk;
    } catch (const MissingFileError& e) {
      std::cerr << "cloudbake: error: " << e.what() << "\n";
      *exit_code = kNotFound;
    } catch (const InputError& e) {
      std::cerr << "cloudbake: error: " << e.what() << "\n";
      *exit_code = kBadInput;
    } catch (const Cancelled& e) {
      std::cerr << "cloudbake: cancelled: " << e.what() << "\n";
      *exit_code = kCancelled;
    } catch (const std::exception& e) {
      std::cerr << "cloudbake: internal error: " << e.what() << "\n";
      *exit_code = kFailure;
    }
  });
}

}  // namespace cloudbake::tool
