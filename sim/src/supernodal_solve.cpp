#include "supernodal_solve.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "octocut/sim/parallel.hpp"
#include "supernode_kernels.hpp"

namespace octocut::sim {

namespace {

// The longer part's work after dealing the subtrees `pieces` (their work `sub`), heaviest first, each to the part
// with less so far; `bins` receives each piece's part.
double deal(const std::vector<int>& pieces, const std::vector<double>& sub, std::vector<int>& bins) {
  std::vector<int> order(pieces.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return sub[std::size_t(pieces[std::size_t(a)])] > sub[std::size_t(pieces[std::size_t(b)])];
  });
  double load[2] = {0.0, 0.0};
  bins.assign(pieces.size(), 0);
  for (const int i : order) {
    const int p = load[1] < load[0] ? 1 : 0;
    bins[std::size_t(i)] = p;
    load[p] += sub[std::size_t(pieces[std::size_t(i)])];
  }
  return std::max(load[0], load[1]);
}

// A supernode's forward (or backward) kernel on L's values in the precision `packed` holds: its block starts at
// `offset` in the packed layout, its columns at k1.
void supernode_kernel(bool forward, const PackedFactor& packed, long offset, int k1, int nscol, int nsrow, int ld,
                      float* w) {
  const float* d = packed.diag_inv.data() + k1;
  const float* s = packed.scale.data() + k1;
  if (packed.half()) {
    const std::uint16_t* L = packed.codes.data() + offset;
    forward ? supernode_forward(L, d, s, nscol, nsrow, ld, w) : supernode_backward(L, d, s, nscol, nsrow, ld, w);
  } else {
    const float* L = packed.values.data() + offset;
    forward ? supernode_forward(L, d, s, nscol, nsrow, ld, w) : supernode_backward(L, d, s, nscol, nsrow, ld, w);
  }
}

}  // namespace

void SupernodalSolvePlan::build(const SupernodalStructure& L) {
  const int ns = L.nsuper;
  m_px.assign(std::size_t(ns) + 1, 0);  // the packed layout: each supernode's columns at its leading dimension
  for (int s = 0; s < ns; ++s) {
    const int nscol = L.super[s + 1] - L.super[s], nsrow = L.pi[s + 1] - L.pi[s];
    m_px[std::size_t(s) + 1] = m_px[std::size_t(s)] + long(nscol) * leading_dimension(nsrow);
  }
  m_super_of.assign(std::size_t(L.n), 0);
  for (int s = 0; s < ns; ++s) std::fill(m_super_of.begin() + L.super[s], m_super_of.begin() + L.super[s + 1], s);

  // The supernodal elimination tree: a supernode's parent holds its first row below its own columns. Postorder:
  // children come before their parent, so one ascending pass sums the subtrees.
  const auto nsz = std::size_t(ns);
  std::vector<int> parent(nsz, -1);
  std::vector<double> cost(nsz, 0.0), sub(nsz, 0.0);  // entries of L: the supernode's, its subtree's
  m_first.resize(nsz);
  std::iota(m_first.begin(), m_first.end(), 0);
  std::vector<std::vector<int>> children(nsz);
  for (int s = 0; s < ns; ++s) {
    const int nscol = L.super[s + 1] - L.super[s], nsrow = L.pi[s + 1] - L.pi[s];
    cost[std::size_t(s)] = double(nscol) * double(nsrow);
    sub[std::size_t(s)] += cost[std::size_t(s)];
    if (nsrow > nscol) parent[std::size_t(s)] = m_super_of[std::size_t(L.rows[L.pi[s] + nscol])];
    const int p = parent[std::size_t(s)];
    if (p < 0) continue;
    sub[std::size_t(p)] += sub[std::size_t(s)];
    m_first[std::size_t(p)] = std::min(m_first[std::size_t(p)], m_first[std::size_t(s)]);
    children[std::size_t(p)].push_back(s);
  }

  // Split the heaviest subtree at its root while that helps: the time is the top's work plus the longer part's.
  std::vector<int> pieces, bins, split;
  for (int s = 0; s < ns; ++s)
    if (parent[std::size_t(s)] < 0) pieces.push_back(s);
  double top = 0.0;
  double best = deal(pieces, sub, bins);
  std::vector<int> best_pieces = pieces, best_bins = bins;
  std::size_t best_split = 0;
  for (int round = 0; round < 256 && !pieces.empty(); ++round) {
    const auto heaviest = std::max_element(pieces.begin(), pieces.end(), [&](int a, int b) {
      return sub[std::size_t(a)] < sub[std::size_t(b)];
    });
    const int h = *heaviest;
    if (children[std::size_t(h)].empty()) break;
    pieces.erase(heaviest);
    pieces.insert(pieces.end(), children[std::size_t(h)].begin(), children[std::size_t(h)].end());
    split.push_back(h);
    top += cost[std::size_t(h)];
    const double t = top + deal(pieces, sub, bins);
    if (t < best) {
      best = t;
      best_pieces = pieces;
      best_bins = bins;
      best_split = split.size();
    }
  }

  // The chosen partition: each part's roots ascending, the top (the split supernodes) ascending, and its columns.
  m_work = {0.0, 0.0, 0.0};
  for (Part& p : m_parts) {
    p.roots.clear();
    p.updates.assign(std::size_t(L.n), 0.0f);
  }
  for (std::size_t i = 0; i < best_pieces.size(); ++i) {
    m_parts[std::size_t(best_bins[i])].roots.push_back(best_pieces[i]);
    m_work[std::size_t(best_bins[i])] += sub[std::size_t(best_pieces[i])];
  }
  for (Part& p : m_parts) std::sort(p.roots.begin(), p.roots.end());
  m_top.assign(split.begin(), split.begin() + std::ptrdiff_t(best_split));
  std::sort(m_top.begin(), m_top.end());
  m_top_cols.clear();
  for (const int s : m_top) {
    m_work[2] += cost[std::size_t(s)];
    for (int j = L.super[s]; j < L.super[s + 1]; ++j) m_top_cols.push_back(j);
  }
}

