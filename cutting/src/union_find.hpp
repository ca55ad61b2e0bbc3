#pragma once
// Union-find shared by the cutting translation units (private header).
#include <numeric>
#include <utility>
#include <vector>

namespace octocut::cutting::detail {

/// Union-find over n elements, with path halving; the root of a set is its smallest member.
struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(int n) : parent(std::size_t(n)) { std::iota(parent.begin(), parent.end(), 0); }
  int find(int i) {
    while (parent[std::size_t(i)] != i) {
      parent[std::size_t(i)] = parent[std::size_t(parent[std::size_t(i)])];
      i = parent[std::size_t(i)];
    }
    return i;
  }
  void unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    parent[std::size_t(a)] = b;
  }
};

}  // namespace octocut::cutting::detail
