// Corotational hexahedron: stiffness properties, finite differences (also through P with hanging nodes), rotation
// invariance and the patch test (SPEC §3, §10).
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <numbers>
#include <random>

#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/parallel.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

TEST(HexElement, UnitStiffnessIsSymmetricWithSixRigidModes) {
  const Mat24 K = unit_hex_stiffness(0.3);
  EXPECT_LT((K - K.transpose()).norm(), 1e-14 * K.norm());
  Eigen::SelfAdjointEigenSolver<Mat24> eig(K);
  const auto& ev = eig.eigenvalues();
  for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(ev[i]), 1e-12 * ev[23]);
  EXPECT_GT(ev[6], 1e-3 * ev[23]);
}

TEST(HexElement, UniaxialStretchGivesYoungsModulusTimesArea) {
  // Displace the x = 1 face of a unit cube by delta with the lateral faces free to contract: the total reaction
  // equals E A delta / L for nu = 0 (no lateral coupling), exactly for trilinear elements.
  const Mat24 K = unit_hex_stiffness(0.0);
  Vec24 u = Vec24::Zero();
  for (int a = 0; a < 8; ++a)
    if (a & 1) u[3 * a] = 0.01;
  const Vec24 f = K * u;
  double fx = 0.0;
  for (int a = 0; a < 8; ++a)
    if (a & 1) fx += f[3 * a];
  EXPECT_NEAR(fx, 0.01, 1e-14);
}

TEST(HexElement, PolarRotationIsProperForInvertedAndDegenerateGradients) {
  std::mt19937 rng(2);
  std::normal_distribution<double> n;
  for (int i = 0; i < 200; ++i) {
    Mat3 F;
    for (int k = 0; k < 9; ++k) F(k / 3, k % 3) = n(rng);
    if (i % 3 == 0) F.col(0) = -F.col(0);  // inverted
    if (i % 5 == 0) F.col(2) = F.col(1);   // degenerate
    const Mat3 R = polar_rotation(F);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
  }
  EXPECT_LT((polar_rotation(Mat3::Zero()) - Mat3::Identity()).norm(), 1e-12);
  // A pure rotation is recovered exactly.
  const Mat3 Q = Eigen::AngleAxisd(2.0, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  EXPECT_LT((polar_rotation(Q * Vec3(1.5, 0.7, 1.1).asDiagonal()) - Q).norm(), 1e-12);
}

// The Newton path of polar_rotation (det F > 0, well conditioned) recovers the rotation Q of F = Q S for symmetric
// positive definite stretches S with stretch ratios up to 1:250, to round-off; the rotation is proper and
// orthonormal. Reference: Q itself (F is built from it).
TEST(HexElement, PolarRotationRecoversTheRotationOfStretchedRotations) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> angle(-3.1, 3.1), stretch(0.2, 2.0);
  std::normal_distribution<double> n;
  for (int i = 0; i < 500; ++i) {
    const Mat3 Q = Eigen::AngleAxisd(angle(rng), Vec3(n(rng), n(rng), n(rng)).normalized()).toRotationMatrix();
    const Mat3 V = Eigen::AngleAxisd(angle(rng), Vec3(n(rng), n(rng), n(rng)).normalized()).toRotationMatrix();
    Vec3 s(stretch(rng), stretch(rng), stretch(rng));
    if (i % 4 == 0) s[i % 3] *= 0.04;  // strongly flattened
    const Mat3 S = V * s.asDiagonal() * V.transpose();
    const Mat3 R = polar_rotation(Q * S);
    EXPECT_LT((R - Q).norm(), 1e-11 * s.maxCoeff() / s.minCoeff()) << "case " << i;
    EXPECT_NEAR(R.determinant(), 1.0, 1e-13);
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-13);
  }
}

// A model with hanging nodes: a box refined unevenly.
ObjectModel hanging_model(HexFormulation element = HexFormulation::trilinear) {
  MaterialParams p;
  p.young_modulus = 1e4;
  p.poisson_ratio = 0.35;
  p.element = element;
  ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(0.04, 0.03, 0.02)}, Vec3(0, 0, 0), 0.04, 2,
                                  {{Box3{Vec3(0, 0, 0), Vec3(0.01, 0.01, 0.01)}, 4}}, {}, p);
  return m;
}

