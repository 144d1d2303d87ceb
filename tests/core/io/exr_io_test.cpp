#include "core/io/exr_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <string>

#include "core/error.h"
#include "tests/tiny_volume.h"

namespace cloudbake {
namespace {

std::string tempPath(const std::string& name) {
  return ::testing::TempDir() + "/cloudbake_exr_" + std::to_string(::getpid()) + "_" + name;
}

Image pattern(int w, int h, int c, float offset) {
  Image im(w, h, c);
  for (size_t i = 0; i < im.data.size(); ++i) im.data[i] = offset + 0.25f * float(i) - 3.0f;
  return im;
}

TEST(ExrIo, RoundTripLayersAndAttributes) {
  const std::string path = tempPath("layers.exr");
  const Image beauty = pattern(7, 5, 4, 0.f);
  const Image sun = pattern(7, 5, 3, 100.f);
  const Image sky = pattern(7, 5, 3, 200.f);
  const Image mask = pattern(7, 5, 1, 300.f);
  writeExr(path, {{"", beauty}, {"sun", sun}, {"sky", sky}, {"mask", mask}},
           {{"cloudbake:method", "pathtrace"}, {"cloudbake:spp", "64"}});

  const ExrContents in = readExr(path);
  EXPECT_EQ(in.width, 7);
  EXPECT_EQ(in.height, 5);
  ASSERT_EQ(in.layers.size(), 4u);
  EXPECT_EQ(in.channel_names.at(""), (std::vector<std::string>{"R", "G", "B", "A"}));
  EXPECT_EQ(in.channel_names.at("sun"), (std::vector<std::string>{"R", "G", "B"}));
  EXPECT_EQ(in.channel_names.at("mask"), (std::vector<std::string>{"Y"}));
  EXPECT_EQ(in.layers.at("").data, beauty.data);  // FLOAT pixels: bit-exact
  EXPECT_EQ(in.layers.at("sun").data, sun.data);
  EXPECT_EQ(in.layers.at("sky").data, sky.data);
  EXPECT_EQ(in.layers.at("mask").data, mask.data);
  EXPECT_EQ(in.attributes.at("cloudbake:method"), "pathtrace");
  EXPECT_EQ(in.attributes.at("cloudbake:spp"), "64");
  EXPECT_EQ(in.attributes.at("cloudbake:version"), CLOUDBAKE_VERSION);

  // Pixel (x, y) = (6, 0) is the top-right pixel of the beauty layer in both images.
  EXPECT_EQ(in.layers.at("").at(6, 0)[2], beauty.at(6, 0)[2]);

  const Image rgb = readExrRgb(path);
  ASSERT_EQ(rgb.channels, 3);
  EXPECT_EQ(rgb.at(3, 4)[0], beauty.at(3, 4)[0]);
  EXPECT_EQ(rgb.at(3, 4)[2], beauty.at(3, 4)[2]);
  std::remove(path.c_str());
}

TEST(ExrIo, OverwriteIsAtomicAndLeavesNoTempFiles) {
  const std::string path = tempPath("overwrite.exr");
  writeExr(path, {{"", pattern(4, 4, 3, 0.f)}});
  writeExr(path, {{"", pattern(2, 3, 3, 9.f)}});
  const ExrContents in = readExr(path);
  EXPECT_EQ(in.width, 2);
  EXPECT_EQ(in.height, 3);
  EXPECT_EQ(in.layers.at("").data, pattern(2, 3, 3, 9.f).data);
  for (const auto& entry : std::filesystem::directory_iterator(::testing::TempDir())) {
    EXPECT_EQ(entry.path().string().find(path + ".tmp"), std::string::npos) << entry.path();
  }
  std::remove(path.c_str());
}

std::string fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// OpenEXR compresses the line blocks on its pool and writes them in order: the file must not
// depend on how many threads did it, so a shot gives the same bytes on any machine.
TEST(ExrIo, SameBytesWhateverTheCompressionThreads) {
  const Image beauty = pattern(97, 83, 4, 0.f);  // 6 blocks of 16 lines, the last one short
  const Image sun = pattern(97, 83, 3, 50.f);
  // With every compression: the server's scrub rebuilds an output and expects its bytes.
  for (const ExrCompressionName& c : kExrCompressionNames) {
    SCOPED_TRACE(std::string(c.name));
    std::string bytes[3];
    const int threads[3] = {1, 4, 0};
    for (int i = 0; i < 3; ++i) {
      setExrThreads(threads[i]);
      const std::string path = tempPath("threads" + std::to_string(i) + ".exr");
      writeExr(path, {{"", beauty}, {"sun", sun}}, {}, {}, c.value);
      bytes[i] = fileBytes(path);
      const ExrContents in = readExr(path);
      EXPECT_EQ(in.layers.at("sun").data, sun.data) << threads[i] << " threads";
      std::remove(path.c_str());
    }
    setExrThreads(1);
    ASSERT_GT(bytes[0].size(), 1000u);
    EXPECT_EQ(bytes[1], bytes[0]);
    EXPECT_EQ(bytes[2], bytes[0]);
  }
}

// The compression OpenEXR's header records: the value byte of the attribute named and typed
// "compression" (OpenEXR's file layout), or -1 when absent.
int headerCompression(const std::string& bytes) {
  static constexpr char kTag[] = "compression\0compression\0\1\0\0\0";  // name, type, size
  const std::string tag(kTag, sizeof(kTag) - 1);
  const size_t at = bytes.find(tag);
  return at == std::string::npos ? -1 : int(uint8_t(bytes[at + tag.size()]));
}

TEST(ExrIo, EveryCompressionKeepsThePixels) {
  const Image beauty = pattern(97, 83, 4, 0.f);
  const Image sun = pattern(97, 83, 3, 50.f);
  // OpenEXR's numbering of these compressions (ImfCompression.h), which the file stores.
  const std::map<ExrCompression, int> on_file = {{ExrCompression::kNone, 0},
                                                 {ExrCompression::kRle, 1},
                                                 {ExrCompression::kZips, 2},
                                                 {ExrCompression::kZip, 3},
                                                 {ExrCompression::kPiz, 4}};
  std::map<ExrCompression, size_t> sizes;
  for (const ExrCompressionName& c : kExrCompressionNames) {
    SCOPED_TRACE(std::string(c.name));
    const std::string path = tempPath("compression-" + std::string(c.name) + ".exr");
    writeExr(path, {{"", beauty}, {"sun", sun}}, {}, {}, c.value);
    const std::string bytes = fileBytes(path);
    EXPECT_EQ(headerCompression(bytes), on_file.at(c.value));
    sizes[c.value] = bytes.size();
    const ExrContents in = readExr(path);
    EXPECT_EQ(in.layers.at("").data, beauty.data);
    EXPECT_EQ(in.layers.at("sun").data, sun.data);
    std::remove(path.c_str());
    EXPECT_EQ(exrCompressionFromName(c.name), c.value);
  }
  // Uncompressed holds every float: 7 channels of 97 x 83.
  EXPECT_GT(sizes[ExrCompression::kNone], 7u * 4 * 97 * 83);
  EXPECT_LT(sizes[ExrCompression::kZip], sizes[ExrCompression::kNone]);
  EXPECT_EQ(exrCompressionFromName("dwaa"), std::nullopt);
  EXPECT_EQ(exrCompressionFromName("ZIP"), std::nullopt);
}

TEST(ExrIo, ThreadCountOutsideItsRangeIsAnInputError) {
  EXPECT_THROW(setExrThreads(-1), InputError);
  EXPECT_THROW(setExrThreads(4097), InputError);
}

TEST(ExrIo, GreyImageReadsAsRgb) {
  const std::string path = tempPath("grey.exr");
  writeExr(path, {{"", pattern(3, 2, 1, 1.f)}});
  const Image rgb = readExrRgb(path);
  EXPECT_EQ(rgb.at(2, 1)[0], pattern(3, 2, 1, 1.f).at(2, 1)[0]);
  EXPECT_EQ(rgb.at(2, 1)[1], rgb.at(2, 1)[0]);
  std::remove(path.c_str());
}

TEST(ExrIo, RejectsInvalidLayers) {
  const std::string path = tempPath("bad.exr");
  EXPECT_THROW(writeExr(path, {}), InputError);
  EXPECT_THROW(writeExr(path, {{"", pattern(2, 2, 2, 0.f)}}), InputError);
  EXPECT_THROW(writeExr(path, {{"", pattern(2, 2, 3, 0.f)}, {"sun", pattern(3, 2, 3, 0.f)}}),
               InputError);
  EXPECT_THROW(writeExr(path, {{"sun", pattern(2, 2, 3, 0.f)}, {"sun", pattern(2, 2, 3, 0.f)}}),
               InputError);
  EXPECT_THROW(writeExr("/nonexistent-dir/x.exr", {{"", pattern(2, 2, 3, 0.f)}}), InputError);
}

TEST(ExrIo, MissingAndCorruptFilesThrowInputErrorNamingThePath) {
  const std::string missing = tempPath("does_not_exist.exr");
  try {
    readExr(missing);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }

  const std::string garbage = tempPath("garbage.exr");
  {
    std::ofstream f(garbage, std::ios::binary);
    f << "this is not an image";
  }
  EXPECT_THROW(readExr(garbage), InputError);

  // A real EXR cut in half: the header parses, the pixel data does not.
  const std::string good = tempPath("good.exr");
  writeExr(good, {{"", pattern(64, 64, 4, 0.f)}});
  std::string bytes;
  {
    std::ifstream f(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(f), {});
  }
  for (size_t keep : {size_t(8), size_t(100), bytes.size() / 2, bytes.size() - 10}) {
    const std::string truncated = tempPath("truncated.exr");
    {
      std::ofstream f(truncated, std::ios::binary);
      f.write(bytes.data(), static_cast<std::streamsize>(keep));
    }
    EXPECT_THROW(readExr(truncated), InputError) << "kept " << keep << " bytes";
    std::remove(truncated.c_str());
  }
  std::remove(garbage.c_str());
  std::remove(good.c_str());
}

// A full disk: StorageFullError, and neither the EXR nor a temporary is left behind.
TEST(ExrIo, FullDiskThrowsStorageFullAndLeavesNoFile) {
  const std::string dir = (std::filesystem::temp_directory_path() /
                           ("cloudbake_exr_full_" + std::to_string(::getpid())))
                              .string();
  testing::TinyVolume volume(dir, 1);
  if (!volume.ok()) GTEST_SKIP() << volume.why();
  Image noise(512, 512, 4);
  uint32_t state = 1;
  for (float& v : noise.data) {  // incompressible, so ZIP cannot make it fit
    state = state * 1664525u + 1013904223u;
    v = float(state >> 8) / float(1 << 24);
  }
  const std::string path = volume.dir() + "/view.exr";
  EXPECT_THROW(writeExr(path, {{"", noise}}), StorageFullError);
  size_t left = 0;
  for (const auto& e : std::filesystem::directory_iterator(volume.dir())) {
    ++left;
    ADD_FAILURE() << "left behind: " << e.path();
  }
  EXPECT_EQ(left, 0u);
}

}  // namespace
}  // namespace cloudbake
