#pragma once
// The dense kernels of the supernodal triangular solves (sim/src only): one supernode's block of L at a time.
#include <cstdint>
#include <vector>

namespace octocut::sim {

/// Zeros a supernode's column needs after its nsrow rows so that the kernels below read whole 16-entry vectors.
constexpr int kSupernodePadding = 15;

/// L's entries are read as single-precision floats, or, for factors too large for the caches, as 16-bit codes of
/// IEEE half precision (1 sign, 5 exponent, 10 fraction bits; normal numbers and zero only), each column scaled by a
/// power of two so that its largest entry below the diagonal lies in [2^14, 2^15): the codes then hold 11
/// significant bits of every entry within 2^28 of the column's largest (smaller ones are zero), in half the bytes.
/// The exact value of a code, in single precision (every half-precision number is one).
[[nodiscard]] inline float half_value(std::uint16_t code) {
  const std::uint32_t magnitude = std::uint32_t(code & 0x7fffu) << 13;
  const std::uint32_t bits = (magnitude != 0 ? magnitude + 0x38000000u : 0u) | (std::uint32_t(code & 0x8000u) << 16);
  float f;
  __builtin_memcpy(&f, &bits, sizeof f);
  return f;
}
/// The code nearest to v (ties to even), v's magnitude in [2^-14, 65504]; 0 for smaller magnitudes. On the double's
/// bits, without branches on the value (pack codes millions of entries per factorisation: with libm's ilogb, ldexp and
/// nearbyint this took 26 ns an entry).
[[nodiscard]] inline std::uint16_t half_code(double v) {
  std::uint64_t bits;
  __builtin_memcpy(&bits, &v, sizeof bits);
  const auto sign = std::uint32_t(bits >> 48) & 0x8000u;
  const int e = int((bits >> 52) & 0x7ff) - 1023;  // |v| in [2^e, 2^(e + 1))
  if (e < -14) return 0;                           // below the smallest normal half (and zero)
  const std::uint64_t m = (bits & ((std::uint64_t(1) << 52) - 1)) | (std::uint64_t(1) << 52);  // 53 bits
  // 11 of them, to nearest, ties to even: add just under half a unit, plus one when the kept part is odd.
  std::uint64_t r = (m + ((std::uint64_t(1) << 41) - 1) + ((m >> 42) & 1)) >> 42;
  const int carry = int(r >> 11);  // rounded up into the next binade (r = 2^11)
  r >>= carry;
  return std::uint16_t(sign | (std::uint32_t(e + carry + 15) << 10) | (std::uint32_t(r) & 0x3ffu));
}

/// One supernode of the forward solve L y = b. `L` is the supernode's column-major block of entries (floats or
/// codes), nscol columns with leading dimension ld >= nsrow + kSupernodePadding: its own columns' strict lower
/// triangle on top (the diagonal and the upper triangle are never read), the rows below it after, and zeros from row
/// nsrow to ld. Column j's entries are scale[j] times the values stored (a power of two; 1 for floats); diag_inv[j]
/// is the reciprocal of its diagonal entry. `w` (ld) holds the supernode's part of y in w[0, nscol) and zeros after.
/// On return w[0, nscol) = D^-1 w (D the triangle) and w[nscol, nsrow) = -B w[0, nscol) (B the rows below), which
/// the caller adds to the rows they stand for; w past nsrow stays zero. Each entry is computed in an order fixed by
/// the code, so the result is the same bit for bit whatever vector width the CPU offers (AVX-512, AVX2, SSE2: chosen
/// once at load time on x86-64).
void supernode_forward(const float* L, const float* diag_inv, const float* scale, int nscol, int nsrow, int ld,
                       float* w);
void supernode_forward(const std::uint16_t* L, const float* diag_inv, const float* scale, int nscol, int nsrow, int ld,
                       float* w);

/// One supernode of the backward solve L^T y = b, `L`, `diag_inv` and `scale` as above: w (ld) holds the
/// supernode's part of b in w[0, nscol), the solution's entries at the rows below (already final) in w[nscol, nsrow),
/// and zeros after. On return w[0, nscol) = D^-T (w[0, nscol) - B^T w[nscol, nsrow)). The same bits on every CPU.
void supernode_backward(const float* L, const float* diag_inv, const float* scale, int nscol, int nsrow, int ld,
                        float* w);
void supernode_backward(const std::uint16_t* L, const float* diag_inv, const float* scale, int nscol, int nsrow,
                        int ld, float* w);

/// One copy of the kernels above, compiled for one instruction set (each gives the same bits).
struct SupernodeKernelCopy {
  const char* name;  ///< "avx512", "avx2" (with F16C) or "generic"
  void (*forward)(const float*, const float*, const float*, int, int, int, float*);
  void (*backward)(const float*, const float*, const float*, int, int, int, float*);
  void (*forward_half)(const std::uint16_t*, const float*, const float*, int, int, int, float*);
  void (*backward_half)(const std::uint16_t*, const float*, const float*, int, int, int, float*);
};
/// The copies this CPU can run, the one supernode_forward and supernode_backward use first (for tests).
[[nodiscard]] std::vector<SupernodeKernelCopy> supernode_kernel_copies();

}  // namespace octocut::sim
