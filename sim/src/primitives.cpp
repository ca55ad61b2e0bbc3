#include "octocut/sim/primitives.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <stdexcept>

namespace octocut::sim {

namespace {

// The grid of closed_box_grid; `welded`: faces share the vertices along the box's edges.
TriMesh box_grid(const Box3& b, int cells, bool welded) {
  const Vec3 size = b.max - b.min;
  std::array<int, 3> n{};
  for (int a = 0; a < 3; ++a) n[std::size_t(a)] = std::max(1, int(std::lround(cells * size[a] / size.maxCoeff())));
  // Grid coordinate i of axis a; the last one is the box's own bound, so that faces meet exactly.
  auto coord = [&](int a, int i) {
    return i == n[std::size_t(a)] ? b.max[a] : b.min[a] + size[a] * double(i) / double(n[std::size_t(a)]);
  };
  TriMesh m;
  std::map<std::array<int, 3>, int32_t> index;  // grid node -> vertex
  auto vertex = [&](std::array<int, 3> g) {
    auto [it, fresh] = index.emplace(g, int32_t(m.vertices.size()));
    if (fresh) m.vertices.emplace_back(coord(0, g[0]), coord(1, g[1]), coord(2, g[2]));
    return it->second;
  };
  for (int a = 0; a < 3; ++a) {
    for (int side = 0; side < 2; ++side) {
      int u = (a + 1) % 3, v = (a + 2) % 3;
      if (side == 0) std::swap(u, v);  // u x v points out of the box
      for (int j = 0; j < n[std::size_t(v)]; ++j) {
        for (int i = 0; i < n[std::size_t(u)]; ++i) {
          auto node = [&](int di, int dj) {
            std::array<int, 3> g{};
            g[std::size_t(a)] = side ? n[std::size_t(a)] : 0;
            g[std::size_t(u)] = i + di;
            g[std::size_t(v)] = j + dj;
            return vertex(g);
          };
          const int32_t p00 = node(0, 0), p10 = node(1, 0), p01 = node(0, 1), p11 = node(1, 1);
          m.triangles.push_back({p00, p10, p11});
          m.triangles.push_back({p00, p11, p01});
        }
      }
      if (!welded) index.clear();  // the next face gets vertices of its own
    }
  }
  return m;
}

}  // namespace

TriMesh closed_box_grid(const Box3& b, int cells) { return box_grid(b, cells, true); }

TriMesh box_face_grids(const Box3& b, int cells) {
  const Vec3 size = b.max - b.min;
  if (!(size.minCoeff() > 0.0) || !size.allFinite()) throw std::invalid_argument("box_face_grids: empty box");
  return box_grid(b, std::max(1, cells), false);
}

TriMesh cylinder_mesh(double radius, double height, int segments) {
  if (!(std::isfinite(radius) && radius > 0.0)) throw std::invalid_argument("cylinder_mesh: radius must be > 0");
  if (!(std::isfinite(height) && height > 0.0)) throw std::invalid_argument("cylinder_mesh: height must be > 0");
  if (segments < 3) throw std::invalid_argument("cylinder_mesh: segments must be >= 3");
  // Vertices: the bottom ring (0..n-1), the top ring (n..2n-1), the bottom centre (2n), the top centre (2n+1).
  TriMesh mesh;
  const int n = segments;
  const double z0 = -0.5 * height, z1 = 0.5 * height;
  for (const double z : {z0, z1}) {
    for (int k = 0; k < n; ++k) {
      const double phi = 2.0 * std::numbers::pi * k / n;
      mesh.vertices.emplace_back(radius * std::cos(phi), radius * std::sin(phi), z);
    }
  }
  mesh.vertices.emplace_back(0.0, 0.0, z0);
  mesh.vertices.emplace_back(0.0, 0.0, z1);
  const int bottom = 2 * n, top = 2 * n + 1;
  // Triangles, counter-clockwise seen from outside: side quads as two triangles, and a fan on each cap.
  for (int k = 0; k < n; ++k) {
    const int k1 = (k + 1) % n;
    mesh.triangles.push_back({k, k1, n + k1});
    mesh.triangles.push_back({k, n + k1, n + k});
    mesh.triangles.push_back({bottom, k1, k});
    mesh.triangles.push_back({top, n + k, n + k1});
  }
  return mesh;
}

// A conforming tet mesh of a box at about `cell` (m): a grid of cubes, each split into 6 tets around its main
// diagonal (Kuhn). Its material is exactly the box.
TetMesh box_tet_mesh(const Box3& b, double cell) {
  const Vec3 size = b.max - b.min;
  std::array<int, 3> n{};
  for (int a = 0; a < 3; ++a) n[std::size_t(a)] = std::max(1, int(std::ceil(size[a] / cell - 1e-9)));
  auto coord = [&](int a, int i) {
    return i == n[std::size_t(a)] ? b.max[a] : b.min[a] + size[a] * double(i) / double(n[std::size_t(a)]);
  };
  TetMesh mesh;
  const int nx = n[0] + 1, ny = n[1] + 1;
  for (int k = 0; k <= n[2]; ++k)
    for (int j = 0; j <= n[1]; ++j)
      for (int i = 0; i <= n[0]; ++i) mesh.vertices.emplace_back(coord(0, i), coord(1, j), coord(2, k));
  static constexpr std::array<std::array<int, 4>, 6> kKuhn = {
      {{0, 1, 3, 7}, {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}, {0, 4, 5, 7}, {0, 5, 1, 7}}};
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        std::array<int32_t, 8> c{};
        for (int q = 0; q < 8; ++q)
          c[std::size_t(q)] = int32_t((i + (q & 1)) + nx * ((j + ((q >> 1) & 1)) + ny * (k + ((q >> 2) & 1))));
        for (const auto& t : kKuhn)
          mesh.tets.push_back({c[std::size_t(t[0])], c[std::size_t(t[1])], c[std::size_t(t[2])], c[std::size_t(t[3])]});
      }
  return mesh;
}

}  // namespace octocut::sim
