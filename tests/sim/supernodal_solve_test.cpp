// The triangular solves on two threads (sim/src/supernodal_solve.hpp): the tree partition puts independent subtrees
// in different parts and their separator in the top, and the solves agree with a dense solve and give bit-identical
// results with one thread and two. Through the solver: PCG with the lagged factor gives the same iterates on one
// thread and two.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <limits>

#include "octocut/sim/linear_solver.hpp"
#include "octocut/sim/parallel.hpp"
#include "supernodal_solve.hpp"

namespace octocut::sim {
namespace {

// A nested-dissection-shaped SPD matrix: two chains of `k` unknowns each (tridiagonal), not coupled to each other,
// both coupled to every one of `s` separator unknowns, which come last. Its Cholesky factor has one supernode per
// column here: each chain's column j has rows j, j + 1 (within the chain) and the separator's; the separator is dense.
struct Arrow {
  Eigen::MatrixXd A;                    // the matrix (n x n)
  std::vector<int> super, pi, px, rows;  // the single-column supernodal structure of its factor
  std::vector<float> values;            // the factor's entries, column by column
  int n = 0;
};

Arrow arrow(int k, int s) {
  Arrow a;
  a.n = 2 * k + s;
  a.A = Eigen::MatrixXd::Zero(a.n, a.n);
  for (int c = 0; c < 2; ++c)
    for (int j = 0; j < k; ++j) {
      const int i = c * k + j;
      a.A(i, i) = 4.0 + 0.1 * j;
      if (j + 1 < k) a.A(i, i + 1) = a.A(i + 1, i) = -1.0;
      for (int q = 0; q < s; ++q) a.A(i, 2 * k + q) = a.A(2 * k + q, i) = -0.1 / (1.0 + q);
    }
  for (int q = 0; q < s; ++q) a.A(2 * k + q, 2 * k + q) = 10.0 + q;
  const Eigen::MatrixXd L = a.A.llt().matrixL();
  for (int j = 0; j < a.n; ++j) {
    a.super.push_back(j);
    a.pi.push_back(int(a.rows.size()));
    a.px.push_back(int(a.values.size()));
    const bool chain = j < 2 * k;
    for (int i = j; i < a.n; ++i) {
      const bool structural = i == j || (chain && i == j + 1 && (j % k) + 1 < k) || i >= 2 * k;
      if (!structural) {
        EXPECT_LT(std::abs(L(i, j)), 1e-12) << "entry (" << i << ", " << j << ") outside the pattern";
        continue;
      }
      a.rows.push_back(i);
      a.values.push_back(float(L(i, j)));
    }
  }
  a.super.push_back(a.n);
  a.pi.push_back(int(a.rows.size()));
  a.px.push_back(int(a.values.size()));
  return a;
}

// The same matrix with its separator as one supernode: a dense s x s column-major block (leading dimension s) whose
// upper triangle, which no solve may read, holds NaN.
Arrow arrow_with_dense_separator(int k, int s) {
  Arrow a = arrow(k, s);
  const Eigen::MatrixXd L = a.A.llt().matrixL();
  const int first = 2 * k;
  a.super.resize(std::size_t(first) + 1);  // the chains' columns, then the separator's start
  a.pi.resize(std::size_t(first) + 1);
  a.px.resize(std::size_t(first) + 1);
  a.rows.resize(std::size_t(a.pi.back()));
  a.values.resize(std::size_t(a.px.back()));
  for (int i = 0; i < s; ++i) a.rows.push_back(first + i);
  for (int j = 0; j < s; ++j)
    for (int i = 0; i < s; ++i)
      a.values.push_back(i >= j ? float(L(first + i, first + j)) : std::numeric_limits<float>::quiet_NaN());
  a.super.push_back(a.n);
  a.pi.push_back(int(a.rows.size()));
  a.px.push_back(int(a.values.size()));
  return a;
}

SupernodalStructure structure(const Arrow& a) {
  SupernodalStructure L;
  L.n = a.n;
  L.nsuper = int(a.super.size()) - 1;
  L.super = a.super.data();
  L.pi = a.pi.data();
  L.px = a.px.data();
  L.rows = a.rows.data();
  return L;
}

TEST(SupernodalSolve, PartsAreTheIndependentSubtreesAndTheTopTheirSeparator) {
  const int k = 40, s = 6;
  const Arrow a = arrow(k, s);
  SupernodalSolvePlan plan;
  plan.build(structure(a));
  // Each chain: k columns of 2 + s rows, the last of 1 + s; the separator: s (s + 1) / 2 entries.
  const double chain = double(k - 1) * (2 + s) + (1 + s), separator = double(s * (s + 1) / 2);
  const auto w = plan.work();
  EXPECT_EQ(w[0], chain);
  EXPECT_EQ(w[1], chain);
  EXPECT_EQ(w[2], separator);
}

// Small supernodes (the chains' single columns) and, in the second matrix, one large enough (120 x 120 = 14,400
// entries) for the BLAS kernels: each solve against a dense solve of the matrix, and bit for bit on one thread and two.
class SupernodalSolves : public ::testing::TestWithParam<bool> {};

TEST_P(SupernodalSolves, MatchADenseSolveOnOneThreadAndTwo) {
  const Arrow a = GetParam() ? arrow_with_dense_separator(300, 120) : arrow(300, 12);
  const SupernodalStructure L = structure(a);
  SupernodalSolvePlan plan;
  plan.build(L);
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(a.n, -1.0, 2.0);
  const Eigen::VectorXd exact = a.A.llt().solve(b);
  Executor one(1), two(2);
  std::vector<std::vector<float>> results;
  for (Executor* ex : {static_cast<Executor*>(nullptr), &one, &two}) {
    std::vector<float> y(b.data(), b.data() + b.size());
    plan.forward(L, a.values.data(), y.data(), ex);
    plan.backward(L, a.values.data(), y.data(), ex);
    double err = 0.0;
    for (int i = 0; i < a.n; ++i) err = std::max(err, std::abs(double(y[std::size_t(i)]) - exact[i]));
    EXPECT_LT(err, 1e-5 * exact.cwiseAbs().maxCoeff());  // single precision
    results.push_back(y);
  }
  for (std::size_t r = 1; r < results.size(); ++r)
    for (int i = 0; i < a.n; ++i)
      ASSERT_TRUE(results[r][std::size_t(i)] == results[0][std::size_t(i)]) << "run " << r << ", row " << i;
}

INSTANTIATE_TEST_SUITE_P(SupernodalSolve, SupernodalSolves, ::testing::Bool(),
                         [](const ::testing::TestParamInfo<bool>& info) {
                           return info.param ? "WithADenseSeparator" : "SingleColumns";
                         });

// Through PCG with the lagged single-precision factor on a 3D Laplacian of 8,000 unknowns (its factor's tree splits):
// the same iterates with no executor, one thread and two, each meeting the tolerance by the residual recomputed here.
TEST(SupernodalSolve, PcgWithTheLaggedFactorGivesTheSameIteratesOnOneThreadAndTwo) {
  const int n = 20;
  std::vector<Eigen::Triplet<double>> t;
  const auto id = [n](int i, int j, int k) { return (k * n + j) * n + i; };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int r = id(i, j, k);
        t.emplace_back(r, r, 6.01 + 0.5 * double(i) / n);
        if (i > 0) t.emplace_back(r, id(i - 1, j, k), -1.0), t.emplace_back(id(i - 1, j, k), r, -1.0);
        if (j > 0) t.emplace_back(r, id(i, j - 1, k), -1.0), t.emplace_back(id(i, j - 1, k), r, -1.0);
        if (k > 0) t.emplace_back(r, id(i, j, k - 1), -1.0), t.emplace_back(id(i, j, k - 1), r, -1.0);
      }
  SpMat A0(n * n * n, n * n * n);
  A0.setFromTriplets(t.begin(), t.end());
  SpMat A1 = A0;  // the matrix of the solve: the factor's, drifted
  for (Eigen::Index i = 0; i < A1.rows(); ++i) A1.coeffRef(i, i) *= 1.0 + 0.3 * double(i % 7) / 7.0;
  const VecX b = VecX::LinSpaced(A0.rows(), -1.0, 2.0);
  LinearSolverOptions o;
  o.tolerance = 1e-9;
  o.factor_flop_advantage = 1e-12;  // never refresh: every solve of A1 uses A0's factor
  Executor one(1), two(2);
  std::vector<VecX> xs;
  for (Executor* ex : {static_cast<Executor*>(nullptr), &one, &two}) {
    auto s = make_linear_solver("pcg", o);
    s->set_executor(ex);
    s->analyze_pattern(A0);
    ASSERT_TRUE(s->factorize(A0));
    VecX x = VecX::Zero(A0.rows());
    ASSERT_TRUE(s->solve(b, x).ok);
    ASSERT_TRUE(s->factorize(A1));
    x.setZero();
    const SolveInfo info = s->solve(b, x);
    ASSERT_TRUE(info.ok);
    EXPECT_GT(info.iterations, 3);
    EXPECT_LE((b - A1 * x).norm() / b.norm(), 1e-9);
    xs.push_back(x);
  }
  for (std::size_t r = 1; r < xs.size(); ++r)
    for (Eigen::Index i = 0; i < xs[0].size(); ++i) ASSERT_TRUE(xs[r][i] == xs[0][i]) << "run " << r << ", row " << i;
}

}  // namespace
}  // namespace octocut::sim
