// Binding rest points to leaves (SPEC §2.4): the regular trilinear embedding in the leaf that holds a point, and the
// fallback rule for points in no leaf (nearest leaf of the anchor's material component, found on a bucket grid;
// anchors along the triangles of S; weights clamped).
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <stdexcept>

#include "octocut/sim/embedding.hpp"

namespace octocut::sim {

namespace {

// Squared distance from p to the closed box b, m^2.
double box_distance2(const Box3& b, const Vec3& p) {
  const Vec3 d = (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0);
  return d.squaredNorm();
}

// Local coordinates of p in leaf box b: 0 at the lower corner and 1 at the upper one along each axis.
Vec3 local_coordinates(const Box3& b, const Vec3& p) {
  return ((p - b.min).array() / (b.max - b.min).array()).matrix();
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
// `tri_begin`, `tri` are the vertex-to-triangle CSR of `triangles`. Writes one anchor per vertex (|V|), -1 for the
// regular vertices. A breadth-first search from all regular vertices at once, layer by layer through fallback
// vertices only: the nearest regular vertices of a vertex at depth d + 1 are the union of those of its neighbours at
// depth d, so keeping the lowest anchor among those neighbours gives the tie-break exactly. Cost: the triangles
// around the fallback vertices, independent of |V| beyond one array fill.
// `anchor` and `depth` (|V| each) are the caller's arrays, so that repeated calls reuse their pages; on return
// `anchor` holds the result and `depth` is scratch.
void fallback_anchors(std::span<const VertexEmbedding> embedding, std::span<const std::size_t> lost,
                      std::span<const int> tri_begin, std::span<const int> tri,
                      std::span<const std::array<int32_t, 3>> triangles, std::vector<int>& anchor,
                      std::vector<int>& depth) {
  anchor.assign(embedding.size(), -1);
  depth.assign(embedding.size(), -1);
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
}

// Appends the composed row of e to (dof, weight): vertex = sum_k w_k (P x)_(8 leaf + k), the entries of one DOF
// The regular embedding of p (leaf = -1 when p lies in no leaf).
VertexEmbedding regular_embedding(const Octree& tree, const RootGeometry& root, const Vec3& p) {
  VertexEmbedding e;
  // Inside the root cube: the leaf that holds the vertex's finest cell, a binary search on the leaf codes.
  const Box3 root_box{root.min, root.min + Vec3::Constant(root.size)};
  if (root_box.contains(p)) e.leaf = tree.locate_cell(zcurve_cell(root, p));
  if (e.leaf >= 0) e.weights = trilinear_weights(local_coordinates(root.cell_box(tree.leaf(e.leaf)), p));
  return e;
}

// Fallback embedding of p in `leaf`: extrapolated trilinear weights, projected into the allowed range.
VertexEmbedding fallback_embedding(const Octree& tree, const RootGeometry& root, int leaf, const Vec3& p) {
  VertexEmbedding e;
  e.leaf = leaf;
  e.fallback = true;
  e.weights = clamp_fallback_weights(trilinear_weights(local_coordinates(root.cell_box(tree.leaf(leaf)), p)));
  return e;
}

// The leaves of a new tree that the old one did not have, for the fallback hints of SurfaceEmbedding::embed: a hinted
// leaf stays the nearest unless one of them is at least as near.
class NewLeaves {
 public:
  NewLeaves(const Octree& tree, const RootGeometry& root, std::span<const char> kept_new) {
    for (std::size_t l = 0; l < kept_new.size(); ++l) {
      if (kept_new[l]) continue;
      const Box3 b = root.cell_box(tree.leaf(int(l)));
      m_all = m_box.empty() ? b : Box3{m_all.min.cwiseMin(b.min), m_all.max.cwiseMax(b.max)};
      m_box.push_back(b);
    }
  }
  // Whether some new leaf lies within squared distance d2 (m^2) of p, ties included.
  [[nodiscard]] bool within(const Vec3& p, double d2) const {
    if (m_box.empty() || box_distance2(m_all, p) > d2) return false;
    return std::any_of(m_box.begin(), m_box.end(), [&](const Box3& b) { return box_distance2(b, p) <= d2; });
  }

 private:
  std::vector<Box3> m_box;  ///< rest boxes of the new leaves, m
  Box3 m_all;               ///< their bounding box, m
};

}  // namespace

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


void SurfaceEmbedding::embed(const ObjectModel& model, const TriMesh& surface, std::span<const int> redo, bool all,
                             Executor* exec, std::span<const FallbackHint> hints, std::span<const char> kept_new) {
  // Re-embed the listed vertices (all of them when `all` is set); those in no leaf are collected, ascending. Each
  // vertex is written by one task only and reads nothing another task writes, so the result does not depend on the
  // thread count.
  if (m_tree.size() == 0) throw std::invalid_argument("SurfaceEmbedding: the model has no leaf");
  const std::vector<Vec3>& rest = surface.vertices;
  const std::size_t n = all ? rest.size() : redo.size();
  const auto vertex = [&](std::size_t i) { return all ? i : std::size_t(redo[i]); };
  const auto parallel = [&](std::size_t count, const std::function<void(std::size_t)>& body) {
    const auto chunk = [&](int begin, int end) {
      for (int i = begin; i < end; ++i) body(std::size_t(i));
    };
    if (exec)
      exec->parallel_for(int(count), 256, chunk);
    else
      chunk(0, int(count));
  };
  parallel(n, [&](std::size_t i) {
    const std::size_t v = vertex(i);
    m_embedding[v] = regular_embedding(m_tree, m_root, rest[v]);
  });
  std::vector<std::size_t> lost;
  for (std::size_t i = 0; i < n; ++i)
    if (m_embedding[vertex(i)].leaf < 0) lost.push_back(vertex(i));
  m_fallback_anchor.clear();
  if (lost.empty()) return;
  // The fallback vertices go to the nearest leaf of their anchor's material component (the plain nearest leaf when
  // their surface component has no regular vertex), found on a bucket grid built once for all of them. Every
  // vertex not in `lost` is regular here (update() re-embeds all fallback vertices), and m_tri matches the triangles
  // of `surface`. The plain nearest leaf is the answer when it lies in the anchor's component (it is then also the
  // nearest there, with the same tie-break); sharing a DOF with the anchor's leaf proves that without the global
  // pass over the components, which runs only when some vertex needs it.
  fallback_anchors(m_embedding, lost, m_tri_begin, m_tri, surface.triangles, m_anchor, m_depth);
  const std::vector<int>& anchor = m_anchor;
  for (const std::size_t v : lost) m_fallback_anchor.emplace_back(int(v), anchor[v]);
  // The hint of each lost vertex (-1: none). A hinted vertex keeps its leaf (state 1) when its anchor is the same and
  // no new leaf is as near; the component check below may still send it to the search (state 0).
  std::vector<int> hint(lost.size(), -1);
  for (std::size_t i = 0, h = 0; i < lost.size() && h < hints.size(); ++i) {
    while (h < hints.size() && std::size_t(hints[h].vertex) < lost[i]) ++h;
    if (h < hints.size() && std::size_t(hints[h].vertex) == lost[i]) hint[i] = int(h);
  }
  const NewLeaves fresh(m_tree, m_root, kept_new);
  const DofMap& P = model.dofs();
  std::vector<int> leaf(lost.size(), -1);
  std::vector<char> other(lost.size(), 0);  // 1: the leaf found shares no DOF with the anchor's leaf
  std::vector<char> state(lost.size(), 0);
  parallel(lost.size(), [&](std::size_t i) {
    if (hint[i] < 0) return;
    const std::size_t v = lost[i];
    const FallbackHint& h = hints[std::size_t(hint[i])];
    if (h.leaf < 0 || h.anchor != anchor[v]) return;
    if (fresh.within(rest[v], box_distance2(m_root.cell_box(m_tree.leaf(h.leaf)), rest[v]))) return;
    leaf[i] = h.leaf;
    state[i] = 1;
  });
  // The others search, on a grid built only when some vertex needs it.
  std::optional<NearestLeafGrid> grid;
  if (std::find(state.begin(), state.end(), char(0)) != state.end()) grid.emplace(m_tree, m_root);
  parallel(lost.size(), [&](std::size_t i) {
    const int a = anchor[lost[i]];
    if (state[i] == 0) leaf[i] = grid->nearest(rest[lost[i]]);
    other[i] = a >= 0 && !leaves_share_dof(P, leaf[i], m_embedding[std::size_t(a)].leaf);
  });
  std::vector<int> component;  // per leaf: two leaves are one component when they share a DOF
  if (std::find(other.begin(), other.end(), char(1)) != other.end()) {
    int count = 0;
    component = element_components(model, count);
    if (!grid) grid.emplace(m_tree, m_root);
  }
  // The anchors are regular vertices, which this pass does not write.
  parallel(lost.size(), [&](std::size_t i) {
    const std::size_t v = lost[i];
    if (other[i]) {
      const int c = component[std::size_t(m_embedding[std::size_t(anchor[v])].leaf)];
      if (component[std::size_t(leaf[i])] != c) {
        leaf[i] = grid->nearest(rest[v], c, component);
        state[i] = 0;
      }
    }
    m_embedding[v] = fallback_embedding(m_tree, m_root, leaf[i], rest[v]);
    if (state[i] != 0) m_reuse_from[v] = hints[std::size_t(hint[i])].reuse_from;
  });
}

}  // namespace octocut::sim
