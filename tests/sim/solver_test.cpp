// Linear solvers: both agree with a dense reference, on scalar patterns and on the 3 x 3 blocked FEM system (block
// ordering); pcg reuses its lagged factor; non-SPD input is reported.
#include <gtest/gtest.h>

#include <dlfcn.h>

#include <cmath>
#include <cstdlib>
#include <thread>

#include <Eigen/Dense>

#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/linear_solver.hpp"
#include "octocut/sim/parallel.hpp"
#include "test_util.hpp"

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

// The implicit Euler system matrices M + k K of model m at rest with its z = 0 face clamped, one per stiffness
// coefficient k.
std::vector<SpMat> implicit_systems(const ObjectModel& m, const std::vector<double>& k) {
  const int nd = m.num_dofs();
  std::vector<char> constrained(static_cast<std::size_t>(nd), 0);
  for (int d = 0; d < nd; ++d) constrained[std::size_t(d)] = m.dofs().dof_rest[std::size_t(d)].z() <= 1e-12;
  Executor ex(1);
  FemSystem fem(m, ex);
  ElementFrame frame;
  fem.rotations(m.dofs().dof_rest, frame);
  std::vector<SpMat> out;
  for (const double kc : k) {
    SpMat A;
    VecX coupling;
    fem.assemble_system(1.0, kc, frame, constrained, VecX::Zero(3 * nd), A, coupling);
    out.push_back(A);
  }
  return out;
}

// The implicit Euler system of a small mixed-level FEM model (hanging slots bound to their carriers, a clamped
// face): 3 x 3 blocks, so the ordering is computed on the block graph and handed to CHOLMOD as a given ordering.
TEST(LinearSolver, BlockOrderingOnFemSystemMatchesDenseReference) {
  const ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 2,
                                        {{Box3{Vec3(0.3, 0.3, 0.3), Vec3(0.6, 0.6, 0.6)}, 4}});
  ASSERT_GT(m.dofs().hanging_slots, 0);
  const SpMat A = implicit_systems(m, {1e-4})[0];
  const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
  const Eigen::MatrixXd dense(A);
  const VecX ref = dense.llt().solve(b);
  const double ref_residual = (b - A * ref).norm() / b.norm();
  for (const char* name : {"cholmod", "pcg"}) {
    LinearSolverOptions o;
    o.tolerance = 1e-12;
    o.single_precision_factor = false;  // here the preconditioner is the exact factor (see PcgSinglePrecision...)
    auto s = make_linear_solver(name, o);
    s->analyze_pattern(A);
    EXPECT_EQ(s->ordering_block_size(), 3) << name;
    ASSERT_TRUE(s->factorize(A)) << name;
    VecX x = VecX::Zero(A.rows());
    const SolveInfo info = s->solve(b, x);
    EXPECT_TRUE(info.ok) << name;
    EXPECT_LT((x - ref).norm(), 1e-10 * ref.norm()) << name;
    // As accurate as the dense Cholesky solve, up to a small factor of round-off.
    EXPECT_LT((b - A * x).norm() / b.norm(), std::max(10.0 * ref_residual, 1e-14)) << name;
  }
  // A scalar pattern (not 3 x 3 blocked) is ordered on its own graph.
  auto s = make_linear_solver("cholmod", {});
  const SpMat L = laplacian(5, 0.1);
  s->analyze_pattern(L);
  EXPECT_EQ(s->ordering_block_size(), 1);
}

// Analysing a second pattern replaces the first: the factor follows the new matrix.
TEST(LinearSolver, ReanalysisFollowsTheNewPattern) {
  auto s = make_linear_solver("cholmod", {});
  for (int n : {4, 6, 5}) {
    const SpMat A = laplacian(n, 0.2);
    const VecX b = VecX::LinSpaced(A.rows(), 1.0, 3.0);
    s->analyze_pattern(A);
    ASSERT_TRUE(s->factorize(A));
    VecX x;
    const SolveInfo info = s->solve(b, x);
    EXPECT_TRUE(info.ok);
    EXPECT_LT((A * x - b).norm(), 1e-12 * b.norm());
  }
}

