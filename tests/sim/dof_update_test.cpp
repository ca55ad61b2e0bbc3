// The local DOF update (SPEC §2.3: P is rebuilt locally after refinement or splitting) against the global build:
// after refinements, removals and material changes the two must agree field by field, bit for bit.
#include <gtest/gtest.h>

#include <random>

#include "octocut/sim/dof_map.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

using test::expect_same;

const RootGeometry kRoot{Vec3(0, 0, 0), 1.0};

TEST(DofUpdate, RandomRefinementsMatchTheGlobalBuild) {
  ObjectModel m = test::box_model({Vec3(0.05, 0.1, 0.0), Vec3(0.9, 0.95, 0.7)}, Vec3(0, 0, 0), 1.0, 2);
  std::mt19937 rng(42);
  for (int round = 0; round < 25; ++round) {
    std::vector<int> pick;
    const int count = 1 + int(rng() % 3);
    for (int i = 0; i < count; ++i) pick.push_back(int(rng() % unsigned(m.num_elements())));
    const ObjectModel next = m.refined(pick);  // uses update_dof_map
    const DofMap global = build_dof_map(next.tree(), next.root(), next.material());
    expect_same(next.dofs(), global);
    ASSERT_EQ(next.dofs().check_invariants(), "");
    m = next;
  }
  EXPECT_GT(m.dofs().hanging_slots, 0);
}

TEST(DofUpdate, RemovedLeavesAndChangedConnectivityMatchTheGlobalBuild) {
  // Before: 8 level-1 octants, one solid block. After: the material is split along x = 1/2 (both sides retract from
  // the plane) and the octant at the origin is gone entirely.
  std::vector<Cell> before;
  for (int k = 0; k < 8; ++k) before.push_back(Cell{}.child(k));
  const Octree old_tree(before);
  const BoxMaterial solid({Vec3(0, 0, 0), Vec3(1, 1, 1)});
  const DofMap old = build_dof_map(old_tree, kRoot, solid);

  std::vector<Box3> boxes;
  for (int k = 1; k < 8; ++k) {
    Box3 b{Vec3((k & 1) * 0.5, ((k >> 1) & 1) * 0.5, ((k >> 2) & 1) * 0.5), Vec3::Zero()};
    b.max = b.min + Vec3::Constant(0.5);
    if (k & 1)
      b.min.x() += 0.01;
    else
      b.max.x() -= 0.01;
    boxes.push_back(b);
  }
  const BoxSetMaterial split(boxes);
  std::vector<Cell> after(before.begin() + 1, before.end());
  const Octree new_tree(after);
  // Every remaining leaf touches the changed plane, so all of them are listed as changed.
  const DofMap updated = update_dof_map(old, old_tree, new_tree, kRoot, split, after);
  const DofMap global = build_dof_map(new_tree, kRoot, split);
  expect_same(updated, global);
  EXPECT_GT(global.num_dofs, 27 - 1);
}

TEST(DofUpdate, LocalChangeFarFromMostNodesMatchesTheGlobalBuild) {
  // A large uniform block; one corner leaf is refined twice and, separately, material changes in one leaf.
  ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 3);
  ObjectModel r = m.refined({5}).refined({3, 9});
  expect_same(r.dofs(), build_dof_map(r.tree(), r.root(), r.material()));

  // Material change confined to four leaves: a thin slot carved along the +x faces of a 2 x 2 block of leaves
  // disconnects them from their neighbours there, so the node at the centre of the block's face splits in two.
  const int first = r.embed(Vec3(0.4, 0.55, 0.55))->leaf;
  const Box3 tb = r.root().cell_box(r.tree().leaf(first));
  const double h = tb.max.x() - tb.min.x();
  const double mid = tb.max.x();
  const Vec3 lo(mid - 1e-3, tb.min.y(), tb.min.z()), hi(mid + 1e-3, tb.min.y() + 2 * h, tb.min.z() + 2 * h);
  std::vector<Cell> changed;
  for (const Vec3& p : {Vec3(0.4, 0.55, 0.55), Vec3(0.4, 0.65, 0.55), Vec3(0.4, 0.55, 0.65), Vec3(0.4, 0.65, 0.65)})
    changed.push_back(r.tree().leaf(r.embed(p)->leaf));
  // The unit cube minus the slot, as disjoint boxes: left, right, and the four parts around the slot.
  const std::vector<Box3> parts = {{Vec3(0, 0, 0), Vec3(lo.x(), 1, 1)},
                                   {Vec3(hi.x(), 0, 0), Vec3(1, 1, 1)},
                                   {Vec3(lo.x(), 0, 0), Vec3(hi.x(), lo.y(), 1)},
                                   {Vec3(lo.x(), hi.y(), 0), Vec3(hi.x(), 1, 1)},
                                   {Vec3(lo.x(), lo.y(), 0), Vec3(hi.x(), hi.y(), lo.z())},
                                   {Vec3(lo.x(), lo.y(), hi.z()), Vec3(hi.x(), hi.y(), 1)}};
  const BoxSetMaterial carved(parts);
  const DofMap global = build_dof_map(r.tree(), r.root(), carved);
  EXPECT_EQ(global.num_dofs, r.num_dofs() + 1);
  const DofMap updated = update_dof_map(r.dofs(), r.tree(), r.tree(), r.root(), carved, changed);
  expect_same(updated, global);
  // Without naming the changed cell the update keeps the old DOFs: the change list is what makes it local.
  EXPECT_EQ(update_dof_map(r.dofs(), r.tree(), r.tree(), r.root(), carved, {}).num_dofs, r.num_dofs());
}

}  // namespace
}  // namespace octocut::sim
