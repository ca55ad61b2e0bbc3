// The B-bar (mean dilatation) hexahedron of issue 17 §3: its element stiffness against analytic truths (rigid-body
// null space of dimension exactly 6, constant strain reproduced exactly, the energy of the bending mode with its
// volumetric part removed), and on a whole mesh: the nearly incompressible cantilever no longer locks. The
// system-level checks shared with the trilinear element (finite differences through P with hanging nodes, energy
// gradient, rotation invariance, the patch test) run for both formulations in fem_test.cpp.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <random>

#include "octocut/sim/hex_element.hpp"
#include "sim/reference/cantilever_reference.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

double shear_modulus(double nu) { return 1.0 / (2.0 * (1.0 + nu)); }  // for E = 1

// The 6 rigid motions of the unit cube, linearised (translations and infinitesimal rotations about its centre).
std::vector<Vec24> rigid_modes() {
  std::vector<Vec24> modes;
  for (int m = 0; m < 6; ++m) {
    Vec24 v;
    for (int a = 0; a < 8; ++a) {
      const Vec3 X(double(a & 1) - 0.5, double((a >> 1) & 1) - 0.5, double((a >> 2) & 1) - 0.5);
      v.segment<3>(3 * a) = m < 3 ? Vec3(Vec3::Unit(m)) : Vec3(Vec3::Unit(m - 3).cross(X));
    }
    modes.push_back(v.normalized());
  }
  return modes;
}

TEST(HexElementBbar, HasExactlySixZeroEnergyModesTheRigidMotions) {
  for (const double nu : {0.0, 0.3, 0.45, 0.49, 0.499}) {
    const Mat24 K = unit_hex_stiffness_bbar(nu);
    EXPECT_EQ(K, K.transpose());
    Eigen::SelfAdjointEigenSolver<Mat24> eig(K);
    const auto& ev = eig.eigenvalues();
    // Six zero eigenvalues, and the seventh of the order of the shear modulus (no hourglass mode): the rank is 18.
    for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(ev[i]), 1e-12 * ev[23]) << "nu " << nu;
    EXPECT_GT(ev[6], 0.05 * shear_modulus(nu)) << "nu " << nu;
    // The null space is the rigid motions.
    for (const Vec24& r : rigid_modes()) EXPECT_LT((K * r).norm(), 1e-12 * ev[23]) << "nu " << nu;
  }
}

TEST(HexElementBbar, ConstantStrainGivesTheExactNodalForces) {
  // Under an affine displacement u = G X the strain is constant, its mean is itself, and B-bar equals B: the nodal
  // forces are those of the constant stress sigma = D eps, f_a = sigma * integral of grad N_a = sigma (+-1/4)^3.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> r(-1e-2, 1e-2);
  for (const double nu : {0.3, 0.49}) {
    const double lambda = nu / ((1 + nu) * (1 - 2 * nu)), mu = shear_modulus(nu);
    Mat3 G;
    for (int k = 0; k < 9; ++k) G(k / 3, k % 3) = r(rng);
    const Mat3 eps = 0.5 * (G + G.transpose());
    const Mat3 sigma = lambda * eps.trace() * Mat3::Identity() + 2 * mu * eps;
    Vec24 u;
    for (int a = 0; a < 8; ++a) u.segment<3>(3 * a) = G * Vec3(double(a & 1), double((a >> 1) & 1), double((a >> 2) & 1));
    const Vec24 f = unit_hex_stiffness_bbar(nu) * u;
    for (int a = 0; a < 8; ++a) {
      const Vec3 g((a & 1) ? 0.25 : -0.25, (a & 2) ? 0.25 : -0.25, (a & 4) ? 0.25 : -0.25);
      EXPECT_LT((f.segment<3>(3 * a) - sigma * g).norm(), 1e-12 * sigma.norm()) << "nu " << nu << " corner " << a;
    }
    // The same forces as the trilinear element: the two differ only in the volumetric part of non-constant strain.
    EXPECT_LT((f - unit_hex_stiffness(nu) * u).norm(), 1e-12 * f.norm());
  }
}

