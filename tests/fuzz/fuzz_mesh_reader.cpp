// libFuzzer target: the mesh readers. The first byte picks the format (even: PLY, odd: OBJ), so
// one corpus exercises both.
#include <cstdint>

#include "core/volume/mesh_io.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const char* suffix = (data[0] & 1) ? ".obj" : ".ply";
  cloudbake::fuzz::withTempFile(data + 1, size - 1, suffix,
                                [](const std::string& path) { (void)cloudbake::readMesh(path); });
  return 0;
}