TEST(LinearSolver, PcgWithLaggedFactorConvergesFastOnANearbyMatrix) {
  const SpMat A0 = laplacian(8, 0.1);
  SpMat A1 = A0;
  A1.diagonal().array() += 0.05;  // same pattern, slightly different values
  LinearSolverOptions o;
  o.tolerance = 1e-10;
  o.factor_flop_advantage = 1e-6;  // a factorisation priced far above any solve: the lagged factor is kept
  o.single_precision_factor = false;  // the exact factor solves its own matrix in one iteration
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

// set_reference_norm: the residual is measured against max(|b|, reference). Checked against the residual of the
// returned x computed here: with a reference 100x |b| the solve stops as soon as |b - A x| <= tol * reference, in
// fewer iterations; with a reference below |b| (or 0, or NaN) the iterates are those of a solve without one.
TEST(LinearSolver, PcgMeasuresTheResidualAgainstTheReferenceWhereItIsLarger) {
  const SpMat A = laplacian(8, 0.1);
  const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
  LinearSolverOptions o;
  o.tolerance = 1e-6;
  o.preconditioner = "jacobi";  // many iterations, each reducing the residual a little
  const auto solve = [&](double reference, VecX& x) {
    auto s = make_linear_solver("pcg", o);
    s->analyze_pattern(A);
    EXPECT_TRUE(s->factorize(A));
    s->set_reference_norm(reference);
    x = VecX::Zero(A.rows());
    return s->solve(b, x);
  };
  VecX x0, x_ref, x_small, x_nan;
  const SolveInfo plain = solve(0.0, x0);
  const double reference = 100.0 * b.norm();
  const SolveInfo loose = solve(reference, x_ref);
  ASSERT_TRUE(plain.ok && loose.ok);
  EXPECT_LE((b - A * x0).norm(), o.tolerance * b.norm());
  EXPECT_LE((b - A * x_ref).norm(), o.tolerance * reference);
  EXPECT_GT((b - A * x_ref).norm(), o.tolerance * b.norm());  // it did stop earlier than the plain criterion
  EXPECT_NEAR(loose.residual, (b - A * x_ref).norm() / reference, 1e-3 * loose.residual);
  EXPECT_LT(loose.iterations, plain.iterations);
  EXPECT_EQ(solve(0.5 * b.norm(), x_small).iterations, plain.iterations);
  EXPECT_EQ(x_small, x0);
  EXPECT_EQ(solve(std::nan(""), x_nan).iterations, plain.iterations);
  EXPECT_EQ(x_nan, x0);
}

// The rent-or-buy rule: a matrix that stays where it is after one step of change (the baseline) never buys a new
// factor, however many solves follow.
TEST(LinearSolver, PcgKeepsTheLaggedFactorWhileIterationsStayAtTheBaseline) {
  const SpMat A0 = laplacian(8, 0.1);
  SpMat A1 = A0;
  A1.diagonal().array() += 0.5;
  LinearSolverOptions o;
  o.tolerance = 1e-8;
  auto s = make_linear_solver("pcg", o);
  s->analyze_pattern(A0);
  ASSERT_TRUE(s->factorize(A0));
  VecX x = VecX::Zero(A0.rows());
  ASSERT_TRUE(s->solve(VecX::Ones(A0.rows()), x).ok);
  ASSERT_TRUE(s->factorize(A1));
  int refactorizations = 0;
  for (int k = 0; k < 40; ++k) {
    const VecX b = VecX::LinSpaced(A1.rows(), -1.0, 1.0);
    x.setZero();
    const SolveInfo info = s->solve(b, x);
    ASSERT_TRUE(info.ok);
    EXPECT_LT((A1 * x - b).norm(), 1e-7 * b.norm());
    refactorizations += info.refactorized ? 1 : 0;
  }
  EXPECT_EQ(refactorizations, 0);
}

// What a pcg solver did over 60 solves of a matrix that drifts further every solve (a growing, non-uniform change:
// the diagonal of the first half of the unknowns rises), every solve checked for accuracy.
struct DriftRun {
  std::vector<VecX> x;  // the solutions
  int iterations = 0, refactorizations = 0, background = 0, inline_refreshes = 0;
};
DriftRun drift_run(const SpMat& A0, LinearSolverOptions o) {
  o.tolerance = 1e-8;
  o.max_iterations = 1000;
  auto s = make_linear_solver("pcg", o);
  s->analyze_pattern(A0);
  DriftRun r;
  for (int k = 0; k < 60; ++k) {
    SpMat A = A0;
    for (int i = 0; i < A.rows() / 2; ++i) A.coeffRef(i, i) += 0.2 * k * (1.0 + (i % 7));
    EXPECT_TRUE(s->factorize(A));
    const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
    VecX x = VecX::Zero(A.rows());
    const SolveInfo info = s->solve(b, x);
    EXPECT_TRUE(info.ok);
    EXPECT_LT((A * x - b).norm(), 1e-7 * b.norm());
    r.iterations += info.iterations;
    r.refactorizations += info.refactorized ? 1 : 0;
    r.background += info.background ? 1 : 0;
    r.inline_refreshes += info.refactorized && !info.background ? 1 : 0;
    r.x.push_back(x);
  }
  return r;
}

// The rule buys new factors for a drifting matrix, and the iterations plus factorisations cost less than keeping
// the first factor for ever (a factorisation priced at infinity), with every solve accurate.
TEST(LinearSolver, PcgRefreshesTheFactorOfADriftingMatrixAndSavesWork) {
  const SpMat A0 = laplacian(10, 0.05);
  LinearSolverOptions o;
  o.factor_flop_advantage = 1.5;
  const DriftRun rule = drift_run(A0, o);
  o.factor_flop_advantage = 1e-12;
  const DriftRun never = drift_run(A0, o);
  EXPECT_LE(never.refactorizations, 1);  // the first factorisation only (inside factorize)
  EXPECT_GT(rule.refactorizations, 0);
  EXPECT_LT(rule.iterations, never.iterations / 2);
}

// The implicit Euler matrices of a small FEM model whose stiffness term grows solve by solve (a stiffening, moving
// object): the same pattern, drifting values.
std::vector<SpMat> drifting_fem_systems(int count) {
  const ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 3,
                                        {{Box3{Vec3(0.2, 0.2, 0.2), Vec3(0.7, 0.7, 0.7)}, 4}});
  std::vector<double> k;
  for (int i = 0; i < count; ++i) k.push_back(1e-3 * (1.0 + 0.15 * i));
  return implicit_systems(m, k);
}

