// How an endless walk uses its database (precomputed's video texture): per shot, per future-cost
// weight alpha and per seed, the share of the walk's later half spent in the last H + 1 basic
// volumes (the dead end's loop), the basic volumes and distinct blends it shows, its jumps, and
// its largest frame-to-frame change against the input's own. Prints a table; asserts nothing.
// Usage (from the repository root, after deploy/build.sh):
//   build/bench/walk/walk_bench [--frames 1000] [--alphas 0,0.9,0.99,0.999] [--seeds 1,2,3,4]
//       [--sigma S] shot.json...   (sequence shots; sigma, dissolve and the lattice as the shot's)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "core/animation/basic_volumes.h"
#include "core/animation/video_texture.h"
#include "core/error.h"
#include "core/methods/precomputed.h"
#include "core/shot/scene_builder.h"
#include "core/shot/shot_parser.h"

using namespace cloudbake;

namespace {

std::vector<double> numberList(const std::string& s) {
  std::vector<double> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) out.push_back(std::stod(item));
  return out;
}

struct WalkStats {
  double tail_share = 0;  // later half's frames whose heavier volume is among the last H + 1
  int volumes = 0;        // basic volumes shown at all
  int blends = 0;         // distinct (a, b, w)
  int later_blends = 0;   // distinct in the later half
  double jumps_per_100 = 0;
  double max_change = 0;
};

WalkStats measure(const BasicVolumes& db, const std::vector<BlendFrame>& walk, int h) {
  const int n = int(db.size());
  WalkStats s;
  std::set<int> shown;
  std::set<std::tuple<int, int, double>> all, later;
  int tail = 0, jumps = 0;
  const size_t half = walk.size() / 2;
  for (size_t i = 0; i < walk.size(); ++i) {
    const BlendFrame& f = walk[i];
    if (f.w > 0) shown.insert(f.a);
    if (f.w < 1) shown.insert(f.b);
    all.insert({f.a, f.b, f.w});
    // A jump: a dissolve's first frame, or (hard cuts) a whole frame not its predecessor's
    // successor.
    const bool cut = i > 0 && f.w == 1 && walk[i - 1].w == 1 && f.a != walk[i - 1].a + 1;
    if ((f.w < 1 && (i == 0 || walk[i - 1].w == 1)) || cut) ++jumps;
    if (i >= half) {
      later.insert({f.a, f.b, f.w});
      tail += (f.w >= 0.5 ? f.a : f.b) >= n - 1 - h;
    }
  }
  s.tail_share = double(tail) / double(walk.size() - half);
  s.volumes = int(shown.size());
  s.blends = int(all.size());
  s.later_blends = int(later.size());
  s.jumps_per_100 = 100.0 * jumps / double(walk.size());
  // Identical volumes change nothing; the ratio is then 0 (not a division by ~0).
  const double input = maxInputFrameChange(db);
  s.max_change = input > 1e-12 ? maxFrameChange(db, walk) / input : 0.0;
  return s;
}

void benchShot(const std::string& path, int frames, const std::vector<double>& alphas,
               const std::vector<double>& seeds, double sigma) {
  const ShotSpec shot = parseShotFile(path);
  const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume);
  if (!seq) throw InputError(path + ": /volume: the walk needs a `sequence` volume");
  const PrecomputedShotOptions o = precomputedOptions(shot);
  VolumeFrames vf;
  vf.count = seq->frames;
  vf.build = [&](int i) { return buildSequenceFrame(*seq, i, path); };
  vf.same_voxel_size = !seq->paths.empty();
  const BasicVolumeDatabase db = buildBasicVolumes(vf, o.light_resolution);
  const std::vector<double> d = frameDistances(db.frames);
  const int n = int(db.frames.size());
  std::printf("%s: %d basic volumes, H = %d, sigma %g, %d frames\n", path.c_str(), n,
              o.walk.dissolve_frames, sigma > 0 ? sigma : o.walk.sigma, frames);
  std::printf("  %-6s %-5s %-10s %-8s %-7s %-13s %-9s %-11s %s\n", "alpha", "seed", "tail share",
              "volumes", "blends", "later blends", "jumps/100", "max change", "P seconds");
  for (double alpha : alphas) {
    for (double seed : seeds) {
      VideoTextureOptions w = o.walk;
      if (sigma > 0) w.sigma = sigma;
      w.future_cost = alpha;
      w.seed = uint64_t(seed);
      const auto t0 = std::chrono::steady_clock::now();
      const std::vector<double> p = transitionProbabilities(d, n, w);
      const double secs =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const WalkStats s = measure(db.frames, endlessWalk(p, n, frames, w), w.dissolve_frames);
      std::printf("  %-6g %-5g %-10.2f %-8d %-7d %-13d %-9.1f %-11.2f %.4f\n", alpha, seed,
                  s.tail_share, s.volumes, s.blends, s.later_blends, s.jumps_per_100, s.max_change,
                  secs);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 1000;
  std::vector<double> alphas = {0, 0.9, 0.99, 0.999}, seeds = {1, 2, 3, 4};
  double sigma = 0;
  std::vector<std::string> shots;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      const bool has_value = i + 1 < argc;
      if (a == "--frames" && has_value) {
        frames = std::stoi(argv[++i]);
      } else if (a == "--alphas" && has_value) {
        alphas = numberList(argv[++i]);
      } else if (a == "--seeds" && has_value) {
        seeds = numberList(argv[++i]);
      } else if (a == "--sigma" && has_value) {
        sigma = std::stod(argv[++i]);
      } else if (!a.empty() && a[0] != '-') {
        shots.push_back(a);
      } else {
        std::fprintf(stderr, "walk_bench: unknown argument %s\n", a.c_str());
        return 2;
      }
    }
    if (shots.empty()) shots = {"examples/endless_cloud.json", "bench/endless_300.json"};
    for (const std::string& s : shots) benchShot(s, frames, alphas, seeds, sigma);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "walk_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
