// The static Newton solve (Simulator::solve_static) near incompressibility, and the tangent it uses. The tangent is
// the corotated stiffness R K R^T: checked against finite differences of the full nonlinear force, it differs by a
// term of the order of the strain (dR/dx), which the analytic full derivative below accounts for to round-off. The
// truth for the solve is the equilibrium itself, found by plain undamped Newton on a dense matrix in this file.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <random>

#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/hex_element.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/simulator.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

Mat3 cross_matrix(const Vec3& a) {
  Mat3 m;
  m << 0.0, -a.z(), a.y(), a.z(), 0.0, -a.x(), -a.y(), a.x(), 0.0;
  return m;
}

// The full derivative -df/dx of the corotated force f = -R K u, u = R^T (x - x_c) - (X - X_c), R the polar rotation
// of the centre gradient F = sum_b x_b g_b^T / h. With dR = R [w]x, R^T dF - dF^T R = [(tr S I - S) w]x (S = R^T F),
// so w = (tr S I - S)^-1 sum_b [g_b]x R^T dx_b / h, and in the element frame (z = R^T dx, y_b = R^T (x_b - x_c)):
// -R^T df = K z + (K Y - C) w, Y the [y_b]x and C the [(K u)_a]x stacked (24 x 3).
Mat24 full_tangent(const Mat24& K, const Vec24& x, const Vec24& X, double h) {
  Eigen::Matrix<double, 3, 8> xm;
  for (int a = 0; a < 8; ++a) xm.col(a) = x.segment<3>(3 * a);
  const Mat3 F = hex_center_gradient(xm, h);
  const Mat3 R = polar_rotation(F);
  const Mat3 S = R.transpose() * F;
  const Mat3 G = (S.trace() * Mat3::Identity() - S).inverse();
  const Vec24 ku = K * corotated_displacement(R, x, X);
  const Vec3 xc = xm.rowwise().mean();
  Eigen::Matrix<double, 24, 3> Y, C;
  Eigen::Matrix<double, 3, 24> W;
  for (int b = 0; b < 8; ++b) {
    const Vec3 g(((b & 1) ? 0.25 : -0.25), ((b & 2) ? 0.25 : -0.25), ((b & 4) ? 0.25 : -0.25));
    Y.block<3, 3>(3 * b, 0) = cross_matrix(R.transpose() * (xm.col(b) - xc));
    C.block<3, 3>(3 * b, 0) = cross_matrix(ku.segment<3>(3 * b));
    W.block<3, 3>(0, 3 * b) = G * cross_matrix(g) / h;
  }
  const Mat24 local = K + (K * Y - C) * W;
  Mat24 out;
  for (int a = 0; a < 8; ++a)
    for (int b = 0; b < 8; ++b) out.block<3, 3>(3 * a, 3 * b) = R * local.block<3, 3>(3 * a, 3 * b) * R.transpose();
  return out;
}

TEST(CorotatedTangent, OmitsOnlyTheRotationDerivativeWhichScalesWithTheStrain) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> r(-1, 1);
  const double h = 0.01;
  for (const HexFormulation e : {HexFormulation::trilinear, HexFormulation::bbar}) {
    for (const double nu : {0.3, 0.499}) {
      for (const double strain : {0.01, 0.1}) {
        const Mat24 K = 1e4 * h * unit_hex_stiffness(nu, e);
        Mat3 G;
        for (int k = 0; k < 9; ++k) G(k / 3, k % 3) = strain * r(rng);
        const Mat3 Q = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
        Vec24 X, x;
        for (int a = 0; a < 8; ++a) {
          X.segment<3>(3 * a) = h * Vec3(a & 1, (a >> 1) & 1, (a >> 2) & 1);
          x.segment<3>(3 * a) = Q * ((Mat3::Identity() + G) * X.segment<3>(3 * a));
        }
        auto force = [&](const Vec24& y) {
          Eigen::Matrix<double, 3, 8> ym;
          for (int a = 0; a < 8; ++a) ym.col(a) = y.segment<3>(3 * a);
          return Vec24(corotated_force(K, polar_rotation(hex_center_gradient(ym, h)), y, X));
        };
        Mat24 fd;
        const double eps = 1e-7 * h;
        for (int i = 0; i < 24; ++i) {
          Vec24 p = x, m = x;
          p[i] += eps;
          m[i] -= eps;
          fd.col(i) = -(force(p) - force(m)) / (2 * eps);
        }
        Eigen::Matrix<double, 3, 8> xm;
        for (int a = 0; a < 8; ++a) xm.col(a) = x.segment<3>(3 * a);
        const double used = (fd - corotated_stiffness(K, polar_rotation(hex_center_gradient(xm, h)))).norm() / fd.norm();
        const double full = (fd - full_tangent(K, x, X, h)).norm() / fd.norm();
        std::printf("%s nu %g strain %g: |FD - R K R^T| / |FD| = %.2e, |FD - full| / |FD| = %.2e\n",
                    e == HexFormulation::bbar ? "bbar" : "trilinear", nu, strain, used, full);
        EXPECT_LT(full, 1e-6);
        // What the corotated stiffness leaves out is of the order of the strain, not of the bulk modulus.
        EXPECT_GT(used, 0.01 * strain);
        EXPECT_LT(used, 2.0 * strain);
      }
    }
  }
}