// PCG preconditioned with the factor rounded to single precision converges to the same tolerance in at most one
// iteration more per solve than with the double factor, on the FEM system with a lagged factor; both reach the
// tolerance (the residual recomputed here).
TEST(LinearSolver, PcgSinglePrecisionFactorConvergesLikeTheDoubleOne) {
  const std::vector<SpMat> systems = drifting_fem_systems(12);
  for (const double tol : {1e-4, 1e-8}) {
    std::vector<int> iterations[2];
    for (const bool single : {false, true}) {
      LinearSolverOptions o;
      o.tolerance = tol;
      o.single_precision_factor = single;
      auto s = make_linear_solver("pcg", o);
      s->analyze_pattern(systems[0]);
      for (const SpMat& A : systems) {
        ASSERT_TRUE(s->factorize(A));
        const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
        VecX x = VecX::Zero(A.rows());
        const SolveInfo info = s->solve(b, x);
        ASSERT_TRUE(info.ok);
        EXPECT_LE((b - A * x).norm() / b.norm(), tol);
        iterations[single ? 1 : 0].push_back(info.iterations);
      }
    }
    int more = 0;
    for (std::size_t k = 0; k < systems.size(); ++k) {
      EXPECT_LE(iterations[1][k], iterations[0][k] + 1) << "solve " << k << ", tolerance " << tol;
      more += iterations[1][k] - iterations[0][k];
    }
    EXPECT_LE(more, int(systems.size()) / 2) << "tolerance " << tol;
  }
}

