// libFuzzer target: the EXR reader that `cloudbake compare` and previews use.
#include <cstdint>

#include "core/io/exr_io.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  cloudbake::fuzz::withTempFile(data, size, ".exr",
                                [](const std::string& path) { (void)cloudbake::readExr(path); });
  return 0;
}
