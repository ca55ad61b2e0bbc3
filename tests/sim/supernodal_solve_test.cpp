// The triangular solves on two threads (sim/src/supernodal_solve.hpp): the tree partition puts independent subtrees
// in different parts and their separator in the top, and the solves agree with a dense solve and give bit-identical
// results with one thread and two. Through the solver: PCG with the lagged factor gives the same iterates on one
// thread and two.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <bit>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <tuple>

#include "octocut/sim/linear_solver.hpp"
#include "octocut/sim/parallel.hpp"
#include "supernodal_solve.hpp"
#include "supernode_kernels.hpp"

namespace octocut::sim {
namespace {

// A nested-dissection-shaped SPD matrix: two chains of `k` unknowns each (tridiagonal), not coupled to each other,
// both coupled to every one of `s` separator unknowns, which come last. Its Cholesky factor has one supernode per
// column here: each chain's column j has rows j, j + 1 (within the chain) and the separator's; the separator is dense.
struct Arrow {
  Eigen::MatrixXd A;                    // the matrix (n x n)
  std::vector<int> super, pi, px, rows;  // the single-column supernodal structure of its factor
  std::vector<double> values;           // the factor's entries, column by column (CHOLMOD's layout)
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
      a.values.push_back(L(i, j));
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
      a.values.push_back(i >= j ? L(first + i, first + j) : std::numeric_limits<double>::quiet_NaN());
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

// Small supernodes (the chains' single columns) and, in the second matrix, a large one (120 x 120, whose upper
// triangle holds NaN), with the factor in single and in half precision: the values kept against the factor's (single
// precision: rounded to float; half: 11 significant bits, or zero below 2^-28 of the column's largest entry), each
// solve against a dense double-precision solve with the values kept, and bit for bit on one thread and two.
class SupernodalSolves : public ::testing::TestWithParam<std::tuple<bool, bool>> {};

TEST_P(SupernodalSolves, MatchADenseSolveOnOneThreadAndTwo) {
  const auto [dense_separator, half] = GetParam();
  const Arrow a = dense_separator ? arrow_with_dense_separator(300, 120) : arrow(300, 12);
  const SupernodalStructure L = structure(a);
  SupernodalSolvePlan plan;
  plan.build(L);
  PackedFactor packed;
  plan.pack(L, a.values.data(), half, packed);
  ASSERT_EQ(packed.half(), half);
  const std::vector<double> kept = plan.unpack(L, packed);
  Eigen::MatrixXd Lk = Eigen::MatrixXd::Zero(a.n, a.n);  // the values kept, as a dense lower triangle
  for (int s = 0; s < L.nsuper; ++s)
    for (int j = L.super[s]; j < L.super[s + 1]; ++j) {
      const int c = j - L.super[s], nsrow = L.pi[s + 1] - L.pi[s];
      double largest = 0.0;
      const double* column = a.values.data() + L.px[s] + c * nsrow;
      for (int r = c + 1; r < nsrow; ++r) largest = std::max(largest, std::abs(column[r]));
      for (int r = c; r < nsrow; ++r) {
        const double x = column[r];
        const double k = kept[std::size_t(L.px[s] + c * nsrow + r)];
        Lk(L.rows[L.pi[s] + r], j) = k;
        if (r == c || !half)  // the diagonal: 1 / float(1 / x); single precision: float(x)
          EXPECT_NEAR(k, x, 1.2e-7 * std::abs(x)) << "entry " << r << " of column " << j;
        else if (std::abs(x) >= 0x1p-28 * largest)
          EXPECT_NEAR(k, x, 0x1p-11 * std::abs(x)) << "entry " << r << " of column " << j;
        else
          EXPECT_LE(std::abs(k), 0x1p-28 * largest) << "entry " << r << " of column " << j;
      }
    }
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(a.n, -1.0, 2.0);
  const Eigen::VectorXd exact = (Lk * Lk.transpose()).llt().solve(b);
  Executor one(1), two(2);
  std::vector<std::vector<float>> results;
  for (Executor* ex : {static_cast<Executor*>(nullptr), &one, &two}) {
    std::vector<float> y(b.data(), b.data() + b.size());
    plan.forward(L, packed, y.data(), ex);
    plan.backward(L, packed, y.data(), ex);
    double err = 0.0;
    for (int i = 0; i < a.n; ++i) err = std::max(err, std::abs(double(y[std::size_t(i)]) - exact[i]));
    EXPECT_LT(err, 1e-5 * exact.cwiseAbs().maxCoeff());  // single-precision arithmetic
    results.push_back(y);
  }
  for (std::size_t r = 1; r < results.size(); ++r)
    for (int i = 0; i < a.n; ++i)
      ASSERT_TRUE(results[r][std::size_t(i)] == results[0][std::size_t(i)]) << "run " << r << ", row " << i;
}

INSTANTIATE_TEST_SUITE_P(SupernodalSolve, SupernodalSolves, ::testing::Combine(::testing::Bool(), ::testing::Bool()),
                         [](const ::testing::TestParamInfo<std::tuple<bool, bool>>& info) {
                           return std::string(std::get<0>(info.param) ? "WithADenseSeparator" : "SingleColumns") +
                                  (std::get<1>(info.param) ? "InHalfPrecision" : "InSinglePrecision");
                         });

// half_code rounds to the nearest half-precision number, ties to even, as the compiler's own conversion does, over
// the normal range and at its edges; half_value gives that number exactly.
TEST(SupernodalSolve, HalfCodesAreTheNearestHalfPrecisionNumbers) {
#if defined(__FLT16_MAX__)
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> exponent(-14.0, 15.99), mantissa(1.0, 2.0);
  std::vector<double> values{0x1p-14, 65504.0, 1.0, 1.0 + 0x1p-11, 1.0 + 3 * 0x1p-11, 2047.5, 2048.5, 0.1, -0.1};
  for (int i = 0; i < 20000; ++i) values.push_back((i % 2 ? -1.0 : 1.0) * std::exp2(exponent(rng)));
  for (const double v : values) {
    const auto expected = std::bit_cast<std::uint16_t>(static_cast<_Float16>(v));
    ASSERT_EQ(half_code(v), expected) << v;
    ASSERT_EQ(double(half_value(expected)), double(static_cast<_Float16>(v))) << v;
  }
#else
  GTEST_SKIP() << "no _Float16 in this compiler to compare with";
#endif
  EXPECT_EQ(half_code(0x1p-15), 0);  // below the normal range: zero (pack scales columns to keep entries above it)
  EXPECT_EQ(half_code(0.0), 0);
}

// The kernels' arithmetic, written out one float at a time in the order supernode_kernels.hpp defines (blocks of 8
// columns; a dot product's 16 partial sums over rows j1 + l, j1 + 16 + l, ..., added by a tree of halves; each column's
// scale applied to x in the forward solve and to the dot product in the backward one): the kernels, in whichever copy
// this CPU runs (AVX-512, AVX2 or SSE2), for floats and for half-precision codes, must give the same bits. Supernodes
// of 1 to 50 columns and up to 201 rows, random entries and scales, NaN in the upper triangles (never read); every
// copy this CPU can run (supernode_kernel_copies), the one the solves use first.
namespace kernel_order {
constexpr int kBlock = 8, kLanes = 16;
struct Block {
  std::vector<float> L;                // the entries' values (column-major, leading dimension ld)
  std::vector<float> diag_inv, scale;  // per column
  int ld = 0;
  [[nodiscard]] float at(int i, int j) const { return L[std::size_t(j) * std::size_t(ld) + std::size_t(i)]; }
};

void forward(const Block& B, int nscol, int nsrow, std::vector<float>& w) {
  for (int j0 = 0; j0 < nscol; j0 += kBlock) {
    const int nc = std::min(kBlock, nscol - j0), j1 = j0 + nc;
    for (int j = j0; j < j1; ++j) {
      w[std::size_t(j)] = w[std::size_t(j)] * B.diag_inv[std::size_t(j)];
      const float x = w[std::size_t(j)] * B.scale[std::size_t(j)];
      for (int i = j + 1; i < j1; ++i) w[std::size_t(i)] = w[std::size_t(i)] - B.at(i, j) * x;
    }
    float x[kBlock];
    for (int q = 0; q < kBlock; ++q) x[q] = q < nc ? w[std::size_t(j0 + q)] * B.scale[std::size_t(j0 + q)] : 0.0f;
    for (int i = j1; i < nsrow; ++i) {
      float v = w[std::size_t(i)];
      for (int q = 0; q < kBlock; ++q) v = v - (q < nc ? B.at(i, j0 + q) : B.at(i, j0)) * x[q];
      w[std::size_t(i)] = v;
    }
  }
}

void backward(const Block& B, int nscol, int nsrow, std::vector<float>& w) {
  for (int j1 = nscol, nc = nscol % kBlock ? nscol % kBlock : kBlock; j1 > 0; j1 -= nc, nc = kBlock) {
    const int j0 = j1 - nc;
    float s[kBlock];
    for (int q = 0; q < nc; ++q) {
      float lane[kLanes] = {};
      for (int i = j1; i < nsrow; i += kLanes)
        for (int l = 0; l < kLanes; ++l)
          lane[l] = lane[l] + (i + l < nsrow ? B.at(i + l, j0 + q) * w[std::size_t(i + l)] : 0.0f);
      for (int h = kLanes / 2; h >= 1; h /= 2)
        for (int l = 0; l < h; ++l) lane[l] = lane[l] + lane[l + h];
      s[q] = lane[0] * B.scale[std::size_t(j0 + q)];
    }
    for (int q = nc - 1; q >= 0; --q) {
      const int j = j0 + q;
      float v = w[std::size_t(j)] - s[q];
      for (int r = j + 1; r < j1; ++r) v = v - (B.at(r, j) * B.scale[std::size_t(j)]) * w[std::size_t(r)];
      w[std::size_t(j)] = v * B.diag_inv[std::size_t(j)];
    }
  }
}
}  // namespace kernel_order

// One supernode of nscol x nsrow, random entries (floats in [-1, 1), or codes of [-2^14, 2^14) with scales of 2^-16 to
// 2^-14) and NaN in the upper triangle: `copy`'s forward and backward solves against kernel_order's, bit for bit.
void check_kernels(const SupernodeKernelCopy& copy, bool half, int nscol, int nsrow, std::mt19937& rng) {
  std::uniform_real_distribution<float> entry(-1.0f, 1.0f), diagonal(0.5f, 2.0f);
  std::uniform_int_distribution<int> exponent(-16, -14);
  kernel_order::Block B;
  B.ld = (nsrow + kSupernodePadding + 15) / 16 * 16;
  B.L.assign(std::size_t(nscol) * std::size_t(B.ld), 0.0f);
  std::vector<float> floats = B.L;
  std::vector<std::uint16_t> codes(B.L.size(), 0);
  for (int j = 0; j < nscol; ++j) {
    B.diag_inv.push_back(diagonal(rng));
    B.scale.push_back(half ? std::ldexp(1.0f, exponent(rng)) : 1.0f);
    for (int i = 0; i < nsrow; ++i) {
      const std::size_t k = std::size_t(j) * std::size_t(B.ld) + std::size_t(i);
      if (i <= j) {  // never read: NaN (codes: 0x7e00, a half-precision NaN)
        floats[k] = B.L[k] = std::numeric_limits<float>::quiet_NaN();
        codes[k] = 0x7e00;
        continue;
      }
      codes[k] = half_code(double(entry(rng)) * 16384.0);
      floats[k] = entry(rng);
      B.L[k] = half ? half_value(codes[k]) : floats[k];
    }
  }
  const std::string what = std::string(copy.name) + (half ? " half, " : " single, ") + std::to_string(nscol) + " x " +
                           std::to_string(nsrow);
  for (const bool forward : {true, false}) {
    // The forward solve reads w[0, nscol), the backward one w[0, nsrow); zeros after.
    std::vector<float> w(std::size_t(B.ld), 0.0f);
    for (int i = 0; i < (forward ? nscol : nsrow); ++i) w[std::size_t(i)] = entry(rng);
    std::vector<float> expected = w;
    const auto kernel = half ? (forward ? copy.forward_half : copy.backward_half) : nullptr;
    const auto kernel_f = half ? nullptr : (forward ? copy.forward : copy.backward);
    if (half)
      kernel(codes.data(), B.diag_inv.data(), B.scale.data(), nscol, nsrow, B.ld, w.data());
    else
      kernel_f(floats.data(), B.diag_inv.data(), B.scale.data(), nscol, nsrow, B.ld, w.data());
    (forward ? kernel_order::forward : kernel_order::backward)(B, nscol, nsrow, expected);
    for (int i = 0; i < B.ld; ++i)
      ASSERT_EQ(std::bit_cast<std::uint32_t>(w[std::size_t(i)]), std::bit_cast<std::uint32_t>(expected[std::size_t(i)]))
          << (forward ? "forward, " : "backward, ") << what << ", row " << i;
  }
}

TEST(SupernodalSolve, KernelsGiveTheBitsOfTheirDefinedOrderOnThisCpu) {
  std::mt19937 rng(7);
  const std::array<std::pair<int, int>, 11> shapes{{{1, 1}, {1, 17}, {3, 3}, {3, 20}, {5, 40}, {8, 8}, {9, 31},
                                                    {13, 70}, {24, 100}, {50, 50}, {37, 201}}};
  const std::vector<SupernodeKernelCopy> copies = supernode_kernel_copies();
  ASSERT_FALSE(copies.empty());
  for (const SupernodeKernelCopy& copy : copies)
    for (const bool half : {false, true})
      for (const auto& [nscol, nsrow] : shapes) {
        check_kernels(copy, half, nscol, nsrow, rng);
        if (HasFatalFailure()) return;
      }
}

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
