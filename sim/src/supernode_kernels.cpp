#include "supernode_kernels.hpp"

// Compiled with -ffp-contract=off (sim/CMakeLists.txt), like the element kernel: no copy fuses a multiply-add. The
// arithmetic is written on GCC's vector extension, each copy (supernode_kernels_body.inc, compiled once per
// instruction set) on its native width (16 floats for AVX-512, 8 for AVX2, 4 for SSE2), lane by lane, and every sum
// is in an order fixed by this code (the dot products' 16 partial sums and the tree that adds them); half
// precision's codes are widened to floats exactly. So every copy gives the same bits.

#include <cstddef>
#include <cstring>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <cpuid.h>
#include <immintrin.h>
#endif

namespace octocut::sim {

namespace {

typedef float Vec16 __attribute__((vector_size(64)));
typedef float Vec8 __attribute__((vector_size(32)));
typedef float Vec4 __attribute__((vector_size(16)));
typedef std::uint16_t Code4 __attribute__((vector_size(8)));
typedef std::uint32_t Bits4 __attribute__((vector_size(16)));
constexpr int kLanes = 16;
constexpr int kBlock = 8;  // columns per pass over the rows below a block

// The helpers that take or return vectors are always inlined (at -O0 too): called, they would pass a vector by the
// plain ABI to a copy that expects it in a wide register.
#define OCTOCUT_VECTOR_HELPER inline __attribute__((always_inline))

inline float entry_value(float v) { return v; }
inline float entry_value(std::uint16_t code) { return half_value(code); }

// The columns of the block [j0, j0 + nc): a partial block (nc < kBlock) repeats its first column (whose x is 0 in
// the forward solve; in the backward one its sums go unused).
template <class Entry>
inline void block_columns(const Entry* L, int j0, int nc, int ld, const Entry* (&c)[kBlock]) {
  for (int q = 0; q < kBlock; ++q) c[q] = L + std::ptrdiff_t(j0 + (q < nc ? q : 0)) * ld;
}

// One copy of the kernels per instruction set, each widening half precision's codes its own way: AVX-512 and AVX2 +
// F16C with the hardware's conversion (vcvtph2ps), the others with integer operations (half_value, lane by lane);
// both exact. (GCC 12 converts vectors of _Float16 one lane at a time, so the vector extension cannot do it.)
#if defined(__x86_64__) && defined(__GNUC__)
#define OCTOCUT_KERNEL_TARGET __attribute__((target("avx512f")))
namespace avx512 {
using VecW = Vec16;
constexpr int kSums = 8;  // backward's column sums per pass over the rows: 8 of the 32 registers
#if !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // GCC 12's _mm512_cvtph_ps starts from an undefined vector
#endif
OCTOCUT_VECTOR_HELPER OCTOCUT_KERNEL_TARGET Vec16 load_entries(const std::uint16_t* p) {
  const __m512 f = _mm512_cvtph_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)));
  Vec16 v;
  std::memcpy(&v, &f, sizeof v);
  return v;
}
#if !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#include "supernode_kernels_body.inc"
}  // namespace avx512
#undef OCTOCUT_KERNEL_TARGET

#define OCTOCUT_KERNEL_TARGET __attribute__((target("avx2,f16c")))
namespace avx2 {
using VecW = Vec8;
constexpr int kSums = 4;  // 8 of the 16 registers
OCTOCUT_VECTOR_HELPER OCTOCUT_KERNEL_TARGET Vec8 load_entries(const std::uint16_t* p) {
  const __m256 f = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
  Vec8 v;
  std::memcpy(&v, &f, sizeof v);
  return v;
}
#include "supernode_kernels_body.inc"
}  // namespace avx2
#undef OCTOCUT_KERNEL_TARGET
#endif

#define OCTOCUT_KERNEL_TARGET
namespace generic {
using VecW = Vec4;
constexpr int kSums = 2;  // 8 of SSE2's 16 registers
OCTOCUT_VECTOR_HELPER OCTOCUT_KERNEL_TARGET Vec4 load_entries(const std::uint16_t* p) {
  Code4 c;
  std::memcpy(&c, p, sizeof c);
  const Bits4 u = __builtin_convertvector(c, Bits4);
  const Bits4 magnitude = (u & 0x7fffu) << 13;
  const Bits4 bits = ((magnitude + 0x38000000u) & Bits4(magnitude != 0u)) | ((u & 0x8000u) << 16);
  Vec4 v;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}
#include "supernode_kernels_body.inc"
}  // namespace generic
#undef OCTOCUT_KERNEL_TARGET

// The copies this CPU runs, the widest first (chosen once).
std::vector<SupernodeKernelCopy> copies_here() {
  std::vector<SupernodeKernelCopy> out;
#if defined(__x86_64__) && defined(__GNUC__)
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f"))
    out.push_back({"avx512", avx512::forward<float>, avx512::backward<float>, avx512::forward<std::uint16_t>,
                   avx512::backward<std::uint16_t>});
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  const bool f16c = __get_cpuid(1, &eax, &ebx, &ecx, &edx) && (ecx & bit_F16C) != 0;
  if (__builtin_cpu_supports("avx2") && f16c)
    out.push_back({"avx2", avx2::forward<float>, avx2::backward<float>, avx2::forward<std::uint16_t>,
                   avx2::backward<std::uint16_t>});
#endif
  out.push_back({"generic", generic::forward<float>, generic::backward<float>, generic::forward<std::uint16_t>,
                 generic::backward<std::uint16_t>});
  return out;
}
const SupernodeKernelCopy& kernels() {
  static const SupernodeKernelCopy k = copies_here().front();
  return k;
}

}  // namespace

std::vector<SupernodeKernelCopy> supernode_kernel_copies() { return copies_here(); }

void supernode_forward(const float* L, const float* diag_inv, const float* scale, int nscol, int nsrow, int ld,
                       float* w) {
  kernels().forward(L, diag_inv, scale, nscol, nsrow, ld, w);
}
void supernode_forward(const std::uint16_t* L, const float* diag_inv, const float* scale, int nscol, int nsrow, int ld,
                       float* w) {
  kernels().forward_half(L, diag_inv, scale, nscol, nsrow, ld, w);
}

void supernode_backward(const float* L, const float* diag_inv, const float* scale, int nscol, int nsrow, int ld,
                        float* w) {
  kernels().backward(L, diag_inv, scale, nscol, nsrow, ld, w);
}
void supernode_backward(const std::uint16_t* L, const float* diag_inv, const float* scale, int nscol, int nsrow,
                        int ld, float* w) {
  kernels().backward_half(L, diag_inv, scale, nscol, nsrow, ld, w);
}

}  // namespace octocut::sim