TEST(HexElementBbar, BendingModeEnergyIsDeviatoricOnly) {
  // The in-element bending mode u_x = (x - 1/2)(y - 1/2): eps_xx = y - 1/2, gamma_xy = x - 1/2, div u = y - 1/2 with
  // mean zero. B-bar keeps only the deviatoric energy mu (eps:eps - tr^2/3), which integrates to 7 mu / 72 whatever
  // lambda is; the trilinear element adds lambda/2 tr^2, i.e. lambda / 24, which grows without bound as nu -> 1/2
  // (volumetric locking).
  Vec24 u = Vec24::Zero();
  for (int a = 0; a < 8; ++a) u[3 * a] = (double(a & 1) - 0.5) * (double((a >> 1) & 1) - 0.5);
  for (const double nu : {0.0, 0.3, 0.49, 0.4999}) {
    const double mu = shear_modulus(nu), lambda = nu / ((1 + nu) * (1 - 2 * nu));
    const double bbar = 0.5 * u.dot(unit_hex_stiffness_bbar(nu) * u);
    const double tri = 0.5 * u.dot(unit_hex_stiffness(nu) * u);
    EXPECT_NEAR(bbar, 7.0 * mu / 72.0, 1e-14 * (1.0 + lambda)) << "nu " << nu;  // round-off grows with lambda
    EXPECT_NEAR(tri, mu * (1.0 / 12 + 1.0 / 24) + lambda / 24, 1e-12 * tri) << "nu " << nu;
  }
}

TEST(HexElementBbar, TrilinearIsUnchanged) {
  // The formulation switch returns the trilinear stiffness bit for bit (shipped scenes must not move).
  for (const double nu : {0.0, 0.3, 0.45}) {
    EXPECT_EQ(unit_hex_stiffness(nu, HexFormulation::trilinear), unit_hex_stiffness(nu));
    EXPECT_EQ(unit_hex_stiffness(nu, HexFormulation::bbar), unit_hex_stiffness_bbar(nu));
  }
}

// ---- the cantilever of issue 17 §3 -----------------------------------------------------------------------------

// The 0.1 x 0.02 x 0.02 m beam of cantilever_test.cpp (E = 1e7 Pa, rho = 1000 kg/m^3), clamped on x = 0, under
// gravity along -z, uniform at `level` (level 5: 20 x 4 x 4 elements). Returns the downward deflection of the tip
// centre (0.1, 0, 0), m.
double cantilever_tip(int level, double nu, HexFormulation element) {
  constexpr double kL = 0.1, kB = 0.02;
  MaterialParams p;
  p.young_modulus = 1e7;
  p.poisson_ratio = nu;
  p.density = 1000.0;
  p.element = element;
  HandleSpec clamp{{Vec3(-1, -1, -1), Vec3(1e-9, 1, 1)}, {}};
  const ObjectModel m = test::box_model({Vec3(0, -kB / 2, -kB / 2), Vec3(kL, kB / 2, kB / 2)}, Vec3(0, -0.08, -0.08),
                                        0.16, level, {}, {clamp}, p);
  SimulatorOptions o;
  o.dynamic = false;
  o.linear_solver = "cholmod";
  // Newton stops at a residual of 1e-8 of the load; at level 6 and nu = 0.49 that is below the round-off of the
  // forces (bulk modulus 17 E), so the finest mesh stops at 1e-7 (the deflection is then still good to ~1e-6).
  o.tolerance = level >= 6 ? 1e-7 : 1e-8;
  o.gravity = Vec3(0, 0, -9.81);
  Simulator sim(m, o);
  EXPECT_TRUE(sim.solve_static(0.0));
  return -sim.position(*m.embed(Vec3(kL, 0, 0))).z();
}

// Converged tip deflections, m, from another code (CalculiX, C3D20R 60 x 12 x 12; sim/reference/
// cantilever_reference.hpp): the last refinement of that sequence moves them by 0.05% (nu = 0.3) and 0.24% (nu =
// 0.49), so they are converged to well within the 1% and 5% tolerances they check (what is left is the clamp's corner
// singularity, which converges slowly and only raises the nearly incompressible value, by about 0.3% by
// extrapolation). The corotational model is geometrically nonlinear but deflects by 0.4% of the length, so the linear
// reference differs from its answer by O(1e-5) only.
constexpr double kCcxTip03 = ::octocut::test::kCantileverTipNu03, kCcxTip049 = ::octocut::test::kCantileverTipNu049;

