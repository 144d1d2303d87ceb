// Timings for the volume sources (not a test): cloudbake_bench_volume [max_threads]
// Runs each case with 1 thread and with max_threads (default: all cores) threads.
#include <tbb/global_control.h>
#include <tbb/info.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>

#include "core/volume/grid_volume.h"
#include "core/volume/mesh_io.h"
#include "core/volume/mesh_volume.h"
#include "core/volume/sources.h"

namespace {

using cloudbake::GridVolume;

double seconds(const std::function<void()>& fn) {
  const auto t0 = std::chrono::steady_clock::now();
  fn();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void report(const char* what, int threads, double secs, const cloudbake::DensityField& f) {
  const auto& g = dynamic_cast<const GridVolume&>(f);
  const cloudbake::Bounds3 b = g.bounds();
  std::printf(
      "%-28s threads %d: %8.3f s  %10llu active voxels, voxel %.4g, bounds [%g %g %g]-[%g %g %g]\n",
      what, threads, secs, static_cast<unsigned long long>(g.activeVoxelCount()), g.voxelSize(),
      b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z);
}

}  // namespace

int main(int argc, char** argv) {
  const int max_threads = argc > 1 ? std::atoi(argv[1]) : tbb::info::default_concurrency();
  const std::string data = std::string(CLOUDBAKE_SHARED_DIR) + "/data/";
  for (int threads : {1, max_threads}) {
    tbb::global_control control(tbb::global_control::max_allowed_parallelism, threads);
    const std::string vdb = data + "wdas_cloud_sixteenth.vdb";
    if (std::filesystem::exists(vdb)) {
      cloudbake::DensityFieldPtr f;
      const double s = seconds([&] { f = cloudbake::loadVdbVolume({vdb, "density"}); });
      report("wdas_cloud_sixteenth load", threads, s, *f);
    }
    const std::string bunny = data + "bun_zipper.ply";
    if (std::filesystem::exists(bunny)) {
      cloudbake::TriangleMesh mesh;
      const double read = seconds([&] { mesh = cloudbake::readMesh(bunny); });
      cloudbake::MeshSourceOptions o;
      o.path = bunny;
      o.resolution = 256;
      cloudbake::DensityFieldPtr f;
      const double s = seconds([&] { f = cloudbake::meshToVolume(mesh, o); });
      std::printf("bun_zipper.ply read: %.3f s\n", read);
      report("bunny mesh->volume res 256", threads, s, *f);
    }
    cloudbake::PerlinCloudOptions p;
    p.resolution = 128;
    cloudbake::DensityFieldPtr f;
    const double s = seconds([&] { f = cloudbake::makePerlinCloud(p); });
    report("perlin cloud res 128", threads, s, *f);
    if (max_threads == 1) break;
  }
  return 0;
}
