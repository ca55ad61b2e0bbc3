#include "octocut/sim/dof_map.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

namespace octocut::sim {

namespace {

// Union-find over the 8 octants of one node.
struct OctantSets {
  std::array<int, 8> parent{0, 1, 2, 3, 4, 5, 6, 7};
  int find(int a) {
    while (parent[std::size_t(a)] != a) a = parent[std::size_t(a)] = parent[std::size_t(parent[std::size_t(a)])];
    return a;
  }
  void unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
  }
};

// How one slot is resolved before chains are followed: a DOF, or bound to the corners of a bigger leaf (with the
// master's trilinear weights at the slot's node, computed when the row is resolved).
struct SlotBinding {
  int dof = -1;     // >= 0: the slot is this DOF
  int master = -1;  // >= 0: hard-bound to this leaf's corner slots
};

}  // namespace

std::optional<std::pair<Box3, int>> common_face(const Cell& a, const Cell& b, const RootGeometry& root) {
  const std::uint32_t sa = a.size(), sb = b.size();
  const std::array<std::uint32_t, 3> amin{a.anchor.x, a.anchor.y, a.anchor.z}, bmin{b.anchor.x, b.anchor.y, b.anchor.z};
  int axis = -1;
  std::uint32_t plane = 0;
  std::array<std::uint32_t, 3> lo{}, hi{};
  for (int d = 0; d < 3; ++d) {
    const std::uint32_t a0 = amin[std::size_t(d)], a1 = a0 + sa, b0 = bmin[std::size_t(d)], b1 = b0 + sb;
    if (a1 == b0 || b1 == a0) {
      // Touching along d: at most one such axis for face neighbours.
      if (axis >= 0) return std::nullopt;
      axis = d;
      plane = (a1 == b0) ? a1 : a0;
      lo[std::size_t(d)] = hi[std::size_t(d)] = plane;
    } else {
      lo[std::size_t(d)] = std::max(a0, b0);
      hi[std::size_t(d)] = std::min(a1, b1);
      if (hi[std::size_t(d)] <= lo[std::size_t(d)]) return std::nullopt;
    }
  }
  if (axis < 0) return std::nullopt;
  const Box3 face{root.to_world({lo[0], lo[1], lo[2]}), root.to_world({hi[0], hi[1], hi[2]})};
  return std::make_pair(face, axis);
}

namespace {

// Face connectivity of leaf pairs, cached: many nodes ask about the same pair.
class ConnectivityCache {
 public:
  ConnectivityCache(const Octree& tree, const RootGeometry& root, const MaterialSource& material)
      : m_tree(tree), m_root(root), m_material(material) {}
  bool operator()(int a, int b) {
    if (a > b) std::swap(a, b);
    const std::uint64_t key = (std::uint64_t(std::uint32_t(a)) << 32) | std::uint32_t(b);
    auto it = m_cache.find(key);
    if (it != m_cache.end()) return it->second;
    const auto face = common_face(m_tree.leaf(a), m_tree.leaf(b), m_root);
    const bool c = face && m_material.face_connected(face->first, face->second);
    m_cache.emplace(key, c);
    return c;
  }

