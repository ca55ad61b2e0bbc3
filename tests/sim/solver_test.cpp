// Linear solvers: both agree with a dense reference; pcg reuses its lagged factor; non-SPD input is reported.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "octocut/sim/linear_solver.hpp"

namespace octocut::sim {
namespace {

// A 3D Laplacian-like SPD matrix (7-point stencil on an n^3 grid) plus a diagonal shift.
SpMat laplacian(int n, double shift) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [n](int i, int j, int k) { return (k * n + j) * n + i; };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int r = id(i, j, k);
        t.emplace_back(r, r, 6.0 + shift);
        if (i > 0) t.emplace_back(r, id(i - 1, j, k), -1.0);
        if (i + 1 < n) t.emplace_back(r, id(i + 1, j, k), -1.0);
        if (j > 0) t.emplace_back(r, id(i, j - 1, k), -1.0);
        if (j + 1 < n) t.emplace_back(r, id(i, j + 1, k), -1.0);
        if (k > 0) t.emplace_back(r, id(i, j, k - 1), -1.0);
        if (k + 1 < n) t.emplace_back(r, id(i, j, k + 1), -1.0);
      }
  SpMat A(n * n * n, n * n * n);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

TEST(LinearSolver, AllSolversMatchDenseReference) {
  const SpMat A = laplacian(8, 0.1);
  const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
  const VecX ref = Eigen::MatrixXd(A).llt().solve(b);
  for (const char* name : {"cholmod", "pcg"}) {
    for (const char* pre : {"cholesky", "jacobi"}) {
      LinearSolverOptions o;
      o.tolerance = 1e-12;
      o.max_iterations = 2000;
      o.preconditioner = pre;
      auto s = make_linear_solver(name, o);
      s->analyze_pattern(A);
      ASSERT_TRUE(s->factorize(A));
      VecX x = VecX::Zero(A.rows());
      const SolveInfo info = s->solve(b, x);
      EXPECT_TRUE(info.ok) << name << "/" << pre;
      EXPECT_LT((x - ref).norm(), 1e-9 * ref.norm()) << name << "/" << pre;
    }
  }
}

TEST(LinearSolver, PcgWithLaggedFactorConvergesFastOnANearbyMatrix) {
  const SpMat A0 = laplacian(8, 0.1);
  SpMat A1 = A0;
  A1.diagonal().array() += 0.05;  // same pattern, slightly different values
  LinearSolverOptions o;
  o.tolerance = 1e-10;
  auto s = make_linear_solver("pcg", o);
  s->analyze_pattern(A0);
  ASSERT_TRUE(s->factorize(A0));
  VecX x = VecX::Zero(A0.rows());
  const VecX b = VecX::Ones(A0.rows());
  EXPECT_LE(s->solve(b, x).iterations, 1);
  // The factor of A0 preconditions A1: a few iterations, no refactorisation.
  ASSERT_TRUE(s->factorize(A1));
  x.setZero();
  const SolveInfo info = s->solve(b, x);
  EXPECT_TRUE(info.ok);
  EXPECT_FALSE(info.refactorized);
  EXPECT_LE(info.iterations, 8);
  EXPECT_LT((A1 * x - b).norm(), 1e-9 * b.norm());
}

TEST(LinearSolver, IndefiniteMatrixIsReportedNotCrashing) {
  SpMat A = laplacian(4, 0.0);
  A.coeffRef(0, 0) = -5.0;
  for (const char* name : {"cholmod", "pcg"}) {
    auto s = make_linear_solver(name, {});
    s->analyze_pattern(A);
    const bool factored = s->factorize(A);
    VecX x = VecX::Zero(A.rows());
    const SolveInfo info = factored ? s->solve(VecX::Ones(A.rows()), x) : SolveInfo{};
    EXPECT_FALSE(factored && info.ok) << name;
  }
  EXPECT_THROW(make_linear_solver("nope", {}), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::sim
