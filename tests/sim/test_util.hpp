#pragma once
// Shared helpers and tolerances of the sim tests.
#include <memory>
#include <random>

#include "octocut/sim/object.hpp"
#include "octocut/sim/simulator.hpp"

namespace octocut::sim::test {

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
