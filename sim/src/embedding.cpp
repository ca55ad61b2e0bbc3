#include "octocut/sim/embedding.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

namespace octocut::sim {

namespace {

// "vertex 12 (nan, 0, 1)"-style description of a point, for error messages.
std::string describe_point(const char* what, std::size_t i, const Vec3& p) {
  return std::string(what) + " " + std::to_string(i) + " (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
         ", " + std::to_string(p.z()) + ")";
}

// Throws when an index list has an entry outside [0, n) or a duplicate; `what` names the list.
void check_index_list(std::span<const int> list, std::size_t n, const char* what) {
  std::vector<char> seen(n, 0);
  for (std::size_t i = 0; i < list.size(); ++i) {
    const int v = list[i];
    if (v < 0 || std::size_t(v) >= n)
      throw std::invalid_argument(std::string(what) + "[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is out of range [0, " + std::to_string(n) + ")");
    if (seen[std::size_t(v)])
      throw std::invalid_argument(std::string(what) + "[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is listed twice");
    seen[std::size_t(v)] = 1;
  }
}

// Throws naming the first non-finite point; `what` names the list.
void check_finite(std::span<const Vec3> points, const char* what) {
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite()) throw std::invalid_argument(describe_point(what, i, points[i]) + " is not finite");
}

// Squared distance from p to the closed box b, m^2.
double box_distance2(const Box3& b, const Vec3& p) {
  const Vec3 d = (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0);
  return d.squaredNorm();
}

// Local coordinates of p in leaf box b: 0 at the lower corner and 1 at the upper one along each axis.
Vec3 local_coordinates(const Box3& b, const Vec3& p) {
  return ((p - b.min).array() / (b.max - b.min).array()).matrix();
}

// For each leaf of `old_tree`, its index in `tree` when the same cell is a leaf there, else -1. Both trees are in
// Morton order, so one merge pass suffices.
std::vector<int> match_leaves(const Octree& old_tree, const Octree& tree, std::vector<char>& kept_new) {
  std::vector<int> old_to_new(std::size_t(old_tree.size()), -1);
  kept_new.assign(std::size_t(tree.size()), 0);
  int i = 0, j = 0;
  while (i < old_tree.size() && j < tree.size()) {
    const std::uint64_t ci = old_tree.leaf(i).morton(), cj = tree.leaf(j).morton();
    if (ci == cj) {
      if (old_tree.leaf(i).level == tree.leaf(j).level) {
        old_to_new[std::size_t(i)] = j;
        kept_new[std::size_t(j)] = 1;
      }
      ++i;
      ++j;
    } else if (ci < cj) {
      ++i;
    } else {
      ++j;
    }
  }
  return old_to_new;
}

// Nearest-leaf search for fallback vertices: a uniform grid of G^3 buckets over the root, each listing the leaves
// whose box overlaps it, searched ring by ring around the point. Gives exactly the brute-force answer of
// embed_vertex (same distance function, same tie-break) at a cost independent of the number of leaves far away;
// restricted to one material component, it gives the brute-force answer over that component's leaves.
class NearestLeafGrid {
 public:
  NearestLeafGrid(const Octree& tree, const RootGeometry& root) : m_tree(tree), m_root(root) {
    // About two buckets per leaf inside the material (G^3 f <= 2 n, f the fraction of the root the n leaves fill),
    // so that a search near the material scans few leaves however little of the root cube the object fills; at
    // most 64 buckets per leaf and 128^3 buckets in all. G is a power of two so buckets align with cells.
    double fill = 0.0;
    for (const Cell& c : tree.leaves()) fill += std::ldexp(1.0, -3 * c.level);
    const double n = double(tree.size());
    const double max_buckets = std::min(2.0 * n / std::max(fill, 1e-300), 64.0 * n);
    m_log_g = 0;
    while (m_log_g < 7 && std::ldexp(1.0, 3 * (m_log_g + 1)) <= max_buckets) ++m_log_g;
    m_g = 1 << m_log_g;
    const int shift = kMaxDepth - m_log_g;
    // Bucket range of each leaf, then a CSR fill in leaf order (so each bucket lists leaves ascending).
    auto range = [&](const Cell& c, int d) {
      const std::uint32_t a = d == 0 ? c.anchor.x : d == 1 ? c.anchor.y : c.anchor.z;
      return std::pair<int, int>(int(a >> shift), int((a + c.size() - 1) >> shift));
    };
    m_begin.assign(std::size_t(m_g) * m_g * m_g + 1, 0);
    for (int pass = 0; pass < 2; ++pass) {
      std::vector<int> fill;
      if (pass == 1) {
        for (std::size_t b = 1; b < m_begin.size(); ++b) m_begin[b] += m_begin[b - 1];
        m_leaf.resize(std::size_t(m_begin.back()));
        fill.assign(m_begin.begin(), m_begin.end() - 1);
      }
      for (int l = 0; l < tree.size(); ++l) {
        const Cell& c = tree.leaf(l);
        const auto [x0, x1] = range(c, 0);
        const auto [y0, y1] = range(c, 1);
        const auto [z0, z1] = range(c, 2);
        for (int z = z0; z <= z1; ++z)
          for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x) {
              const std::size_t b = bucket(x, y, z);
              if (pass == 0)
                ++m_begin[b + 1];
              else
                m_leaf[std::size_t(fill[b]++)] = l;
            }
      }
    }
  }

