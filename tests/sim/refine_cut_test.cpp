// Multi-level refinement in one revision (ObjectModel::refined_where) and the cut that follows it (with_material),
// against independent truths: repeated single-level refinement, and the global DOF build of the result. Field by
// field, bit for bit. The material is a tet slab on a regular grid, as in cut_model_test.
#include <gtest/gtest.h>

#include <functional>

#include "octocut/sim/dof_map.hpp"
#include "../common/kuhn_grid.hpp"
#include "octocut/sim/material_graph.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

// Tet grid: cubes of edge 1/16 over [0,1] x [0,1] x [0, 1/4] (16 x 16 x 4 cubes), 6 Kuhn tets per cube.
constexpr int kNx = 16, kNy = 16, kNz = 4;
constexpr double kCube = 1.0 / 16.0;  // m

std::shared_ptr<MaterialGraph> slab(const std::function<bool(int, int, int)>& keep) {
  return std::make_shared<MaterialGraph>(
      octocut::test::kuhn_grid(Vec3::Zero(), Vec3::Constant(kCube), {kNx, kNy, kNz}, keep));
}

// The slab in a root cube grown beyond it (so that leaves along its faces are partly empty and some children are
// dropped), level 3, with a handle on its x = 0 end.
ObjectModel slab_model(const std::shared_ptr<MaterialGraph>& material, int max_level = 7) {
  OctreeSpec spec;
  spec.root = {Vec3(-0.03, -0.03, -0.03), 1.1};
  spec.base_level = 3;
  spec.max_level = max_level;
  HandleSpec handle;
  handle.box = {Vec3(-1, -1, -1), Vec3(0.1, 2, 2)};
  return ObjectModel::build(spec, material, {}, {handle});
}

using test::expect_same;

void expect_same(const ObjectModel& a, const ObjectModel& b) {
  EXPECT_EQ(a.tree().leaves(), b.tree().leaves());
  EXPECT_EQ(a.occupancy(), b.occupancy());
  EXPECT_EQ(a.edge(), b.edge());
  EXPECT_EQ(a.stiffness_scale(), b.stiffness_scale());
  EXPECT_EQ(a.slot_rest(), b.slot_rest());
  EXPECT_EQ(a.dof_mass(), b.dof_mass());
  EXPECT_EQ(a.dof_handle(), b.dof_handle());
  expect_same(a.dofs(), b.dofs());
}

// The refine loop of cutting stage 4, one revision per level: refined() on every leaf that `split` accepts.
ObjectModel refine_level_by_level(ObjectModel m, const std::function<bool(const Cell&)>& split, int& refined) {
  refined = 0;
  for (;;) {
    std::vector<int> pick;
    for (int e = 0; e < m.num_elements(); ++e)
      if (m.tree().leaf(e).level < m.max_level() && split(m.tree().leaf(e))) pick.push_back(e);
    if (pick.empty()) return m;
    refined += int(pick.size());
    m = m.refined(pick);
  }
}

// Leaves whose closed box meets the segment-like box `b` (a blade stand-in) and are coarser than `level`.
std::function<bool(const Cell&)> meets(const RootGeometry& root, const Box3& b, int level) {
  return [root, b, level](const Cell& c) {
    const Box3 box = root.cell_box(c);
    return c.level < level && (box.min.array() <= b.max.array()).all() && (b.min.array() <= box.max.array()).all();
  };
}

TEST(RefineWhere, EqualsRepeatedSingleLevelRefinement) {
  const auto material = slab([](int, int, int) { return true; });
  const ObjectModel m = slab_model(material);
  const Box3 blade{Vec3(0.41, 0.43, -0.1), Vec3(0.47, 0.49, 0.3)};
  for (int level : {4, 5, 6, 7, 9}) {
    int expected_count = 0, count = 0;
    const auto split = meets(m.root(), blade, level);
    const ObjectModel a = refine_level_by_level(m, split, expected_count);
    const ObjectModel b = m.refined_where(split, &count);
    SCOPED_TRACE(level);
    EXPECT_GT(expected_count, 0);
    EXPECT_EQ(count, expected_count);
    EXPECT_EQ(b.revision(), m.revision() + 1);
    expect_same(a, b);
    expect_same(b.dofs(), build_dof_map(b.tree(), b.root(), b.material()));
    EXPECT_EQ(b.dofs().check_invariants(), "");
    EXPECT_LE(b.tree().leaves().back().level, m.max_level());
  }
}

TEST(RefineWhere, DropsEmptyChildrenAtEveryLevel) {
  // The blade box runs along the slab's top face z = 1/4, which halves leaves of every level there: children above
  // the face are empty and must go with their subtrees, as refined() drops them.
  const auto material = slab([](int, int, int) { return true; });
  const ObjectModel m = slab_model(material);
  const Box3 blade{Vec3(0.2, 0.2, 0.24), Vec3(0.7, 0.3, 0.26)};
  int expected_count = 0;
  const ObjectModel a = refine_level_by_level(m, meets(m.root(), blade, 6), expected_count);
  int count = 0;
  const ObjectModel b = m.refined_where(meets(m.root(), blade, 6), &count);
  EXPECT_EQ(count, expected_count);
  EXPECT_LT(b.num_elements(), m.num_elements() + 7 * count);  // some children were empty
  expect_same(a, b);
  expect_same(b.dofs(), build_dof_map(b.tree(), b.root(), b.material()));
  for (double occ : b.occupancy()) EXPECT_GE(occ, kEmptyOccupancy);
}