// A factor above half_precision_entries is copied in half precision when that copy solves its own matrix to within
// half_precision_probe: on a Laplacian (probe 1.4e-4) PCG then needs more iterations than with the single-precision
// copy on the factor's own matrix at a tight tolerance (the copy is visibly the half one), and still converges (the
// residual recomputed here). A stiff, nearly incompressible FEM system (E = 1e9 Pa, nu = 0.499, B-bar; probe 0.094)
// fails the probe and keeps single precision: as many iterations as with the copy forced to single precision, where
// the half copy let through costs twice as many.
TEST(LinearSolver, PcgKeepsTheFactorInHalfPrecisionOnlyWhereItPreconditions) {
  MaterialParams stiff;
  stiff.young_modulus = 1e9;
  stiff.poisson_ratio = 0.499;
  const ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 3, {}, {}, stiff);
  const SpMat soft = laplacian(12, 0.05), hard = implicit_systems(m, {1e-2})[0];
  // The iterations of a solve of A with its own fresh factor, and its residual recomputed.
  const auto iterations = [](const SpMat& A, std::size_t half_above, double probe) {
    LinearSolverOptions o;
    o.tolerance = 1e-10;
    o.half_precision_entries = half_above;
    o.half_precision_probe = probe;
    auto s = make_linear_solver("pcg", o);
    s->analyze_pattern(A);
    EXPECT_TRUE(s->factorize(A));
    const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
    VecX x = VecX::Zero(A.rows());
    const SolveInfo info = s->solve(b, x);
    EXPECT_TRUE(info.ok);
    EXPECT_LE((b - A * x).norm() / b.norm(), 1e-10);
    return info.iterations;
  };
  const std::size_t never = std::numeric_limits<std::size_t>::max();
  const double probe = LinearSolverOptions{}.half_precision_probe;
  const int soft_single = iterations(soft, never, probe), soft_half = iterations(soft, 0, probe);
  const int hard_single = iterations(hard, never, probe), hard_probed = iterations(hard, 0, probe);
  const int hard_half = iterations(hard, 0, 1e30);
  EXPECT_LE(soft_single, 2);
  EXPECT_GT(soft_half, soft_single);
  EXPECT_EQ(hard_probed, hard_single);
  EXPECT_GE(hard_half, 2 * hard_single);
}

// The background refresh (factor_lag_solves > 0): the factor is computed on a second thread and put in place a
// fixed number of solves later. Every solve stays accurate (drift_run), the refreshes come from the background (no
// solve factorises inline after the first), the work stays far below never refreshing, and two runs give
// bit-identical iterates whatever the threads' timing.
TEST(LinearSolver, PcgBackgroundRefreshIsAccurateAndDeterministic) {
  const SpMat A0 = laplacian(10, 0.05);
  LinearSolverOptions o;
  o.factor_flop_advantage = 1.5;
  o.factor_lag_solves = 3;
  const DriftRun a = drift_run(A0, o), b = drift_run(A0, o);
  o.factor_flop_advantage = 1e-12;
  const DriftRun never = drift_run(A0, o);
  EXPECT_GT(a.background, 2);
  EXPECT_EQ(a.inline_refreshes, 0);  // the first factor comes from factorize(), not from a solve
  EXPECT_LT(a.iterations, never.iterations / 2);
  EXPECT_EQ(never.background, 0);
  ASSERT_EQ(a.x.size(), b.x.size());
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.background, b.background);
  for (std::size_t k = 0; k < a.x.size(); ++k) EXPECT_TRUE(a.x[k] == b.x[k]) << "solve " << k;
}

// An operator that counts how its entries are asked for: matrix() (the step's own storage) or assemble_into (a
// background refresh's copy, which takes them without filling or copying the step's storage).
class CountingOperator final : public SystemOperator {
 public:
  explicit CountingOperator(const SpMat& A) : m_A(A) {}
  [[nodiscard]] Eigen::Index rows() const override { return m_A.rows(); }
  [[nodiscard]] Eigen::Index nonzeros() const override { return m_A.nonZeros(); }
  void product(const VecX& x, VecX& y) override { y = m_A * x; }
  const SpMat& matrix() override {
    ++matrix_calls;
    return m_A;
  }
  void assemble_into(SpMat& out) override {
    ++assemble_calls;
    out = m_A;
  }
  int matrix_calls = 0, assemble_calls = 0;

 private:
  const SpMat& m_A;
};