std::vector<Vec3> perturbed(const ObjectModel& m, double amp, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amp, amp);
  std::vector<Vec3> x = m.dofs().dof_rest;
  for (Vec3& p : x) p += Vec3(u(rng), u(rng), u(rng));
  return x;
}

// Largest difference between the columns of K and central differences of -f (every `stride`-th coordinate),
// relative to the largest entry of K. With `fixed_frame` the rotations stay those of x; otherwise they are
// recomputed at every perturbed configuration (the full nonlinear force).
double fd_stiffness_error(const FemSystem& fem, const std::vector<Vec3>& x, const SpMat& K, double h, int stride,
                          bool fixed_frame) {
  ElementFrame frame;
  fem.rotations(x, frame);
  const int n = int(K.cols());
  double max_err = 0.0, max_k = 0.0;
  for (int i = 0; i < n; i += stride) {
    std::vector<Vec3> xp = x, xm = x;
    xp[std::size_t(i / 3)][i % 3] += h;
    xm[std::size_t(i / 3)][i % 3] -= h;
    ElementFrame fp_frame = frame, fm_frame = frame;
    if (!fixed_frame) {
      fem.rotations(xp, fp_frame);
      fem.rotations(xm, fm_frame);
    }
    VecX fp, fm;
    fem.elastic_force(xp, fp_frame, fp);
    fem.elastic_force(xm, fm_frame, fm);
    const VecX col = -(fp - fm) / (2 * h);
    const VecX kcol = K * VecX::Unit(n, i);
    max_err = std::max(max_err, (col - kcol).cwiseAbs().maxCoeff());
    max_k = std::max(max_k, kcol.cwiseAbs().maxCoeff());
  }
  return max_err / max_k;
}

// The system-level tests run for both hexahedron formulations.
class Fem : public ::testing::TestWithParam<HexFormulation> {};

TEST_P(Fem, StiffnessMatchesFiniteDifferencesThroughP) {
  const ObjectModel m = hanging_model(GetParam());
  ASSERT_GT(m.dofs().hanging_slots, 0);
  Executor ex(1);
  FemSystem fem(m, ex);
  const std::vector<Vec3> x = perturbed(m, 2e-3, 1);
  ElementFrame frame;
  fem.rotations(x, frame);
  const SpMat K = fem.stiffness(frame);
  // With the rotations held fixed the force is linear in x: central differences are exact up to round-off.
  EXPECT_LT(fd_stiffness_error(fem, x, K, 1e-6, 7, true), 1e-6);
  const int n = 3 * m.num_dofs();
  // K is symmetric and K v matches the matrix-free product.
  EXPECT_LT((SpMat(K.transpose()) - K).norm(), 1e-12 * K.norm());
  const VecX v = VecX::Random(n);
  VecX kv;
  fem.stiffness_product(frame, v, kv);
  EXPECT_LT((kv - K * v).norm(), 1e-10 * (K * v).norm());
}

TEST_P(Fem, ForceIsMinusEnergyGradient) {
  const ObjectModel m = hanging_model(GetParam());
  Executor ex(1);
  FemSystem fem(m, ex);
  const std::vector<Vec3> x = perturbed(m, 3e-3, 2);
  ElementFrame frame;
  fem.rotations(x, frame);
  VecX f;
  fem.elastic_force(x, frame, f);
  const double h = 1e-7;
  for (int i = 0; i < 3 * m.num_dofs(); i += 5) {
    std::vector<Vec3> xp = x, xm = x;
    xp[std::size_t(i / 3)][i % 3] += h;
    xm[std::size_t(i / 3)][i % 3] -= h;
    const double g = (fem.elastic_energy(xp, frame) - fem.elastic_energy(xm, frame)) / (2 * h);
    EXPECT_NEAR(-g, f[i], 1e-6 * f.cwiseAbs().maxCoeff() + 1e-9);
  }
}

