// A function attribute for loops the compiler vectorises: on x86-64 the function is compiled
// twice, for AVX2 and for the baseline, and the loader picks one by the CPU (GNU ifunc). AVX2
// without FMA performs the same IEEE operations in the same order on wider registers, so both
// versions give the same results bit for bit; only the speed differs.
#pragma once

#if defined(__x86_64__) && defined(__GNUC__) && defined(__linux__)
#define CLOUDBAKE_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CLOUDBAKE_VECTOR_CLONES
#endif