  // The leaf nearest to p (distance to the leaf box), the lowest index among equals. With `component` >= 0 only the
  // leaves l with leaf_component[l] == component count (leaf_component: one entry per leaf; unused when component
  // is -1); -1 when no leaf qualifies.
  [[nodiscard]] int nearest(const Vec3& p, int component = -1, std::span<const int> leaf_component = {}) const {
    // Start from the bucket of p clamped into the root; buckets on ring r + 1 are at least r bucket edges away.
    const double edge = m_root.size / m_g;
    const Vec3 g = ((p - m_root.min) / edge).cwiseMax(0.0).cwiseMin(double(m_g) - 0.5);
    const int cx = int(g.x()), cy = int(g.y()), cz = int(g.z());
    double best = std::numeric_limits<double>::infinity();
    int best_leaf = -1;
    for (int r = 0; r < m_g; ++r) {
      // Stop once no unvisited bucket can hold a leaf at least as near (with margins for rounding): the buckets not
      // yet visited lie outside the block of rings 0 .. r - 1, so they are at least as far from p as that block's
      // faces that do not lie on the grid's boundary; stop too when every face does (nothing is left).
      if (r >= 1) {
        double bound = std::numeric_limits<double>::infinity();
        const int c[3] = {cx, cy, cz};
        for (int d = 0; d < 3; ++d) {
          if (c[d] - r + 1 > 0) bound = std::min(bound, p[d] - (m_root.min[d] + double(c[d] - r + 1) * edge));
          if (c[d] + r < m_g) bound = std::min(bound, m_root.min[d] + double(c[d] + r) * edge - p[d]);
        }
        if (bound == std::numeric_limits<double>::infinity()) break;
        bound -= 1e-9 * edge;
        if (bound > 0.0 && bound * bound > best * (1.0 + 1e-9)) break;
      }
      for (int z = std::max(cz - r, 0); z <= std::min(cz + r, m_g - 1); ++z)
        for (int y = std::max(cy - r, 0); y <= std::min(cy + r, m_g - 1); ++y)
          for (int x = std::max(cx - r, 0); x <= std::min(cx + r, m_g - 1); ++x) {
            // Only the shell of the ring: the inside was visited before.
            if (std::max({std::abs(x - cx), std::abs(y - cy), std::abs(z - cz)}) != r) continue;
            const std::size_t b = bucket(x, y, z);
            for (int i = m_begin[b]; i < m_begin[b + 1]; ++i) {
              const int l = m_leaf[std::size_t(i)];
              if (component >= 0 && leaf_component[std::size_t(l)] != component) continue;
              const double d = box_distance2(m_root.cell_box(m_tree.leaf(l)), p);
              if (d < best || (d == best && l < best_leaf)) {
                best = d;
                best_leaf = l;
              }
            }
          }
    }
    return best_leaf;
  }

 private:
  [[nodiscard]] std::size_t bucket(int x, int y, int z) const {
    return (std::size_t(z) * std::size_t(m_g) + std::size_t(y)) * std::size_t(m_g) + std::size_t(x);
  }

  const Octree& m_tree;
  const RootGeometry& m_root;
  int m_log_g = 0;
  int m_g = 1;                 ///< buckets per axis
  std::vector<int> m_begin;    ///< CSR row starts (G^3 + 1)
  std::vector<int> m_leaf;     ///< leaves overlapping each bucket, ascending (nnz)
};

// True when leaves a and b are the same leaf or some slot of each reaches the same DOF through P (then they are in
// one material component). At most 8 x 8 short rows compared.
bool leaves_share_dof(const DofMap& P, int a, int b) {
  if (a == b) return true;
  const int a0 = P.slot_begin[8 * std::size_t(a)], a1 = P.slot_begin[8 * std::size_t(a) + 8];
  const int b0 = P.slot_begin[8 * std::size_t(b)], b1 = P.slot_begin[8 * std::size_t(b) + 8];
  for (int i = a0; i < a1; ++i)
    for (int j = b0; j < b1; ++j)
      if (P.slot_dof[std::size_t(i)] == P.slot_dof[std::size_t(j)]) return true;
  return false;
}

// The anchor of each fallback vertex: the nearest regularly bound vertex of its surface component along triangle
// edges (fewest edges, the lowest vertex index among equals), or -1 when the component has none. `embedding` (|V|)
// marks the fallback vertices by leaf -1 and the regular ones by their leaf; `lost` lists the fallback vertices;
// `tri_begin`, `tri` are the vertex-to-triangle CSR of `triangles`. Returns one anchor per vertex (|V|), -1 for the
// regular vertices. A breadth-first search from all regular vertices at once, layer by layer through fallback
// vertices only: the nearest regular vertices of a vertex at depth d + 1 are the union of those of its neighbours at
// depth d, so keeping the lowest anchor among those neighbours gives the tie-break exactly. Cost: the triangles
// around the fallback vertices, independent of |V| beyond one array fill.
std::vector<int> fallback_anchors(std::span<const VertexEmbedding> embedding, std::span<const std::size_t> lost,
                                  std::span<const int> tri_begin, std::span<const int> tri,
                                  std::span<const std::array<int32_t, 3>> triangles) {
  std::vector<int> anchor(embedding.size(), -1), depth(embedding.size(), -1);
  std::vector<std::size_t> frontier, next;
  // Depth 1: fallback vertices with a regular neighbour take the lowest one.
  for (const std::size_t v : lost) {
    int best = -1;
    for (int i = tri_begin[v]; i < tri_begin[v + 1]; ++i)
      for (const int32_t u : triangles[std::size_t(tri[std::size_t(i)])])
        if (embedding[std::size_t(u)].leaf >= 0 && (best < 0 || u < best)) best = u;
    if (best < 0) continue;
    anchor[v] = best;
    depth[v] = 1;
    frontier.push_back(v);
  }
  // Depth d + 1: unreached fallback neighbours of depth-d vertices take the lowest anchor among those neighbours.
  for (int d = 1; !frontier.empty(); ++d) {
    next.clear();
    for (const std::size_t v : frontier)
      for (int i = tri_begin[v]; i < tri_begin[v + 1]; ++i)
        for (const int32_t u32 : triangles[std::size_t(tri[std::size_t(i)])]) {
          const std::size_t u = std::size_t(u32);
          if (embedding[u].leaf >= 0) continue;
          if (depth[u] < 0) {
            depth[u] = d + 1;
            anchor[u] = anchor[v];
            next.push_back(u);
          } else if (depth[u] == d + 1 && anchor[v] < anchor[u]) {
            anchor[u] = anchor[v];
          }
        }
    frontier.swap(next);
  }
  return anchor;
}

