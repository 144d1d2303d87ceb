// Golden outputs: one tiny scene per method whose output statistics are pinned together with the
// method's algorithm version. A change of a method's output without a version bump fails here
// (a server with an old cache would serve old physics otherwise); a version bump without new
// golden values fails too, so the two always move together. Re-pin with
//   CLOUDBAKE_GOLDEN_PRINT=1 build/tests/core/methods/test_methods --gtest_filter='Golden*'
// and paste the printed table below.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/io/exr_io.h"
#include "core/job/file_util.h"
#include "core/job/run_shot.h"
#include "core/methods/registry.h"
#include "core/methods/versions.h"
#include "core/shot/shot_parser.h"
#include "core/transport/layers_exr.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

// A sphere of HG 0.6 droplets lit by a low sun and a blue sky, seen from the side: every layer
// of every method is non-zero.
constexpr const char* kSphere = R"({"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
// A box whose faces cut the lattices' voxels: its means on a lattice are exact (single 6,
// pointcloud 10, photon 11, precomputed 9), where they were sampled.
constexpr const char* kBox =
    R"({"box": {"min": [-0.9, -0.8, -0.37], "max": [0.85, 0.8, 0.41], "density": 1}})";
// The same light on a grid (a procedural cloud): the bakes' lattices aligned with its voxels.
constexpr const char* kGrid =
    R"({"procedural": {"type": "perlin_cloud", "seed": 3, "center": [0, 0, 0],
        "size": [2, 2, 2], "resolution": 12, "cover": 0.6, "density": 1}})";

std::string goldenShot(const std::string& method, const std::string& knobs,
                       const std::string& volume, int resolution) {
  return R"({"version": 1, "name": "golden",
    "volume": )" +
         volume + R"(,
    "medium": {"extinction": 3, "albedo": 0.95, "phase": {"type": "hg", "g": 0.6}},
    "lighting": {"sun": {"direction": [0.6, -0.3, 0.74], "irradiance": [1, 0.9, 0.8]},
                 "sky": {"radiance": [0.05, 0.08, 0.12]}},
    "bake": {"method": ")" +
         method + "\"" + knobs + R"(},
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [)" +
         std::to_string(resolution) + ", " + std::to_string(resolution) + "]}]}";
}

struct Golden {
  std::string method;
  std::string knobs;                   // JSON text after "method"
  int version;                         // the method's version these values were pinned for
  std::map<std::string, double> mean;  // per layer: mean of R, G, B over the image
  double pixel;                        // beauty R at the centre pixel
  const char* volume = kSphere;        // the shot's volume (JSON)
  int resolution = 16;                 // the view's pixels a side (16: every pixel traced)
};