 private:
  const Octree& m_tree;
  const RootGeometry& m_root;
  const MaterialSource& m_material;
  std::unordered_map<std::uint64_t, bool> m_cache;
};

// The leaves covering the 8 octants around node n (-1 where none); octant bit d set = the + side along d.
std::array<int, 8> octant_leaves(const Octree& tree, const GridPoint& n) {
  std::array<int, 8> leaf{};
  for (int o = 0; o < 8; ++o) {
    const bool px = o & 1, py = o & 2, pz = o & 4;
    if ((!px && n.x == 0) || (!py && n.y == 0) || (!pz && n.z == 0) || (px && n.x == kGridCells) ||
        (py && n.y == kGridCells) || (pz && n.z == kGridCells)) {
      leaf[std::size_t(o)] = -1;
      continue;
    }
    leaf[std::size_t(o)] = tree.locate_cell({px ? n.x : n.x - 1, py ? n.y : n.y - 1, pz ? n.z : n.z - 1});
  }
  return leaf;
}

// Node splitting at one logical node: appends its DOFs to `map` and sets the bindings of its slots.
void process_node(std::uint64_t key, const std::array<int, 8>& leaf, const Octree& tree, const RootGeometry& root,
                  ConnectivityCache& connected, DofMap& map, std::vector<SlotBinding>& binding) {
  const GridPoint n = node_from_key(key);

  // Graph G_i: same leaf, or face-adjacent octants whose leaves are connected.
  OctantSets sets;
  for (int o = 0; o < 8; ++o) {
    const int lo = leaf[std::size_t(o)];
    if (lo < 0) continue;
    for (int p = o + 1; p < 8; ++p) {
      const int lp = leaf[std::size_t(p)];
      if (lp < 0) continue;
      const int diff = o ^ p;
      if (lo == lp || ((diff == 1 || diff == 2 || diff == 4) && connected(lo, lp))) sets.unite(o, p);
    }
  }

  // One DOF per component whose leaves all have the node as a corner; otherwise hard-bind to the coarsest leaf of
  // the component that has the node inside a face or an edge.
  for (int r = 0; r < 8; ++r) {
    if (leaf[std::size_t(r)] < 0 || sets.find(r) != r) continue;
    int master = -1;
    for (int o = 0; o < 8; ++o) {
      const int l = leaf[std::size_t(o)];
      if (l < 0 || sets.find(o) != r || tree.leaf(l).has_corner(n)) continue;
      if (master < 0 || tree.leaf(l).level < tree.leaf(master).level ||
          (tree.leaf(l).level == tree.leaf(master).level && l < master))
        master = l;
    }
    int dof = -1;
    if (master < 0) {
      dof = map.num_dofs++;
      map.dof_rest.push_back(root.to_world(n));
      map.dof_node.push_back(key);
      map.dof_slot.push_back(-1);
    }
    for (int o = 0; o < 8; ++o) {
      const int l = leaf[std::size_t(o)];
      if (l < 0 || sets.find(o) != r || !tree.leaf(l).has_corner(n)) continue;
      const std::size_t s = std::size_t(8 * l + (o ^ 7));
      binding[s] = SlotBinding{};
      if (dof >= 0) {
        binding[s].dof = dof;
        if (map.dof_slot[std::size_t(dof)] < 0) map.dof_slot[std::size_t(dof)] = int(s);
      } else {
        binding[s].master = master;
      }
    }
  }
}

// Turns the slot bindings into the CSR rows of P, following chains of hard binding. A master is always strictly
// coarser than the bound slot's leaf, so the recursion ends. Only hanging rows are memoised, in one pool.
class RowResolver {
 public:
  RowResolver(const std::vector<SlotBinding>& binding, const Octree& tree)
      : m_binding(binding), m_tree(tree), m_row(binding.size(), {-1, -1}) {}

