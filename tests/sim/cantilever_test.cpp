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

Result solve(int base_level, std::vector<RefineSpec> refine = {}) {
  MaterialParams p;
  p.young_modulus = kE;
  p.poisson_ratio = kNu;
  p.density = kRho;
  HandleSpec clamp{{Vec3(-1, -1, -1), Vec3(1e-9, 1, 1)}, {}};
  const ObjectModel m = test::box_model({Vec3(0, -kB / 2, -kB / 2), Vec3(kL, kB / 2, kB / 2)},
                                        Vec3(0, -0.08, -0.08), 0.16, base_level, std::move(refine), {clamp}, p);
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

}  // namespace
}  // namespace octocut::sim
