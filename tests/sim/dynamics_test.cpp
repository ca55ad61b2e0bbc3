// Implicit Euler: free fall against the analytic solution, energy never increases without damping, guards recover.
#include <gtest/gtest.h>

#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/parallel.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

MaterialParams soft() {
  MaterialParams p;
  p.young_modulus = 5e4;
  p.poisson_ratio = 0.45;
  p.density = 1000.0;
  return p;
}

// The 1 cm soft cube in a root cube of edge `root_size` at `level`, its bottom face clamped.
ObjectModel clamped_cube(double root_size, int level) {
  const HandleSpec clamp{{Vec3(-1, -1, -1), Vec3(1, 1, 1e-9)}, {}};
  return test::box_model({Vec3(0, 0, 0), Vec3(0.01, 0.01, 0.01)}, Vec3(0, 0, 0), root_size, level, {}, {clamp},
                         soft());
}

TEST(Dynamics, UnconstrainedBlockFallsAsTheAnalyticFreeFall) {
  const ObjectModel m =
      test::box_model({Vec3(0, 0, 0), Vec3(0.01, 0.01, 0.01)}, Vec3(0, 0, 0), 0.01, 2, {}, {}, soft());
  SimulatorOptions o;
  o.dt = 1e-3;
  o.gravity = Vec3(0, 0, -9.81);
  o.tolerance = 1e-12;
  Simulator sim(m, o);
  const int steps = 50;
  for (int i = 0; i < steps; ++i) sim.step();
  // Backward Euler on x'' = g: v_n = g n dt, x_n = x_0 + g dt^2 n (n + 1) / 2, and the block stays undeformed.
  const double t = steps * o.dt;
  const double drop = 9.81 * o.dt * o.dt * steps * (steps + 1) / 2.0;
  for (int d = 0; d < m.num_dofs(); ++d) {
    const Vec3 expected = m.dofs().dof_rest[std::size_t(d)] - Vec3(0, 0, drop);
    EXPECT_NEAR((sim.state().x[std::size_t(d)] - expected).norm(), 0.0, 1e-12);
    EXPECT_NEAR(sim.state().v[std::size_t(d)].z(), -9.81 * t, 1e-10);
  }
  // And it converges to the continuous free fall 1/2 g t^2 with error g t dt / 2.
  EXPECT_NEAR(drop, 0.5 * 9.81 * t * t, 0.5 * 9.81 * t * o.dt + 1e-15);
  EXPECT_EQ(sim.stats().recoveries, 0);
}

TEST(Dynamics, UndampedImplicitEulerNeverIncreasesEnergy) {
  // A cube clamped at the bottom, released from a stretched and sheared state, gravity off.
  const ObjectModel m = clamped_cube(0.01, 3);
  SimulatorOptions o;
  o.dt = 2e-3;
  o.gravity = Vec3::Zero();
  o.tolerance = 1e-12;
  o.linear_solver = "cholmod";
  Simulator sim(m, o);
  SimState s = sim.state();
  for (std::size_t d = 0; d < s.x.size(); ++d) {
    const Vec3 X = s.x[d];
    s.x[d] = X + Vec3(0.3 * X.z(), 0.0, 0.2 * X.z());
  }
  sim.set_state(s);
  double energy = sim.kinetic_energy() + sim.elastic_energy();
  const double e0 = energy;
  for (int i = 0; i < 200; ++i) {
    sim.step();
    const double e = sim.kinetic_energy() + sim.elastic_energy();
    ASSERT_LE(e, energy * (1 + 1e-9) + 1e-12 * e0) << "step " << i;
    energy = e;
  }
  EXPECT_LT(energy, e0);
  EXPECT_GT(energy, 0.0);
}