// Appends the composed row of e to (dof, weight): vertex = sum_k w_k (P x)_(8 leaf + k), the entries of one DOF
// summed in slot order, DOFs ascending, zero sums dropped. `acc` is scratch.
void compose_row(const DofMap& P, const VertexEmbedding& e, std::vector<std::pair<int, double>>& acc,
                 std::vector<int>& dof, std::vector<double>& weight) {
  acc.clear();
  for (int k = 0; k < 8; ++k) {
    const double w = e.weights[std::size_t(k)];
    if (w == 0.0) continue;
    const std::size_t s = 8 * std::size_t(e.leaf) + std::size_t(k);
    for (int i = P.slot_begin[s]; i < P.slot_begin[s + 1]; ++i)
      acc.emplace_back(P.slot_dof[std::size_t(i)], w * P.slot_weight[std::size_t(i)]);
  }
  // Group by DOF, keeping the slot order within a DOF (a stable insertion sort: the lists are short), and sum.
  for (std::size_t i = 1; i < acc.size(); ++i) {
    const auto item = acc[i];
    std::size_t j = i;
    for (; j > 0 && acc[j - 1].first > item.first; --j) acc[j] = acc[j - 1];
    acc[j] = item;
  }
  for (std::size_t i = 0; i < acc.size();) {
    double w = 0.0;
    std::size_t j = i;
    for (; j < acc.size() && acc[j].first == acc[i].first; ++j) w += acc[j].second;
    if (w != 0.0) {
      dof.push_back(acc[i].first);
      weight.push_back(w);
    }
    i = j;
  }
}

// Old-to-new DOF map by logical node: the r-th DOF of a node in the old DOF list goes to the r-th DOF of the same
// node in the new one, -1 where the new list has none (|old|). `old_node`, `new_node`: node key of each DOF. DOF maps
// number their DOFs by node key, then by component, so the map is strictly increasing on the DOFs it maps; should
// either list not be sorted by node, nothing is mapped (all -1), which only costs speed.
std::vector<int> match_dofs(std::span<const std::uint64_t> old_node, std::span<const std::uint64_t> new_node) {
  std::vector<int> map(old_node.size(), -1);
  if (!std::is_sorted(old_node.begin(), old_node.end()) || !std::is_sorted(new_node.begin(), new_node.end()))
    return map;
  std::size_t i = 0, j = 0;
  while (i < old_node.size() && j < new_node.size()) {
    if (old_node[i] < new_node[j]) {
      ++i;
    } else if (new_node[j] < old_node[i]) {
      ++j;
    } else {
      // The DOFs of one node on both sides, paired in order.
      const std::uint64_t key = old_node[i];
      for (; i < old_node.size() && j < new_node.size() && old_node[i] == key && new_node[j] == key; ++i, ++j)
        map[i] = int(j);
      while (i < old_node.size() && old_node[i] == key) ++i;
      while (j < new_node.size() && new_node[j] == key) ++j;
    }
  }
  return map;
}

// True when the 8 rows of P for old leaf i (old_begin, old_dof, old_weight: the CSR of the old P) and for new leaf j
// hold the same entries in the same order, every old DOF mapped by dof_map onto the new one and the weights equal
// bit for bit. A vertex bound to the leaf with the same weights then composes to its old row, renumbered.
bool same_leaf_rows(std::span<const int> old_begin, std::span<const int> old_dof, std::span<const double> old_weight,
                    int i, const DofMap& P, int j, std::span<const int> dof_map) {
  const std::size_t a0 = std::size_t(old_begin[8 * std::size_t(i)]), a1 = std::size_t(old_begin[8 * std::size_t(i) + 8]);
  const std::size_t b0 = std::size_t(P.slot_begin[8 * std::size_t(j)]);
  if (a1 - a0 != std::size_t(P.slot_begin[8 * std::size_t(j) + 8]) - b0) return false;
  for (int k = 1; k < 8; ++k)
    if (std::size_t(old_begin[8 * std::size_t(i) + std::size_t(k)]) - a0 !=
        std::size_t(P.slot_begin[8 * std::size_t(j) + std::size_t(k)]) - b0)
      return false;
  for (std::size_t n = 0; n < a1 - a0; ++n) {
    if (dof_map[std::size_t(old_dof[a0 + n])] != P.slot_dof[b0 + n]) return false;
    if (std::bit_cast<std::uint64_t>(old_weight[a0 + n]) != std::bit_cast<std::uint64_t>(P.slot_weight[b0 + n]))
      return false;
  }
  return true;
}

// Fallback embedding of p in `leaf`: extrapolated trilinear weights, projected into the allowed range.
VertexEmbedding fallback_embedding(const Octree& tree, const RootGeometry& root, int leaf, const Vec3& p);

// The regular embedding of p (leaf = -1 when p lies in no leaf).
VertexEmbedding regular_embedding(const Octree& tree, const RootGeometry& root, const Vec3& p) {
  VertexEmbedding e;
  // Inside the root cube: the leaf that holds the vertex's finest cell, a binary search on the leaf codes.
  const Box3 root_box{root.min, root.min + Vec3::Constant(root.size)};
  if (root_box.contains(p)) e.leaf = tree.locate_cell(zcurve_cell(root, p));
  if (e.leaf >= 0) e.weights = trilinear_weights(local_coordinates(root.cell_box(tree.leaf(e.leaf)), p));
  return e;
}

}  // namespace

GridPoint zcurve_cell(const RootGeometry& root, const Vec3& rest) {
  // Fixed point on the finest grid, floored and clamped to the last cell, so the upper root faces stay inside.
  const Vec3 g = (rest - root.min) / root.unit();
  auto to_int = [](double v) {
    return std::uint32_t(std::clamp(std::floor(v), 0.0, double(kGridCells - 1)));
  };
  return {to_int(g.x()), to_int(g.y()), to_int(g.z())};
}