  // The resolved row of hanging slot s: entries [first, second) of dofs() and weights().
  std::pair<int, int> hanging(int s, int depth) {
    if (m_row[std::size_t(s)].first >= 0) return m_row[std::size_t(s)];
    if (depth > kMaxDepth + 1) throw std::logic_error("build_dof_map: cyclic hard binding");
    const SlotBinding& b = m_binding[std::size_t(s)];
    // The master's trilinear weights at the slot's node.
    const std::array<double, 8> corner_w =
        trilinear_weights(m_tree.leaf(b.master).local(m_tree.leaf(s / 8).corner(s % 8)));
    // Rows of hanging master slots first, so that the pool does not grow while this row is gathered.
    for (int k = 0; k < 8; ++k) {
      const int ms = 8 * b.master + k;
      if (corner_w[std::size_t(k)] != 0.0 && m_binding[std::size_t(ms)].dof < 0) (void)hanging(ms, depth + 1);
    }
    m_acc.clear();
    for (int k = 0; k < 8; ++k) {
      const double w = corner_w[std::size_t(k)];
      if (w == 0.0) continue;
      const int ms = 8 * b.master + k;
      const SlotBinding& mb = m_binding[std::size_t(ms)];
      if (mb.dof >= 0) {
        m_acc.emplace_back(mb.dof, w);
      } else {
        const auto [r0, r1] = m_row[std::size_t(ms)];
        for (int i = r0; i < r1; ++i) m_acc.emplace_back(m_dof[std::size_t(i)], w * m_weight[std::size_t(i)]);
      }
    }
    // Merge the entries of each DOF, in DOF order.
    std::sort(m_acc.begin(), m_acc.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    const int begin = int(m_dof.size());
    for (const auto& [d, w] : m_acc) {
      if (int(m_dof.size()) > begin && m_dof.back() == d)
        m_weight.back() += w;
      else {
        m_dof.push_back(d);
        m_weight.push_back(w);
      }
    }
    // Drop entries that cancelled to zero.
    int end = begin;
    for (int i = begin; i < int(m_dof.size()); ++i) {
      if (m_weight[std::size_t(i)] == 0.0) continue;
      m_dof[std::size_t(end)] = m_dof[std::size_t(i)];
      m_weight[std::size_t(end)] = m_weight[std::size_t(i)];
      ++end;
    }
    m_dof.resize(std::size_t(end));
    m_weight.resize(std::size_t(end));
    return m_row[std::size_t(s)] = {begin, end};
  }
  [[nodiscard]] const std::vector<int>& dofs() const { return m_dof; }
  [[nodiscard]] const std::vector<double>& weights() const { return m_weight; }

 private:
  const std::vector<SlotBinding>& m_binding;
  const Octree& m_tree;
  std::vector<std::pair<int, int>> m_row;           // pool range of each hanging slot's row, -1 until resolved
  std::vector<int> m_dof;                           // pooled row entries: DOF
  std::vector<double> m_weight;                     // pooled row entries: weight
  std::vector<std::pair<int, double>> m_acc;        // scratch for one row
};

void resolve_rows(const std::vector<SlotBinding>& binding, const Octree& tree, DofMap& map) {
  const int num_slots = int(binding.size());
  RowResolver rows(binding, tree);
  map.hanging_slots = 0;
  map.slot_master.assign(std::size_t(num_slots), -1);
  map.slot_begin.clear();
  map.slot_dof.clear();
  map.slot_weight.clear();
  map.slot_begin.reserve(std::size_t(num_slots) + 1);
  map.slot_dof.reserve(std::size_t(num_slots) + std::size_t(num_slots) / 2);
  map.slot_weight.reserve(std::size_t(num_slots) + std::size_t(num_slots) / 2);
  map.slot_begin.push_back(0);
  for (int s = 0; s < num_slots; ++s) {
    const SlotBinding& b = binding[std::size_t(s)];
    if (b.dof >= 0) {
      map.slot_dof.push_back(b.dof);
      map.slot_weight.push_back(1.0);
    } else if (b.master >= 0) {
      ++map.hanging_slots;
      map.slot_master[std::size_t(s)] = b.master;
      const auto [r0, r1] = rows.hanging(s, 0);
      map.slot_dof.insert(map.slot_dof.end(), rows.dofs().begin() + r0, rows.dofs().begin() + r1);
      map.slot_weight.insert(map.slot_weight.end(), rows.weights().begin() + r0, rows.weights().begin() + r1);
    } else {
      throw std::logic_error("build_dof_map: a slot was not reached by its node");
    }
    map.slot_begin.push_back(int(map.slot_dof.size()));
  }
}

// Closed grid boxes of the cells whose DOFs must be recomputed. After finalize(), a point is looked up in a sorted
// list of (bucket, box) pairs: buckets are cubes of the largest box's edge, so each box meets at most 8 of them and a
// point only tests the few boxes of its own bucket.
class DirtyRegion {
 public:
  void add(const Cell& c) {
    const GridPoint lo = c.anchor, hi = c.corner(7);
    m_boxes.push_back({lo, hi});
    m_shift = std::max(m_shift, kMaxDepth - c.level);
    if (m_boxes.size() == 1) {
      m_lo = lo;
      m_hi = hi;
    } else {
      m_lo = {std::min(m_lo.x, lo.x), std::min(m_lo.y, lo.y), std::min(m_lo.z, lo.z)};
      m_hi = {std::max(m_hi.x, hi.x), std::max(m_hi.y, hi.y), std::max(m_hi.z, hi.z)};
    }
  }
  // Files every box under each bucket its closed box meets; call after the last add() and before contains().
  void finalize() {
    m_index.clear();
    m_index.reserve(8 * m_boxes.size());
    for (std::size_t b = 0; b < m_boxes.size(); ++b) {
      const GridPoint lo = m_boxes[b].first, hi = m_boxes[b].second;
      for (std::uint32_t z = lo.z >> m_shift; z <= hi.z >> m_shift; ++z)
        for (std::uint32_t y = lo.y >> m_shift; y <= hi.y >> m_shift; ++y)
          for (std::uint32_t x = lo.x >> m_shift; x <= hi.x >> m_shift; ++x)
            m_index.emplace_back(node_key({x, y, z}), int(b));
    }
    std::sort(m_index.begin(), m_index.end());
  }
  bool contains(const GridPoint& p) const {
    auto inside = [&p](const GridPoint& lo, const GridPoint& hi) {
      return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z;
    };
    if (m_boxes.empty() || !inside(m_lo, m_hi)) return false;
    // A box that holds p meets p's bucket, so it is filed under it.
    const std::uint64_t bucket = node_key({p.x >> m_shift, p.y >> m_shift, p.z >> m_shift});
    auto it = std::lower_bound(m_index.begin(), m_index.end(), std::make_pair(bucket, -1));
    for (; it != m_index.end() && it->first == bucket; ++it) {
      const auto& b = m_boxes[std::size_t(it->second)];
      if (inside(b.first, b.second)) return true;
    }
    return false;
  }