// The pinned values (see the file comment for how to re-pin).
const std::vector<Golden>& goldens() {
  static const std::vector<Golden> kGoldens = {
      // clang-format off
      {"pathtrace", R"(, "samples": 8)", 4, {{"", 0.0558711313}, {"sun", 0.0222841051}, {"sky", 0.0335870264}, {"single", 0.0109086441}, {"multiple", 0.0449624873}}, 0.12705636},
      // With delta tracking: the version 2 estimator, tracked over the support only (version 4).
      {"pathtrace", R"(, "samples": 8, "tracking": "delta")", 4, {{"", 0.0538194516}, {"sun", 0.0213323034}, {"sky", 0.0324871482}, {"single", 0.0105096641}, {"multiple", 0.0433097876}}, 0.0459012277},
      // With its variance reduction off too: the version 1 estimator over the support only.
      {"pathtrace", R"(, "samples": 8, "sun_guiding": 0, "sun_split_max": 1, "tracking": "delta")", 4, {{"", 0.0579821683}, {"sun", 0.0248850294}, {"sky", 0.0330971389}, {"single", 0.01079392}, {"multiple", 0.0471882482}}, 0.0742698312},
      {"single", R"(, "light_resolution": 16)", 9, {{"", 0.0138020199}, {"sun", 0.00390740733}, {"sky", 0.0098946126}, {"single", 0.0138020199}, {"multiple", 0}}, 0.0114315925},
      // pointcloud 8 sums the passes' flux once after them, reads its pairs in another order and
      // its sky's sources as floats: the same values to 1e-9. pointcloud 9 leaves k_i at 1 for
      // points that capture under 1e-30 (nearly transparent media): the same values here.
      {"pointcloud", R"(, "light_resolution": 16, "points": 1024, "passes": 4)", 14, {{"", 0.0591456081}, {"sun", 0.0235808041}, {"sky", 0.0355648041}, {"single", 0.0138020199}, {"multiple", 0.0453435882}}, 0.101559907},
      // precomputed 7 adds each channel's own forward beam: the same values for this grey medium.
      // precomputed 8 evaluates the sky transmittance on every second voxel where it varies
      // smoothly inside the cloud and interpolates between: on this 12-voxel lattice the sky's
      // light moves by 0.04 % and its single scattering by 0.5 %; sky_spacing 1 is version 7's
      // output, pinned below.
      {"precomputed", R"(, "light_resolution": 12, "sample_points": 128, "transfer_resolution": 6)", 10, {{"", 0.0533887656}, {"sun", 0.0185589217}, {"sky", 0.034829844}, {"single", 0.0150260478}, {"multiple", 0.0383627179}}, 0.0841196626},
      {"precomputed", R"(, "light_resolution": 12, "sample_points": 128, "transfer_resolution": 6, "sky_spacing": 1)", 10, {{"", 0.0533737246}, {"sun", 0.0185589217}, {"sky", 0.034814803}, {"single", 0.0149548477}, {"multiple", 0.038418877}}, 0.0840953887},
      // Without the zonal terms, tallies on the bake's lattice: the version 2 bake (version 4 rounds
      // each photon's sums per voxel, not each segment's; version 5 splits off a forward peak
      // its expansion cannot hold, which this HG phase does not have: the same values; version 8
      // reads a view's tallies from a field per view, which these small views mostly do not
      // build: the same values to 1e-9; version 9 reads the sun's transmittance by a short
      // characteristic, which moves the sun layer; version 10 traces a sparse film where a
      // view's pixels are finer than the lattice, which these small views are not: the same
      // values, as for single 5, pointcloud 7 and precomputed 6).
      // photon 14 moved the sky's single scattering alone: its sun and multiple layers kept
      // their values in every row.
      {"photon", R"(, "light_resolution": 16, "photons": 20000, "order": 2, "zonal_order": 0, "tally_resolution": 0)", 14, {{"", 0.0561730532}, {"sun", 0.0210417217}, {"sky", 0.0351313316}, {"single", 0.0142258825}, {"multiple", 0.0419471709}}, 0.0959159732},
      {"photon", R"(, "light_resolution": 16, "photons": 20000, "order": 2, "tally_resolution": 8)", 14, {{"", 0.0563638352}, {"sun", 0.0210565151}, {"sky", 0.0353073202}, {"single", 0.0154485328}, {"multiple", 0.0409153026}}, 0.0969719291},
      // On a grid: the lattices of single, pointcloud and photon are its voxel centres (since
      // single 2, pointcloud 3, photon 6), every other row's lattice the box means.
      {"single", R"(, "light_resolution": 12)", 9, {{"", 0.00442479647}, {"sun", 0.000981170792}, {"sky", 0.0034436257}, {"single", 0.0044247965}, {"multiple", 0}}, 0.0234914701, kGrid},
      {"pointcloud", R"(, "light_resolution": 12, "points": 1024, "passes": 4)", 14, {{"", 0.00995121951}, {"sun", 0.00313073408}, {"sky", 0.00682048545}, {"single", 0.0044247965}, {"multiple", 0.00552642306}}, 0.0856778175, kGrid},
      // Views of 96 pixels a side trace a sparse film of spacing 4 (render_from_bake 6).
      {"single", R"(, "light_resolution": 16)", 9, {{"", 0.0133329567}, {"sun", 0.0038268359}, {"sky", 0.00950612084}, {"single", 0.0133329567}, {"multiple", 0}}, 0.011244949, kSphere, 96},
      {"photon", R"(, "light_resolution": 12, "photons": 20000, "order": 2, "tally_resolution": 8)", 14, {{"", 0.00961498887}, {"sun", 0.0029117155}, {"sky", 0.00670327338}, {"single", 0.00452684469}, {"multiple", 0.00508814417}}, 0.0828929394, kGrid},
      // A box (single 6, pointcloud 10, photon 11, precomputed 9: exact means; the rows above
      // hold no box and kept their values).
      {"single", R"(, "light_resolution": 16)", 9, {{"", 0.0081865663}, {"sun", 0.00247336212}, {"sky", 0.00571320419}, {"single", 0.00818656629}, {"multiple", 0}}, 0.0127486857, kBox},
      {"pointcloud", R"(, "light_resolution": 16, "points": 1024, "passes": 4)", 14, {{"", 0.0310208782}, {"sun", 0.0118994317}, {"sky", 0.0191214464}, {"single", 0.00818656629}, {"multiple", 0.0228343119}}, 0.0929502845, kBox},
      {"photon", R"(, "light_resolution": 16, "photons": 20000, "order": 2, "tally_resolution": 8)", 14, {{"", 0.032039315}, {"sun", 0.0113007443}, {"sky", 0.0207385706}, {"single", 0.0107668228}, {"multiple", 0.0212724922}}, 0.0963231623, kBox},
      // render_from_bake 8 splits the steps into optically thick blocks at the lattice's cells:
      // precomputed's thick, coarse box moved by about 1 %, the rows above not at all.
      {"precomputed", R"(, "light_resolution": 12, "sample_points": 128, "transfer_resolution": 6)", 10, {{"", 0.0279559719}, {"sun", 0.00957394262}, {"sky", 0.0183820293}, {"single", 0.00842257717}, {"multiple", 0.0195333947}}, 0.0812937915, kBox},
      // clang-format on
  };
  return kGoldens;
}

