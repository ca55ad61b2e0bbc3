#include "supernode_kernels.hpp"

// Compiled with -ffp-contract=off (sim/CMakeLists.txt), like the element kernel: no clone fuses a multiply-add. The
// arithmetic is written on 16-float vectors (GCC's vector extension), which each clone maps onto its own registers
// (one AVX-512 register, two AVX2 ones, four SSE2 ones) lane by lane, and every sum is in an order fixed by this code
// (the dot products' 16 partial sums and the tree that adds them), so every clone gives the same bits.

#include <cstddef>
#include <cstring>

namespace octocut::sim {

namespace {

typedef float Vec16 __attribute__((vector_size(64)));
typedef float Vec8 __attribute__((vector_size(32)));
typedef float Vec4 __attribute__((vector_size(16)));
constexpr int kLanes = 16;
constexpr int kBlock = 8;  // columns per pass over the rows below a block

// The helpers that take or return vectors are always inlined (at -O0 too): called, they would pass a vector by the
// plain ABI to a clone that expects it in a wide register.
#define OCTOCUT_VECTOR_HELPER inline __attribute__((always_inline))

OCTOCUT_VECTOR_HELPER Vec16 load(const float* p) {
  Vec16 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
OCTOCUT_VECTOR_HELPER void store(float* p, Vec16 v) { std::memcpy(p, &v, sizeof v); }

// The sum of the 16 lanes, always in this order: lane i + lane i + 8, then i + (i + 4), ... (a tree of halves).
OCTOCUT_VECTOR_HELPER float lane_sum(Vec16 v) {
  Vec8 a, b;
  std::memcpy(&a, &v, sizeof a);
  std::memcpy(&b, reinterpret_cast<const char*>(&v) + sizeof a, sizeof b);
  const Vec8 s8 = a + b;
  Vec4 c, d;
  std::memcpy(&c, &s8, sizeof c);
  std::memcpy(&d, reinterpret_cast<const char*>(&s8) + sizeof c, sizeof d);
  const Vec4 s4 = c + d;
  const float s0 = s4[0] + s4[2], s1 = s4[1] + s4[3];
  return s0 + s1;
}

// The columns of the block [j0, j0 + nc): a partial block (nc < kBlock) repeats its first column (whose x is 0 in
// the forward solve; in the backward one its sums go unused).
inline void block_columns(const float* L, int j0, int nc, int ld, const float* (&c)[kBlock]) {
  for (int q = 0; q < kBlock; ++q) c[q] = L + std::ptrdiff_t(j0 + (q < nc ? q : 0)) * ld;
}

}  // namespace

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
void supernode_forward(const float* __restrict L, int nscol, int nsrow, int ld, float* __restrict w) {
  for (int j0 = 0; j0 < nscol; j0 += kBlock) {
    const int nc = nscol - j0 < kBlock ? nscol - j0 : kBlock, j1 = j0 + nc;
    // The block's own triangle, column by column.
    for (int j = j0; j < j1; ++j) {
      const float* c = L + std::ptrdiff_t(j) * ld;
      w[j] = w[j] * c[j];  // c[j]: the reciprocal of the diagonal entry
      for (int i = j + 1; i < j1; ++i) w[i] = w[i] - c[i] * w[j];
    }
    // The rows below it: w_i = (((w_i - L_i,j0 w_j0) - L_i,j0+1 w_j0+1) - ...), every row alike. A partial block's
    // repeated column has x = 0: subtracting 0 changes no value. The columns and w are padded with zeros to ld >=
    // nsrow + 15, so the last vector reads and writes only zeros past nsrow.
    const float* c[kBlock];
    block_columns(L, j0, nc, ld, c);
    float x[kBlock];
    for (int q = 0; q < kBlock; ++q) x[q] = q < nc ? w[j0 + q] : 0.0f;
    for (int i = j1; i < nsrow; i += kLanes) {
      Vec16 v = load(w + i);
#pragma GCC unroll 8
      for (int q = 0; q < kBlock; ++q) v = v - load(c[q] + i) * x[q];
      store(w + i, v);
    }
  }
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
void supernode_backward(const float* __restrict L, int nscol, int nsrow, int ld, float* __restrict w) {
  const int last = nscol % kBlock == 0 ? kBlock : nscol % kBlock;  // the last block is the partial one
  for (int j1 = nscol, nc = last; j1 > 0; j1 -= nc, nc = kBlock) {
    const int j0 = j1 - nc;
    // s_q = L(j1:, j0 + q) . w(j1:) for the block's columns: 16 partial sums each (the zeros past nsrow add
    // nothing), then the tree of halves.
    const float* c[kBlock];
    block_columns(L, j0, nc, ld, c);
    Vec16 a[kBlock] = {};
    for (int i = j1; i < nsrow; i += kLanes) {
      const Vec16 v = load(w + i);
#pragma GCC unroll 8
      for (int q = 0; q < kBlock; ++q) a[q] = a[q] + load(c[q] + i) * v;
    }
    float s[kBlock];
#pragma GCC unroll 8
    for (int q = 0; q < kBlock; ++q) s[q] = lane_sum(a[q]);
    // The block's own triangle, backwards.
    for (int q = nc - 1; q >= 0; --q) {
      const int j = j0 + q;
      float v = w[j] - s[q];
      for (int r = j + 1; r < j1; ++r) v = v - c[q][r] * w[r];
      w[j] = v * c[q][j];
    }
  }
}

}  // namespace octocut::sim
