// Issue 2 stability matrix on the 1 cm cube of 10 x 10 x 10 leaves: stiff, nearly incompressible, huge steps, a
// crush to 5% of the height, and a 360 degree twist all run without a failed step and without an attempt rejected for
// NaN, speed or the linear solve, and stay bounded. The energy guard (SimulatorOptions::energy_guard) may retry an
// attempt whose energy rose without work put in: the B-bar crush retries one step that way.
#include <gtest/gtest.h>

#include "test_util.hpp"

namespace octocut::sim {
namespace {

struct Case {
  double young = 5e4, nu = 0.45, dt = 1e-3, duration = 0.1;
  std::vector<PoseKeyframe> top;  // keyframes of a handle on the top face (none: top free)
  HexFormulation element = HexFormulation::trilinear;
};

void expect_stable(const Case& c) {
  MaterialParams p;
  p.young_modulus = c.young;
  p.poisson_ratio = c.nu;
  p.element = c.element;
  std::vector<HandleSpec> handles{{{Vec3(-1, -1, -1), Vec3(1, 1, 1e-9)}, {}}};
  if (!c.top.empty()) handles.push_back({{Vec3(-1, -1, 0.01 - 1e-9), Vec3(1, 1, 1)}, c.top});
  const ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(0.01, 0.01, 0.01)}, Vec3(0, 0, 0), 0.016, 4, {},
                                        handles, p);
  ASSERT_EQ(m.num_elements(), 1000);
  SimulatorOptions o;
  o.dt = c.dt;
  o.tolerance = 1e-6;
  o.max_iterations = 500;
  Simulator sim(m, o);
  const int steps = int(std::lround(c.duration / c.dt));
  double max_extent = 0.0;
  for (int i = 0; i < steps; ++i) {
    sim.step();
    for (const Vec3& x : sim.state().x) {
      ASSERT_TRUE(x.allFinite()) << "step " << i;
      max_extent = std::max(max_extent, (x - Vec3(0.005, 0.005, 0.005)).norm());
    }
  }
  // Stable: no attempt was rejected for NaN, speed or the solve, none reset; a retry is the energy guard's alone.
  const StabilityStats& st = sim.stats();
  std::printf("recoveries %d (energy rejections %d), failed steps %d, max speed %.3g m/s, max extent %.3g m\n",
              st.recoveries, st.energy_rejections, st.failed_steps, st.max_speed, max_extent);
  EXPECT_EQ(st.failed_steps, 0);
  EXPECT_LE(st.recoveries, st.energy_rejections);
  EXPECT_EQ(st.solver_failures, 0);
  EXPECT_EQ(st.nonfinite, 0);
  EXPECT_EQ(st.speed_limit, 0);
  // Bounded: nothing leaves a 5 cm ball around the cube centre.
  EXPECT_LT(max_extent, 0.05);
}

TEST(Stability, StiffMaterial) {
  Case c;
  c.young = 1e9;
  expect_stable(c);
}

TEST(Stability, NearlyIncompressible) {
  Case c;
  c.nu = 0.499;
  expect_stable(c);
}

TEST(Stability, HugeTimeStep) {
  Case c;
  c.dt = 0.05;
  c.duration = 1.0;
  expect_stable(c);
}

TEST(Stability, CrushToFivePercentOfHeight) {
  Case c;
  c.dt = 5e-3;
  c.duration = 0.6;
  c.top = {{0.5, Vec3(0, 0, -0.0095), Vec3::Zero()}};
  expect_stable(c);
}

TEST(Stability, TwistTopFaceByFullTurn) {
  Case c;
  c.dt = 5e-3;
  c.duration = 1.0;
  // Quarter turns: the rotation between keyframes is interpolated along the shorter arc, so one keyframe at 360
  // degrees would not turn at all.
  c.top = {{0.25, Vec3::Zero(), Vec3(0, 0, 90)},
           {0.5, Vec3::Zero(), Vec3(0, 0, 180)},
           {0.75, Vec3::Zero(), Vec3(0, 0, 270)},
           {1.0, Vec3::Zero(), Vec3(0, 0, 360)}};
  expect_stable(c);
}

// The hard cases again with B-bar hexahedra (issue 17 §3), which do not lock: nearly incompressible and crushed
// (the twist, 35 s on a loaded machine, is left to the stability study).
TEST(Stability, NearlyIncompressibleBbar) {
  Case c;
  c.nu = 0.499;
  c.element = HexFormulation::bbar;
  expect_stable(c);
}

TEST(Stability, CrushToFivePercentOfHeightBbar) {
  Case c;
  c.dt = 5e-3;
  c.duration = 0.6;
  c.top = {{0.5, Vec3(0, 0, -0.0095), Vec3::Zero()}};
  c.element = HexFormulation::bbar;
  expect_stable(c);
}

}  // namespace
}  // namespace octocut::sim