 private:
  std::vector<std::pair<GridPoint, GridPoint>> m_boxes;
  std::vector<std::pair<std::uint64_t, int>> m_index;  // (bucket key, box), sorted
  int m_shift = 0;                                     // log2 of the bucket edge, finest-grid units
  GridPoint m_lo, m_hi;
};

}  // namespace

DofMap build_dof_map(const Octree& tree, const RootGeometry& root, const MaterialSource& material) {
  const int num_slots = 8 * tree.size();

  // Logical nodes: the distinct corners of all leaves, sorted by key.
  DofMap map;
  map.nodes.reserve(std::size_t(num_slots));
  for (const Cell& c : tree.leaves())
    for (int k = 0; k < 8; ++k) map.nodes.push_back(node_key(c.corner(k)));
  std::sort(map.nodes.begin(), map.nodes.end());
  map.nodes.erase(std::unique(map.nodes.begin(), map.nodes.end()), map.nodes.end());

  // Node splitting node by node, in key order: DOFs are numbered by node, then by component.
  ConnectivityCache connected(tree, root, material);
  std::vector<SlotBinding> binding(static_cast<std::size_t>(num_slots));
  map.node_dof_begin.reserve(map.nodes.size() + 1);
  for (const std::uint64_t key : map.nodes) {
    map.node_dof_begin.push_back(map.num_dofs);
    process_node(key, octant_leaves(tree, node_from_key(key)), tree, root, connected, map, binding);
  }
  map.node_dof_begin.push_back(map.num_dofs);
  resolve_rows(binding, tree, map);
  return map;
}

DofMap update_dof_map(const DofMap& old, const Octree& old_tree, const Octree& tree, const RootGeometry& root,
                      const MaterialSource& material, const std::vector<Cell>& material_changed) {
  const int num_slots = 8 * tree.size();

  // Leaves kept from the old tree (same cell, Morton order on both sides); removed and added leaves are dirty.
  std::vector<int> old_to_new(std::size_t(old_tree.size()), -1);
  std::vector<char> kept(std::size_t(tree.size()), 0);
  DirtyRegion dirty;
  for (const Cell& c : material_changed) dirty.add(c);
  {
    int i = 0, j = 0;
    while (i < old_tree.size() || j < tree.size()) {
      const std::uint64_t ci = i < old_tree.size() ? old_tree.leaf(i).morton() : ~0ull;
      const std::uint64_t cj = j < tree.size() ? tree.leaf(j).morton() : ~0ull;
      if (ci == cj && old_tree.leaf(i).level == tree.leaf(j).level) {
        old_to_new[std::size_t(i)] = j;
        kept[std::size_t(j)] = 1;
        ++i;
        ++j;
      } else if (ci <= cj && i < old_tree.size()) {
        dirty.add(old_tree.leaf(i++));
      } else {
        dirty.add(tree.leaf(j++));
      }
    }
  }
  dirty.finalize();

  // Nodes: old nodes outside the dirty region stay; inside it, old nodes and the corners of added leaves are
  // candidates that remain nodes when some new leaf has them as a corner.
  std::vector<std::uint64_t> candidates;
  for (const std::uint64_t key : old.nodes)
    if (dirty.contains(node_from_key(key))) candidates.push_back(key);
  for (int j = 0; j < tree.size(); ++j)
    if (!kept[std::size_t(j)])
      for (int k = 0; k < 8; ++k) candidates.push_back(node_key(tree.leaf(j).corner(k)));
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());

