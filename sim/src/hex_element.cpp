#include "octocut/sim/hex_element.hpp"

#include <Eigen/SVD>
#include <array>
#include <cmath>

#include "element_kernels.hpp"

namespace octocut::sim {

namespace {
// Isotropic elasticity for E = 1 in Voigt order (xx, yy, zz, xy, yz, zx) with engineering shear strains.
Eigen::Matrix<double, 6, 6> unit_elasticity(double nu) {
  const double lambda = nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
  const double mu = 1.0 / (2.0 * (1.0 + nu));
  Eigen::Matrix<double, 6, 6> D = Eigen::Matrix<double, 6, 6>::Zero();
  D.topLeftCorner<3, 3>().setConstant(lambda);
  D.topLeftCorner<3, 3>().diagonal().array() += 2.0 * mu;
  D.bottomRightCorner<3, 3>().diagonal().setConstant(mu);
  return D;
}

// Strain-displacement matrix B (6 x 24) of the unit cube at the point xi of [0,1]^3.
Eigen::Matrix<double, 6, 24> unit_strain_operator(const double xi[3]) {
  Eigen::Matrix<double, 6, 24> B = Eigen::Matrix<double, 6, 24>::Zero();
  for (int a = 0; a < 8; ++a) {
    double f[3], df[3];
    for (int d = 0; d < 3; ++d) {
      const bool bit = (a >> d) & 1;
      f[d] = bit ? xi[d] : 1.0 - xi[d];
      df[d] = bit ? 1.0 : -1.0;
    }
    const double gx = df[0] * f[1] * f[2], gy = f[0] * df[1] * f[2], gz = f[0] * f[1] * df[2];
    B(0, 3 * a + 0) = gx;
    B(1, 3 * a + 1) = gy;
    B(2, 3 * a + 2) = gz;
    B(3, 3 * a + 0) = gy;
    B(3, 3 * a + 1) = gx;
    B(4, 3 * a + 1) = gz;
    B(4, 3 * a + 2) = gy;
    B(5, 3 * a + 0) = gz;
    B(5, 3 * a + 2) = gx;
  }
  return B;
}
}  // namespace

Mat24 unit_hex_stiffness(double nu) {
  const Eigen::Matrix<double, 6, 6> D = unit_elasticity(nu);
  // 2x2x2 Gauss quadrature on [0,1]^3, each point weighted 1/8.
  const double g[2] = {0.5 - 0.5 / std::sqrt(3.0), 0.5 + 0.5 / std::sqrt(3.0)};
  Mat24 K = Mat24::Zero();
  for (int q = 0; q < 8; ++q) {
    const double xi[3] = {g[q & 1], g[(q >> 1) & 1], g[(q >> 2) & 1]};
    const Eigen::Matrix<double, 6, 24> B = unit_strain_operator(xi);
    K.noalias() += 0.125 * B.transpose() * D * B;
  }
  return K;
}

Mat24 unit_hex_stiffness_bbar(double nu) {
  const Eigen::Matrix<double, 6, 6> D = unit_elasticity(nu);
  const double g[2] = {0.5 - 0.5 / std::sqrt(3.0), 0.5 + 0.5 / std::sqrt(3.0)};
  // B at the 8 Gauss points (each weighted 1/8, the cube's volume being 1) and the mean divergence row.
  std::array<Eigen::Matrix<double, 6, 24>, 8> B;
  Eigen::Matrix<double, 1, 24> mean_div = Eigen::Matrix<double, 1, 24>::Zero();
  for (int q = 0; q < 8; ++q) {
    const double xi[3] = {g[q & 1], g[(q >> 1) & 1], g[(q >> 2) & 1]};
    B[std::size_t(q)] = unit_strain_operator(xi);
    mean_div += 0.125 * B[std::size_t(q)].topRows<3>().colwise().sum();
  }
  Mat24 K = Mat24::Zero();
  for (int q = 0; q < 8; ++q) {
    Eigen::Matrix<double, 6, 24> Bbar = B[std::size_t(q)];
    const Eigen::Matrix<double, 1, 24> shift = (mean_div - B[std::size_t(q)].topRows<3>().colwise().sum()) / 3.0;
    Bbar.topRows<3>().rowwise() += shift;
    K.noalias() += 0.125 * Bbar.transpose() * D * Bbar;
  }
  // Symmetric up to round-off; make it exactly so.
  return 0.5 * (K + K.transpose());
}

Mat24 unit_hex_stiffness(double nu, HexFormulation f) {
  return f == HexFormulation::bbar ? unit_hex_stiffness_bbar(nu) : unit_hex_stiffness(nu);
}

Mat3 hex_center_gradient(const Eigen::Matrix<double, 3, 8>& x, double h) {
  // At the centre, dN_a/dxi_d = +-1/4 with the sign of corner a's bit d: F(i, d) sums x(i, a) dN_a/dxi_d over the
  // corners in order (the products by 1/4 are exact), then divides by h.
  Mat3 F;
  for (int d = 0; d < 3; ++d) {
    Vec3 sum = Vec3::Zero();
    for (int a = 0; a < 8; ++a) sum += x.col(a) * (((a >> d) & 1) ? 0.25 : -0.25);
    F.col(d) = sum / h;
  }
  return F;
}

namespace {
// The rotation of F = R S by Newton's iteration X <- (g X + (g X)^-T) / 2 (Higham 1986), with the determinant
// scaling g = |det X|^(-1/3) while far from converged. For det F > 0 it converges quadratically to the orthogonal
// polar factor, which is then the rotation that the SVD below gives (U V^T has det +1, no sign correction). Returns
// false, leaving R unset, when F is inverted or nearly singular (det F <= 1e-3 |F|_F^3; the identity has 0.19) or
// when 24 iterations do not converge: the SVD decides those.
// The cofactor matrix of X: X^-T det X.
Mat3 cofactor(const Mat3& X) {
  Mat3 c;
  c.col(0) = X.col(1).cross(X.col(2));
  c.col(1) = X.col(2).cross(X.col(0));
  c.col(2) = X.col(0).cross(X.col(1));
  return c;
}

bool newton_polar_rotation(const Mat3& F, Mat3& R) {
  const double fn = F.norm();
  const double det = F.determinant();
  if (!std::isfinite(det) || !(det > 1e-3 * fn * fn * fn)) return false;
  Mat3 X = F;
  double d = det;
  bool scale = true;
  for (int it = 0; it < 24; ++it) {
    const double g = scale ? 1.0 / std::cbrt(d) : 1.0;
    const Mat3 Y = 0.5 * (g * X + cofactor(X) / (g * d));  // X^-T = cofactor(X) / det X
    const double delta = (Y - X).norm();
    X = Y;
    if (delta < 1e-9) {
      // Quadratic convergence: one more step brings the error below round-off.
      R = 0.5 * (X + cofactor(X) / X.determinant());
      return true;
    }
    scale = delta > 1e-2;
    d = X.determinant();
    if (!(d > 0.0)) return false;
  }
  return false;
}
}  // namespace

Mat3 gram_schmidt_rotation(const Mat3& m) {
  Vec3 a = m.col(0), b = m.col(1);
  const double na = a.norm();
  if (!(na > 0.0)) return Mat3::Identity();
  a /= na;
  b -= a.dot(b) * a;
  const double nb = b.norm();
  if (!(nb > 1e-12 * na)) return Mat3::Identity();
  b /= nb;
  Mat3 r;
  r.col(0) = a;
  r.col(1) = b;
  r.col(2) = a.cross(b);
  return r;
}

Mat3 polar_rotation(const Mat3& F) {
  Mat3 R;
  if (newton_polar_rotation(F, R)) return R;
  Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  const Mat3& V = svd.matrixV();
  // Sign correction (Irving et al. 2004): flip the direction of the smallest singular value so det R = +1.
  if ((U * V.transpose()).determinant() < 0.0) U.col(2) *= -1.0;
  return U * V.transpose();
}

Vec24 corotated_displacement(const Mat3& R, const Vec24& x, const Vec24& X) {
  // Relative to the element centroids: K annihilates translations exactly only in exact arithmetic, so removing
  // them first keeps round-off independent of where the object is.
  Vec3 xc = Vec3::Zero(), Xc = Vec3::Zero();
  for (int a = 0; a < 8; ++a) {
    xc += x.segment<3>(3 * a);
    Xc += X.segment<3>(3 * a);
  }
  xc /= 8.0;
  Xc /= 8.0;
  Vec24 u;
  for (int a = 0; a < 8; ++a) u.segment<3>(3 * a) = R.transpose() * (x.segment<3>(3 * a) - xc) - (X.segment<3>(3 * a) - Xc);
  return u;
}

Vec24 corotated_force(const Mat24& K, const Mat3& R, const Vec24& x, const Vec24& X, double* energy) {
  const Vec24 local = corotated_displacement(R, x, X);
  Vec24 k;
  apply_stiffness24(K.data(), local.data(), k.data());
  if (energy != nullptr) *energy = 0.5 * local.dot(k);
  Vec24 f;
  for (int a = 0; a < 8; ++a) f.segment<3>(3 * a) = -(R * k.segment<3>(3 * a));
  return f;
}

void corotated_stiffness(const Mat24& K, const Mat3& R, double c, Mat24& out) {
  // K is symmetric, so block (b, a) of R K R^T is the transpose of block (a, b): compute the upper blocks only.
  const Mat3 cRt = c * R.transpose();
  for (int a = 0; a < 8; ++a) {
    for (int b = a; b < 8; ++b) {
      const Mat3 blk = R * K.block<3, 3>(3 * a, 3 * b) * cRt;
      out.block<3, 3>(3 * a, 3 * b) = blk;
      if (b != a) out.block<3, 3>(3 * b, 3 * a) = blk.transpose();
    }
  }
}

Mat24 corotated_stiffness(const Mat24& K, const Mat3& R) {
  Mat24 out;
  corotated_stiffness(K, R, 1.0, out);
  return out;
}

}  // namespace octocut::sim
