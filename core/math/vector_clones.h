// A function attribute for hot code that AVX2's instruction set speeds up: loops the compiler
// vectorises (wider registers) and code that rounds (SSE4.1's roundsd for std::floor, which the
// x86-64 baseline lacks). On x86-64 Linux the function is compiled twice, for AVX2 and for the
// baseline, and the loader picks one by the CPU (GNU ifunc). AVX2 without FMA performs the same
// IEEE operations in the same order, so both versions give the same results bit for bit; only
// the speed differs. Not for virtual functions (GCC refuses to multiversion them).
//
// GCC only: clang 14 (Debian 12's) links a call from another translation unit to a cloned
// member function wrongly (a test returned its argument instead of its result), so under clang
// (the fuzz build) every function is compiled once, for the baseline.
#pragma once

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define CLOUDBAKE_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CLOUDBAKE_VECTOR_CLONES
#endif

// The same with a third clone for AVX-512 (eight doubles a register), for loops written on
// 64-byte vectors. AVX-512F has fused multiply-adds of its own, so a file that uses this must be
// compiled with -ffp-contract=off for its clones to agree bit for bit (as shexp.cpp is).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define CLOUDBAKE_WIDE_VECTOR_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define CLOUDBAKE_WIDE_VECTOR_CLONES
#endif