TEST_P(Fem, FullNonlinearForceDerivativeAtARigidPoseIsTheCorotatedStiffness) {
  // At a rigidly rotated pose the strain vanishes, so dR/dx drops out and the true Jacobian is -R K R^T.
  const ObjectModel m = hanging_model(GetParam());
  Executor ex(1);
  FemSystem fem(m, ex);
  const Mat3 Q = Eigen::AngleAxisd(0.7, Vec3(0.3, -1, 0.5).normalized()).toRotationMatrix();
  std::vector<Vec3> x = m.dofs().dof_rest;
  for (Vec3& p : x) p = Q * p + Vec3(0.1, 0.2, 0.3);
  ElementFrame frame;
  fem.rotations(x, frame);
  const SpMat K = fem.stiffness(frame);
  EXPECT_LT(fd_stiffness_error(fem, x, K, 1e-7, 11, false), 1e-5);
}

TEST_P(Fem, RigidRotationsIncluding180DegreesGiveZeroForce) {
  const ObjectModel m = hanging_model(GetParam());
  Executor ex(2);
  FemSystem fem(m, ex);
  VecX f_scale;
  ElementFrame frame0;
  const std::vector<Vec3> xs = perturbed(m, 1e-3, 4);
  fem.rotations(xs, frame0);
  fem.elastic_force(xs, frame0, f_scale);
  const double scale = f_scale.norm();
  std::mt19937 rng(9);
  std::vector<Mat3> rotations = {
      Eigen::AngleAxisd(std::numbers::pi, Vec3::UnitX()).toRotationMatrix(),
      Eigen::AngleAxisd(std::numbers::pi, Vec3::UnitY()).toRotationMatrix(),
      Eigen::AngleAxisd(std::numbers::pi, Vec3::UnitZ()).toRotationMatrix(),
      Eigen::AngleAxisd(std::numbers::pi, Vec3(1, 1, 1).normalized()).toRotationMatrix()};
  for (int i = 0; i < 20; ++i) rotations.push_back(Eigen::Quaterniond::UnitRandom().toRotationMatrix());
  for (const Mat3& Q : rotations) {
    std::vector<Vec3> x = m.dofs().dof_rest;
    for (Vec3& p : x) p = Q * p + Vec3(-1, 2, 0.5);
    ElementFrame frame;
    fem.rotations(x, frame);
    VecX f;
    fem.elastic_force(x, frame, f);
    EXPECT_LT(f.norm(), 1e-9 * scale);
    EXPECT_LT(fem.elastic_energy(x, frame), 1e-12 * fem.elastic_energy(xs, frame0));
  }
}

TEST_P(Fem, PatchTestReproducesAffineFieldWithHangingNodes) {
  // Impose x = A X + b on the boundary DOFs of a mixed-level mesh, solve the nonlinear static problem for the
  // interior, and expect the affine field exactly with zero residual.
  MaterialParams params;
  params.element = GetParam();
  ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 2,
                                  {{Box3{Vec3(0.3, 0.3, 0.3), Vec3(0.6, 0.6, 0.6)}, 4}}, {}, params);
  ASSERT_GT(m.dofs().hanging_slots, 0);
  const Mat3 A = (Mat3() << 1.2, 0.1, 0.05, -0.1, 0.9, 0.2, 0.0, 0.15, 1.1).finished();
  const Vec3 b(0.3, -0.1, 0.2);
  const int nd = m.num_dofs();
  std::vector<char> constrained(static_cast<std::size_t>(nd), 0);
  std::vector<Vec3> x = m.dofs().dof_rest;
  int interior = 0;
  for (int d = 0; d < nd; ++d) {
    const Vec3& X = m.dofs().dof_rest[std::size_t(d)];
    const bool boundary = (X.array() <= 1e-12).any() || (X.array() >= 1 - 1e-12).any();
    constrained[std::size_t(d)] = boundary;
    if (boundary) x[std::size_t(d)] = A * X + b;
    interior += boundary ? 0 : 1;
  }
  ASSERT_GT(interior, 30);
  Executor ex(2);
  FemSystem fem(m, ex);
  SpMat K;
  const VecX zero = VecX::Zero(3 * nd);
  double rn = 0.0, r0 = -1.0;
  for (int it = 0; it < 50; ++it) {
    ElementFrame frame;
    fem.rotations(x, frame);
    VecX r;
    fem.elastic_force(x, frame, r);
    for (int d = 0; d < nd; ++d)
      if (constrained[std::size_t(d)]) r.segment<3>(3 * d).setZero();
    rn = r.norm();
    if (r0 < 0) r0 = rn;
    if (rn < 1e-13 * r0) break;
    VecX coupling;
    fem.assemble_system(0.0, 1.0, frame, constrained, zero, K, coupling);
    Eigen::SimplicialLDLT<SpMat> ldlt(K);
    ASSERT_EQ(ldlt.info(), Eigen::Success);
    const VecX dx = ldlt.solve(r);
    for (int d = 0; d < nd; ++d) x[std::size_t(d)] += dx.segment<3>(3 * d);
  }
  EXPECT_LT(rn, 1e-13 * r0);
  for (int d = 0; d < nd; ++d)
    EXPECT_LT((x[std::size_t(d)] - (A * m.dofs().dof_rest[std::size_t(d)] + b)).norm(), 1e-12);
}

