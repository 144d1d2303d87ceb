// `cloudbake compare TEST.exr REFERENCE.exr [--json] [--cloud-alpha A]`: how far a view (e.g.
// from a bake method) lands from a reference render of the same view: per layer, the mean of
// each image and the relative RMSE, sqrt(mean over pixels and RGB of (x - r)^2) / mean(r), plus
// the pseudo-layer `scattered` = sun + sky (the cloud's own light). With --cloud-alpha only the
// pixels where the reference's beauty alpha (or that of --mask-from FILE) is at least A count,
// so the background does not dilute the error of the cloud.
#include <array>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/cli_number.h"
#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/transport/layers_exr.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {

struct LayerStats {
  double mean_test = 0, mean_ref = 0, rmse = 0;
  // Per channel (R, G, B): the means over channels hid a coloured albedo's blue channel at 3.7x
  // the reference behind a layer's 1.14x (an outside probe).
  std::vector<double> channel_test, channel_ref;  // as many as both images have, up to 3
  double rel_rmse = 0;  // NaN where it is undefined: an image against a reference of mean 0
};

// The pixels that count: all, or those whose reference alpha is at least `min_alpha`.
using PixelMask = std::vector<bool>;

// `test_what` and `ref_what` name the two images ("FILE layer 'L'") in errors.
LayerStats compareLayer(const Image& test, const Image& ref, const PixelMask& mask,
                        const std::string& test_what, const std::string& ref_what) {
  if (test.width != ref.width || test.height != ref.height) {
    throw InputError(test_what + ": images differ in size (" + std::to_string(test.width) + "x" +
                     std::to_string(test.height) + " vs " + std::to_string(ref.width) + "x" +
                     std::to_string(ref.height) + ")");
  }
  double sum_t = 0, sum_r = 0, sq = 0;
  std::array<double, 3> ch_t{}, ch_r{};
  size_t n = 0, pixels = 0;
  for (int y = 0; y < ref.height; ++y)
    for (int x = 0; x < ref.width; ++x) {
      if (!mask.empty() && !mask[size_t(y) * ref.width + x]) continue;
      ++pixels;
      for (int c = 0; c < 3 && c < ref.channels && c < test.channels; ++c) {
        const double t = test.at(x, y)[c], r = ref.at(x, y)[c];
        if (!std::isfinite(t) || !std::isfinite(r)) {
          throw InputError((std::isfinite(t) ? ref_what : test_what) + ": non-finite pixel at (" +
                           std::to_string(x) + ", " + std::to_string(y) + ")");
        }
        sum_t += t;
        sum_r += r;
        ch_t[size_t(c)] += t;
        ch_r[size_t(c)] += r;
        sq += (t - r) * (t - r);
        ++n;
      }
    }
  LayerStats s;
  if (n == 0) return s;
  s.mean_test = sum_t / double(n);
  s.mean_ref = sum_r / double(n);
  s.rmse = std::sqrt(sq / double(n));
  for (int c = 0; c < 3 && c < ref.channels && c < test.channels; ++c) {
    s.channel_test.push_back(ch_t[size_t(c)] / double(pixels));
    s.channel_ref.push_back(ch_r[size_t(c)] / double(pixels));
  }
  // Against a reference without light any difference is infinitely large relative to it: no
  // number says that, and 0 would call a mismatch a perfect match.
  s.rel_rmse = s.mean_ref > 0 ? s.rmse / s.mean_ref
               : s.rmse == 0  ? 0
                              : std::numeric_limits<double>::quiet_NaN();
  return s;
}

PixelMask cloudMask(const ExrContents& ref, double min_alpha, const std::string& ref_path) {
  if (!(min_alpha > 0)) return {};
  auto it = ref.layers.find("");
  if (it == ref.layers.end() || it->second.channels < 4) {
    throw InputError("--cloud-alpha: " + ref_path + " has no beauty alpha channel");
  }
  const Image& beauty = it->second;
  PixelMask mask(size_t(beauty.width) * beauty.height);
  size_t kept = 0;
  for (int y = 0; y < beauty.height; ++y)
    for (int x = 0; x < beauty.width; ++x) {
      const bool in = beauty.at(x, y)[3] >= min_alpha;
      mask[size_t(y) * beauty.width + x] = in;
      kept += in;
    }
  if (kept == 0) {
    throw InputError("--cloud-alpha: no pixel of " + ref_path +
                     " has alpha >= " + std::to_string(min_alpha));
  }
  return mask;
}