  // Walk the merged node list in key order: clean nodes copy their DOFs, dirty nodes are split anew.
  DofMap map;
  ConnectivityCache connected(tree, root, material);
  std::vector<SlotBinding> binding(static_cast<std::size_t>(num_slots));
  std::vector<int> old_dof_to_new(std::size_t(old.num_dofs), -1);
  std::size_t oi = 0, ci = 0;
  map.nodes.reserve(old.nodes.size() + candidates.size());
  std::array<int, 8> candidate_leaves{};  // octant leaves of candidates[checked]
  std::size_t checked = candidates.size();
  while (true) {
    while (oi < old.nodes.size() && dirty.contains(node_from_key(old.nodes[oi]))) ++oi;
    // A candidate stays a node when some new leaf has it as a corner; each is looked at once.
    while (ci < candidates.size() && checked != ci) {
      const GridPoint n = node_from_key(candidates[ci]);
      candidate_leaves = octant_leaves(tree, n);
      if (std::any_of(candidate_leaves.begin(), candidate_leaves.end(),
                      [&](int l) { return l >= 0 && tree.leaf(l).has_corner(n); })) {
        checked = ci;
        break;
      }
      ++ci;
    }
    const bool have_old = oi < old.nodes.size(), have_new = ci < candidates.size();
    if (!have_old && !have_new) break;
    map.node_dof_begin.push_back(map.num_dofs);
    if (have_old && (!have_new || old.nodes[oi] < candidates[ci])) {
      const std::uint64_t key = old.nodes[oi];
      map.nodes.push_back(key);
      for (int d = old.node_dof_begin[oi]; d < old.node_dof_begin[oi + 1]; ++d) {
        old_dof_to_new[std::size_t(d)] = map.num_dofs++;
        map.dof_rest.push_back(old.dof_rest[std::size_t(d)]);
        map.dof_node.push_back(key);
        const int s = old.dof_slot[std::size_t(d)];
        map.dof_slot.push_back(8 * old_to_new[std::size_t(s / 8)] + s % 8);
      }
      ++oi;
    } else {
      map.nodes.push_back(candidates[ci]);
      process_node(candidates[ci], candidate_leaves, tree, root, connected, map, binding);
      ++ci;
    }
  }
  map.node_dof_begin.push_back(map.num_dofs);

  // Slots of kept leaves at clean nodes keep their binding, renumbered.
  for (int i = 0; i < old_tree.size(); ++i) {
    const int j = old_to_new[std::size_t(i)];
    if (j < 0) continue;
    for (int k = 0; k < 8; ++k) {
      const GridPoint n = tree.leaf(j).corner(k);
      if (dirty.contains(n)) continue;
      const std::size_t os = std::size_t(8 * i + k), ns = std::size_t(8 * j + k);
      const int master = old.slot_master[os];
      binding[ns] = SlotBinding{};
      if (master < 0) {
        binding[ns].dof = old_dof_to_new[std::size_t(old.slot_dof[std::size_t(old.slot_begin[os])])];
      } else {
        binding[ns].master = old_to_new[std::size_t(master)];
      }
    }
  }
  resolve_rows(binding, tree, map);
  return map;
}

std::string DofMap::check_invariants() const {
  std::ostringstream err;
  std::vector<char> used(static_cast<std::size_t>(num_dofs), 0);
  for (int s = 0; s < num_slots(); ++s) {
    const int b = slot_begin[std::size_t(s)], e = slot_begin[std::size_t(s) + 1];
    if (e <= b) {
      err << "slot " << s << " resolves to no DOF";
      return err.str();
    }
    double sum = 0.0;
    for (int i = b; i < e; ++i) {
      const int d = slot_dof[std::size_t(i)];
      if (d < 0 || d >= num_dofs) {
        err << "slot " << s << " references DOF " << d << " out of range";
        return err.str();
      }
      used[std::size_t(d)] = 1;
      sum += slot_weight[std::size_t(i)];
    }
    if (std::abs(sum - 1.0) > 1e-12) {
      err << "row " << s << " of P sums to " << sum;
      return err.str();
    }
  }
  for (int d = 0; d < num_dofs; ++d) {
    if (!used[std::size_t(d)]) {
      err << "DOF " << d << " is referenced by no slot";
      return err.str();
    }
  }
  return {};
}

void DofMap::prolong(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots) const {
  slots.resize(std::size_t(num_slots()));
  prolong_range(dofs, slots, 0, num_slots());
}

void DofMap::prolong_range(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots, int begin, int end) const {
  for (int s = begin; s < end; ++s) {
    Vec3 p = Vec3::Zero();
    for (int i = slot_begin[std::size_t(s)]; i < slot_begin[std::size_t(s) + 1]; ++i)
      p += slot_weight[std::size_t(i)] * dofs[std::size_t(slot_dof[std::size_t(i)])];
    slots[std::size_t(s)] = p;
  }
}

}  // namespace octocut::sim
