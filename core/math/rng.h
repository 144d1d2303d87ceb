// Deterministic per-thread random numbers.
#pragma once

#include <cstdint>

namespace cloudbake {

/// PCG32 (O'Neill 2014): small state, good statistics, and cheap independent streams, so each
/// image tile or point gets its own stream from (seed, index) and results do not depend on the
/// number of threads or the order work is scheduled in.
class Rng {
 public:
  explicit Rng(uint64_t seed = 0x853c49e6748fea9bULL, uint64_t stream = 0xda3e39cb94b95bdbULL) {
    setSeed(seed, stream);
  }
  void setSeed(uint64_t seed, uint64_t stream) {
    state_ = 0u;
    inc_ = (stream << 1u) | 1u;
    nextU32();
    state_ += seed;
    nextU32();
  }
  uint32_t nextU32() {
    const uint64_t old = state_;
    state_ = old * 6364136223846793005ULL + inc_;
    const uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
    const uint32_t rot = static_cast<uint32_t>(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
  }
  /// Uniform double in [0, 1).
  double uniform() {
    const uint64_t hi = nextU32();
    const uint64_t lo = nextU32();
    return static_cast<double>(((hi << 21) ^ lo) & ((1ULL << 53) - 1)) * 0x1.0p-53;
  }

 private:
  uint64_t state_ = 0, inc_ = 0;
};

/// Mixes two integers into a well-spread 64-bit value (SplitMix64 finaliser), used to derive
/// per-pixel / per-point stream ids from a user seed.
inline uint64_t mixBits(uint64_t a, uint64_t b = 0) {
  uint64_t z = a + 0x9e3779b97f4a7c15ULL * (b + 1);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

}  // namespace cloudbake