int SupernodalSolvePlan::leading_dimension(int nsrow) {
  return (nsrow + kSupernodePadding + 15) / 16 * 16;  // a whole number of 64-byte lines per column
}

void SupernodalSolvePlan::pack(const SupernodalStructure& L, const double* x, bool half, PackedFactor& packed) const {
  pack_values(L, x, half, packed);
}

void SupernodalSolvePlan::pack(const SupernodalStructure& L, const float* x, bool half, PackedFactor& packed) const {
  pack_values(L, x, half, packed);
}

template <class T>
void SupernodalSolvePlan::pack_values(const SupernodalStructure& L, const T* x, bool half, PackedFactor& packed) const {
  if (half) {
    std::vector<float>().swap(packed.values);
    assign_with_room(packed.codes, packed_size(), std::uint16_t(0));
  } else {
    std::vector<std::uint16_t>().swap(packed.codes);
    assign_with_room(packed.values, packed_size(), 0.0f);
  }
  assign_with_room(packed.diag_inv, std::size_t(L.n), 0.0f);
  assign_with_room(packed.scale, std::size_t(L.n), 1.0f);
  for (int s = 0; s < L.nsuper; ++s) {
    const int nscol = L.super[s + 1] - L.super[s], nsrow = L.pi[s + 1] - L.pi[s], ld = leading_dimension(nsrow);
    for (int j = 0; j < nscol; ++j) {
      const T* from = x + L.px[s] + std::ptrdiff_t(j) * nsrow;
      const std::ptrdiff_t at = m_px[std::size_t(s)] + std::ptrdiff_t(j) * ld;
      const auto col = std::size_t(L.super[s] + j);
      packed.diag_inv[col] = float(1.0 / double(from[j]));  // the kernels multiply by the diagonal's reciprocal
      if (!half) {
        for (int i = j + 1; i < nsrow; ++i) packed.values[std::size_t(at + i)] = float(from[i]);
        continue;
      }
      double largest = 0.0;
      for (int i = j + 1; i < nsrow; ++i) largest = std::max(largest, std::abs(double(from[i])));
      // The scale 2^k puts the largest entry in [2^14, 2^15) (half precision's largest normal: 65504), within
      // single precision's range.
      const int k = largest > 0.0 ? std::clamp(std::ilogb(largest) - 14, -126, 127) : 0;
      packed.scale[col] = std::ldexp(1.0f, k);
      const double unscale = std::ldexp(1.0, -k);  // exact products: a power of two, nothing overflows
      for (int i = j + 1; i < nsrow; ++i) packed.codes[std::size_t(at + i)] = half_code(double(from[i]) * unscale);
    }
  }
}

std::vector<double> SupernodalSolvePlan::unpack(const SupernodalStructure& L, const PackedFactor& packed) const {
  std::vector<double> x(std::size_t(L.px[L.nsuper]), 0.0);
  for (int s = 0; s < L.nsuper; ++s) {
    const int nscol = L.super[s + 1] - L.super[s], nsrow = L.pi[s + 1] - L.pi[s], ld = leading_dimension(nsrow);
    for (int j = 0; j < nscol; ++j) {
      double* to = x.data() + L.px[s] + std::ptrdiff_t(j) * nsrow;
      const std::ptrdiff_t at = m_px[std::size_t(s)] + std::ptrdiff_t(j) * ld;
      const auto col = std::size_t(L.super[s] + j);
      to[j] = 1.0 / double(packed.diag_inv[col]);
      for (int i = j + 1; i < nsrow; ++i) {
        const auto k = std::size_t(at + i);
        const float stored = packed.half() ? half_value(packed.codes[k]) : packed.values[k];
        to[i] = double(stored) * double(packed.scale[col]);
      }
    }
  }
  return x;
}