TEST_P(Fem, ParallelAssemblyIsBitIdenticalToSerial) {
  const ObjectModel m = hanging_model(GetParam());
  const std::vector<Vec3> x = perturbed(m, 2e-3, 3);
  auto run = [&](int threads) {
    Executor ex(threads);
    FemSystem fem(m, ex);
    ElementFrame frame;
    fem.rotations(x, frame);
    VecX f, coupling;
    fem.elastic_force(x, frame, f);
    SpMat A;
    // Every fifth DOF prescribed, with a prescribed increment: its columns move to the coupling vector.
    std::vector<char> c(std::size_t(m.num_dofs()), 0);
    for (std::size_t d = 0; d < c.size(); d += 5) c[d] = 1;
    const VecX u = VecX::LinSpaced(3 * m.num_dofs(), -1e-3, 2e-3);
    fem.assemble_system(1.0, 1e-3, frame, c, u, A, coupling);
    return std::make_tuple(f, VecX(Eigen::Map<VecX>(A.valuePtr(), A.nonZeros())), coupling);
  };
  const auto a = run(1);
  EXPECT_GT(std::get<2>(a).norm(), 0.0);
  for (const int threads : {2, 3}) {
    const auto b = run(threads);
    EXPECT_TRUE(std::get<0>(a) == std::get<0>(b)) << threads;
    EXPECT_TRUE(std::get<1>(a) == std::get<1>(b)) << threads;
    EXPECT_TRUE(std::get<2>(a) == std::get<2>(b)) << threads;
  }
}

// The system applied without assembling it (the solver's operator) against the assembled matrix, on a rotated and
// strained mixed-level model with every fifth DOF prescribed: the matrix-free product A x, the coupling A_fc u_c and
// the columns of a region of DOFs (the contact's exact solve) equal the assembled ones to round-off, and the product
// is bit-identical on one, two and three threads.
TEST_P(Fem, MatrixFreeProductCouplingAndColumnsMatchTheAssembledSystem) {
  const ObjectModel m = hanging_model(GetParam());
  const std::vector<Vec3> x = perturbed(m, 2e-3, 3);
  const int nd = m.num_dofs();
  std::vector<char> c(std::size_t(nd), 0);
  for (std::size_t d = 0; d < c.size(); d += 5) c[d] = 1;
  const VecX u = VecX::LinSpaced(3 * nd, -1e-3, 2e-3);
  const VecX v = VecX::LinSpaced(3 * nd, 1.0, -0.5).cwiseProduct(VecX::LinSpaced(3 * nd, 0.2, 3.0));
  std::vector<VecX> products;
  std::vector<Eigen::MatrixXd> columns;  // the region's columns on 1, 2, 3 threads: the same bits
  for (const int threads : {1, 2, 3}) {
    Executor ex(threads);
    FemSystem fem(m, ex);
    ElementFrame frame;
    fem.rotations(x, frame);
    SpMat A;
    VecX coupling, y, mf_coupling;
    fem.assemble_system(1.3, 1e-3, frame, c, u, A, coupling);
    fem.system_product(1.3, 1e-3, frame, c, v, y);
    const VecX Av = A * v;
    EXPECT_LT((y - Av).norm(), 1e-13 * Av.norm()) << threads;
    fem.system_coupling(1e-3, frame, c, u, mf_coupling);
    EXPECT_GT(coupling.norm(), 0.0);
    EXPECT_LT((mf_coupling - coupling).norm(), 1e-13 * coupling.norm()) << threads;
    // Columns of a region with free and prescribed DOFs.
    std::vector<int> region;
    for (int d = 1; d < nd; d += 3) region.push_back(d);
    const SpMat cols = fem.system_columns(1.3, 1e-3, frame, c, region);
    ASSERT_EQ(cols.cols(), 3 * Eigen::Index(region.size()));
    const Eigen::MatrixXd dense(A);
    for (std::size_t i = 0; i < region.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        const VecX want = dense.col(3 * region[i] + k);
        const VecX got = Eigen::MatrixXd(cols).col(3 * Eigen::Index(i) + k);
        EXPECT_LT((got - want).norm(), 1e-13 * dense.norm()) << "DOF " << region[i];
      }
    products.push_back(y);
    columns.emplace_back(cols);
  }
  EXPECT_TRUE(products[1] == products[0]);
  EXPECT_TRUE(products[2] == products[0]);
  EXPECT_TRUE(columns[1] == columns[0]);
  EXPECT_TRUE(columns[2] == columns[0]);
}

