// Speed of what follows a bake (issue 18), in-process, at any list of thread counts:
//   view   a new view from a bake, per method of the shot's list (bake once, then time views);
//   frame  a `precomputed` frame of a sequence shot: lit from the database, then its view;
//   bake   a light bake of the shot's own method (the bunny `pointcloud` of the issue).
// Each figure is the best of --repeats runs, with its scaling over the first thread count.
// Usage (from the repository root, after deploy/build.sh):
//   build/bench/speed/speed_bench [--threads 1,2] [--repeats 3] [--parts view,frame,bake]
//       [--view-shot bench/speed/view_mie.json] [--frame-shot bench/speed/frames.json]
//       [--bake-shot bench/speed/bunny_pointcloud.json] [--methods single,pointcloud,photon]
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/animation/basic_volumes.h"
#include "core/animation/precomputed.h"
#include "core/bake/photon_bake.h"
#include "core/bake/pointcloud_bake.h"
#include "core/bake/render_from_bake.h"
#include "core/bake/single_bake.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/bake/sparse_film.h"
#include "core/error.h"
#include "core/methods/common.h"
#include "core/methods/photon.h"
#include "core/methods/pointcloud.h"
#include "core/methods/precomputed.h"
#include "core/methods/single.h"
#include "core/shot/scene_builder.h"
#include "core/shot/shot_parser.h"
#include "core/transport/sky.h"