std::uint64_t zcurve_code(const RootGeometry& root, const Vec3& rest) {
  const GridPoint c = zcurve_cell(root, rest);
  return morton_encode(c.x, c.y, c.z);
}

ZCurveList::ZCurveList(const RootGeometry& root, std::span<const Vec3> rest) : m_root(root) {
  check_finite(rest, "vertex");
  // Encode every vertex, then sort by (code, vertex).
  m_entries.resize(rest.size());
  for (std::size_t i = 0; i < rest.size(); ++i) m_entries[i] = {zcurve_code(root, rest[i]), std::int32_t(i)};
  std::sort(m_entries.begin(), m_entries.end());
}

std::span<const ZEntry> ZCurveList::in_cell(const Cell& c) const {
  // A cell covers the Morton codes [code(anchor), code(anchor) + size^3).
  const std::uint64_t s = c.size();
  const std::uint64_t lo = c.morton(), hi = lo + s * s * s;
  const auto by_code = [](const ZEntry& e, std::uint64_t code) { return e.code < code; };
  const auto b = std::lower_bound(m_entries.begin(), m_entries.end(), lo, by_code);
  const auto e = std::lower_bound(b, m_entries.end(), hi, by_code);
  return {m_entries.data() + (b - m_entries.begin()), std::size_t(e - b)};
}

std::vector<int> ZCurveList::update(std::span<const int> removed, std::span<const Vec3> inserted_rest) {
  std::vector<int> map;
  update(removed, inserted_rest, map);
  return map;
}

void ZCurveList::update(std::span<const int> removed, std::span<const Vec3> inserted_rest, std::vector<int>& map) {
  const std::size_t n_old = m_entries.size();
  check_finite(inserted_rest, "inserted vertex");

  // Old-to-new map, which also finds bad and repeated indices before anything changes; kept vertices keep their
  // relative order. All buffers are reused from call to call, so an update allocates nothing in steady state.
  map.assign(n_old, 0);
  for (std::size_t i = 0; i < removed.size(); ++i) {
    const int v = removed[i];
    if (v < 0 || std::size_t(v) >= n_old)
      throw std::invalid_argument("removed_vertices[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is out of range [0, " + std::to_string(n_old) + ")");
    if (map[std::size_t(v)] < 0)
      throw std::invalid_argument("removed_vertices[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is listed twice");
    map[std::size_t(v)] = -1;
  }
  int next = 0;
  for (int& m : map) m = m < 0 ? -1 : next++;

  // Delete and renumber in one stable pass; the map is monotone, so the list stays sorted by (code, vertex).
  std::size_t out = 0;
  for (std::size_t i = 0; i < n_old; ++i) {
    const int v = map[std::size_t(m_entries[i].vertex)];
    if (v < 0) continue;
    m_entries[out++] = {m_entries[i].code, v};
  }
  m_entries.resize(out);

  // The new entries, numbered after the kept vertices.
  const std::size_t n = out, n_new = inserted_rest.size();
  m_added.resize(n_new);
  for (std::size_t i = 0; i < n_new; ++i)
    m_added[i] = {zcurve_code(m_root, inserted_rest[i]), std::int32_t(n + i)};
  std::sort(m_added.begin(), m_added.end());

  // Paper §4.5: one by one when n' < n / (log2 n - 1), else sort the batch and merge.
  const double denom = std::log2(double(std::max<std::size_t>(n, 2))) - 1.0;
  const bool one_by_one = denom <= 0.0 || double(n_new) < double(n) / denom;
  m_merged = !one_by_one;
  if (one_by_one) {
    // Each new entry finds its place by binary search (O(log n) each, on the part of the list not yet passed); the
    // list then opens all gaps in one backward pass, so no element moves more than once.
    m_at.resize(n_new);
    std::size_t from = 0;
    for (std::size_t i = 0; i < n_new; ++i) {
      from = std::size_t(std::upper_bound(m_entries.begin() + std::ptrdiff_t(from), m_entries.end(), m_added[i]) -
                         m_entries.begin());
      m_at[i] = from;
    }
    m_entries.resize(n + n_new);
    std::size_t end = n;
    for (std::size_t i = n_new; i-- > 0;) {
      // Shift the block [at[i], end) up by i + 1 places, then drop the new entry in front of it.
      std::move_backward(m_entries.begin() + std::ptrdiff_t(m_at[i]), m_entries.begin() + std::ptrdiff_t(end),
                         m_entries.begin() + std::ptrdiff_t(end + i + 1));
      m_entries[m_at[i] + i] = m_added[i];
      end = m_at[i];
    }
  } else {
    // Merge from the back into the grown list: no second buffer.
    m_entries.resize(n + n_new);
    std::size_t a = n, b = n_new, o = n + n_new;
    while (b > 0) {
      if (a > 0 && m_added[b - 1] < m_entries[a - 1]) m_entries[--o] = m_entries[--a];
      else m_entries[--o] = m_added[--b];
    }
  }
}

std::array<double, 8> clamp_fallback_weights(const std::array<double, 8>& w) {
  const double lo = kFallbackWeightMin, hi = kFallbackWeightMax;
  if (std::all_of(w.begin(), w.end(), [&](double v) { return v >= lo && v <= hi; })) return w;
  // Sum of the shifted, clamped weights; it falls monotonically with the shift.
  auto shifted_sum = [&](double shift) {
    double s = 0.0;
    for (const double v : w) s += std::clamp(v - shift, lo, hi);
    return s;
  };
  // Bisection on the shift: at a the sum is 8 hi > 1, at b it is 8 lo < 1.
  double a = *std::min_element(w.begin(), w.end()) - hi, b = *std::max_element(w.begin(), w.end()) - lo;
  for (int it = 0; it < 200 && b - a > 0.0; ++it) {
    const double m = 0.5 * (a + b);
    if (m <= a || m >= b) break;
    (shifted_sum(m) > 1.0 ? a : b) = m;
  }
  // With the clamped set known, solve for the shift exactly on the free weights.
  const double shift0 = 0.5 * (a + b);
  double fixed = 0.0, free_sum = 0.0;
  int free_count = 0;
  for (const double v : w) {
    const double s = v - shift0;
    if (s <= lo) {
      fixed += lo;
    } else if (s >= hi) {
      fixed += hi;
    } else {
      free_sum += v;
      ++free_count;
    }
  }
  const double shift = free_count > 0 ? (free_sum + fixed - 1.0) / double(free_count) : shift0;
  std::array<double, 8> out{};
  for (std::size_t k = 0; k < 8; ++k) out[k] = std::clamp(w[k] - shift, lo, hi);
  return out;
}

