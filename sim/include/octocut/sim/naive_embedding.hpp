#pragma once
// The naive vertex-element correspondence that paper Fig. 6 compares the Z-curve against: an explicit octree whose
// every node, on every level, stores the list of surface vertices inside it. Used by the embedding benchmark and as a
// brute-force reference in tests.
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "octocut/sim/octree.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::sim {

/// Per-node vertex lists on all levels of an explicit octree (root, every ancestor of a leaf, and the leaves).
class NaiveEmbedding {
 public:
  /// Builds the nodes of `tree` and its ancestors and files each rest vertex (|V|, m) into every node on its path.
  NaiveEmbedding(const Octree& tree, const RootGeometry& root, std::span<const Vec3> rest);

  /// Removes the vertices `removed` (old indices, any order, no duplicates) from the lists of every level, renumbers
  /// the kept vertices in their old order in every list, and files the new vertices `inserted_rest` (m) as indices
  /// k, k+1, ... into every level. Returns the old-to-new map, -1 for a removed vertex. Throws
  /// std::invalid_argument for an index out of range or a duplicate.
  std::vector<int> update(std::span<const int> removed, std::span<const Vec3> inserted_rest);

  /// The vertices (ascending) stored in the node of leaf `leaf` of the tree this was built from.
  [[nodiscard]] std::span<const std::int32_t> vertices_in_leaf(int leaf) const;
  [[nodiscard]] int num_nodes() const { return int(m_nodes.size()); }
  [[nodiscard]] int num_vertices() const { return int(m_cell.size()); }
  /// Total length of all node lists, i.e. the number of stored correspondences.
  [[nodiscard]] std::size_t num_entries() const;

 private:
  struct Node {
    Cell cell;
    std::array<std::int32_t, 8> child{-1, -1, -1, -1, -1, -1, -1, -1};  ///< node index of each child, -1 if none
    std::vector<std::int32_t> vertices;                                 ///< vertices inside, ascending
  };
  // Files vertex v with finest cell p into every node on its path (appending keeps lists ascending when v is the
  // largest index so far).
  void file(std::int32_t v, const GridPoint& p);
  // Removes vertex v with finest cell p from every node on its path.
  void unfile(std::int32_t v, const GridPoint& p);

  RootGeometry m_root;
  std::vector<Node> m_nodes;          ///< node 0 is the root (num_nodes)
  std::vector<std::int32_t> m_leaf_node;  ///< node of each leaf of the tree (num_leaves)
  std::vector<GridPoint> m_cell;      ///< finest grid cell of each vertex (|V|)
};

}  // namespace octocut::sim
