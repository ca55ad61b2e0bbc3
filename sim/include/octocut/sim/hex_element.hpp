#pragma once
// The corotational trilinear hexahedron (SPEC §3).
#include <Eigen/Core>

#include "octocut/sim/types.hpp"

namespace octocut::sim {

using Mat24 = Eigen::Matrix<double, 24, 24>;
using Vec24 = Eigen::Matrix<double, 24, 1>;

/// How the element's strain is interpolated (the scene key object.material.element).
enum class HexFormulation {
  trilinear,  ///< the standard trilinear (Q1) hexahedron, fully integrated: locks as nu -> 1/2
  bbar,       ///< B-bar (Hughes 1980): the volumetric strain replaced by its element mean (mean dilatation)
};

/// Stiffness of the unit cube [0,1]^3 with Young's modulus 1 and Poisson ratio nu, 2x2x2 Gauss quadrature
/// (24 x 24, N/m per unit E). A cube of edge h and modulus E has stiffness E * h * unit_stiffness. Corner k has the
/// bits (k&1, k>>1&1, k>>2&1) along x, y, z; DOF 3k+d is corner k's coordinate d.
Mat24 unit_hex_stiffness(double nu);

/// The B-bar (mean dilatation) stiffness of the unit cube, same conventions as unit_hex_stiffness: at each of the
/// 2x2x2 Gauss points the strain operator is B_bar = B + m (b_mean - b) / 3, with m = (1,1,1,0,0,0) and b the
/// divergence row of B (b_mean its element mean), and K = sum_q w_q B_bar^T D B_bar. Equivalently the deviatoric
/// energy is integrated fully and the volumetric energy kappa/2 (mean div u)^2 V once per element, so the element
/// does not lock volumetrically as nu -> 1/2 and keeps exactly 6 zero-energy modes (the rigid motions).
Mat24 unit_hex_stiffness_bbar(double nu);

/// The unit-cube stiffness of formulation f (one of the two above).
Mat24 unit_hex_stiffness(double nu, HexFormulation f);

/// Deformation gradient at the centre of a cube of edge h (m) whose 8 corners are at x (m, 3 x 8 columns).
Mat3 hex_center_gradient(const Eigen::Matrix<double, 3, 8>& x, double h);

/// Rotation of the polar decomposition F = R S, robust to inverted and degenerate F: det R = +1 always. Scaled
/// Newton iteration for well-conditioned F with det F > 0; otherwise SVD with the sign correction of Irving et al.
/// 2004 (flip the direction of the smallest singular value).
Mat3 polar_rotation(const Mat3& F);

/// The rotation Gram-Schmidt makes of M's first two columns (the third their cross product): for a weighted sum of
/// nearby rotations, the rotation they share up to second order in their spread, at a fraction of a polar
/// decomposition's cost. Identity when M's columns are degenerate.
Mat3 gram_schmidt_rotation(const Mat3& m);

/// Corotated displacement R^T (x - x_c) - (X - X_c) of the 8 corners relative to their centroids (m, 24).
Vec24 corotated_displacement(const Mat3& R, const Vec24& x, const Vec24& X);

/// Restoring force -R K (R^T x - X) of one element (N, 24), with K = E h K_unit scaled by occupancy (K given); with
/// `energy`, also its elastic energy u^T K u / 2 (J).
Vec24 corotated_force(const Mat24& K, const Mat3& R, const Vec24& x, const Vec24& X, double* energy = nullptr);

/// The corotated stiffness R K R^T (24 x 24).
Mat24 corotated_stiffness(const Mat24& K, const Mat3& R);

/// out = c R K R^T (24 x 24), written in place (K symmetric).
void corotated_stiffness(const Mat24& K, const Mat3& R, double c, Mat24& out);

}  // namespace octocut::sim
