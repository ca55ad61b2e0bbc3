// The preconditioner's single-precision supernodal Cholesky factorisation (sim/src/supernodal_factor.hpp) against
// the dense Cholesky factor of the same permuted matrix, on the supernodal structure CHOLMOD's analysis gives; the
// double-precision one of the small exact solves and its solve against a dense factor and a dense solve.
#include <cholmod.h>
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "octocut/sim/types.hpp"
#include "supernodal_factor.hpp"

namespace octocut::sim {
namespace {

// A matrix with the pattern of a hexahedral FEM system: an m x m x m grid of nodes with 3 unknowns each, every cell
// adding a random symmetric positive semi-definite 24 x 24 block over its 8 nodes, plus `shift` on the diagonal.
SpMat grid_system(int m, double shift, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int nodes = m * m * m, n = 3 * nodes;
  const auto node = [m](int i, int j, int k) { return (k * m + j) * m + i; };
  std::vector<Eigen::Triplet<double>> t;
  for (int k = 0; k + 1 < m; ++k)
    for (int j = 0; j + 1 < m; ++j)
      for (int i = 0; i + 1 < m; ++i) {
        int dofs[24];
        for (int c = 0; c < 8; ++c)
          for (int d = 0; d < 3; ++d) dofs[3 * c + d] = 3 * node(i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2)) + d;
        Eigen::MatrixXd B(24, 24);
        for (int r = 0; r < 24; ++r)
          for (int c = 0; c < 24; ++c) B(r, c) = u(rng);
        const Eigen::MatrixXd K = B.transpose() * B / 24.0;
        for (int r = 0; r < 24; ++r)
          for (int c = 0; c < 24; ++c) t.emplace_back(dofs[r], dofs[c], K(r, c));
      }
  for (int i = 0; i < n; ++i) t.emplace_back(i, i, shift);
  SpMat A(n, n);
  A.setFromTriplets(t.begin(), t.end());
  A.makeCompressed();
  return A;
}

// CHOLMOD's supernodal analysis of A's pattern (its structure; the factor's values are not used).
class Analysis {
 public:
  explicit Analysis(const SpMat& A, bool natural = false) {
    cholmod_start(&m_c);
    m_c.print = 0;
    m_c.supernodal = CHOLMOD_SUPERNODAL;
    if (natural) {  // the matrix's own ordering instead of AMD's
      m_c.nmethods = 1;
      m_c.method[0].ordering = CHOLMOD_NATURAL;
      m_c.postorder = 0;
    }
    cholmod_sparse a{};
    a.nrow = a.ncol = std::size_t(A.rows());
    a.nzmax = std::size_t(A.nonZeros());
    a.p = const_cast<int*>(A.outerIndexPtr());
    a.i = const_cast<int*>(A.innerIndexPtr());
    a.x = const_cast<double*>(A.valuePtr());
    a.stype = -1;
    a.itype = CHOLMOD_INT;
    a.xtype = CHOLMOD_REAL;
    a.dtype = CHOLMOD_DOUBLE;
    a.sorted = 1;
    a.packed = 1;
    m_L = cholmod_analyze(&a, &m_c);
  }
  ~Analysis() {
    if (m_L) cholmod_free_factor(&m_L, &m_c);
    cholmod_finish(&m_c);
  }
  Analysis(const Analysis&) = delete;
  Analysis& operator=(const Analysis&) = delete;
  [[nodiscard]] bool ok() const { return m_L != nullptr && m_L->is_super; }
  [[nodiscard]] SupernodalStructure structure() const { return supernodal_structure_of(*m_L); }
  [[nodiscard]] const int* perm() const { return static_cast<const int*>(m_L->Perm); }