namespace {
VertexEmbedding fallback_embedding(const Octree& tree, const RootGeometry& root, int leaf, const Vec3& p) {
  VertexEmbedding e;
  e.leaf = leaf;
  e.fallback = true;
  e.weights = clamp_fallback_weights(trilinear_weights(local_coordinates(root.cell_box(tree.leaf(leaf)), p)));
  return e;
}
}  // namespace

VertexEmbedding embed_vertex(const Octree& tree, const RootGeometry& root, const Vec3& rest) {
  if (tree.size() == 0) throw std::invalid_argument("embed_vertex: the octree has no leaf");
  const VertexEmbedding e = regular_embedding(tree, root, rest);
  if (e.leaf >= 0) return e;
  // Fallback: the nearest leaf box by a scan of all leaves, the lower index on ties.
  double best = std::numeric_limits<double>::infinity();
  int leaf = -1;
  for (int i = 0; i < tree.size(); ++i) {
    const double d = box_distance2(root.cell_box(tree.leaf(i)), rest);
    if (d < best) {
      best = d;
      leaf = i;
    }
  }
  return fallback_embedding(tree, root, leaf, rest);
}

SurfaceEmbedding::SurfaceEmbedding(const ObjectModel& model, std::vector<Vec3> rest,
                                   std::vector<std::array<int32_t, 3>> triangles)
    : m_root(model.root()), m_tree(model.tree()), m_rest(std::move(rest)), m_triangles(std::move(triangles)) {
  count_corners(m_triangles, m_rest.size());
  m_zcurve = ZCurveList(m_root, m_rest);
  m_embedding.assign(m_rest.size(), VertexEmbedding{});
  build_adjacency();
  embed(model, {}, true);
  compose(model.dofs(), {}, {});
  m_last_reembedded = num_vertices();
  // Room for the first cuts, written once here, so that the first update() neither moves the per-vertex arrays
  // and the CSR nor takes its scratch pages from the system (a cut adds a few hundred vertices at most).
  const std::size_t room = m_rest.size() + m_rest.size() / 8;
  m_rest.reserve(room);
  m_embedding.reserve(room);
  m_dof.reserve(m_dof.size() + m_dof.size() / 8);
  m_weight.reserve(m_dof.capacity());
  m_next_begin.assign(room + 1, 0);
  m_next_tri_begin.assign(room + 2, 0);
  m_redo.assign(room, 0);
  m_reuse_from.assign(room, 0);
}

std::span<const ZEntry> SurfaceEmbedding::vertices_in_leaf(int leaf) const {
  if (leaf < 0 || leaf >= m_tree.size())
    throw std::out_of_range("SurfaceEmbedding::vertices_in_leaf: leaf " + std::to_string(leaf) + " out of range");
  return m_zcurve.in_cell(m_tree.leaf(leaf));
}

int SurfaceEmbedding::num_fallback() const {
  return int(std::count_if(m_embedding.begin(), m_embedding.end(), [](const auto& e) { return e.fallback; }));
}

void SurfaceEmbedding::check_triangles(const std::vector<std::array<int32_t, 3>>& triangles,
                                       std::size_t num_vertices) const {
  // One unsigned comparison per corner (negative indices wrap above any size); the search for the culprit only on
  // failure.
  std::uint32_t largest = 0;
  for (const auto& t : triangles)
    largest = std::max({largest, std::uint32_t(t[0]), std::uint32_t(t[1]), std::uint32_t(t[2])});
  if (triangles.empty() || std::size_t(largest) < num_vertices) return;
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int32_t v = triangles[t][std::size_t(k)];
      if (v < 0 || std::size_t(v) >= num_vertices)
        throw std::invalid_argument("triangle " + std::to_string(t) + " corner " + std::to_string(k) + " = " +
                                    std::to_string(v) + " is out of range [0, " + std::to_string(num_vertices) + ")");
    }
}

void SurfaceEmbedding::embed(const ObjectModel& model, std::span<const int> redo, bool all) {
  // Re-embed the listed vertices (all of them when `all` is set); those in no leaf are collected, ascending.
  if (m_tree.size() == 0) throw std::invalid_argument("SurfaceEmbedding: the model has no leaf");
  std::vector<std::size_t> lost;
  auto one = [&](std::size_t v) {
    m_embedding[v] = regular_embedding(m_tree, m_root, m_rest[v]);
    if (m_embedding[v].leaf < 0) lost.push_back(v);
  };
  if (all) {
    for (std::size_t v = 0; v < m_rest.size(); ++v) one(v);
  } else {
    for (const int v : redo) one(std::size_t(v));
  }
  // The fallback vertices go to the nearest leaf of their anchor's material component (the plain nearest leaf when
  // their surface component has no regular vertex), found on a bucket grid built once for all of them. Every
  // vertex not in `lost` is regular here (update() re-embeds all fallback vertices), and m_tri matches m_triangles.
  if (!lost.empty()) {
    const NearestLeafGrid grid(m_tree, m_root);
    const std::vector<int> anchor = fallback_anchors(m_embedding, lost, m_tri_begin, m_tri, m_triangles);
    std::vector<int> component;  // per leaf, computed on first need (one pass over P)
    for (const std::size_t v : lost) {
      // The plain nearest leaf is the answer when it lies in the anchor's component (it is then also the nearest
      // there, with the same tie-break). Sharing a DOF with the anchor's leaf proves that without the global pass.
      int leaf = grid.nearest(m_rest[v]);
      const int a = anchor[v];
      if (a >= 0) {
        const int home = m_embedding[std::size_t(a)].leaf;
        if (!leaves_share_dof(model.dofs(), leaf, home)) {
          if (component.empty()) {
            int count = 0;
            component = element_components(model, count);  // two leaves are one component when they share a DOF
          }
          const int c = component[std::size_t(home)];
          if (component[std::size_t(leaf)] != c) leaf = grid.nearest(m_rest[v], c, component);
        }
      }
      m_embedding[v] = fallback_embedding(m_tree, m_root, leaf, m_rest[v]);
    }
  }
}