struct Measured {
  std::map<std::string, double> mean;
  double pixel = 0;
  std::string film_spacing;  // the EXR's cloudbake:film_spacing (views from a bake)
};

Measured measure(const Golden& g) {
  const fs::path dir = fs::temp_directory_path() / ("cloudbake-golden-" + uniqueSuffix());
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.threads = 2;
  const RunResult r =
      runShot(parseShot(goldenShot(g.method, g.knobs, g.volume, g.resolution), ""), opt);
  std::string exr;
  for (const OutputFile& f : r.files) {
    if (f.name.size() > 4 && f.name.substr(f.name.size() - 4) == ".exr") exr = f.path;
  }
  Measured m;
  for (const ExrLayer& layer : readRenderLayersExr(exr)) {
    const Image& im = layer.image;
    double sum = 0;
    for (int64_t p = 0; p < int64_t(im.width) * im.height; ++p) {
      for (int c = 0; c < 3; ++c) sum += im.data[size_t(p * im.channels + c)];
    }
    m.mean[layer.name] = sum / (3.0 * im.width * im.height);
    if (layer.name.empty()) {
      m.pixel = im.data[size_t((im.height / 2 * im.width + im.width / 2) * im.channels)];
    }
  }
  const auto attributes = readExr(exr).attributes;
  const auto it = attributes.find("cloudbake:film_spacing");
  if (it != attributes.end()) m.film_spacing = it->second;
  fs::remove_all(dir);
  return m;
}

std::string versionFile(const std::string& method) {
  return "core/methods/" + method +
         ".cpp (MethodInfo::version), or a shared version in "
         "core/methods/versions.h (now " +
         sharedVersionSalt() + ")";
}

TEST(Golden, EveryRunnableMethodHasGoldenValues) {
  for (const std::string& name : methodNames(/*runnable_only=*/true)) {
    // auto writes what its choice writes (pinned in that method's rows); which method it
    // chooses rests on measured seconds, so it is tested by its own tests (auto_test.cpp).
    if (name == "auto") continue;
    bool found = false;
    for (const Golden& g : goldens()) found = found || g.method == name;
    EXPECT_TRUE(found) << "method '" << name << "' has no golden scene in " << __FILE__;
  }
}

TEST(Golden, OutputsMatchThePinnedValuesOfTheirVersion) {
  const bool print = std::getenv("CLOUDBAKE_GOLDEN_PRINT") != nullptr;
  for (const Golden& g : goldens()) {
    SCOPED_TRACE(g.method);
    const int version = findMethod(g.method)->info().version;
    const Measured m = measure(g);
    if (print) {
      std::printf("      {\"%s\", R\"(%s)\", %d, {", g.method.c_str(), g.knobs.c_str(), version);
      for (const char* l : {"", "sun", "sky", "single", "multiple"}) {
        std::printf("{\"%s\", %.9g}%s", l, m.mean.at(l), std::string(l) == "multiple" ? "" : ", ");
      }
      std::printf("}, %.9g%s},\n", m.pixel,
                  g.resolution != 16
                      ? (std::string(", kSphere, ") + std::to_string(g.resolution)).c_str()
                  : g.volume == kGrid ? ", kGrid"
                  : g.volume == kBox  ? ", kBox"
                                      : "");
      continue;
    }
    ASSERT_EQ(version, g.version) << "method '" << g.method << "' is now version " << version
                                  << " but its golden values "
                                  << "were pinned for version " << g.version
                                  << ": re-pin them (see " << __FILE__ << ")";
    // Deterministic code: only floating-point reassociation may move the numbers.
    auto close = [](double a, double b) { return std::abs(a - b) <= 1e-4 * std::abs(b) + 1e-7; };
    for (const auto& [layer, pinned] : g.mean) {
      EXPECT_TRUE(close(m.mean.at(layer), pinned))
          << "method '" << g.method << "' layer '" << layer << "' mean " << m.mean.at(layer)
          << ", pinned " << pinned << ". Its output changed: bump its algorithm version in "
          << versionFile(g.method) << ", then re-pin (see " << __FILE__ << ")";
    }
    // The film the views traced: every pixel at 16 a side; a voxel covers 6 pixels at 96.
    if (g.method != "pathtrace") {
      EXPECT_EQ(m.film_spacing, g.resolution == 16 ? "1" : "4");
    }
    EXPECT_TRUE(close(m.pixel, g.pixel))
        << "method '" << g.method << "' centre pixel " << m.pixel << ", pinned " << g.pixel
        << ". Its output changed: bump its algorithm version in " << versionFile(g.method);
  }
}

}  // namespace
}  // namespace cloudbake