void SupernodalSolvePlan::forward_range(const SupernodalStructure& L, const PackedFactor& packed, float* y,
                                        int first, int last, int root, Part* part) {
  std::vector<float>& w = part ? part->w : m_w;
  for (int sn = first; sn <= last; ++sn) {
    const int k1 = L.super[sn], nscol = L.super[sn + 1] - k1, nsrow = L.pi[sn + 1] - L.pi[sn];
    const int ld = leading_dimension(nsrow);
    w.resize(std::size_t(ld));
    std::copy(y + k1, y + k1 + nscol, w.begin());
    std::fill(w.begin() + nscol, w.end(), 0.0f);
    supernode_kernel(true, packed, m_px[std::size_t(sn)], k1, nscol, nsrow, ld, w.data());
    std::copy(w.begin(), w.begin() + nscol, y + k1);
    const int nb = nsrow - nscol;  // the rows below hold -B y_diag, added to the rows they stand for
    const int* r = L.rows + L.pi[sn] + nscol;
    const float* t = w.data() + nscol;
    if (part == nullptr) {
      for (int i = 0; i < nb; ++i) y[r[i]] += t[i];
      continue;
    }
    // Rows in the subtree are the part's alone; the others are the top's, gathered per part.
    for (int i = 0; i < nb; ++i) {
      if (m_super_of[std::size_t(r[i])] <= root)
        y[r[i]] += t[i];
      else
        part->updates[std::size_t(r[i])] -= t[i];
    }
  }
}

void SupernodalSolvePlan::backward_range(const SupernodalStructure& L, const PackedFactor& packed, float* y,
                                         int first, int last, std::vector<float>& w) {
  for (int sn = last; sn >= first; --sn) {
    const int k1 = L.super[sn], nscol = L.super[sn + 1] - k1, nsrow = L.pi[sn + 1] - L.pi[sn];
    const int ld = leading_dimension(nsrow);
    w.resize(std::size_t(ld));
    std::copy(y + k1, y + k1 + nscol, w.begin());
    const int* r = L.rows + L.pi[sn] + nscol;
    for (int i = nscol; i < nsrow; ++i) w[std::size_t(i)] = y[r[i - nscol]];
    std::fill(w.begin() + nsrow, w.end(), 0.0f);
    supernode_kernel(false, packed, m_px[std::size_t(sn)], k1, nscol, nsrow, ld, w.data());
    std::copy(w.begin(), w.begin() + nscol, y + k1);
  }
}

void SupernodalSolvePlan::forward(const SupernodalStructure& L, const PackedFactor& packed, float* y,
                                  Executor* executor) {
  // The parts' subtrees, side by side; then their updates of the top, in part order; then the top.
  const auto parts = [&](int b, int e) {
    for (int p = b; p < e; ++p)
      for (const int root : m_parts[std::size_t(p)].roots)
        forward_range(L, packed, y, m_first[std::size_t(root)], root, root, &m_parts[std::size_t(p)]);
  };
  if (executor != nullptr)
    executor->parallel_for(2, 1, parts);
  else
    parts(0, 2);
  for (const int j : m_top_cols)
    for (Part& p : m_parts) {
      y[j] -= p.updates[std::size_t(j)];
      p.updates[std::size_t(j)] = 0.0f;
    }
  for (const int s : m_top) forward_range(L, packed, y, s, s, -1, nullptr);
}

void SupernodalSolvePlan::backward(const SupernodalStructure& L, const PackedFactor& packed, float* y,
                                   Executor* executor) {
  // The top first (descending), then the parts' subtrees side by side: each reads only rows above it.
  for (auto s = m_top.rbegin(); s != m_top.rend(); ++s) backward_range(L, packed, y, *s, *s, m_w);
  const auto parts = [&](int b, int e) {
    for (int p = b; p < e; ++p)
      for (auto root = m_parts[std::size_t(p)].roots.rbegin(); root != m_parts[std::size_t(p)].roots.rend(); ++root)
        backward_range(L, packed, y, m_first[std::size_t(*root)], *root, m_parts[std::size_t(p)].w);
  };
  if (executor != nullptr)
    executor->parallel_for(2, 1, parts);
  else
    parts(0, 2);
}

}  // namespace octocut::sim