void SurfaceEmbedding::compose(const DofMap& P, std::span<const int> reuse_from, std::span<const int> dof_map) {
  const std::size_t nv = m_rest.size();
  std::vector<std::pair<int, double>> acc;
  if (reuse_from.empty()) {
    // Every row anew, in vertex order.
    m_begin.resize(nv + 1);
    m_begin[0] = 0;
    m_dof.clear();
    m_weight.clear();
    for (std::size_t v = 0; v < nv; ++v) {
      compose_row(P, m_embedding[v], acc, m_dof, m_weight);
      m_begin[v + 1] = int(m_dof.size());
    }
  } else {
    // The new CSR is a sequence of segments of entries: runs of kept rows, which are consecutive old rows
    // (reuse_from increases, so their sources and destinations come in the same order), and runs of rows composed
    // anew (into m_new_* first). The kept runs move inside m_dof and m_weight, DOFs renumbered: those that move down
    // front to back, then those that move up back to front, so that none overwrites a source not yet moved; then
    // the new rows fill the gaps.
    struct Segment {
      std::size_t src, dst, len;  // entries: old position (or position in m_new_*), new position, count
      bool fresh;                 // composed anew
    };
    std::vector<Segment> segments;
    m_next_begin.resize(nv + 1);
    m_new_dof.clear();
    m_new_weight.clear();
    // Vertices 0 .. q - 1 keep their own rows where they are.
    const std::size_t nv_old = m_begin.size() - 1;
    std::size_t q = 0;
    while (q < nv && q < nv_old && reuse_from[q] == int(q)) ++q;
    std::copy(m_begin.begin(), m_begin.begin() + std::ptrdiff_t(q + 1), m_next_begin.begin());
    if (q > 0) segments.push_back({0, 0, std::size_t(m_begin[q]), false});
    for (std::size_t v = q; v < nv;) {
      const int from = reuse_from[v];
      const std::size_t dst = std::size_t(m_next_begin[v]);
      if (from < 0) {
        const std::size_t src = m_new_dof.size();
        compose_row(P, m_embedding[v], acc, m_new_dof, m_new_weight);
        const std::size_t len = m_new_dof.size() - src;
        m_next_begin[v + 1] = int(dst + len);
        if (!segments.empty() && segments.back().fresh && segments.back().dst + segments.back().len == dst)
          segments.back().len += len;
        else
          segments.push_back({src, dst, len, true});
        ++v;
        continue;
      }
      std::size_t end = v + 1;
      while (end < nv && reuse_from[end] == from + int(end - v)) ++end;
      const std::size_t a = std::size_t(m_begin[std::size_t(from)]);
      const std::size_t b = std::size_t(m_begin[std::size_t(from) + (end - v)]);
      const int shift = int(dst) - int(a);
      for (std::size_t u = v; u < end; ++u) m_next_begin[u + 1] = m_begin[std::size_t(from) + (u - v) + 1] + shift;
      if (!segments.empty() && !segments.back().fresh && segments.back().src + segments.back().len == a &&
          segments.back().dst + segments.back().len == dst)
        segments.back().len += b - a;
      else
        segments.push_back({a, dst, b - a, false});
      v = end;
    }
    const std::size_t nnz = std::size_t(m_next_begin[nv]);
    if (nnz > m_dof.size()) {
      m_dof.resize(nnz);
      m_weight.resize(nnz);
    }
    // The DOFs below d0 keep their numbers (a cut renumbers those after its first new or removed node).
    int d0 = 0;
    while (std::size_t(d0) < dof_map.size() && dof_map[std::size_t(d0)] == d0) ++d0;
    int* dof = m_dof.data();
    double* weight = m_weight.data();
    const int* renumber = dof_map.data();
    for (const Segment& g : segments) {
      if (g.fresh || g.dst > g.src) continue;
      if (g.dst == g.src) {
        for (std::size_t i = g.src; i < g.src + g.len; ++i)
          if (dof[i] >= d0) dof[i] = renumber[dof[i]];
      } else {
        for (std::size_t i = 0; i < g.len; ++i) dof[g.dst + i] = renumber[dof[g.src + i]];
        std::copy(weight + g.src, weight + g.src + g.len, weight + g.dst);
      }
    }
    for (auto it = segments.rbegin(); it != segments.rend(); ++it) {
      const Segment& g = *it;
      if (g.fresh || g.dst <= g.src) continue;
      for (std::size_t i = g.len; i-- > 0;) dof[g.dst + i] = renumber[dof[g.src + i]];
      std::copy_backward(weight + g.src, weight + g.src + g.len, weight + g.dst + g.len);
    }
    for (const Segment& g : segments) {
      if (!g.fresh) continue;
      std::copy(m_new_dof.begin() + std::ptrdiff_t(g.src), m_new_dof.begin() + std::ptrdiff_t(g.src + g.len),
                dof + g.dst);
      std::copy(m_new_weight.begin() + std::ptrdiff_t(g.src), m_new_weight.begin() + std::ptrdiff_t(g.src + g.len),
                weight + g.dst);
    }
    m_dof.resize(nnz);
    m_weight.resize(nnz);
    m_begin.swap(m_next_begin);
  }

  // Keep the rows of P and the DOF nodes for the next update().
  m_num_dofs = P.num_dofs;
  m_slot_begin = P.slot_begin;
  m_slot_dof = P.slot_dof;
  m_slot_weight = P.slot_weight;
  m_dof_node = P.dof_node;
}

