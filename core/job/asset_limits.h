// How many files one job may name: shared by the server, which enforces it, and its clients,
// which check it before they hash and upload anything. Header-only, so a client needs no more
// of core/job than this.
#pragma once

#include <cstddef>

namespace cloudbake {

/// Files one job may name (a sequence's frames, a sky map, ...). cloudctl checks it first: a
/// shot of 5000 frames had been hashed for 14 s before the server refused it.
inline constexpr size_t kMaxJobAssets = 4096;

}  // namespace cloudbake
