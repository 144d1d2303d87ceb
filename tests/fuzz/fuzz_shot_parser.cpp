// libFuzzer target: the shot parser (JSON text to ShotSpec), without touching files.
#include <cstdint>
#include <string>

#include "core/error.h"
#include "core/shot/shot_parser.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  cloudbake::ParseOptions options;
  options.check_files_exist = false;
  try {
    (void)cloudbake::parseShot(text, "/nonexistent", options);
  } catch (const cloudbake::InputError&) {
  }
  return 0;
}
