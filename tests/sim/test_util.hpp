#pragma once
// Shared helpers and tolerances of the sim tests.
#include <gtest/gtest.h>

#include <memory>
#include <random>

#include "octocut/sim/object.hpp"
#include "octocut/sim/simulator.hpp"

namespace octocut::sim::test {

/// Every field of two DOF maps is equal (the local update against the global build, for instance).
inline void expect_same(const DofMap& a, const DofMap& b) {
  EXPECT_EQ(a.num_dofs, b.num_dofs);
  EXPECT_EQ(a.hanging_slots, b.hanging_slots);
  EXPECT_EQ(a.nodes, b.nodes);
  EXPECT_EQ(a.node_dof_begin, b.node_dof_begin);
  EXPECT_EQ(a.dof_node, b.dof_node);
  EXPECT_EQ(a.dof_slot, b.dof_slot);
  EXPECT_EQ(a.slot_begin, b.slot_begin);
  EXPECT_EQ(a.slot_dof, b.slot_dof);
  EXPECT_EQ(a.slot_weight, b.slot_weight);
  EXPECT_EQ(a.slot_master, b.slot_master);
  EXPECT_EQ(a.dof_rest, b.dof_rest);
}

/// Relative tolerance for identities that hold up to round-off.
inline constexpr double kExact = 1e-10;

/// A model of the unit-ish box [lo, hi] in a root cube at `root_min` of edge `root_size`, uniform to `level`, with
/// optional refine regions and handles.
inline ObjectModel box_model(const Box3& box, const Vec3& root_min, double root_size, int level,
                             std::vector<RefineSpec> refine = {}, std::vector<HandleSpec> handles = {},
                             MaterialParams params = {}, int max_level = 10) {
  OctreeSpec spec;
  spec.root = {root_min, root_size};
  spec.base_level = level;
  spec.max_level = max_level;
  spec.refine = std::move(refine);
  return ObjectModel::build(spec, std::make_shared<BoxMaterial>(box), params, std::move(handles));
}

/// Brute-force count of logical nodes that are DOF carriers in a fully connected octree: nodes that no leaf holds
/// in the interior of a face or an edge.
inline int brute_force_free_nodes(const Octree& tree) {
  std::vector<std::uint64_t> nodes;
  for (const Cell& c : tree.leaves())
    for (int k = 0; k < 8; ++k) nodes.push_back(node_key(c.corner(k)));
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  int count = 0;
  for (std::uint64_t key : nodes) {
    const GridPoint n = node_from_key(key);
    bool hanging = false;
    for (const Cell& c : tree.leaves())
      if (c.contains(n) && !c.has_corner(n)) hanging = true;
    count += hanging ? 0 : 1;
  }
  return count;
}

}  // namespace octocut::sim::test
