#pragma once
// Conforming tetrahedral grids for the material-graph tests and benchmarks: cubes split into the 6 Kuhn tets around
// their main diagonal, optionally with some cubes left out (a cut) or the interior vertices jittered.
#include <array>
#include <cstdint>
#include <functional>
#include <random>

#include "octocut/sim/material_graph.hpp"

namespace octocut::test {

/// n[0] x n[1] x n[2] cells of size `cell` (m, per axis) from `origin` (m). Every cell (i, j, k) that `keep` accepts
/// (all without `keep`) becomes 6 tets, one per axis permutation, walking from its corner 0 to its corner 7. With
/// `jitter` > 0, every vertex not on the grid's boundary moves by up to `jitter` of a cell along each axis (seeded
/// by `seed`), so the tets still tile the grid's box exactly.
inline sim::TetMesh kuhn_grid(const sim::Vec3& origin, const sim::Vec3& cell, const std::array<int, 3>& n,
                              const std::function<bool(int, int, int)>& keep = {}, double jitter = 0.0,
                              unsigned seed = 0) {
  sim::TetMesh m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  auto id = [&](int i, int j, int k) { return int32_t((k * (n[1] + 1) + j) * (n[0] + 1) + i); };
  for (int k = 0; k <= n[2]; ++k)
    for (int j = 0; j <= n[1]; ++j)
      for (int i = 0; i <= n[0]; ++i) {
        sim::Vec3 p = origin + sim::Vec3(i * cell.x(), j * cell.y(), k * cell.z());
        const std::array<int, 3> g{i, j, k};
        if (jitter > 0.0)
          for (int a = 0; a < 3; ++a)
            if (g[std::size_t(a)] > 0 && g[std::size_t(a)] < n[std::size_t(a)]) p[a] += u(rng) * cell[a];
        m.vertices.push_back(p);
      }
  // The six tets of a cube along the main diagonal (0 -> 7), one per axis permutation.
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        if (keep && !keep(i, j, k)) continue;
        for (const auto& p : perms) {
          std::array<int, 3> c{i, j, k};
          std::array<int32_t, 4> t{};
          t[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[std::size_t(p[s])];
            t[std::size_t(s) + 1] = id(c[0], c[1], c[2]);
          }
          m.tets.push_back(t);
        }
      }
  return m;
}

/// The box [min, max] as n^3 jittered Kuhn cells (6 n^3 tets).
inline sim::TetMesh kuhn_box(const sim::Box3& box, int n, double jitter, unsigned seed) {
  return kuhn_grid(box.min, (box.max - box.min) / n, {n, n, n}, {}, jitter, seed);
}

}  // namespace octocut::test