// The background refreshes take their matrix through assemble_into, one per refresh, and never through matrix():
// only the first solve's inline factorisation reads it. Every solve meets the tolerance by the residual recomputed
// here, and the refreshes' factors are those of their matrices (the iterations stay far below never refreshing).
TEST(LinearSolver, PcgBackgroundRefreshAssemblesIntoItsOwnMatrix) {
  const SpMat A0 = laplacian(10, 0.05);
  LinearSolverOptions o;
  o.tolerance = 1e-8;
  o.max_iterations = 1000;
  o.factor_flop_advantage = 1.5;
  o.factor_lag_solves = 3;
  auto s = make_linear_solver("pcg", o);
  s->analyze_pattern(A0);
  int matrix_calls = 0, assemble_calls = 0, background = 0, iterations = 0;
  for (int k = 0; k < 60; ++k) {
    SpMat A = A0;
    for (int i = 0; i < A.rows() / 2; ++i) A.coeffRef(i, i) += 0.2 * k * (1.0 + (i % 7));
    CountingOperator op(A);
    ASSERT_TRUE(s->factorize_operator(op));
    const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
    VecX x = VecX::Zero(A.rows());
    const SolveInfo info = s->solve(b, x);
    EXPECT_TRUE(info.ok);
    EXPECT_LT((A * x - b).norm(), 1e-7 * b.norm()) << "solve " << k;
    if (k > 0) matrix_calls += op.matrix_calls;
    assemble_calls += op.assemble_calls;
    background += info.background ? 1 : 0;
    iterations += info.iterations;
  }
  EXPECT_EQ(matrix_calls, 0);  // after the first solve's inline factor
  EXPECT_GT(background, 2);
  EXPECT_GE(assemble_calls, background);  // each adopted refresh was assembled (a last one may still be running)
  EXPECT_LE(assemble_calls, background + 1);
  const DriftRun never = [&] {
    LinearSolverOptions n = o;
    n.factor_flop_advantage = 1e-12;
    return drift_run(A0, n);
  }();
  EXPECT_LT(iterations, never.iterations / 2);
}

// PCG's products with A run on the executor's threads (set_executor) in row ranges: the iterates are bit-identical
// with no executor, one thread and two, and the solution meets the tolerance by the residual Eigen recomputes. A
// system of 8,000 unknowns, so that the products are split, and the Jacobi preconditioner, so that there are many.
TEST(LinearSolver, PcgProductsOnExecutorThreadsGiveTheSameIterates) {
  const SpMat A = laplacian(20, 0.01);
  const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
  LinearSolverOptions o;
  o.tolerance = 1e-10;
  o.max_iterations = 1000;
  o.preconditioner = "jacobi";
  Executor one(1), two(2);
  std::vector<VecX> xs;
  std::vector<int> its;
  for (Executor* ex : {static_cast<Executor*>(nullptr), &one, &two}) {
    auto s = make_linear_solver("pcg", o);
    s->set_executor(ex);
    s->analyze_pattern(A);
    ASSERT_TRUE(s->factorize(A));
    VecX x = VecX::Zero(A.rows());
    const SolveInfo info = s->solve(b, x);
    ASSERT_TRUE(info.ok);
    EXPECT_GT(info.iterations, 20);
    EXPECT_LE((b - A * x).norm() / b.norm(), 1e-10);
    xs.push_back(x);
    its.push_back(info.iterations);
  }
  for (std::size_t k = 1; k < xs.size(); ++k) {
    EXPECT_EQ(its[k], its[0]);
    for (Eigen::Index i = 0; i < xs[0].size(); ++i) ASSERT_TRUE(xs[k][i] == xs[0][i]) << "run " << k << ", row " << i;
  }
}

