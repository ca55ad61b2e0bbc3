#pragma once
// The dense kernels of the supernodal triangular solves (sim/src only): one supernode's block of L at a time.

namespace octocut::sim {

/// Zeros a supernode's column needs after its nsrow rows so that the kernels below read whole 16-float vectors.
constexpr int kSupernodePadding = 15;

/// One supernode of the forward solve L y = b. `L` is the supernode's column-major block, nscol columns with leading
/// dimension ld >= nsrow + kSupernodePadding: its own columns' lower triangle on top (each diagonal entry holding its
/// reciprocal; the upper triangle is never read), the rows below it after, and zeros from row nsrow to ld. `w` (ld)
/// holds the supernode's part of y in w[0, nscol) and zeros after. On return w[0, nscol) = D^-1 w (D the triangle)
/// and w[nscol, nsrow) = -B w[0, nscol) (B the rows below), which the caller adds to the rows they stand for; w past
/// nsrow stays zero. Each entry is computed in an order fixed by the code, so the result is the same bit for bit
/// whatever vector width the CPU offers (AVX-512, AVX2, SSE2: chosen once at load time on x86-64).
void supernode_forward(const float* L, int nscol, int nsrow, int ld, float* w);

/// One supernode of the backward solve L^T y = b, `L` as above: w (ld) holds the supernode's part of b in
/// w[0, nscol), the solution's entries at the rows below (already final) in w[nscol, nsrow), and zeros after. On
/// return w[0, nscol) = D^-T (w[0, nscol) - B^T w[nscol, nsrow)). The same bits on every CPU, as above.
void supernode_backward(const float* L, int nscol, int nsrow, int ld, float* w);

}  // namespace octocut::sim
