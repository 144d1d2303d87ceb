// The basic-volume database from an animated procedural cloud, and the walk over it: the seed's
// report of the largest frame-to-frame change of a 1000-frame walk against the input's.
#include "core/animation/basic_volumes.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/io/vdb_io.h"
#include "core/volume/analytic.h"
#include "core/volume/sources.h"

namespace cloudbake {
namespace {

// The procedural cloud at successive times, as a shot's procedural `sequence` builds it.
VolumeFrames proceduralSequence(int frames, double step) {
  PerlinCloudOptions cloud;
  cloud.resolution = 24;
  cloud.seed = 3;
  cloud.cover = 0.4;
  VolumeFrames f;
  f.count = frames;
  f.build = [cloud, step](int i) {
    PerlinCloudOptions at = cloud;
    at.time += i * step;
    return makePerlinCloud(at);
  };
  return f;
}

// VDB files as frames, named as a shot's `paths` are in errors.
VolumeFrames vdbSequence(const std::vector<std::string>& paths) {
  VolumeFrames f;
  f.count = int(paths.size());
  f.build = [paths](int i) {
    VdbSourceOptions options;
    options.path = paths[size_t(i)];
    return loadVdbVolume(options);
  };
  f.same_voxel_size = true;
  f.name = [](int i) { return "shot.json: /volume/sequence/paths/" + std::to_string(i); };
  return f;
}

TEST(BasicVolumes, ThirtyProceduralFramesOnOneLatticeAndAnEndlessWalk) {
  const BasicVolumeDatabase db = buildBasicVolumes(proceduralSequence(30, 0.05), 24);
  ASSERT_EQ(db.frames.size(), 30u);
  for (const auto& f : db.frames) EXPECT_EQ(f.size(), db.grid.voxelCount());
  const std::vector<double> d = frameDistances(db.frames);
  VideoTextureOptions o;
  o.dissolve_frames = 4;
  const std::vector<double> p = transitionProbabilities(d, 30, o);
  const std::vector<BlendFrame> walk = endlessWalk(p, 30, 1000, o);
  const double input = maxInputFrameChange(db.frames), endless = maxFrameChange(db.frames, walk);
  std::printf(
      "[ animation ] procedural cloud, 30 basic volumes: largest frame-to-frame RMS "
      "density change: input %.4f, 1000-frame walk %.4f\n",
      input, endless);
  EXPECT_GT(input, 0);
  EXPECT_LE(endless, 2.0 * input);
}

TEST(BasicVolumes, VdbFramesMustShareOneTransform) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("cloudbake_basic_volumes_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  VdbWriteOptions fine, coarse;
  fine.voxel_size = 0.1;
  coarse.voxel_size = 0.2;
  const BoxDensity box(Vec3(0.0), Vec3(1.0), 1.0), moved(Vec3(0.2), Vec3(1.1), 1.0);
  writeVdb((dir / "a.vdb").string(), box, fine);
  writeVdb((dir / "b.vdb").string(), moved, fine);
  writeVdb((dir / "c.vdb").string(), box, coarse);
  std::vector<std::string> paths = {(dir / "a.vdb").string(), (dir / "b.vdb").string()};
  const BasicVolumeDatabase db = buildBasicVolumes(vdbSequence(paths), 16);
  ASSERT_EQ(db.frames.size(), 2u);
  EXPECT_EQ(db.frames[0].size(), db.frames[1].size());  // one lattice over both
  EXPECT_NE(db.frames[0], db.frames[1]);
  paths.push_back((dir / "c.vdb").string());
  try {
    buildBasicVolumes(vdbSequence(paths), 16);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/sequence/paths/2: voxel size"), std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

TEST(BasicVolumes, BadDatabasesAreRefused) {
  EXPECT_THROW(buildBasicVolumes(proceduralSequence(1, 0.1), 24), InputError);
  EXPECT_THROW(buildBasicVolumes(proceduralSequence(3, 0.1), 4), InputError);  // resolution
  EXPECT_THROW(buildBasicVolumes(proceduralSequence(3, 0.1), 24, [](double) { return false; }),
               Cancelled);
}

}  // namespace
}  // namespace cloudbake