// The 0.1 x 0.02 x 0.02 m cantilever of bbar_test.cpp at level 4 (10 x 2 x 2), clamped at x = 0, under gravity.
ObjectModel cantilever(double nu, HexFormulation e) {
  MaterialParams p;
  p.young_modulus = 1e7;
  p.poisson_ratio = nu;
  p.density = 1000.0;
  p.element = e;
  HandleSpec clamp{{Vec3(-1, -1, -1), Vec3(1e-9, 1, 1)}, {}};
  return test::box_model({Vec3(0, -0.01, -0.01), Vec3(0.1, 0.01, 0.01)}, Vec3(0, -0.08, -0.08), 0.16, 4, {}, {clamp},
                         p);
}

// Equilibrium by plain Newton (full steps, dense LU of R K R^T with identity rows for the clamped DOFs), DOFs (m).
std::vector<Vec3> plain_newton(const ObjectModel& m) {
  Executor ex(1);
  FemSystem fem(m, ex);
  const int nd = m.num_dofs(), n = 3 * nd;
  VecX fext = VecX::Zero(n);
  for (int d = 0; d < nd; ++d)
    if (m.dof_handle()[std::size_t(d)] < 0) fext.segment<3>(3 * d) = m.dof_mass()[std::size_t(d)] * Vec3(0, 0, -9.81);
  std::vector<Vec3> x = m.dofs().dof_rest;
  for (int it = 0; it < 12; ++it) {
    ElementFrame frame;
    fem.rotations(x, frame);
    VecX r;
    fem.elastic_force(x, frame, r);
    r += fext;
    Eigen::MatrixXd T(fem.stiffness(frame));
    for (int d = 0; d < nd; ++d) {
      if (m.dof_handle()[std::size_t(d)] < 0) continue;
      for (int k = 0; k < 3; ++k) {
        r[3 * d + k] = 0.0;
        T.row(3 * d + k).setZero();
        T.col(3 * d + k).setZero();
        T(3 * d + k, 3 * d + k) = 1.0;
      }
    }
    const VecX dx = T.partialPivLu().solve(r);
    for (int d = 0; d < nd; ++d) x[std::size_t(d)] += dx.segment<3>(3 * d);
  }
  return x;
}

TEST(StaticNewton, NearlyIncompressibleCantileverReachesEquilibrium) {
  // At nu = 0.499 the first full Newton step raises the residual by two to three orders of magnitude (bulk modulus
  // times second-order volume change) although it is right to second order; the damping must not shrink it.
  for (const HexFormulation e : {HexFormulation::bbar, HexFormulation::trilinear}) {
    for (const double nu : {0.49, 0.499}) {
      const ObjectModel m = cantilever(nu, e);
      const std::vector<Vec3> truth = plain_newton(m);
      SimulatorOptions o;
      o.dynamic = false;
      o.linear_solver = "cholmod";
      o.tolerance = 1e-7;  // above the round-off of the forces at nu = 0.499 (bulk modulus 167 E): ~3e-8
      o.max_iterations = 10;
      o.gravity = Vec3(0, 0, -9.81);
      Simulator sim(m, o);
      EXPECT_TRUE(sim.solve_static(0.0)) << "nu " << nu;
      const PointEmbedding tip = *m.embed(Vec3(0.1, 0, 0));
      const double got = sim.position(tip).z();
      SimState s = SimState::rest(m);
      s.x = truth;
      sim.set_state(s);
      const double truth_tip = sim.position(tip).z();
      std::printf("%s nu %g: tip %.9e m, plain Newton %.9e m\n", e == HexFormulation::bbar ? "bbar" : "trilinear", nu,
                  got, truth_tip);
      EXPECT_NEAR(got, truth_tip, 1e-6 * std::abs(truth_tip)) << "nu " << nu;
      // It bends down: by about 0.35 mm with B-bar, by 0.1-0.2 mm with the locking trilinear element.
      EXPECT_LT(got, e == HexFormulation::bbar ? -3e-4 : -5e-5);
    }
  }
}

}  // namespace
}  // namespace octocut::sim
