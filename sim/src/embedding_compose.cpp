// Composition through P (SPEC §2.4): each vertex's 8 trilinear weights times the 8 rows of the prolongation P of its
// leaf, summed by DOF into one short row of (DOF, weight) pairs, the CSR that deformed_positions() reads. After a
// cut, the rows that stay valid are kept (DOFs renumbered) and moved in runs; only the others are composed anew.
#include <algorithm>
#include <utility>
#include <vector>

#include "octocut/sim/embedding.hpp"

namespace octocut::sim {

namespace {

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

// A run of entries of the new CSR: kept rows, which are consecutive old rows moved as one block, or rows composed
// anew (into the scratch arrays first).
struct Segment {
  std::size_t src, dst, len;  // entries: old position (or position in the scratch arrays), new position, count
  bool fresh;                 // composed anew
};

// The layout of the new CSR for compose() with reuse_from (see there): its row starts into `next_begin` (|V| + 1),
// the rows composed anew into `new_dof` and `new_weight`, and the segments in order. `begin` and `embedding`: the
// current row starts (old |V| + 1) and the new vertices' embeddings (|V|).
std::vector<Segment> plan_segments(const DofMap& P, std::span<const VertexEmbedding> embedding,
                                   std::span<const int> begin, std::span<const int> reuse_from,
                                   std::vector<int>& next_begin, std::vector<int>& new_dof,
                                   std::vector<double>& new_weight) {
  const std::size_t nv = embedding.size();
  std::vector<std::pair<int, double>> acc;
  std::vector<Segment> segments;
  next_begin.resize(nv + 1);
  new_dof.clear();
  new_weight.clear();
  // Vertices 0 .. q - 1 keep their own rows where they are.
  const std::size_t nv_old = begin.size() - 1;
  std::size_t q = 0;
  while (q < nv && q < nv_old && reuse_from[q] == int(q)) ++q;
  std::copy(begin.begin(), begin.begin() + std::ptrdiff_t(q + 1), next_begin.begin());
  if (q > 0) segments.push_back({0, 0, std::size_t(begin[q]), false});
  for (std::size_t v = q; v < nv;) {
    const int from = reuse_from[v];
    const std::size_t dst = std::size_t(next_begin[v]);
    if (from < 0) {
      // A row anew, appended to the last fresh segment when that ends here.
      const std::size_t src = new_dof.size();
      compose_row(P, embedding[v], acc, new_dof, new_weight);
      const std::size_t len = new_dof.size() - src;
      next_begin[v + 1] = int(dst + len);
      if (!segments.empty() && segments.back().fresh && segments.back().dst + segments.back().len == dst)
        segments.back().len += len;
      else
        segments.push_back({src, dst, len, true});
      ++v;
      continue;
    }
    // A run of kept rows that were consecutive old rows, appended to the last kept segment when that continues it.
    std::size_t end = v + 1;
    while (end < nv && reuse_from[end] == from + int(end - v)) ++end;
    const std::size_t a = std::size_t(begin[std::size_t(from)]);
    const std::size_t b = std::size_t(begin[std::size_t(from) + (end - v)]);
    const int shift = int(dst) - int(a);
    for (std::size_t u = v; u < end; ++u) next_begin[u + 1] = begin[std::size_t(from) + (u - v) + 1] + shift;
    if (!segments.empty() && !segments.back().fresh && segments.back().src + segments.back().len == a &&
        segments.back().dst + segments.back().len == dst)
      segments.back().len += b - a;
    else
      segments.push_back({a, dst, b - a, false});
    v = end;
  }
  return segments;
}

// Writes the segments into (dof, weight), which hold the old entries and have room for the new ones: the kept runs
// move inside them, DOFs renumbered by dof_map, those that move down front to back, then those that move up back to
// front, so that none overwrites a source not yet moved; then the rows composed anew (new_dof, new_weight) fill the
// gaps.
void move_segments(std::span<const Segment> segments, std::span<const int> dof_map, int* dof, double* weight,
                   std::span<const int> new_dof, std::span<const double> new_weight) {
  // The DOFs below d0 keep their numbers (a cut renumbers those after its first new or removed node).
  int d0 = 0;
  while (std::size_t(d0) < dof_map.size() && dof_map[std::size_t(d0)] == d0) ++d0;
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
    std::copy(new_dof.begin() + std::ptrdiff_t(g.src), new_dof.begin() + std::ptrdiff_t(g.src + g.len), dof + g.dst);
    std::copy(new_weight.begin() + std::ptrdiff_t(g.src), new_weight.begin() + std::ptrdiff_t(g.src + g.len),
              weight + g.dst);
  }
}

}  // namespace

void SurfaceEmbedding::compose(const DofMap& P, std::span<const int> reuse_from, std::span<const int> dof_map) {
  if (reuse_from.empty())
    compose_all(P);
  else
    compose_reusing(P, reuse_from, dof_map);
  // Keep the rows of P and the DOF nodes for the next update().
  m_num_dofs = P.num_dofs;
  m_slot_begin = P.slot_begin;
  m_slot_dof = P.slot_dof;
  m_slot_weight = P.slot_weight;
  m_dof_node = P.dof_node;
}

void SurfaceEmbedding::compose_all(const DofMap& P) {
  const std::size_t nv = m_embedding.size();
  std::vector<std::pair<int, double>> acc;
  m_begin.resize(nv + 1);
  m_begin[0] = 0;
  m_dof.clear();
  m_weight.clear();
  for (std::size_t v = 0; v < nv; ++v) {
    compose_row(P, m_embedding[v], acc, m_dof, m_weight);
    m_begin[v + 1] = int(m_dof.size());
  }
}

void SurfaceEmbedding::compose_reusing(const DofMap& P, std::span<const int> reuse_from, std::span<const int> dof_map) {
  // The new CSR is a sequence of segments of entries: runs of kept rows, which are consecutive old rows (reuse_from
  // increases, so their sources and destinations come in the same order), and runs of rows composed anew.
  const std::vector<Segment> segments =
      plan_segments(P, m_embedding, m_begin, reuse_from, m_next_begin, m_new_dof, m_new_weight);
  const std::size_t nnz = std::size_t(m_next_begin[m_embedding.size()]);
  if (nnz > m_dof.size()) {
    m_dof.resize(nnz);
    m_weight.resize(nnz);
  }
  move_segments(segments, dof_map, m_dof.data(), m_weight.data(), m_new_dof, m_new_weight);
  m_dof.resize(nnz);
  m_weight.resize(nnz);
  m_begin.swap(m_next_begin);
}

}  // namespace octocut::sim