void SurfaceEmbedding::count_corners(const std::vector<std::array<int32_t, 3>>& triangles, std::size_t num_vertices) {
  // The corners at vertex v are counted at [v + 2], so that build_adjacency() turns the counts into row starts in
  // place. One unsigned comparison per corner (negative indices wrap above any size); the culprit is searched for
  // only on failure.
  std::vector<int>& count = m_next_tri_begin;
  count.assign(num_vertices + 2, 0);
  bool bad = false;
  for (const auto& t : triangles)
    for (const int32_t v : t) {
      if (std::size_t(std::uint32_t(v)) < num_vertices)
        ++count[std::size_t(v) + 2];
      else
        bad = true;
    }
  if (bad) check_triangles(triangles, num_vertices);
}

void SurfaceEmbedding::build_adjacency() {
  // Vertex-to-triangle CSR; a triangle appears once per corner it has at the vertex, triangles ascending. A counting
  // sort on the counts of count_corners(): after the prefix sum, start[v + 1] is the first slot of vertex v; the
  // scatter advances it to the first slot of v + 1, so that start[0 .. |V|] ends up as the row starts.
  const std::size_t nv = m_rest.size();
  std::vector<int>& start = m_next_tri_begin;
  for (std::size_t i = 2; i < nv + 2; ++i) start[i] += start[i - 1];
  m_tri.resize(std::size_t(start[nv + 1]));
  int* slot = start.data() + 1;
  int* tri = m_tri.data();
  for (std::size_t t = 0; t < m_triangles.size(); ++t)
    for (const int32_t v : m_triangles[t]) tri[slot[v]++] = int(t);
  start.pop_back();
  m_tri_begin.swap(start);
}

void SurfaceEmbedding::deformed_positions(const std::vector<Vec3>& x_dofs, std::vector<Vec3>& positions,
                                          Executor& exec) const {
  if (int(x_dofs.size()) != m_num_dofs)
    throw std::invalid_argument("SurfaceEmbedding::deformed_positions: " + std::to_string(x_dofs.size()) +
                                " DOF positions for a model with " + std::to_string(m_num_dofs) + " DOFs");
  positions.resize(m_rest.size());
  // Each vertex is written by exactly one task: the result does not depend on the thread count.
  exec.parallel_for(num_vertices(), 2048, [&](int begin, int end) {
    for (int v = begin; v < end; ++v) {
      Vec3 p = Vec3::Zero();
      for (int i = m_begin[std::size_t(v)]; i < m_begin[std::size_t(v) + 1]; ++i)
        p += m_weight[std::size_t(i)] * x_dofs[std::size_t(m_dof[std::size_t(i)])];
      positions[std::size_t(v)] = p;
    }
  });
}

void SurfaceEmbedding::deformed_normals(const std::vector<Vec3>& positions, std::vector<Vec3>& normals,
                                        Executor& exec) const {
  std::vector<Vec3> face_normals;
  deformed_normals(positions, normals, exec, face_normals);
}

void SurfaceEmbedding::deformed_normals(const std::vector<Vec3>& positions, std::vector<Vec3>& normals,
                                        Executor& exec, std::vector<Vec3>& face_normals) const {
  if (positions.size() != m_rest.size())
    throw std::invalid_argument("SurfaceEmbedding::deformed_normals: " + std::to_string(positions.size()) +
                                " positions for " + std::to_string(m_rest.size()) + " vertices");
  // Face normals (twice the area times the unit normal), one task per triangle range.
  face_normals.resize(m_triangles.size());
  exec.parallel_for(int(m_triangles.size()), 4096, [&](int begin, int end) {
    for (int t = begin; t < end; ++t) {
      const auto& tri = m_triangles[std::size_t(t)];
      const Vec3& a = positions[std::size_t(tri[0])];
      face_normals[std::size_t(t)] = (positions[std::size_t(tri[1])] - a).cross(positions[std::size_t(tri[2])] - a);
    }
  });
  // Each vertex sums its incident faces in triangle order, as sim::vertex_normals does, and normalises.
  normals.resize(m_rest.size());
  exec.parallel_for(num_vertices(), 2048, [&](int begin, int end) {
    for (int v = begin; v < end; ++v) {
      Vec3 n = Vec3::Zero();
      for (int i = m_tri_begin[std::size_t(v)]; i < m_tri_begin[std::size_t(v) + 1]; ++i)
        n += face_normals[std::size_t(m_tri[std::size_t(i)])];
      const double len = n.norm();
      normals[std::size_t(v)] = len > 0.0 ? Vec3(n / len) : Vec3::Zero();
    }
  });
}

std::vector<int> SurfaceEmbedding::update(const ObjectModel& new_model, const SurfaceEdit& edit) {
  return apply(new_model, edit, nullptr);
}

std::vector<int> SurfaceEmbedding::update(const ObjectModel& new_model, SurfaceEdit&& edit) {
  return apply(new_model, edit, &edit.triangles);
}

