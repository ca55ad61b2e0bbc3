#include "octocut/cutting/shape_matching.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "octocut/sim/hex_element.hpp"

namespace octocut::cutting {

using sim::Mat3;
using sim::Vec3;

namespace {

// Largest stretch below which a fit counts as collapsed onto one point.
constexpr double kCollapsedStretch = 1e-9;

// cond(A) = σ_max / σ_min, +inf for a singular A.
double condition_number(const Mat3& A) {
  const Vec3 s = Eigen::JacobiSVD<Mat3>(A).singularValues();  // descending
  return s[2] > 0.0 ? s[0] / s[2] : std::numeric_limits<double>::infinity();
}

}  // namespace

ShapeMatch shape_match(std::span<const Vec3> rest, std::span<const Vec3> deformed, std::span<const double> weights,
                       double max_condition) {
  // Validate the input.
  if (rest.size() != deformed.size() || rest.size() != weights.size())
    throw std::invalid_argument("shape matching: " + std::to_string(rest.size()) + " rest points, " +
                                std::to_string(deformed.size()) + " deformed points and " +
                                std::to_string(weights.size()) + " weights");
  if (!(max_condition >= 1.0))
    throw std::invalid_argument("shape matching: max_condition must be at least 1");
  double wsum = 0.0;
  int positive = 0;
  for (std::size_t i = 0; i < rest.size(); ++i) {
    if (!rest[i].allFinite() || !deformed[i].allFinite() || !std::isfinite(weights[i]))
      throw std::invalid_argument("shape matching: point pair " + std::to_string(i) + " is not finite");
    if (weights[i] < 0.0)
      throw std::invalid_argument("shape matching: weight " + std::to_string(i) + " is negative");
    wsum += weights[i];
    if (weights[i] > 0.0) ++positive;
  }
  if (!(wsum > 0.0)) throw std::invalid_argument("shape matching: the weights sum to zero");
  if (positive < 4) throw std::invalid_argument("shape matching: fewer than 4 points with positive weight");

  // Weighted centroids.
  ShapeMatch m;
  m.c_rest = Vec3::Zero();
  m.c_deformed = Vec3::Zero();
  for (std::size_t i = 0; i < rest.size(); ++i) {
    m.c_rest += weights[i] * rest[i];
    m.c_deformed += weights[i] * deformed[i];
  }
  m.c_rest /= wsum;
  m.c_deformed /= wsum;

  // Moment matrices A_pq and A_qq about the centroids.
  Mat3 Apq = Mat3::Zero(), Aqq = Mat3::Zero();
  for (std::size_t i = 0; i < rest.size(); ++i) {
    const Vec3 q = rest[i] - m.c_rest, p = deformed[i] - m.c_deformed;
    Apq += weights[i] * p * q.transpose();
    Aqq += weights[i] * q * q.transpose();
  }
  const Vec3 lambda = Eigen::SelfAdjointEigenSolver<Mat3>(Aqq, Eigen::EigenvaluesOnly).eigenvalues();  // ascending
  if (!(lambda[0] > 1e-12 * lambda[2]))
    throw std::invalid_argument("shape matching: the rest points do not span 3D (coplanar, collinear or coincident)");
  const Mat3 A = Apq * Aqq.inverse();
  if (!A.allFinite()) throw std::invalid_argument("shape matching: the fit is not finite");
  m.condition = condition_number(A);

  // Collapsed onto a point (up to rounding, or beyond any physical compression): nothing to keep but R.
  const Mat3 R = sim::polar_rotation(A);
  if (Eigen::JacobiSVD<Mat3>(A).singularValues()[0] <= kCollapsedStretch) {
    m.A = R;
    m.blend = 1.0;
    return m;
  }

  // A well-conditioned, orientation-preserving fit is used as it is.
  const double det = A.determinant();
  if (m.condition <= max_condition && det > 0.0) {
    m.A = A;
    m.blend = 0.0;
    return m;
  }
  auto blended = [&](double beta) { return beta >= 1.0 ? R : Mat3((1.0 - beta) * A + beta * R); };

  // Signed stretches s_i: the eigenvalues of the symmetric S = R^T A (at most one negative, for an inverted A).
  // The blend (1 − β) A + β R = R ((1 − β) S + β I) has singular values |(1 − β) s_i + β|. Each condition
  // (1 − β) s_i + β <= κ ((1 − β) s_j + β) reads a + β b <= 0 and holds at β = 1; it bounds β from below.
  const Mat3 S = R.transpose() * A;
  const Vec3 s = Eigen::SelfAdjointEigenSolver<Mat3>(0.5 * (S + S.transpose()), Eigen::EigenvaluesOnly).eigenvalues();
  const double kappa = max_condition * (1.0 - 1e-10);  // a margin against rounding in the blended matrix
  double beta = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      if (i == j) continue;
      const double a = s[i] - kappa * s[j], b = (1.0 - s[i]) - kappa * (1.0 - s[j]);
      if (a > 0.0 && b < 0.0) beta = std::max(beta, a / -b);
    }
  beta = std::min(beta, 1.0);

  // Guard against rounding: raise β by growing steps until the blended matrix meets both conditions.
  Mat3 B = blended(beta);
  for (double step = 1e-14; beta < 1.0 && !(condition_number(B) <= max_condition && B.determinant() > 0.0);
       step *= 4.0) {
    beta = std::min(1.0, beta + step);
    B = blended(beta);
  }
  m.A = B;
  m.blend = beta;
  return m;
}

Vec3 to_rest(const ShapeMatch& m, const Vec3& x) { return m.A.lu().solve(x - m.c_deformed) + m.c_rest; }

sim::TriMesh to_rest(const ShapeMatch& m, const sim::TriMesh& deformed_blade) {
  sim::TriMesh out = deformed_blade;
  const Mat3 Ainv = m.A.inverse();
  for (Vec3& v : out.vertices) v = Ainv * (v - m.c_deformed) + m.c_rest;
  return out;
}

}  // namespace octocut::cutting
