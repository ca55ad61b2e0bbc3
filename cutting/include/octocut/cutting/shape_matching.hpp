#pragma once
// Stage 1 of a cut, the robust back-transform (SPEC §4, paper §4.1): a shape-matching affine fit of a group of
// elements (Müller et al. 2005), blended towards its rotation when ill-conditioned, and the map of the blade B into
// rest space, B' = A^-1 (x − c_deformed) + c_rest.
#include <span>

#include "octocut/sim/surface.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::cutting {

/// The affine fit x ≈ A (X − c_rest) + c_deformed of deformed points x to rest points X.
struct ShapeMatch {
  sim::Mat3 A;           ///< the affine part mapping rest offsets to deformed offsets, dimensionless; det(A) > 0 always
  sim::Vec3 c_rest;      ///< weighted centroid of the rest points, m
  sim::Vec3 c_deformed;  ///< weighted centroid of the deformed points, m
  double condition = 0;  ///< cond(A) = σ_max / σ_min of the raw fit, before blending (+inf when singular)
  double blend = 0;      ///< β: 0 = raw fit used, 1 = pure rotation used; A = (1 − β) A_raw + β R
};

/// Fits A = A_pq A_qq^-1 with A_pq = Σ w_i (p_i − c_p)(q_i − c_q)^T and A_qq = Σ w_i (q_i − c_q)(q_i − c_q)^T over
/// the weighted pairs (rest q_i = rest[i], deformed p_i = deformed[i], weight w_i), m (|P| each).
///
/// When cond(A) > max_condition or det(A) <= 0, A is blended towards its polar rotation R (sim::polar_rotation,
/// Irving's sign correction, det R = +1) with the smallest β in [0, 1] that gives cond <= max_condition and
/// det > 0. Writing R^T A = V diag(s) V^T with signed s_i (s_3 < 0 when A is inverted), the blend has singular
/// values (1 − β) s_i + β, so the smallest β is found in closed form from the linear conditions
/// (1 − β) s_i + β <= κ ((1 − β) s_j + β); it is raised by a few ulps if rounding leaves cond above the bound.
/// A fit that collapses every point onto one (largest singular value of A at most 1e-9: A = 0 up to rounding, or a
/// compression no tissue reaches) has no shape to keep and uses R (β = 1); R is then arbitrary but a rotation.
///
/// Throws std::invalid_argument, naming the reason, for spans of different sizes, a non-finite coordinate or
/// weight, a negative weight, weights that sum to zero, rest points with positive weight that do not span 3D
/// (fewer than 4 non-coplanar points), or max_condition < 1.
ShapeMatch shape_match(std::span<const sim::Vec3> rest, std::span<const sim::Vec3> deformed,
                       std::span<const double> weights, double max_condition = 10.0);

/// The rest-space position of a deformed-space point: A^-1 (x − c_deformed) + c_rest, m.
sim::Vec3 to_rest(const ShapeMatch& m, const sim::Vec3& x);

/// The blade mapped into rest space, B' (same triangles, vertices mapped by to_rest). Since det A > 0 the mapped
/// mesh keeps its outward orientation and, being an affine image, stays free of self-intersections.
sim::TriMesh to_rest(const ShapeMatch& m, const sim::TriMesh& deformed_blade);

}  // namespace octocut::cutting