// PCG starts each solve from the last increments extrapolated along the steps (Simulator::warm_start): the
// trajectory of a released, sheared cube still follows the direct solver's to the tolerance, before and after a
// state reset (which restarts the extrapolation), and late in each round the solves need fewer iterations than when
// every step starts from the last increment alone (a set_state before every step drops the history, nothing else).
// The PCG runs use the Jacobi preconditioner, the same in both: with the lagged factor, when its refresh falls (a
// rule on the iterations paid) decides the comparison (with a factor never refreshed, the extrapolated start takes 126
// late iterations and the last increment 124: docs/RESULTS.md).
TEST(Dynamics, ExtrapolatedWarmStartFollowsTheDirectSolversTrajectory) {
  const ObjectModel m = clamped_cube(0.01, 3);
  struct Run {
    const char* solver;
    bool reset_every_step;
    std::vector<std::vector<Vec3>> x;  // the state after each round
    int late_iterations = 0;
  };
  std::vector<Run> runs = {{"cholmod", false, {}}, {"pcg", false, {}}, {"pcg", true, {}}};
  for (Run& run : runs) {
    SimulatorOptions o;
    o.dt = 1e-3;
    o.gravity = Vec3(0, 0, -9.81);
    o.tolerance = 1e-10;
    o.linear_solver = run.solver;
    o.preconditioner = "jacobi";
    Simulator sim(m, o);
    SimState s = sim.state();
    for (std::size_t d = 0; d < s.x.size(); ++d) s.x[d] += Vec3(0.2 * s.x[d].z(), 0.0, 0.0);
    for (int round = 0; round < 2; ++round) {
      sim.set_state(s);
      for (int i = 0; i < 60; ++i) {
        if (run.reset_every_step) sim.set_state(sim.state());
        sim.step();
        if (i >= 40) run.late_iterations += sim.last_solve().iterations;
      }
      run.x.push_back(sim.state().x);
    }
    EXPECT_EQ(sim.stats().recoveries, 0);
  }
  for (std::size_t k = 1; k < runs.size(); ++k)
    for (std::size_t r = 0; r < 2; ++r)
      for (std::size_t d = 0; d < runs[0].x[r].size(); ++d)
        ASSERT_LT((runs[k].x[r][d] - runs[0].x[r][d]).norm(), 1e-9) << "run " << k << ", round " << r << ", DOF " << d;
  EXPECT_LT(runs[1].late_iterations, runs[2].late_iterations);
}

TEST(Dynamics, StepsThatFailAtEveryDtEndInADefinedReset) {
  // A very low speed limit makes every full step fail; halved steps pass. The run never aborts.
  const ObjectModel m = clamped_cube(0.01, 2);
  SimulatorOptions o;
  o.dt = 0.02;
  o.max_speed = 1e-9;
  Simulator sim(m, o);
  for (int i = 0; i < 5; ++i) sim.step();
  EXPECT_NEAR(sim.state().t, 0.1, 1e-12);
  EXPECT_GT(sim.stats().speed_limit, 0);
  EXPECT_EQ(sim.stats().failed_steps, 5);  // nothing can go below 1e-9 m/s under gravity: defined reset
  for (const Vec3& v : sim.state().v) EXPECT_EQ(v.norm(), 0.0);
  for (const Vec3& x : sim.state().x) EXPECT_TRUE(x.allFinite());
}

TEST(Dynamics, HalvedStepsRecoverWhereTheFullStepFails) {
  // Jacobi-PCG with an iteration cap: the full step's system (M + dt^2 K) is too ill-conditioned to converge in
  // time, the halved steps' systems are not. The step must recover without a reset and still reach t + dt.
  const ObjectModel m = clamped_cube(0.016, 4);
  SimulatorOptions o;
  o.dt = 8e-3;
  o.linear_solver = "pcg";
  o.preconditioner = "jacobi";
  o.tolerance = 1e-4;
  o.max_iterations = 60;
  Simulator sim(m, o);
  for (int i = 0; i < 3; ++i) sim.step();
  EXPECT_NEAR(sim.state().t, 3 * o.dt, 1e-12);
  EXPECT_GT(sim.stats().solver_failures, 0);
  EXPECT_GT(sim.stats().recoveries, 0);
  EXPECT_EQ(sim.stats().failed_steps, 0);
  for (const Vec3& x : sim.state().x) EXPECT_TRUE(x.allFinite());
  std::printf("recoveries %d, solver failures %d\n", sim.stats().recoveries, sim.stats().solver_failures);
}

TEST(Dynamics, StaticNewtonSolveBalancesGravity) {
  // Total vertical reaction of the clamp equals the weight.
  const ObjectModel m = clamped_cube(0.01, 3);
  SimulatorOptions o;
  o.dynamic = false;
  o.tolerance = 1e-10;
  o.linear_solver = "cholmod";
  Simulator sim(m, o);
  ASSERT_TRUE(sim.solve_static(0.0));
  Executor ex(1);
  FemSystem fem(sim.model(), ex);
  ElementFrame frame;
  fem.rotations(sim.state().x, frame);
  VecX f;
  fem.elastic_force(sim.state().x, frame, f);
  // Internal forces sum to zero, so the clamped nodes' elastic forces carry the weight of every free DOF.
  double reaction = 0.0, weight = 0.0, free_weight = 0.0;
  for (int d = 0; d < m.num_dofs(); ++d) {
    weight += m.dof_mass()[std::size_t(d)] * 9.81;
    if (m.dof_handle()[std::size_t(d)] >= 0)
      reaction += f[3 * d + 2];
    else
      free_weight += m.dof_mass()[std::size_t(d)] * 9.81;
  }
  EXPECT_NEAR(weight, 1000.0 * 1e-6 * 9.81, 1e-15);
  EXPECT_NEAR(-reaction, free_weight, 1e-8 * weight);
  EXPECT_NEAR(free_weight, weight * 15.0 / 16.0, 1e-12);  // the clamped bottom layer holds 1/16 of the mass
}

}  // namespace
}  // namespace octocut::sim