// Fast DOFs (set_fast_dofs): a contact-like patch of stiff penalty blocks (10^3 times the largest diagonal entry,
// along one normal) that moves to other DOFs at every solve. Told which DOFs are fast, pcg solves them exactly
// beside its lagged factor: every solve meets the tolerance by the residual recomputed here, and the solves need
// under half the iterations and factorisations of the same solver not told.
TEST(LinearSolver, PcgSolvesFastDofsExactlyBesideTheLaggedFactor) {
  const SpMat A0 = drifting_fem_systems(1)[0];
  const int nd = int(A0.rows() / 3);
  const double big = 1e3 * A0.diagonal().maxCoeff();
  const Vec3 n = Vec3(1, 2, 3).normalized();
  const Mat3 S = big * n * n.transpose();
  int work[2] = {0, 0};  // iterations + 30 per factorisation
  for (const bool told : {false, true}) {
    LinearSolverOptions o;
    o.tolerance = 1e-8;
    o.max_iterations = 1000;
    auto s = make_linear_solver("pcg", o);
    s->analyze_pattern(A0);
    for (int k = 0; k < 30; ++k) {
      SpMat A = A0;
      std::vector<int> patch;
      for (int i = 0; i < 12; ++i) patch.push_back((7 * k + 5 * i) % nd);
      std::sort(patch.begin(), patch.end());
      patch.erase(std::unique(patch.begin(), patch.end()), patch.end());
      for (const int d : patch)
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) A.coeffRef(3 * d + r, 3 * d + c) += S(r, c);
      s->set_fast_dofs(told ? patch : std::vector<int>{});
      ASSERT_TRUE(s->factorize(A));
      const VecX b = VecX::LinSpaced(A.rows(), -1.0, 2.0);
      VecX x = VecX::Zero(A.rows());
      const SolveInfo info = s->solve(b, x);
      ASSERT_TRUE(info.ok) << "solve " << k << (told ? ", told" : "");
      EXPECT_LE((A * x - b).norm(), 1.01e-8 * b.norm());
      work[told ? 1 : 0] += info.iterations + (info.refactorized ? 30 : 0);
    }
  }
  EXPECT_LT(2 * work[1], work[0]) << "told " << work[1] << ", not told " << work[0];
}

// The free mixed-level box of the warp tests (hanging nodes around a refined block), and its implicit system at the
// DOF positions x (num_dofs): both triangles, no DOF constrained.
struct FreeBox {
  ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 3,
                                  {{Box3{Vec3(0.2, 0.2, 0.2), Vec3(0.7, 0.7, 0.7)}, 4}});
  Executor ex{1};
  FemSystem fem{m, ex};
  [[nodiscard]] int nd() const { return m.num_dofs(); }
  [[nodiscard]] SpMat system(const std::vector<Vec3>& x) {
    ElementFrame frame;
    fem.rotations(x, frame);
    SpMat A;
    VecX coupling;
    fem.assemble_system(1.0, 1e-2, frame, std::vector<char>(std::size_t(nd()), 0), VecX::Zero(3 * nd()), A, coupling);
    return A;
  }
};

