#pragma once
// The one dense kernel of every step: an element's 24 x 24 stiffness applied to a 24-vector (sim/src only).

namespace octocut::sim {

/// out = K v for a 24 x 24 matrix K (column-major, as Eigen stores Mat24) and 24-vectors v and out (distinct from v).
/// Each entry is summed over k = 0..23 in order with separate multiplies and adds, so the result is the same bit for
/// bit whatever vector width the CPU offers (AVX-512, AVX2, SSE2: chosen once at load time on x86-64).
void apply_stiffness24(const double* K, const double* v, double* out);

}  // namespace octocut::sim