// Files of this version hold the cloud element unprefixed (premultiplied) and the beauty as a
// layer; older files, and other renderers', hold the beauty unprefixed. Layers are compared by
// meaning: "beauty", and "cloud" where a file has one.
void nameLayers(ExrContents* c) {
  auto plain = c->layers.find("");
  if (plain == c->layers.end()) return;
  Image image = std::move(plain->second);
  c->layers.erase(plain);
  c->layers[beautyLayerName(*c).empty() ? "beauty" : "cloud"] = std::move(image);
}

// sun + sky of one file, when it has both.
void addScattered(ExrContents* c) {
  auto sun = c->layers.find("sun"), sky = c->layers.find("sky");
  if (sun == c->layers.end() || sky == c->layers.end()) return;
  if (sun->second.data.size() != sky->second.data.size()) return;
  Image sum = sun->second;
  for (size_t i = 0; i < sum.data.size(); ++i) sum.data[i] += sky->second.data[i];
  c->layers["scattered"] = std::move(sum);
}

}  // namespace

void addCompareCommand(CLI::App& app, int* exit_code) {
  struct Options {
    std::string test, ref;
    bool json = false;
    double cloud_alpha = 0;
    std::string mask_from;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "compare",
      "Compare a rendered view with a reference of the same view: per layer (beauty, cloud, "
      "background, sun, sky, single, multiple, and scattered = sun + sky) the means and the "
      "relative RMSE "
      "sqrt(mean((x - r)^2)) / mean(r) over pixels and RGB (undefined, JSON null, where the "
      "reference's mean is 0 and the images differ; \"rmse\" is the absolute one)");
  cmd->add_option("test", opt->test, "the EXR to judge")->required();
  cmd->add_option("reference", opt->ref, "the reference EXR (e.g. a converged pathtrace)")
      ->required();
  cmd->add_flag("--json", opt->json, "one JSON object on stdout");
  cmd->add_option("--cloud-alpha", opt->cloud_alpha,
                  "count only the pixels whose reference beauty alpha is at least this (0..1; "
                  "default 0 = every pixel)")
      ->check(numberIn(0, 1));
  cmd->add_option("--mask-from", opt->mask_from,
                  "with --cloud-alpha: take the alpha from this EXR's beauty instead of the "
                  "reference's (e.g. to compare two renders of another renderer over one cloud)");
  cmd->callback([opt, exit_code] {
    ExrContents test = readExr(opt->test);
    ExrContents ref = readExr(opt->ref);
    if (!opt->mask_from.empty() && !(opt->cloud_alpha > 0)) {
      throw InputError("--mask-from: needs --cloud-alpha");
    }
    const PixelMask mask = opt->mask_from.empty() ? cloudMask(ref, opt->cloud_alpha, opt->ref)
                                                  : cloudMask(readExr(opt->mask_from),
                                                              opt->cloud_alpha, opt->mask_from);
    if (!mask.empty() && mask.size() != size_t(ref.width) * ref.height) {
      throw InputError("--mask-from: " + opt->mask_from + " differs in size from " + opt->ref);
    }
    nameLayers(&test);
    nameLayers(&ref);
    addScattered(&test);
    addScattered(&ref);
    // Every layer is compared before anything is printed: an error leaves stdout empty.
    nlohmann::json out = nlohmann::json::object();
    std::string table;
    for (const auto& [name, image] : ref.layers) {
      auto it = test.layers.find(name);
      if (it == test.layers.end()) continue;
      const std::string& label = name;
      const LayerStats s =
          compareLayer(it->second, image, mask, opt->test + " layer '" + label + "'",
                       opt->ref + " layer '" + label + "'");
      const bool defined = !std::isnan(s.rel_rmse);
      out[label] = {{"mean", s.mean_test},
                    {"reference_mean", s.mean_ref},
                    {"rmse", s.rmse},
                    {"channel_means", s.channel_test},
                    {"reference_channel_means", s.channel_ref},
                    {"rel_rmse", defined ? nlohmann::json(s.rel_rmse) : nlohmann::json()}};
      char rel[32] = "undefined";
      if (defined) std::snprintf(rel, sizeof rel, "%.4f", s.rel_rmse);
      char row[256];
      std::snprintf(row, sizeof row, "%-10s %14.6g %14.6g %10s\n", label.c_str(), s.mean_test,
                    s.mean_ref, rel);
      table += row;
    }
    if (out.empty()) throw InputError(opt->test + ": no layer in common with " + opt->ref);
    if (opt->json) {
      std::cout << out.dump() << std::endl;
    } else {
      std::printf("%-10s %14s %14s %10s\n%s", "layer", "mean", "reference", "rel_rmse",
                  table.c_str());
    }
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