TEST(RefineWhere, NothingToSplitIsTheSameModel) {
  const ObjectModel m = slab_model(slab([](int, int, int) { return true; }));
  int calls = 0;
  const ObjectModel r = m.refined_where([&](const Cell&) {
    ++calls;
    return false;
  });
  EXPECT_EQ(calls, m.num_elements());
  EXPECT_EQ(r.revision(), m.revision());
  expect_same(r, m);
  // Leaves at max_level are never split and never asked about.
  const ObjectModel fine = slab_model(slab([](int, int, int) { return true; }), 3);
  calls = 0;
  const ObjectModel f = fine.refined_where([&](const Cell&) {
    ++calls;
    return true;
  });
  EXPECT_EQ(calls, 0);
  EXPECT_EQ(f.num_elements(), fine.num_elements());
}

TEST(RefineWhere, ThenACutEqualsTheGlobalBuildAndTheLevelByLevelPath) {
  // Stage 4 of a cut on the slab: a punch through cubes (7..8, 7..8) refined to level 6, then the new material.
  const auto material = slab([](int, int, int) { return true; });
  const auto punched = slab([](int i, int j, int) { return !((i == 7 || i == 8) && (j == 7 || j == 8)); });
  const Box3 changed{kCube * Vec3(7, 7, 0), kCube * Vec3(9, 9, kNz)};
  const ObjectModel m = slab_model(material);
  const auto split = meets(m.root(), changed, 6);
  int count = 0;
  const ObjectModel a = refine_level_by_level(m, split, count).with_material(punched, {changed});
  const ObjectModel r = m.refined_where(split);
  const ObjectModel b = r.with_material(punched, {changed});
  expect_same(a, b);
  expect_same(b.dofs(), build_dof_map(b.tree(), b.root(), *punched));
  EXPECT_EQ(b.dofs().check_invariants(), "");
  // In one revision: the same model, and with_material on it with its own material changes nothing.
  int combined_count = 0;
  const ObjectModel one = m.refined_with_material(split, punched, {changed}, &combined_count);
  EXPECT_EQ(combined_count, count);
  EXPECT_EQ(one.revision(), m.revision() + 1);
  EXPECT_EQ(&one.material(), punched.get());
  expect_same(a, one);
  const ObjectModel again = one.with_material(punched, {changed});
  EXPECT_EQ(again.revision(), one.revision() + 1);
  expect_same(a, again);
  // A second cut on the result: a slit next to the punch, refined and cut again.
  const auto slit = slab([](int i, int j, int) {
    return !((i == 7 || i == 8) && (j == 7 || j == 8)) && !(i == 9 && j >= 4 && j < 12);
  });
  const Box3 changed2{kCube * Vec3(9, 4, 0), kCube * Vec3(10, 12, kNz)};
  const auto split2 = meets(b.root(), changed2, 7);
  const ObjectModel a2 = refine_level_by_level(a, split2, count).with_material(slit, {changed2});
  const ObjectModel b2 = b.refined_where(split2).with_material(slit, {changed2});
  expect_same(a2, b2);
  expect_same(a2, one.refined_with_material(split2, slit, {changed2}));
  expect_same(b2.dofs(), build_dof_map(b2.tree(), b2.root(), *slit));
  // Leaves removed afterwards (a fragment) keep the map exact as well.
  std::vector<int> drop;
  for (int e = 0; e < b2.num_elements(); e += 7) drop.push_back(e);
  const ObjectModel c2 = b2.without_leaves(drop);
  expect_same(c2.dofs(), build_dof_map(c2.tree(), c2.root(), *slit));
}

}  // namespace
}  // namespace octocut::sim

namespace octocut::sim {
namespace {

TEST(RefineWhere, CombinedWithACutThatEmptiesLeavesAndSplitsNodes) {
  // A slit one cube wide through the whole slab (cubes i = 8), given as two changed boxes; leaves inside it lose all
  // material and nodes beside it split. The refinement reaches levels 3 (none) to 6 around its middle part.
  const auto material = slab([](int, int, int) { return true; });
  const auto slit = slab([](int i, int, int) { return i != 8; });
  const std::vector<Box3> changed{{kCube * Vec3(8, 0, 0), kCube * Vec3(9, 8, kNz)},
                                  {kCube * Vec3(8, 8, 0), kCube * Vec3(9, kNy, kNz)}};
  const ObjectModel m = slab_model(material);
  for (int level : {3, 4, 5, 6}) {
    SCOPED_TRACE(level);
    const auto split = meets(m.root(), {kCube * Vec3(8, 2, 0), kCube * Vec3(9, 14, kNz)}, level);
    int count = 0, combined_count = -1;
    const ObjectModel a = refine_level_by_level(m, split, count).with_material(slit, changed);
    const ObjectModel b = m.refined_with_material(split, slit, changed, &combined_count);
    EXPECT_EQ(combined_count, count);
    expect_same(a, b);
    expect_same(b.dofs(), build_dof_map(b.tree(), b.root(), *slit));
    EXPECT_EQ(b.dofs().check_invariants(), "");
  }
  EXPECT_THROW((void)m.refined_with_material(meets(m.root(), changed[0], 4), nullptr, changed), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::sim
