#include "octocut/sim/naive_embedding.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "octocut/sim/embedding.hpp"

namespace octocut::sim {

namespace {

// Octant of cell `c` that holds the finest cell anchored at p (bits along x, y, z as in Cell::child).
int octant(const Cell& c, const GridPoint& p) {
  const std::uint32_t h = c.size() / 2;
  return int(p.x - c.anchor.x >= h) | (int(p.y - c.anchor.y >= h) << 1) | (int(p.z - c.anchor.z >= h) << 2);
}

}  // namespace

NaiveEmbedding::NaiveEmbedding(const Octree& tree, const RootGeometry& root, std::span<const Vec3> rest)
    : m_root(root) {
  // The explicit tree: the root and the path down to every leaf.
  m_nodes.push_back(Node{Cell{}, {}, {}});
  m_nodes.front().child.fill(-1);
  m_leaf_node.resize(std::size_t(tree.size()));
  for (int l = 0; l < tree.size(); ++l) {
    const Cell& leaf = tree.leaf(l);
    std::int32_t n = 0;
    while (m_nodes[std::size_t(n)].cell.level < leaf.level) {
      const Cell c = m_nodes[std::size_t(n)].cell;
      const int k = octant(c, leaf.anchor);
      if (m_nodes[std::size_t(n)].child[std::size_t(k)] < 0) {
        m_nodes[std::size_t(n)].child[std::size_t(k)] = std::int32_t(m_nodes.size());
        Node child{c.child(k), {}, {}};
        child.child.fill(-1);
        m_nodes.push_back(std::move(child));
      }
      n = m_nodes[std::size_t(n)].child[std::size_t(k)];
    }
    m_leaf_node[std::size_t(l)] = n;
  }
  // File every vertex on every level.
  m_cell.resize(rest.size());
  for (std::size_t v = 0; v < rest.size(); ++v) {
    m_cell[v] = zcurve_cell(root, rest[v]);
    file(std::int32_t(v), m_cell[v]);
  }
}

void NaiveEmbedding::file(std::int32_t v, const GridPoint& p) {
  std::int32_t n = 0;
  while (n >= 0) {
    Node& node = m_nodes[std::size_t(n)];
    node.vertices.push_back(v);
    if (node.cell.level >= kMaxDepth) break;
    n = node.child[std::size_t(octant(node.cell, p))];
  }
}

void NaiveEmbedding::unfile(std::int32_t v, const GridPoint& p) {
  std::int32_t n = 0;
  while (n >= 0) {
    Node& node = m_nodes[std::size_t(n)];
    // Lists are ascending: a binary search finds the entry.
    const auto it = std::lower_bound(node.vertices.begin(), node.vertices.end(), v);
    if (it != node.vertices.end() && *it == v) node.vertices.erase(it);
    if (node.cell.level >= kMaxDepth) break;
    n = node.child[std::size_t(octant(node.cell, p))];
  }
}

std::vector<int> NaiveEmbedding::update(std::span<const int> removed, std::span<const Vec3> inserted_rest) {
  const std::size_t n_old = m_cell.size();
  // Validate the removed list and build the old-to-new map.
  std::vector<int> map(n_old, 0);
  for (std::size_t i = 0; i < removed.size(); ++i) {
    const int v = removed[i];
    if (v < 0 || std::size_t(v) >= n_old || map[std::size_t(v)] < 0)
      throw std::invalid_argument("removed_vertices[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is out of range or listed twice");
    map[std::size_t(v)] = -1;
  }
  int next = 0;
  for (int& m : map) m = m < 0 ? -1 : next++;

  // Remove the deleted vertices from the lists of every level on their paths.
  for (const int v : removed) unfile(v, m_cell[std::size_t(v)]);

  // Renumber the lists of every node: the indices of all later vertices have shifted. A node with an empty list has
  // only empty lists below it (every vertex is filed on its whole path), so the walk skips those subtrees.
  std::vector<std::int32_t> stack{0};
  while (!stack.empty()) {
    Node& node = m_nodes[std::size_t(stack.back())];
    stack.pop_back();
    if (node.vertices.empty()) continue;
    for (std::int32_t& v : node.vertices) v = map[std::size_t(v)];
    for (const std::int32_t c : node.child)
      if (c >= 0) stack.push_back(c);
  }
  std::vector<GridPoint> cells(std::size_t(next) + inserted_rest.size());
  for (std::size_t v = 0; v < n_old; ++v)
    if (map[v] >= 0) cells[std::size_t(map[v])] = m_cell[v];
  m_cell = std::move(cells);

  // File the new vertices on every level.
  for (std::size_t i = 0; i < inserted_rest.size(); ++i) {
    const std::size_t v = std::size_t(next) + i;
    m_cell[v] = zcurve_cell(m_root, inserted_rest[i]);
    file(std::int32_t(v), m_cell[v]);
  }
  return map;
}

std::span<const std::int32_t> NaiveEmbedding::vertices_in_leaf(int leaf) const {
  if (leaf < 0 || std::size_t(leaf) >= m_leaf_node.size())
    throw std::out_of_range("NaiveEmbedding::vertices_in_leaf: leaf " + std::to_string(leaf) + " out of range");
  return m_nodes[std::size_t(m_leaf_node[std::size_t(leaf)])].vertices;
}

std::size_t NaiveEmbedding::num_entries() const {
  std::size_t n = 0;
  for (const Node& node : m_nodes) n += node.vertices.size();
  return n;
}

}  // namespace octocut::sim