std::vector<int> SurfaceEmbedding::apply(const ObjectModel& new_model, const SurfaceEdit& edit,
                                         std::vector<std::array<int32_t, 3>>* take) {
  // Validate everything before touching any member but scratch, so that a bad edit leaves the embedding as it was.
  if (new_model.root().min != m_root.min || new_model.root().size != m_root.size)
    throw std::invalid_argument("SurfaceEmbedding::update: the new model has another root cube");
  if (new_model.tree().size() == 0) throw std::invalid_argument("SurfaceEmbedding::update: the new model has no leaf");
  check_index_list(edit.removed_vertices, m_rest.size(), "removed_vertices");
  check_finite(edit.inserted_rest, "inserted vertex");
  const std::size_t nv_old = m_rest.size();
  const std::size_t nv_new = nv_old - edit.removed_vertices.size() + edit.inserted_rest.size();
  for (std::size_t i = 0; i < edit.changed_leaves.size(); ++i) {
    const int l = edit.changed_leaves[i];
    if (l < 0 || l >= new_model.tree().size())
      throw std::invalid_argument("changed_leaves[" + std::to_string(i) + "] = " + std::to_string(l) +
                                  " is out of range [0, " + std::to_string(new_model.tree().size()) + ")");
  }
  // The triangles are validated while their corners are counted for the adjacency (into scratch).
  count_corners(edit.triangles, nv_new);

  // The Z-curve list: delete, renumber, insert.
  std::vector<int> map = m_zcurve.update(edit.removed_vertices, edit.inserted_rest);

  // Leaves kept from the old tree keep their vertices' weights, renumbered (nothing to match when the tree is the same).
  const Octree& tree = new_model.tree();
  const DofMap& P = new_model.dofs();
  const bool same_tree = tree.leaves() == m_tree.leaves();
  std::vector<char> kept_new;
  std::vector<int> old_to_new;
  if (same_tree) {
    old_to_new.resize(std::size_t(m_tree.size()));
    std::iota(old_to_new.begin(), old_to_new.end(), 0);
  } else {
    old_to_new = match_leaves(m_tree, tree, kept_new);
  }

  // Kept leaves whose 8 rows of P are the same up to the renumbering of the DOFs (most of them: a cut rebuilds the
  // DOFs only around the changed region); their regularly bound vertices keep their composed rows.
  const std::vector<int> dof_map = match_dofs(m_dof_node, P.dof_node);
  std::vector<char> same_rows(std::size_t(tree.size()), 0);
  for (int i = 0; i < m_tree.size(); ++i) {
    const int j = old_to_new[std::size_t(i)];
    if (j >= 0) same_rows[std::size_t(j)] = same_leaf_rows(m_slot_begin, m_slot_dof, m_slot_weight, i, P, j, dof_map);
  }

  // Kept vertices move down to their new index (the map is increasing), with their leaf renumbered; the fallback
  // ones and those whose leaf is gone are flagged for re-embedding. m_reuse_from: the old vertex whose composed row
  // a vertex keeps, or -1. Flagged vertices are listed once each in m_redo_list.
  const std::size_t kept = nv_new - edit.inserted_rest.size();
  m_redo.assign(nv_new, 0);
  m_redo_list.clear();
  m_reuse_from.resize(nv_new);
  auto flag = [&](std::size_t k) {
    if (!m_redo[k]) {
      m_redo[k] = 1;
      m_redo_list.push_back(int(k));
    }
    m_reuse_from[k] = -1;
  };
  // Kept vertex k (old index v), already moved to k: its new leaf, or the flag.
  auto rebind_kept = [&](std::size_t k, std::size_t v) {
    VertexEmbedding& e = m_embedding[k];
    const int leaf = e.fallback ? -1 : old_to_new[std::size_t(e.leaf)];
    if (leaf < 0) {
      flag(k);
      return;
    }
    if (e.leaf != leaf) e.leaf = leaf;
    m_reuse_from[k] = same_rows[std::size_t(leaf)] ? int(v) : -1;
  };
  if (nv_new > m_rest.capacity()) {
    // Room for the next cuts too (one reallocation now instead of one per cut).
    m_rest.reserve(nv_new + nv_new / 8);
    m_embedding.reserve(nv_new + nv_new / 8);
  }
  // Before the first removed vertex nothing moves.
  std::size_t first = nv_old;
  for (const int v : edit.removed_vertices) first = std::min(first, std::size_t(v));
  for (std::size_t v = 0; v < first; ++v) rebind_kept(v, v);
  // After it, the runs between removed vertices move down, a cache-sized chunk at a time.
  constexpr std::size_t kChunk = 512;
  std::size_t k = first;
  for (std::size_t v = first; v < nv_old;) {
    if (map[v] < 0) {
      ++v;
      continue;
    }
    std::size_t end = v + 1;
    while (end < nv_old && end - v < kChunk && map[end] >= 0) ++end;
    std::copy(m_rest.begin() + std::ptrdiff_t(v), m_rest.begin() + std::ptrdiff_t(end),
              m_rest.begin() + std::ptrdiff_t(k));
    std::copy(m_embedding.begin() + std::ptrdiff_t(v), m_embedding.begin() + std::ptrdiff_t(end),
              m_embedding.begin() + std::ptrdiff_t(k));
    for (std::size_t u = v; u < end; ++u) rebind_kept(k + (u - v), u);
    k += end - v;
    v = end;
  }
  m_rest.resize(nv_new);
  m_embedding.resize(nv_new);
  for (std::size_t i = 0; i < edit.inserted_rest.size(); ++i) {
    m_rest[kept + i] = edit.inserted_rest[i];
    flag(kept + i);
  }

  // Vertices of new or changed leaves: two binary searches per leaf on the Z-curve list.
  auto flag_leaf = [&](int j) {
    for (const ZEntry& z : m_zcurve.in_cell(tree.leaf(j))) flag(std::size_t(z.vertex));
  };
  for (int j = 0; j < (same_tree ? 0 : tree.size()); ++j)
    if (!kept_new[std::size_t(j)]) flag_leaf(j);
  for (const int j : edit.changed_leaves) flag_leaf(j);
  std::sort(m_redo_list.begin(), m_redo_list.end());

  // Swap in the new surface and tree, re-embed the flagged vertices, and compose: kept rows renumbered, the others
  // anew through the new P.
  if (take != nullptr) {
    m_triangles.swap(*take);
    take->clear();
  } else {
    m_triangles = edit.triangles;
  }
  if (!same_tree) m_tree = tree;
  build_adjacency();
  embed(new_model, m_redo_list, false);
  compose(P, m_reuse_from, dof_map);
  m_last_reembedded = int(m_redo_list.size());
  return map;
}

void SurfaceEmbedding::rebind(const ObjectModel& new_model) {
  SurfaceEdit edit;
  edit.triangles = m_triangles;
  update(new_model, std::move(edit));
}

}  // namespace octocut::sim
