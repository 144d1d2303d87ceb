// The lossless compressions an EXR output can be written with, by the name a shot gives
// (`outputs.exr_compression`). Header-only and free of OpenEXR, so the shot parser can check a
// name without linking the image library.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <string_view>

namespace cloudbake {

/// Lossless only: an output's pixels must be what the method computed (no DWA, B44 or PXR24).
enum class ExrCompression { kNone, kRle, kZips, kZip, kPiz };

struct ExrCompressionName {
  ExrCompression value;
  std::string_view name;
};

/// In the order docs/shot-format.md lists them; "zip" is the default.
inline constexpr std::array<ExrCompressionName, 5> kExrCompressionNames{{
    {ExrCompression::kNone, "none"},
    {ExrCompression::kRle, "rle"},
    {ExrCompression::kZips, "zips"},
    {ExrCompression::kZip, "zip"},
    {ExrCompression::kPiz, "piz"},
}};

inline std::optional<ExrCompression> exrCompressionFromName(std::string_view name) {
  for (const ExrCompressionName& c : kExrCompressionNames) {
    if (c.name == name) return c.value;
  }
  return std::nullopt;
}

/// "none, rle, zips, zip, piz", for error messages.
inline std::string exrCompressionNamesList() {
  std::string out;
  for (const ExrCompressionName& c : kExrCompressionNames) {
    if (!out.empty()) out += ", ";
    out += c.name;
  }
  return out;
}

}  // namespace cloudbake