// The lagged factor warped by the DOFs' rotations (set_dof_rotations). The corotated system of a free body turned
// rigidly by Q is Q A Q^T (checked against the assembly here), whose inverse is Q A^-1 Q^T: the warped factor of the
// body at rest, with the DOFs' rotations FemSystem::dof_rotations gives (Q for every DOF, checked), then solves the
// turned system in one iteration, where the factor alone needs many. Under a twist (each DOF turned about z by an
// angle growing with its height, 0.5 rad from bottom to top, in one go) the element rotations vary from DOF to DOF
// and the warp is no longer exact, but it still saves more than half of the iterations. Turns below 0.01 rad leave
// the factor unwarped. The residual is recomputed each time.
TEST(LinearSolver, PcgWarpsTheLaggedFactorByTheDofsRotations) {
  FreeBox box;
  const ObjectModel& m = box.m;
  const int nd = box.nd();
  const auto dof_rotations = [&](const std::vector<Vec3>& x) {
    ElementFrame frame;
    box.fem.rotations(x, frame);
    return box.fem.dof_rotations(frame);
  };
  const std::vector<Vec3>& rest = m.dofs().dof_rest;
  const SpMat A0 = box.system(rest);
  const VecX b = VecX::LinSpaced(A0.rows(), -1.0, 2.0);
  // Factorises A0 (the DOFs' rotations identity, or none when `turn` is empty), then solves A1 with that lagged
  // factor, the DOFs' rotations `turn`; the residual recomputed.
  const auto solve_lagged = [&](const SpMat& A1, const std::vector<Mat3>& turn, VecX& x1) {
    LinearSolverOptions o;
    o.tolerance = 1e-10;
    o.max_iterations = 1000;
    o.factor_flop_advantage = 1e-6;     // the factor of A0 is kept
    o.single_precision_factor = false;  // exact arithmetic up to rounding: one iteration where the warp is exact
    auto s = make_linear_solver("pcg", o);
    s->analyze_pattern(A0);
    s->set_dof_rotations(turn.empty() ? std::vector<Mat3>{} : std::vector<Mat3>(std::size_t(nd), Mat3::Identity()));
    EXPECT_TRUE(s->factorize(A0));
    VecX x0 = VecX::Zero(A0.rows());
    EXPECT_TRUE(s->solve(b, x0).ok);
    s->set_dof_rotations(turn);
    EXPECT_TRUE(s->factorize(A1));
    x1 = VecX::Zero(A1.rows());
    const SolveInfo info = s->solve(b, x1);
    EXPECT_TRUE(info.ok);
    EXPECT_FALSE(info.refactorized);
    EXPECT_LE((b - A1 * x1).norm(), 1.01e-10 * b.norm());
    return info.iterations;
  };
  const Mat3 Q = Mat3(Eigen::AngleAxisd(0.6, Vec3(1, 2, 3).normalized()));
  for (const bool twist : {false, true}) {
    std::vector<Vec3> x(static_cast<std::size_t>(nd));
    for (int d = 0; d < nd; ++d) {
      const double a = 0.5 * rest[std::size_t(d)].z();
      x[std::size_t(d)] = (twist ? Mat3(Eigen::AngleAxisd(a, Vec3::UnitZ())) : Q) * rest[std::size_t(d)];
    }
    const SpMat A1 = box.system(x);
    // The DOFs' rotations as the simulator gives them: from the elements' corotational frames.
    const std::vector<Mat3> turn = dof_rotations(x);
    if (!twist) {
      for (const Mat3& r : turn) ASSERT_LE((r - Q).norm(), 1e-12);
      SpMat Qb(3 * nd, 3 * nd);
      std::vector<Eigen::Triplet<double>> t;
      for (int d = 0; d < nd; ++d)
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) t.emplace_back(3 * d + r, 3 * d + c, Q(r, c));
      Qb.setFromTriplets(t.begin(), t.end());
      const SpMat rotated = Qb * A0 * SpMat(Qb.transpose());
      ASSERT_LE((A1 - rotated).norm(), 1e-10 * A0.norm());
    }
    VecX x1;
    const int plain = solve_lagged(A1, {}, x1);
    const int warped = solve_lagged(A1, turn, x1);
    if (twist) {
      EXPECT_LT(2 * warped, plain) << "warped " << warped << ", not " << plain;
    } else {
      EXPECT_LE(warped, 1);
      EXPECT_GE(plain, 10);
    }
  }
  // Below a turn of 0.01 rad since the factor's matrix the warp is off: the solve is the unwarped one, bit for bit.
  const Mat3 small = Mat3(Eigen::AngleAxisd(0.005, Vec3(1, 2, 3).normalized()));
  std::vector<Vec3> xs(static_cast<std::size_t>(nd));
  for (int d = 0; d < nd; ++d) xs[std::size_t(d)] = small * rest[std::size_t(d)];
  const SpMat As = box.system(xs);
  VecX solution[2];
  solve_lagged(As, {}, solution[0]);
  solve_lagged(As, std::vector<Mat3>(std::size_t(nd), small), solution[1]);
  EXPECT_EQ(solution[0], solution[1]);
}