 private:
  cholmod_common m_c{};
  cholmod_factor* m_L = nullptr;
};

// The factor's values (CHOLMOD's layout) as a dense lower triangle.
template <class T>
Eigen::MatrixXd dense_factor(const SupernodalStructure& L, const std::vector<T>& x) {
  Eigen::MatrixXd D = Eigen::MatrixXd::Zero(L.n, L.n);
  for (int s = 0; s < L.nsuper; ++s) {
    const int nsrow = L.pi[s + 1] - L.pi[s];
    for (int j = L.super[s]; j < L.super[s + 1]; ++j)
      for (int r = j - L.super[s]; r < nsrow; ++r)
        D(L.rows[L.pi[s] + r], j) = double(x[std::size_t(L.px[s] + (j - L.super[s]) * nsrow + r)]);
  }
  return D;
}

// P A P^T, dense.
Eigen::MatrixXd permuted(const SpMat& A, const int* perm) {
  const Eigen::MatrixXd D(A);
  Eigen::MatrixXd P(D.rows(), D.cols());
  for (Eigen::Index i = 0; i < D.rows(); ++i)
    for (Eigen::Index j = 0; j < D.cols(); ++j) P(i, j) = D(perm[i], perm[j]);
  return P;
}

// Every entry of `ours` within `relative` times its column's largest of the exact factor's entry.
void expect_factor_near(const Eigen::MatrixXd& ours, const Eigen::MatrixXd& exact, double relative) {
  for (Eigen::Index j = 0; j < exact.cols(); ++j) {
    const double largest = exact.col(j).cwiseAbs().maxCoeff();
    for (Eigen::Index i = j; i < exact.rows(); ++i)
      ASSERT_NEAR(ours(i, j), exact(i, j), relative * largest) << "entry (" << i << ", " << j << ")";
  }
}

TEST(SupernodalFactor, MatchesTheDenseCholeskyFactorOfThePermutedMatrix) {
  const SpMat A = grid_system(7, 0.05, 1);
  const Analysis analysis(A);
  ASSERT_TRUE(analysis.ok());
  const SupernodalStructure L = analysis.structure();
  int widest = 0;
  for (int s = 0; s < L.nsuper; ++s) widest = std::max(widest, L.super[s + 1] - L.super[s]);
  EXPECT_GE(widest, 48) << "the separators should reach the BLAS's kernels";
  SupernodalFactorizer<float> factorizer;
  std::vector<float> x;
  ASSERT_TRUE(factorizer.factorize(L, analysis.perm(), A, x));
  const Eigen::MatrixXd PAP = permuted(A, analysis.perm());
  const Eigen::MatrixXd exact = PAP.llt().matrixL();
  const Eigen::MatrixXd ours = dense_factor(L, x);
  // Single precision: each entry within a few units of roundoff of its column's largest (the matrix is well
  // conditioned: the shift), and L L^T reproduces P A P^T to single precision.
  expect_factor_near(ours, exact, 2e-4);
  if (HasFatalFailure()) return;
  EXPECT_LT((ours * ours.transpose() - PAP).norm(), 1e-5 * PAP.norm());
}

TEST(SupernodalFactor, RefactorisingNewValuesGivesTheBitsOfAFreshFactorisation) {
  const SpMat A = grid_system(6, 0.05, 2);
  SpMat B = A;  // the same pattern, other values
  for (Eigen::Index k = 0; k < B.nonZeros(); ++k) B.valuePtr()[k] *= 1.0 + 1e-3 * double(k % 7);
  B = SpMat(B.selfadjointView<Eigen::Lower>());  // symmetric again, the same pattern
  B.makeCompressed();
  const Analysis analysis(A);
  ASSERT_TRUE(analysis.ok());
  SupernodalFactorizer<float> reused, fresh;
  std::vector<float> x1, x2, x3;
  ASSERT_TRUE(reused.factorize(analysis.structure(), analysis.perm(), A, x1));
  ASSERT_TRUE(reused.factorize(analysis.structure(), analysis.perm(), B, x2));
  ASSERT_TRUE(fresh.factorize(analysis.structure(), analysis.perm(), B, x3));
  ASSERT_EQ(x2.size(), x3.size());
  for (std::size_t i = 0; i < x2.size(); ++i) ASSERT_TRUE(x2[i] == x3[i]) << "value " << i;
  bool differ = false;
  for (std::size_t i = 0; i < x1.size() && !differ; ++i) differ = x1[i] != x2[i];
  EXPECT_TRUE(differ) << "the second factorisation must use the new values";
}

TEST(SupernodalFactor, RefusesIndefiniteAndNonFiniteMatricesAndEntriesOutsideThePattern) {
  const SpMat A = grid_system(5, 0.05, 3);
  const Analysis analysis(A);
  ASSERT_TRUE(analysis.ok());
  const SupernodalStructure L = analysis.structure();
  SupernodalFactorizer<float> factorizer;
  std::vector<float> x;
  ASSERT_TRUE(factorizer.factorize(L, analysis.perm(), A, x));

  SpMat indefinite = A;  // one unknown pulled below zero: a pivot turns negative
  indefinite.coeffRef(100, 100) = -1.0;
  EXPECT_FALSE(factorizer.factorize(L, analysis.perm(), indefinite, x));

  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    SpMat nonfinite = A;  // an entry below the diagonal of the first columns, whatever the ordering
    nonfinite.coeffRef(7, 4) = bad;
    nonfinite.coeffRef(4, 7) = bad;
    EXPECT_FALSE(factorizer.factorize(L, analysis.perm(), nonfinite, x)) << bad;
  }

