// An object that cuts removed entirely: the empty ObjectModel is a valid value, and a simulator without an object
// (Simulator::remove_object) only advances time.
#include "test_util.hpp"

namespace octocut::sim {
namespace {

// The model of an empty object answers every accessor with "nothing".
void expect_empty(const ObjectModel& m) {
  EXPECT_EQ(m.num_elements(), 0);
  EXPECT_EQ(m.num_dofs(), 0);
  EXPECT_TRUE(m.tree().leaves().empty());
  EXPECT_EQ(m.dofs().hanging_slots, 0);
  EXPECT_EQ(m.dofs().num_slots(), 0);
  EXPECT_TRUE(m.dof_handle().empty());
  EXPECT_TRUE(m.dof_mass().empty());
  EXPECT_TRUE(m.slot_rest().empty());
  EXPECT_TRUE(m.occupancy().empty());
  EXPECT_EQ(m.volume(), 0.0);
  EXPECT_FALSE(m.embed(Vec3::Zero()).has_value());
  EXPECT_FALSE(m.embed(Vec3(0.005, 0.005, 0.005)).has_value());
  std::vector<Vec3> slots{Vec3::Ones()};
  m.dofs().prolong({}, slots);
  EXPECT_TRUE(slots.empty());
}

// The 1 cm cube at 4 x 4 x 4 leaves, bottom clamped, top pulled up by 1 mm over 10 ms.
ObjectModel cube() {
  const HandleSpec bottom{{Vec3(-1, -1, -1), Vec3(1, 1, 1e-9)}, {}};
  const HandleSpec top{{Vec3(-1, -1, 0.01 - 1e-9), Vec3(1, 1, 1)}, {{0.01, Vec3(0, 0, 0.001), Vec3::Zero()}}};
  MaterialParams p;
  p.young_modulus = 5e4;
  return test::box_model({Vec3(0, 0, 0), Vec3(0.01, 0.01, 0.01)}, Vec3(0, 0, 0), 0.01, 2, {}, {bottom, top}, p);
}

TEST(EmptyObject, DefaultModelIsEmptyAndValid) {
  const ObjectModel m;
  expect_empty(m);
  EXPECT_TRUE(m.handles().empty());
  EXPECT_EQ(m.material().occupancy({Vec3::Zero(), Vec3::Ones()}), 0.0);
  const ObjectModel copy = m;
  expect_empty(copy);
}

TEST(EmptyObject, EmptiedKeepsTheDescriptionAndDropsTheLeaves) {
  const ObjectModel m = cube();
  ASSERT_GT(m.num_elements(), 0);
  const ObjectModel e = m.emptied();
  expect_empty(e);
  EXPECT_EQ(e.revision(), m.revision() + 1);
  EXPECT_EQ(e.handles().size(), m.handles().size());
  EXPECT_EQ(e.params().young_modulus, m.params().young_modulus);
  EXPECT_EQ(e.root().size, m.root().size);
  EXPECT_EQ(&e.material(), &m.material());
  // A rest point inside the old object has no leaf any more.
  EXPECT_TRUE(m.embed(Vec3(0.005, 0.005, 0.005)).has_value());
}

TEST(EmptyObject, RemovedObjectOnlyAdvancesTime) {
  SimulatorOptions o;
  o.dt = 1e-3;
  Simulator sim(cube(), o);
  for (int i = 0; i < 5; ++i) sim.step();
  ASSERT_FALSE(sim.empty());
  ASSERT_GT(sim.kinetic_energy(), 0.0);
  ASSERT_GT(sim.elastic_energy(), 0.0);
  const int revision = sim.model().revision();
  const StabilityStats before = sim.stats();
  const double t0 = sim.state().t;

  sim.remove_object();
  EXPECT_TRUE(sim.empty());
  expect_empty(sim.model());
  EXPECT_EQ(sim.model().revision(), revision + 1);
  EXPECT_TRUE(sim.state().x.empty());
  EXPECT_TRUE(sim.state().v.empty());
  EXPECT_EQ(sim.state().t, t0);
  EXPECT_EQ(sim.kinetic_energy(), 0.0);
  EXPECT_EQ(sim.elastic_energy(), 0.0);
  EXPECT_EQ(sim.max_speed(), 0.0);

  // Steps never fail: time runs on by dt each, nothing else changes.
  double t = t0;
  for (int i = 0; i < 20; ++i) {
    sim.step();
    t += o.dt;
    EXPECT_EQ(sim.state().t, t);
  }
  EXPECT_TRUE(sim.empty());
  EXPECT_EQ(sim.stats().failed_steps, before.failed_steps);
  EXPECT_EQ(sim.stats().recoveries, before.recoveries);
  EXPECT_EQ(sim.stats().solver_failures, before.solver_failures);
  EXPECT_EQ(sim.stats().nonfinite, before.nonfinite);
  EXPECT_EQ(sim.kinetic_energy(), 0.0);
  EXPECT_EQ(sim.elastic_energy(), 0.0);
  EXPECT_EQ(sim.max_speed(), 0.0);
  sim.refresh_solver();
  SimState later;
  later.t = 1.0;
  EXPECT_NO_THROW(sim.set_state(later));
  EXPECT_EQ(sim.state().t, 1.0);
}

TEST(EmptyObject, StaticSimulatorWithoutObjectOnlyAdvancesTime) {
  SimulatorOptions o;
  o.dynamic = false;
  o.dt = 0.01;
  Simulator sim(cube(), o);
  sim.step();
  sim.remove_object();
  for (int i = 0; i < 3; ++i) sim.step();
  EXPECT_DOUBLE_EQ(sim.state().t, 0.04);
  EXPECT_TRUE(sim.solve_static(0.5));
  EXPECT_EQ(sim.state().t, 0.5);
  EXPECT_EQ(sim.stats().newton_unconverged, 0);
  EXPECT_EQ(sim.stats().failed_steps, 0);
}

TEST(EmptyObject, SimulatorBuiltOnAnEmptyModelSteps) {
  SimulatorOptions o;
  o.dt = 0.5;
  Simulator sim(ObjectModel{}, o);
  EXPECT_TRUE(sim.empty());
  sim.step();
  sim.step();
  EXPECT_EQ(sim.state().t, 1.0);
  EXPECT_EQ(sim.stats().failed_steps, 0);
}

TEST(EmptyObject, SetModelBringsAnObjectBackAtRest) {
  SimulatorOptions o;
  o.dt = 1e-3;
  const ObjectModel m = cube();
  Simulator sim(m, o);
  sim.step();
  sim.remove_object();
  sim.step();
  sim.set_model(m);
  EXPECT_FALSE(sim.empty());
  EXPECT_EQ(sim.state().t, 2 * o.dt);
  EXPECT_EQ(sim.state().x, m.dofs().dof_rest);
  for (int i = 0; i < 5; ++i) sim.step();
  EXPECT_EQ(sim.stats().failed_steps, 0);
  EXPECT_GT(sim.kinetic_energy(), 0.0);
}

}  // namespace
}  // namespace octocut::sim
