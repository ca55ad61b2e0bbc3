#include "element_kernels.hpp"

// Compiled with -ffp-contract=off (sim/CMakeLists.txt): no multiply-add is fused, in any of the clones, so every
// clone rounds exactly as the plain one. The loops are unrolled by hand so that -O2 keeps the 24 sums in registers
// (it vectorises them over i; measured on 2,104 elements: 0.063 ms with AVX-512, 0.096 with AVX2, against 0.147 for
// Eigen's SSE2 product, which the build's baseline ISA gives it).

namespace octocut::sim {

// Not under ThreadSanitizer: the clones' resolver runs while the dynamic loader relocates, before TSan's run time is
// set up, and its instrumented code crashes there.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(__SANITIZE_THREAD__)
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
void apply_stiffness24(const double* __restrict K, const double* __restrict v, double* __restrict out) {
  double acc[24];
#pragma GCC unroll 24
  for (int i = 0; i < 24; ++i) acc[i] = K[i] * v[0];
#pragma GCC unroll 23
  for (int k = 1; k < 24; ++k) {
    const double s = v[k];
#pragma GCC unroll 24
    for (int i = 0; i < 24; ++i) acc[i] += K[24 * k + i] * s;
  }
#pragma GCC unroll 24
  for (int i = 0; i < 24; ++i) out[i] = acc[i];
}

}  // namespace octocut::sim