// A system built in storage another system released (FemSystem::release_storage, reuse_storage: what a cut's new
// revision does with the revision before the current one) has the same pattern and assembles the same matrix, bit
// for bit, as one built afresh; it fills that storage in place when it is large enough (a smaller model after a
// larger one) and grows it otherwise (a larger one after a smaller one).
TEST_P(Fem, SystemInReusedStorageEqualsAFreshOne) {
  MaterialParams p;
  p.young_modulus = 1e4;
  p.poisson_ratio = 0.35;
  p.element = GetParam();
  const ObjectModel small = test::box_model({Vec3(0, 0, 0), Vec3(0.04, 0.03, 0.02)}, Vec3(0, 0, 0), 0.04, 2, {}, {}, p);
  const ObjectModel large = hanging_model(GetParam());
  Executor ex(2);
  const auto assembled = [&](FemSystem& fem, const ObjectModel& m) {
    ElementFrame frame;
    fem.rotations(perturbed(m, 2e-3, 5), frame);
    std::vector<char> c(std::size_t(m.num_dofs()), 0);
    for (std::size_t d = 0; d < c.size(); d += 4) c[d] = 1;
    SpMat A;
    VecX coupling;
    fem.assemble_system(1.0, 1e-3, frame, c, VecX::LinSpaced(3 * m.num_dofs(), -1e-3, 1e-3), A, coupling);
    return std::make_pair(A, coupling);
  };
  for (const auto& [first, second] : {std::pair{&large, &small}, std::pair{&small, &large}}) {
    FemSystem before(*first, ex);
    (void)assembled(before, *first);
    FemSystem::Storage storage = before.release_storage();
    const double* given = storage.pattern.valuePtr();
    FemSystem reused(*second, ex), fresh(*second, ex);
    reused.reuse_storage(std::move(storage));
    const auto [Ar, cr] = assembled(reused, *second);
    const auto [Af, cf] = assembled(fresh, *second);
    ASSERT_EQ(Ar.nonZeros(), Af.nonZeros());
    for (Eigen::Index k = 0; k <= Ar.cols(); ++k) ASSERT_EQ(Ar.outerIndexPtr()[k], Af.outerIndexPtr()[k]);
    for (Eigen::Index k = 0; k < Ar.nonZeros(); ++k) {
      ASSERT_EQ(Ar.innerIndexPtr()[k], Af.innerIndexPtr()[k]);
      ASSERT_TRUE(Ar.valuePtr()[k] == Af.valuePtr()[k]) << k;
    }
    EXPECT_TRUE(cr == cf);
    std::vector<char> c(std::size_t(second->num_dofs()), 0);
    for (std::size_t d = 0; d < c.size(); d += 4) c[d] = 1;
    if (first == &large) {
      EXPECT_EQ(reused.system_pattern(c).valuePtr(), given) << "a smaller pattern fills the storage it was given";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Elements, Fem, ::testing::Values(HexFormulation::trilinear, HexFormulation::bbar),
                         [](const ::testing::TestParamInfo<HexFormulation>& info) {
                           return info.param == HexFormulation::bbar ? "bbar" : "trilinear";
                         });

}  // namespace
}  // namespace octocut::sim
