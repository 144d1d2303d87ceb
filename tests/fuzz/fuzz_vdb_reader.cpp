// libFuzzer target: a user's VDB file as the service loads it (loadVdbVolume: OpenVDB behind
// our checked reading, then the grid checks).
#include <cstdint>

#include "core/volume/sources.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  cloudbake::fuzz::withTempFile(data, size, ".vdb", [](const std::string& path) {
    cloudbake::VdbSourceOptions options;
    options.path = path;
    (void)cloudbake::loadVdbVolume(options);
  });
  return 0;
}
