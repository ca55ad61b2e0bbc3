// The clamped cantilever under gravity (issue 2): convergence between Euler-Bernoulli and Timoshenko, and an
// adaptively refined mesh matching the uniform fine one.
#include <gtest/gtest.h>

#include <cmath>

#include "test_util.hpp"

namespace octocut::sim {
namespace {

constexpr double kL = 0.1, kB = 0.02, kE = 1e7, kNu = 0.3, kRho = 1000.0, kG = 9.81;

struct Result {
  double tip = 0.0;  // downward tip deflection, m
  int elements = 0;
};

ObjectModel beam(int base_level, std::vector<RefineSpec> refine = {}, double rayleigh_mass = 0.0) {
  MaterialParams p;
  p.young_modulus = kE;
  p.poisson_ratio = kNu;
  p.density = kRho;
  p.rayleigh_mass = rayleigh_mass;
  HandleSpec clamp{{Vec3(-1, -1, -1), Vec3(1e-9, 1, 1)}, {}};
  return test::box_model({Vec3(0, -kB / 2, -kB / 2), Vec3(kL, kB / 2, kB / 2)}, Vec3(0, -0.08, -0.08), 0.16,
                         base_level, std::move(refine), {clamp}, p);
}

Result solve(int base_level, std::vector<RefineSpec> refine = {}) {
  const ObjectModel m = beam(base_level, std::move(refine));
  SimulatorOptions o;
  o.dynamic = false;
  o.linear_solver = "cholmod";
  o.tolerance = 1e-8;
  o.gravity = Vec3(0, 0, -kG);
  Simulator sim(m, o);
  EXPECT_TRUE(sim.solve_static(0.0));
  const auto tip = m.embed(Vec3(kL, 0, 0));
  EXPECT_TRUE(tip);
  return {-(sim.position(*tip).z()), m.num_elements()};
}

TEST(Cantilever, UniformRefinementConvergesMonotonicallyBetweenBeamTheories) {
  const double A = kB * kB, I = kB * kB * kB * kB / 12.0, q = kRho * kG * A;
  const double euler_bernoulli = q * std::pow(kL, 4) / (8 * kE * I);
  const double G = kE / (2 * (1 + kNu));
  const double timoshenko = euler_bernoulli + q * kL * kL / (2 * (5.0 / 6.0) * G * A);
  const Result r4 = solve(4), r5 = solve(5), r6 = solve(6);
  EXPECT_EQ(r4.elements, 10 * 2 * 2);
  EXPECT_EQ(r6.elements, 40 * 8 * 8);
  // Monotone, with shrinking increments (trilinear hexahedra converge from the stiff side).
  EXPECT_GT(r5.tip, r4.tip);
  EXPECT_GT(r6.tip, r5.tip);
  EXPECT_LT(r6.tip - r5.tip, r5.tip - r4.tip);
  // Richardson extrapolation of the three levels estimates the converged deflection.
  const double ratio = (r5.tip - r4.tip) / (r6.tip - r5.tip);
  const double limit = r6.tip + (r6.tip - r5.tip) / (ratio - 1.0);
  std::printf("tip deflection: L4 %.6e  L5 %.6e  L6 %.6e  extrapolated %.6e  EB %.6e  Timoshenko %.6e\n", r4.tip,
              r5.tip, r6.tip, limit, euler_bernoulli, timoshenko);
  EXPECT_GT(limit, euler_bernoulli);
  EXPECT_LT(limit, timoshenko);
}

TEST(Cantilever, RefiningNearTheClampMatchesTheUniformFineMesh) {
  const Result fine = solve(6);
  const Result adaptive = solve(5, {{Box3{Vec3(-0.01, -0.02, -0.02), Vec3(0.05, 0.02, 0.02)}, 6}});
  std::printf("adaptive %d elements, tip %.6e; uniform %d elements, tip %.6e\n", adaptive.elements, adaptive.tip,
              fine.elements, fine.tip);
  EXPECT_LT(adaptive.elements, fine.elements);
  EXPECT_LT(std::abs(adaptive.tip - fine.tip), 0.01 * fine.tip);
}

TEST(Cantilever, FirstBendingPeriodMatchesEulerBernoulli) {
  // Released from rest under gravity, the beam oscillates about its static deflection in its first bending mode:
  // f1 = 1.8751^2 / (2 pi) sqrt(E I / (rho A L^4)) = 32.3 Hz. Trilinear hexahedra are slightly stiff on this mesh
  // (level 5: 4 elements through the thickness) and implicit Euler lengthens the period by O((w dt)^2), so the
  // measured period must lie within 5% of the analytic one.
  const double A = kB * kB, I = std::pow(kB, 4) / 12.0;
  const double f1 = 1.8751 * 1.8751 / (2 * M_PI) * std::sqrt(kE * I / (kRho * A * std::pow(kL, 4)));
  const ObjectModel m = beam(5);
  SimulatorOptions o;
  o.dt = 1e-4;
  o.linear_solver = "pcg";
  o.tolerance = 1e-8;
  o.gravity = Vec3(0, 0, -kG);
  Simulator sim(m, o);
  const auto tip = *m.embed(Vec3(kL, 0, 0));
  // Upward zero crossings of the tip velocity mark whole periods.
  std::vector<double> crossings;
  double prev_z = 0.0, prev_v = 0.0;
  for (int i = 0; i < 1200 && crossings.size() < 3; ++i) {
    sim.step();
    const double z = sim.position(tip).z();
    const double v = (z - prev_z) / o.dt;
    if (i > 0 && prev_v < 0.0 && v >= 0.0) crossings.push_back(sim.state().t);
    prev_z = z;
    prev_v = v;
  }
  ASSERT_EQ(crossings.size(), 3u);
  const double period = 0.5 * (crossings[2] - crossings[0]);
  std::printf("first bending period %.4f ms, Euler-Bernoulli %.4f ms\n", 1e3 * period, 1e3 / f1);
  EXPECT_NEAR(period * f1, 1.0, 0.05);
}

TEST(Cantilever, DampedDynamicsSettleToTheStaticSolution) {
  // With mass-proportional damping the dynamic beam comes to rest at the static equilibrium of the same mesh.
  const Result statics = solve(4);
  const ObjectModel m = beam(4, {}, 200.0);
  SimulatorOptions o;
  o.dt = 1e-3;
  o.tolerance = 1e-10;
  o.gravity = Vec3(0, 0, -kG);
  Simulator sim(m, o);
  for (int i = 0; i < 400; ++i) sim.step();
  const double tip = -sim.position(*m.embed(Vec3(kL, 0, 0))).z();
  EXPECT_NEAR(tip, statics.tip, 1e-6 * statics.tip);
  EXPECT_LT(sim.max_speed(), 1e-9);
}

}  // namespace
}  // namespace octocut::sim