// After a cut the solves are bridged through the old revision's factor (inherit), and that factor is warped too: its
// matrix's rotations are carried into the new numbering by the transfer T. Here T is the identity (a "cut" that
// changed nothing) and the body has turned rigidly by 0.6 rad since the old factor's matrix: the bridged solve of the
// turned system Q A Q^T takes one iteration with the DOFs' rotations and at least ten without, both to the tolerance
// by the residual recomputed here.
TEST(LinearSolver, PcgWarpsTheCutBridgeByTheTransferredRotations) {
  FreeBox box;
  const int nd = box.nd();
  const std::vector<Vec3>& rest = box.m.dofs().dof_rest;
  const Mat3 Q = Mat3(Eigen::AngleAxisd(0.6, Vec3(1, 2, 3).normalized()));
  std::vector<Vec3> turned(rest.size());
  for (std::size_t d = 0; d < rest.size(); ++d) turned[d] = Q * rest[d];
  const SpMat A0 = box.system(rest), A1 = box.system(turned);
  SpMat T(nd, nd);
  T.setIdentity();
  const VecX b = VecX::LinSpaced(A0.rows(), -1.0, 2.0);
  for (const bool rotations : {true, false}) {
    LinearSolverOptions o;
    o.tolerance = 1e-10;
    o.max_iterations = 1000;
    o.factor_lag_solves = 4;
    o.factor_flop_advantage = 1e-6;     // no refresh on account of the iterations
    o.single_precision_factor = false;  // one iteration where the warp is exact
    auto old_solver = make_linear_solver("pcg", o);
    old_solver->analyze_pattern(A0);
    old_solver->set_dof_rotations(std::vector<Mat3>(std::size_t(nd), Mat3::Identity()));
    ASSERT_TRUE(old_solver->factorize(A0));
    VecX x0 = VecX::Zero(A0.rows());
    ASSERT_TRUE(old_solver->solve(b, x0).ok);
    auto s = make_linear_solver("pcg", o);
    s->analyze_pattern(A1);
    s->inherit(*old_solver, T);
    s->set_dof_rotations(rotations ? std::vector<Mat3>(std::size_t(nd), Q) : std::vector<Mat3>{});
    ASSERT_TRUE(s->factorize(A1));
    VecX x1 = VecX::Zero(A1.rows());
    const SolveInfo info = s->solve(b, x1);
    ASSERT_TRUE(info.ok);
    EXPECT_FALSE(info.refactorized);  // the bridge, not a factor of A1
    EXPECT_LE((b - A1 * x1).norm(), 1.01e-10 * b.norm());
    if (rotations)
      EXPECT_LE(info.iterations, 1);
    else
      EXPECT_GE(info.iterations, 10);
  }
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

// serial_openmp_here() (called before every CHOLMOD factorisation) leaves the calling thread's OpenMP regions one
// thread: libgomp's own getters report dynamic adjustment and one thread (and no active level) on a thread that
// factorised; the settings are that thread's, so a fresh thread still has libgomp's defaults. Without libgomp in the
// process there is nothing to limit (CHOLMOD then has no OpenMP).
TEST(LinearSolver, FactorisingThreadsStartOpenMpRegionsSerially) {
  using GetInt = int (*)();
  const auto get_levels = reinterpret_cast<GetInt>(dlsym(RTLD_DEFAULT, "omp_get_max_active_levels"));
  const auto get_dynamic = reinterpret_cast<GetInt>(dlsym(RTLD_DEFAULT, "omp_get_dynamic"));
  const auto get_threads = reinterpret_cast<GetInt>(dlsym(RTLD_DEFAULT, "omp_get_max_threads"));
  if (get_levels == nullptr || get_dynamic == nullptr || get_threads == nullptr) GTEST_SKIP() << "no libgomp";
  int levels = -1, dynamic = -1, threads = -1, fresh_dynamic = -1;
  double residual = 1.0;
  std::thread([&] {
    const SpMat A = laplacian(6, 0.2);
    const VecX b = VecX::LinSpaced(A.rows(), 1.0, 3.0);
    auto s = make_linear_solver("cholmod", {});
    s->analyze_pattern(A);
    if (!s->factorize(A)) return;
    VecX x;
    if (s->solve(b, x).ok) residual = (A * x - b).norm() / b.norm();
    levels = get_levels();
    dynamic = get_dynamic();
    threads = get_threads();
  }).join();
  std::thread([&] { fresh_dynamic = get_dynamic(); }).join();
  EXPECT_LT(residual, 1e-12);
  EXPECT_EQ(dynamic, 1);
  EXPECT_EQ(threads, 1);
  EXPECT_EQ(levels, 0);
  if (std::getenv("OMP_DYNAMIC") == nullptr) {
    EXPECT_EQ(fresh_dynamic, 0);
  }
}

}  // namespace
}  // namespace octocut::sim
