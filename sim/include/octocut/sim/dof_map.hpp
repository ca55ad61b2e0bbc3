#pragma once
// DOFs by node splitting and hard binding (SPEC §2.3, paper §4.4.2–4.4.3, Fig. 3–4).
#include <string>
#include <vector>

#include "octocut/sim/material.hpp"
#include "octocut/sim/octree.hpp"

namespace octocut::sim {

/// The prolongation from DOFs to element slots, x_slots = P x. Slot s = 8 * leaf + corner.
struct DofMap {
  int num_dofs = 0;
  std::vector<Vec3> dof_rest;               ///< rest position of each DOF, m (num_dofs)
  std::vector<std::uint64_t> dof_node;      ///< node_key() of each DOF's logical node (num_dofs)
  std::vector<int> dof_slot;                ///< one slot that is this DOF itself, not bound (num_dofs)
  std::vector<std::uint64_t> nodes;         ///< node_key() of every logical node, sorted (num_nodes)
  std::vector<int> node_dof_begin;          ///< DOFs of node i are [node_dof_begin[i], node_dof_begin[i+1]) (num_nodes + 1)
  std::vector<int> slot_master;             ///< leaf a hanging slot is bound to, -1 for DOF slots (num_slots)
  std::vector<int> slot_begin;              ///< CSR row starts of P (8 * num_leaves + 1)
  std::vector<int> slot_dof;                ///< CSR column (DOF) of each entry (nnz(P))
  std::vector<double> slot_weight;          ///< CSR value of each entry, dimensionless (nnz(P))
  int hanging_slots = 0;                    ///< slots that are hard-bound instead of being a DOF themselves

  [[nodiscard]] int num_slots() const { return int(slot_begin.size()) - 1; }
  /// Checks the invariants of SPEC §2.3: every slot resolves to DOFs, every row sums to 1, every DOF is used.
  /// Returns an empty string when they hold, otherwise a description of the first violation.
  [[nodiscard]] std::string check_invariants() const;
  /// Slot positions P x (num_slots), from DOF values (num_dofs).
  void prolong(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots) const;
  /// The slots [begin, end) of P x into `slots` (already num_slots long): prolong's sums, for a part of the slots.
  void prolong_range(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots, int begin, int end) const;
};


/// Builds the DOF map of an octree whose leaves all hold material. Two octants around a node are linked when they
/// lie in the same leaf or when they are face-adjacent and their leaves are connected through `material`
/// (the smaller of the two leaf faces must meet material in positive area).
DofMap build_dof_map(const Octree& tree, const RootGeometry& root, const MaterialSource& material);

/// The DOF map of `tree` after an edit of `old_tree` whose map is `old`: leaves that were removed or added, and the
/// cells listed in `material_changed` (every region whose occupancy or face connectivity changed, e.g. by a cut),
/// are redone; every other node keeps its DOFs. The result is identical to build_dof_map(tree, ...), at a cost
/// linear in the number of leaves with small constants plus the node splitting of the changed region.
DofMap update_dof_map(const DofMap& old, const Octree& old_tree, const Octree& tree, const RootGeometry& root,
                      const MaterialSource& material, const std::vector<Cell>& material_changed);

/// The common face of two face-adjacent cells (the smaller of their two faces) and its normal axis, or nullopt when
/// the cells are not face neighbours.
std::optional<std::pair<Box3, int>> common_face(const Cell& a, const Cell& b, const RootGeometry& root);

}  // namespace octocut::sim