TEST(CantileverBbar, NearlyIncompressibleBeamComesWithinFivePercentAtLevel5) {
  const double bbar = cantilever_tip(5, 0.49, HexFormulation::bbar);
  const double tri = cantilever_tip(5, 0.49, HexFormulation::trilinear);
  std::printf("nu 0.49 level 5 (20x4x4): bbar %.6e (%+.2f%%), trilinear %.6e (%+.2f%%), reference %.6e\n", bbar,
              100 * (bbar / kCcxTip049 - 1), tri, 100 * (tri / kCcxTip049 - 1), kCcxTip049);
  EXPECT_LT(std::abs(bbar / kCcxTip049 - 1.0), 0.05);
  // The trilinear element locks: more than 20% too stiff (the issue measured 27%), which B-bar cures.
  EXPECT_LT(tri, 0.8 * kCcxTip049);
}

TEST(CantileverBbar, CompressibleBeamComesWithinOnePercentOfConverged) {
  // At nu = 0.3 B-bar lies within 1% of the converged deflection at level 5, where the trilinear element is still
  // 4% stiff (cantilever_test.cpp). Issue 17 asks that results "move by less than 1%" at nu = 0.3; against the
  // trilinear element on the same mesh they move by 3.3% (0.87% at level 6), all of it towards the converged value:
  // in the trilinear element's bending mode the divergence is not zero at the Gauss points, so its volumetric energy
  // stiffens bending at any nu > 0, and removing it is the cure for locking. The variant that relaxes only the
  // lambda term (mu part fully integrated, also free of locking and patch-test exact) was measured too: it moves by
  // 2.2% and lands 2.0% short of converged (3.554e-4 m, -2.7%, at nu = 0.49). A variant that projects only the bulk
  // modulus above that of some nu_c moves by under 1% from about nu_c = 0.22 on (measured: 1.2% at 0.2, 0.7% at
  // 0.25), but only by keeping the trilinear element's error (nu_c = 0.25: -3.4% here, -4.0% at nu = 0.49;
  // docs/RESULTS.md, "A threshold variant"), so it is not used.
  const double bbar = cantilever_tip(5, 0.3, HexFormulation::bbar);
  const double tri = cantilever_tip(5, 0.3, HexFormulation::trilinear);
  std::printf("nu 0.3 level 5 (20x4x4): bbar %.6e (%+.2f%%), trilinear %.6e (%+.2f%%), reference %.6e\n", bbar,
              100 * (bbar / kCcxTip03 - 1), tri, 100 * (tri / kCcxTip03 - 1), kCcxTip03);
  EXPECT_LT(std::abs(bbar / kCcxTip03 - 1.0), 0.01);
  // It moves towards the converged value, never past it.
  EXPECT_GT(bbar, tri);
  EXPECT_LT(bbar, kCcxTip03);
  // The reference itself lies between the beam theories: Euler-Bernoulli q L^4 / (8 E I) and Timoshenko, which adds
  // q L^2 / (2 k G A) with k = 5/6 (both m).
  const double A = 0.02 * 0.02, I = std::pow(0.02, 4) / 12.0, q = 1000.0 * 9.81 * A, L = 0.1, E = 1e7;
  const double euler_bernoulli = q * std::pow(L, 4) / (8 * E * I);
  const double timoshenko = euler_bernoulli + q * L * L / (2 * (5.0 / 6.0) * E / (2 * 1.3) * A);
  EXPECT_GT(kCcxTip03, euler_bernoulli);
  EXPECT_LT(kCcxTip03, timoshenko);
}

TEST(CantileverBbar, RefiningConvergesToTheReference) {
  // Level 4 (10 x 2 x 2) to level 6 (40 x 8 x 8) at nu = 0.49: the error shrinks, and level 6 is within 2%.
  const double e4 = std::abs(cantilever_tip(4, 0.49, HexFormulation::bbar) / kCcxTip049 - 1.0);
  const double e5 = std::abs(cantilever_tip(5, 0.49, HexFormulation::bbar) / kCcxTip049 - 1.0);
  const double e6 = std::abs(cantilever_tip(6, 0.49, HexFormulation::bbar) / kCcxTip049 - 1.0);
  std::printf("nu 0.49 bbar relative error: level 4 %.3f%%, level 5 %.3f%%, level 6 %.3f%%\n", 100 * e4, 100 * e5,
              100 * e6);
  EXPECT_LT(e6, e4);
  EXPECT_LT(e6, 0.02);
}

}  // namespace
}  // namespace octocut::sim