namespace cloudbake {
namespace {

struct Args {
  std::vector<int> threads{1, 2};
  int repeats = 3;
  std::vector<std::string> parts{"view", "frame", "bake"};
  std::vector<std::string> methods{"single", "pointcloud", "photon"};
  std::string view_shot = "bench/speed/view_mie.json";
  std::string frame_shot = "bench/speed/frames.json";
  std::string bake_shot = "bench/speed/bunny_pointcloud.json";
  // Views: the sparse film's largest spacings (render_from_bake.h, max_film_spacing) to time,
  // each with its error against every pixel traced.
  std::vector<int> film_spacings{4};
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

Args parseArgs(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (i + 1 >= argc) throw InputError("option " + k + " needs a value");
    const std::string v = argv[++i];
    if (k == "--threads") {
      a.threads.clear();
      for (const std::string& t : split(v)) a.threads.push_back(std::stoi(t));
    } else if (k == "--repeats") {
      a.repeats = std::max(1, std::stoi(v));
    } else if (k == "--parts") {
      a.parts = split(v);
    } else if (k == "--methods") {
      a.methods = split(v);
    } else if (k == "--view-shot") {
      a.view_shot = v;
    } else if (k == "--frame-shot") {
      a.frame_shot = v;
    } else if (k == "--bake-shot") {
      a.bake_shot = v;
    } else if (k == "--film-spacing") {
      a.film_spacings.clear();
      for (const std::string& f : split(v)) a.film_spacings.push_back(std::stoi(f));
    } else {
      throw InputError("unknown option " + k);
    }
  }
  for (int t : a.threads) {
    if (t < 1 || t > 4096) throw InputError("--threads: each in 1..4096");
  }
  return a;
}

double seconds(const std::function<void()>& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The best of `repeats` timings of `f` at each thread count, printed with its scaling.
void timeAtThreads(const Args& a, const std::string& label,
                   const std::function<void(int threads)>& f) {
  double first = 0;
  for (size_t i = 0; i < a.threads.size(); ++i) {
    const int t = a.threads[i];
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(t));
    double best = 1e300;
    for (int r = 0; r < a.repeats; ++r) best = std::min(best, seconds([&] { f(t); }));
    if (i == 0) first = best;
    std::printf("%-44s threads %3d  %8.4f s  %7.2f per s  scaling %.2fx\n", label.c_str(), t, best,
                1 / best, first / best);
    std::fflush(stdout);
  }
}

BakedLight bakeFor(const std::string& method, const ShotSpec& shot, const Scene& scene) {
  const Vec3 sun = sunDirection(shot);
  if (method == "single") return bakeSingle(scene.medium, sun, singleBakeOptions(shot));
  if (method == "pointcloud") return bakePointcloud(scene.medium, sun, pointcloudOptions(shot));
  if (method == "photon") return bakePhoton(scene.medium, sun, photonBakeOptions(shot));
  throw InputError("--methods: '" + method + "' is not single, pointcloud or photon");
}

// The shot of file `path` with bake.method `method` (its knobs at their defaults).
ShotSpec shotWithMethod(const std::string& path, const std::string& method) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot be read");
  nlohmann::json j = nlohmann::json::parse(in);
  j["bake"] = {{"method", method}, {"seed", 1}};
  const size_t slash = path.find_last_of('/');
  ParseOptions po;
  po.source_name = path;
  return parseShot(j.dump(), slash == std::string::npos ? "." : path.substr(0, slash), po);
}

// The cloud's own light (sun + sky layers, channel sum) of `a` against `ref` over the pixels
// where ref's alpha is at least 0.05: relative RMSE, mean ratio and the largest relative
// difference of a pixel (over the cloud's mean).
void printFilmError(const RenderLayers& a, const RenderLayers& ref) {
  double se = 0, sum_a = 0, sum_r = 0, worst = 0;
  int64_t n = 0;
  std::vector<double> diffs;
  for (int y = 0; y < ref.beauty.height; ++y) {
    for (int x = 0; x < ref.beauty.width; ++x) {
      if (ref.beauty.at(x, y)[3] < 0.05) continue;
      double va = 0, vr = 0;
      for (int c = 0; c < 3; ++c) {
        va += a.sun.at(x, y)[c] + a.sky.at(x, y)[c];
        vr += ref.sun.at(x, y)[c] + ref.sky.at(x, y)[c];
      }
      se += (va - vr) * (va - vr);
      sum_a += va;
      sum_r += vr;
      diffs.push_back(std::fabs(va - vr));
      ++n;
    }
  }
  if (n == 0 || !(sum_r > 0)) {
    std::printf("  against every pixel traced: no cloud in the view\n");
    return;
  }
  const double mean = sum_r / double(n);
  for (double d : diffs) worst = std::max(worst, d / mean);
  std::printf(
      "  against every pixel traced: relative RMSE %.5f, mean ratio %.5f, worst pixel %.4f"
      " (of the mean), %lld cloud pixels\n",
      std::sqrt(se / double(n)) / mean, sum_a / sum_r, worst, (long long)n);
}

void viewPart(const Args& a) {
  const Scene shot_scene = buildScene(parseShotFile(a.view_shot), a.view_shot);
  for (const std::string& m : a.methods) {
    const ShotSpec shot = shotWithMethod(a.view_shot, m);
    const Scene& scene = shot_scene;
    BakedLight bake;
    const double s = seconds([&] { bake = bakeFor(m, shot, scene); });
    std::printf("view: %s bake for the views took %.2f s (all threads)\n", m.c_str(), s);
    for (const Camera& camera : scene.cameras) {
      const std::string label = "view " + m + " '" + camera.name + "' " +
                                std::to_string(camera.width_px) + "x" +
                                std::to_string(camera.height_px);
      // A further view of a shot reuses what its first view built (BakeViewCache): the timed
      // line. The "first" line is a view that builds it.
      BakeViewCache cache;
      BakeRenderOptions every = bakeRenderOptions(shot, 0);
      every.max_film_spacing = 1;
      every.cache = &cache;
      const RenderLayers full =
          renderFromBake(bake, scene.medium, scene.sun, scene.sky, camera, every);
      for (int spacing : a.film_spacings) {
        RenderLayers layers;
        const std::string film = label + " film " + std::to_string(spacing);
        timeAtThreads(a, film, [&](int threads) {
          BakeRenderOptions o = bakeRenderOptions(shot, threads);
          o.max_film_spacing = spacing;
          o.cache = &cache;
          layers = renderFromBake(bake, scene.medium, scene.sun, scene.sky, camera, o);
        });
        timeAtThreads(a, film + " first", [&](int threads) {
          BakeRenderOptions o = bakeRenderOptions(shot, threads);
          o.max_film_spacing = spacing;
          renderFromBake(bake, scene.medium, scene.sun, scene.sky, camera, o);
        });
        printFilmError(layers, full);
        std::printf("  traced %.1f %% of the pixels\n", 100 * tracedShare(layers));
      }
    }
  }
}

void framePart(const Args& a) {
  const ShotSpec shot = parseShotFile(a.frame_shot);
  const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume);
  if (!seq || seq->frames < 2) throw InputError(a.frame_shot + ": needs a sequence of >= 2 frames");
  ShotSpec light_shot = shot;  // lights, medium and cameras; a stand-in density, not read
  light_shot.volume = BoxVolumeSpec{{0, 0, 0}, {1, 1, 1}, 0.0};
  const Scene lights = buildScene(light_shot, a.frame_shot);
  const PrecomputedShotOptions o = precomputedOptions(shot);
  VolumeFrames frames;
  frames.count = seq->frames;
  frames.build = [&](int i) { return buildSequenceFrame(*seq, i, a.frame_shot); };
  PrecomputedDatabase db;
  const double s = seconds([&] {
    db = precomputeBasicVolumes(buildBasicVolumes(frames, o.light_resolution),
                                lights.medium.extinction, o.precompute);
  });
  std::printf("frame: database of %d basic volumes precomputed in %.2f s (all threads)\n",
              seq->frames, s);
  const auto sky_sh = projectSkyRadiance(SkyLight(lights.sky));
  FrameLightOptions fo = o.frame;
  fo.mean_cosine = lights.medium.phase->meanCosine();
  const Camera& camera = lights.cameras.at(0);
  // A cross-dissolve of the first two basic volumes: each repeat lights a new weight.
  int frame = 0;
  BakedLight light;
  FrameLightStats stats;
  const auto lightFrame = [&] {
    const BlendFrame bf{0, 1, 0.2 + 0.6 * ((frame++ % 7) / 6.0)};
    light =
        lightAnimationFrame(db, bf, sunDirection(shot), lights.medium.albedo, sky_sh, fo, &stats);
  };
  // The view at the last film spacing asked for (render_from_bake.h, max_film_spacing).
  const int film = a.film_spacings.empty() ? kMaxFilmSpacing : a.film_spacings.back();
  // As the method's frames do: one cache, its memory kept and its contents forgotten a frame.
  BakeViewCache cache;
  const auto render = [&](int threads) {
    BakeRenderOptions ro = frameRenderOptions(shot, light, threads);
    ro.max_film_spacing = film;
    ro.cache = &cache;
    cache.forget();
    renderFromBake(light, lights.medium, lights.sun, lights.sky, camera, ro);
  };
  std::printf("frame: views at a film spacing of at most %d\n", film);
  timeAtThreads(a, "frame precomputed: light", [&](int) { lightFrame(); });
  // The stages of the last frame lit (at the last thread count).
  std::printf(
      "  at %d threads: light %.3f s = sun %.3f + sky (SHEXP) %.3f + receivers %.3f + orders %.3f"
      " + multiple %.3f + trim and checks %.3f; %d orders; SHEXP at %zu of %zu voxels\n",
      a.threads.back(), stats.seconds, stats.seconds_sun, stats.seconds_sky,
      stats.seconds_receivers, stats.seconds_orders, stats.seconds_multiple, stats.seconds_finish,
      stats.orders, stats.sky_evaluations, stats.support_voxels);
  timeAtThreads(a, "frame precomputed: view '" + camera.name + "'", render);
  {
    BakeRenderOptions every = frameRenderOptions(shot, light, 0), sparse = every;
    every.max_film_spacing = 1;
    sparse.max_film_spacing = film;
    printFilmError(renderFromBake(light, lights.medium, lights.sun, lights.sky, camera, sparse),
                   renderFromBake(light, lights.medium, lights.sun, lights.sky, camera, every));
  }
  timeAtThreads(a, "frame precomputed: light + view", [&](int threads) {
    lightFrame();
    render(threads);
  });
}

