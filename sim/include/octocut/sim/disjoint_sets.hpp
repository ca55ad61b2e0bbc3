#pragma once
// Union-find (disjoint sets) over the integers 0..n-1.
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <utility>
#include <vector>

namespace octocut::sim {

/// Union-find over 0..n-1 with path halving; the smaller index becomes the root, so results are order-independent.
class DisjointSets {
 public:
  explicit DisjointSets(std::size_t n) : m_parent(n) { std::iota(m_parent.begin(), m_parent.end(), 0); }
  int32_t find(int32_t i) {
    while (m_parent[static_cast<std::size_t>(i)] != i) {
      const auto u = static_cast<std::size_t>(i);
      m_parent[u] = m_parent[static_cast<std::size_t>(m_parent[u])];
      i = m_parent[u];
    }
    return i;
  }
  void unite(int32_t a, int32_t b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    m_parent[static_cast<std::size_t>(a)] = b;
  }

 private:
  std::vector<int32_t> m_parent;  ///< parent of each element (n)
};

}  // namespace octocut::sim
