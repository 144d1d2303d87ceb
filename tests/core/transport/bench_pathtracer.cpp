// Timing of the reference path tracer (built, not registered as a test).
//
//   cloudbake_bench_pathtracer [--size N] [--spp S] [--threads T] [--extinction E] [--albedo A]
//                              [--g G] [--max-depth D] [--vdb PATH] [--exr OUT.exr]
//                              [--ppm OUT.ppm]
//
// Renders an N x N perspective view of a homogeneous sphere (or a VDB cloud with --vdb, when
// core/volume provides loadVdbVolume) under a sun and a gradient sky, and prints pixel samples
// per second for each requested thread count (default: 1 and 2). --exr writes the last render's
// layers; --ppm a clamped sRGB-ish preview of its beauty (for a quick look, not for measurement).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/phase/henyey_greenstein.h"
#include "core/transport/layers_exr.h"
#include "core/transport/path_tracer.h"
#include "core/volume/analytic.h"
#include "core/volume/sources.h"

int main(int argc, char** argv) {
  using namespace cloudbake;
  int size = 256, spp = 8, max_depth = 100000;
  double extinction = 10.0, albedo = 0.99, g = 0.8;
  std::vector<int> threads;
  std::string vdb, exr_out, ppm_out;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const char* v = argv[i + 1];
    if (k == "--size") {
      size = std::atoi(v);
    } else if (k == "--spp") {
      spp = std::atoi(v);
    } else if (k == "--threads") {
      threads.push_back(std::atoi(v));
    } else if (k == "--extinction") {
      extinction = std::atof(v);
    } else if (k == "--albedo") {
      albedo = std::atof(v);
    } else if (k == "--g") {
      g = std::atof(v);
    } else if (k == "--max-depth") {
      max_depth = std::atoi(v);
    } else if (k == "--vdb") {
      vdb = v;
    } else if (k == "--exr") {
      exr_out = v;
    } else if (k == "--ppm") {
      ppm_out = v;
    } else {
      std::fprintf(stderr, "unknown option %s\n", k.c_str());
      return 2;
    }
  }
  if (threads.empty()) threads = {1, 2};
  try {
    Medium medium;
    Camera cam;
    cam.type = Camera::Type::kPerspective;
    cam.width_px = cam.height_px = size;
    cam.fov_deg = 40;
    if (vdb.empty()) {
      medium.density = std::make_shared<SphereDensity>(Vec3(0, 0, 0.5), 0.8, 1.0);
      cam.position = Vec3(0, -4, 0.8);
      cam.look_at = Vec3(0, 0, 0.5);
    } else {
      VdbSourceOptions o;
      o.path = vdb;
      medium.density = loadVdbVolume(o);
      const Bounds3 b = medium.density->bounds();
      const Vec3 c = b.center(), e = b.extent();
      cam.look_at = c;
      cam.position = c + Vec3(0, -2.2 * std::max(e.x, e.z), 0.2 * e.z);
    }
    medium.extinction = extinction;
    medium.albedo = Rgb(albedo);
    medium.phase = std::make_shared<HenyeyGreensteinPhase>(g);
    Sun sun;
    sun.direction = normalize(Vec3(0.5, -0.3, 1.0));
    sun.irradiance = Rgb(3.0, 2.9, 2.7);
    Sky sky;
    sky.type = Sky::Type::kGradient;
    sky.zenith = Rgb(0.1, 0.2, 0.5);
    sky.horizon = Rgb(0.3, 0.35, 0.45);
    sky.ground = Rgb(0.05);
    std::printf("scene: %s, extinction %g, albedo %g, hg g %g, %dx%d, %d spp\n",
                medium.density->describe().c_str(), extinction, albedo, g, size, size, spp);
    RenderLayers last;
    for (int t : threads) {
      PathTracerOptions opt;
      opt.samples_per_pixel = spp;
      opt.threads = t;
      opt.max_depth = max_depth;
      const auto start = std::chrono::steady_clock::now();
      const std::clock_t cpu_start = std::clock();
      const RenderLayers l = renderPathTraced(medium, sun, sky, cam, opt);
      const double s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const double cpu = double(std::clock() - cpu_start) / CLOCKS_PER_SEC;
      double mean = 0;
      for (int i = 0; i < size * size; ++i) mean += l.beauty.data[size_t(i) * 4];
      // CPU seconds show the work done when other processes share the cores.
      std::printf(
          "threads %d: %.3f s wall, %.3f s cpu, %.3g pixel samples/s, %.3g per cpu-s (mean "
          "beauty R %.4f)\n",
          t, s, cpu, double(size) * size * spp / s, double(size) * size * spp / cpu,
          mean / (double(size) * size));
      last = l;
    }
    if (!exr_out.empty()) writeRenderLayers(exr_out, last, {{"cloudbake:bench", "pathtracer"}});
    if (!ppm_out.empty()) {
      FILE* f = std::fopen(ppm_out.c_str(), "wb");
      if (!f) throw InputError(ppm_out + ": cannot write");
      std::fprintf(f, "P6\n%d %d\n255\n", size, size);
      for (size_t i = 0; i < size_t(size) * size; ++i) {
        for (int c = 0; c < 3; ++c) {
          const double v =
              std::pow(std::clamp(double(last.beauty.data[i * 4 + c]), 0.0, 1.0), 1 / 2.2);
          std::fputc(static_cast<int>(v * 255 + 0.5), f);
        }
      }
      std::fclose(f);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