// One pointcloud bake at `threads`: its total and stage seconds (total, lattice + sun + sky,
// points, neighbours, passes, splat); prints its pair rate.
std::vector<double> pointcloudStages(const ShotSpec& shot, const Scene& scene, int threads) {
  PointcloudStats st;
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
  BakedLight bake;
  const double total = seconds([&] {
    bake = bakePointcloud(scene.medium, sunDirection(shot), pointcloudOptions(shot), {}, &st);
  });
  std::printf("  at %2d threads: %llu pair interactions, %.3g pairs/s in passes;", threads,
              static_cast<unsigned long long>(st.pair_interactions),
              double(st.pair_interactions) / st.seconds_passes);
  for (const auto& [key, value] : bake.metadata) {
    const std::string prefix = "cloudbake:seconds_";
    if (key.rfind(prefix, 0) == 0) {
      std::printf(" %s %.3f", key.c_str() + prefix.size(), std::stod(value));
    }
  }
  std::printf("\n");
  return {total,
          total - st.seconds_points - st.seconds_neighbours - st.seconds_passes - st.seconds_splat,
          st.seconds_points,
          st.seconds_neighbours,
          st.seconds_passes,
          st.seconds_splat};
}

void bakePart(const Args& a) {
  const ShotSpec shot = parseShotFile(a.bake_shot);
  const Scene scene = buildScene(shot, a.bake_shot);
  const std::string m = shot.bake.method;
  timeAtThreads(a, "bake " + m + " '" + shot.name + "'", [&](int) { bakeFor(m, shot, scene); });
  if (m == "pointcloud") {
    // The stages at every thread count, each with its scaling over the first: which stage stops
    // scaling shows on a machine of many cores.
    std::vector<double> first;
    for (const int threads : a.threads) {
      const std::vector<double> stages = pointcloudStages(shot, scene, threads);
      if (first.empty()) first = stages;
      auto x = [&](size_t i) { return stages[i] > 0 ? first[i] / stages[i] : 0.0; };
      std::printf(
          "  at %2d threads: total %.3f s = lattice, sun and sky %.3f (%.2fx) + points %.3f "
          "(%.2fx) + neighbours %.3f (%.2fx) + passes %.3f (%.2fx) + splat %.3f (%.2fx)\n",
          threads, stages[0], stages[1], x(1), stages[2], x(2), stages[3], x(3), stages[4], x(4),
          stages[5], x(5));
    }
  }
}
}  // namespace
}  // namespace cloudbake

int main(int argc, char** argv) {
  using namespace cloudbake;
  try {
    const Args a = parseArgs(argc, argv);
    for (const std::string& part : a.parts) {
      if (part == "view") {
        viewPart(a);
      } else if (part == "frame") {
        framePart(a);
      } else if (part == "bake") {
        bakePart(a);
      } else {
        throw InputError("--parts: '" + part + "' is not view, frame or bake");
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "speed_bench: %s\n", e.what());
    return 2;
  }
  return 0;
}