  SpMat wider = A;  // two far corners of the grid coupled: not in L's pattern
  const int last = int(A.rows()) - 1;
  wider.coeffRef(last, 0) = 1e-3;
  wider.coeffRef(0, last) = 1e-3;
  wider.makeCompressed();
  EXPECT_FALSE(factorizer.factorize(L, analysis.perm(), wider, x));
  EXPECT_TRUE(factorizer.factorize(L, analysis.perm(), A, x)) << "and the original pattern again";
}

// The assembly is planned once per pattern of A; after forget() a factorisation on another analysis of the same
// pattern (another ordering) plans anew and matches a fresh factorizer's bits.
TEST(SupernodalFactor, ForgettingThePlanFollowsANewAnalysisOfTheSamePattern) {
  const SpMat A = grid_system(5, 0.05, 4);
  const Analysis amd(A), natural(A, true);
  ASSERT_TRUE(amd.ok() && natural.ok());
  SupernodalFactorizer<float> reused, fresh;
  std::vector<float> x1, x2, x3;
  ASSERT_TRUE(reused.factorize(amd.structure(), amd.perm(), A, x1));
  reused.forget();
  ASSERT_TRUE(reused.factorize(natural.structure(), natural.perm(), A, x2));
  ASSERT_TRUE(fresh.factorize(natural.structure(), natural.perm(), A, x3));
  ASSERT_EQ(x2.size(), x3.size());
  for (std::size_t i = 0; i < x2.size(); ++i) ASSERT_TRUE(x2[i] == x3[i]) << "value " << i;
}

// A factor's storage is kept from one pattern to the next (a cut's new pattern, which usually has a few more
// entries): grown by an eighth more than asked, and not moved for a pattern that fits. The values are a fresh
// factorizer's, bit for bit, whatever storage they are computed in.
TEST(SupernodalFactor, StorageKeptAcrossPatternsGivesTheBitsOfAFreshFactorisation) {
  const SpMat small = grid_system(5, 0.05, 6), large = grid_system(6, 0.05, 7);
  const Analysis a_small(small), a_large(large);
  ASSERT_TRUE(a_small.ok() && a_large.ok());
  SupernodalFactorizer<float> reused;
  std::vector<float> x;
  const auto expect_fresh_bits = [&](const Analysis& analysis, const SpMat& A) {
    SupernodalFactorizer<float> fresh;
    std::vector<float> y;
    ASSERT_TRUE(fresh.factorize(analysis.structure(), analysis.perm(), A, y));
    ASSERT_EQ(x.size(), y.size());
    for (std::size_t i = 0; i < x.size(); ++i) ASSERT_TRUE(x[i] == y[i]) << "value " << i;
  };
  ASSERT_TRUE(reused.factorize(a_large.structure(), a_large.perm(), large, x));
  EXPECT_EQ(x.capacity(), x.size() + x.size() / 8) << "room for a pattern an eighth larger";
  expect_fresh_bits(a_large, large);
  const float* storage = x.data();
  reused.forget();
  ASSERT_TRUE(reused.factorize(a_small.structure(), a_small.perm(), small, x));
  EXPECT_EQ(x.data(), storage) << "a smaller factor in the same storage";
  expect_fresh_bits(a_small, small);
  reused.forget();
  ASSERT_TRUE(reused.factorize(a_large.structure(), a_large.perm(), large, x));
  EXPECT_EQ(x.data(), storage);
  expect_fresh_bits(a_large, large);
}

// In double precision (LocalSolve's region factor), on a pattern small enough for plain loops and on one whose
// separators reach the BLAS's kernels: the factor within 1e-12 of the dense Cholesky factor of P A P^T (its column's
// largest entry), and supernodal_solve's x within 1e-10 of a dense solve of A x = b, the permutation undone.
TEST(SupernodalFactor, InDoublePrecisionMatchesTheDenseFactorAndSolve) {
  for (const int m : {4, 7}) {
    const SpMat A = grid_system(m, 0.05, 5);
    const Analysis analysis(A);
    ASSERT_TRUE(analysis.ok());
    const SupernodalStructure L = analysis.structure();
    SupernodalFactorizer<double> factorizer;
    std::vector<double> x;
    ASSERT_TRUE(factorizer.factorize(L, analysis.perm(), A, x));
    const Eigen::MatrixXd PAP = permuted(A, analysis.perm());
    const Eigen::MatrixXd exact = PAP.llt().matrixL();
    expect_factor_near(dense_factor(L, x), exact, 1e-12);
    if (HasFatalFailure()) return;
    const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(A.rows(), -1.0, 2.0);
    const Eigen::VectorXd expected = Eigen::MatrixXd(A).llt().solve(b);
    Eigen::VectorXd y = b;
    std::vector<double> work;
    supernodal_solve(L, analysis.perm(), x, y.data(), work);
    EXPECT_LT((y - expected).norm(), 1e-10 * expected.norm()) << "m " << m;
  }
}

}  // namespace
}  // namespace octocut::sim
