#pragma once
// Procedural closed meshes shared by the tests and the benchmarks.
#include <cmath>
#include <numbers>

#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::test {

/// A closed UV ellipsoid (centre and radii in m), counter-clockwise seen from outside: two poles on the z axis and
/// rings - 1 rings of `segments` vertices, i.e. segments * (rings - 1) + 2 vertices.
inline sim::TriMesh ellipsoid_mesh(const sim::Vec3& centre, const sim::Vec3& radii, int segments, int rings) {
  using sim::Vec3;
  sim::TriMesh m;
  m.vertices.push_back(centre + Vec3(0, 0, radii.z()));
  for (int i = 1; i < rings; ++i) {
    const double th = std::numbers::pi * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double ph = 2.0 * std::numbers::pi * j / segments;
      m.vertices.push_back(centre + Vec3(radii.x() * std::sin(th) * std::cos(ph),
                                         radii.y() * std::sin(th) * std::sin(ph), radii.z() * std::cos(th)));
    }
  }
  m.vertices.push_back(centre - Vec3(0, 0, radii.z()));
  // Caps and bands.
  const int south = int(m.vertices.size()) - 1;
  auto ring = [&](int i, int j) { return 1 + (i - 1) * segments + (j % segments); };
  for (int j = 0; j < segments; ++j) m.triangles.push_back({0, ring(1, j), ring(1, j + 1)});
  for (int i = 1; i + 1 < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      m.triangles.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      m.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  for (int j = 0; j < segments; ++j) m.triangles.push_back({south, ring(rings - 1, j + 1), ring(rings - 1, j)});
  return m;
}

/// A closed, outward prism around the z axis, centred on `c` (m): sim::cylinder_mesh (a regular n-gon of
/// circumradius r from c.z - h/2 to c.z + h/2, a centre vertex on each cap; the bottom ring first, then the top ring,
/// then the two cap centres) moved to `c`.
inline sim::TriMesh prism_mesh(const sim::Vec3& c, double r, double h, int n) {
  sim::TriMesh m = sim::cylinder_mesh(r, h, n);
  for (sim::Vec3& p : m.vertices) p += c;
  return m;
}

/// The same solid as prism_mesh(c, r, h, n), its sides cut into `rings` bands (rings + 1 rings of n vertices, the
/// bottom one first, then the two cap centres), each band's quads split along the diagonal from (band, k) to
/// (band + 1, k + 1): a blade with many triangles per face, as a finely tessellated instrument mesh has.
inline sim::TriMesh ringed_prism_mesh(const sim::Vec3& c, double r, double h, int n, int rings) {
  sim::TriMesh m;
  for (int j = 0; j <= rings; ++j) {
    const double z = j == rings ? 0.5 * h : -0.5 * h + h * j / rings;
    for (int k = 0; k < n; ++k) {
      const double phi = 2.0 * std::numbers::pi * k / n;
      m.vertices.push_back(c + sim::Vec3(r * std::cos(phi), r * std::sin(phi), z));
    }
  }
  const int bottom = (rings + 1) * n, top = bottom + 1;
  m.vertices.push_back(c + sim::Vec3(0.0, 0.0, -0.5 * h));
  m.vertices.push_back(c + sim::Vec3(0.0, 0.0, 0.5 * h));
  const auto at = [n](int j, int k) { return j * n + k % n; };
  for (int j = 0; j < rings; ++j)
    for (int k = 0; k < n; ++k) {
      m.triangles.push_back({at(j, k), at(j, k + 1), at(j + 1, k + 1)});
      m.triangles.push_back({at(j, k), at(j + 1, k + 1), at(j + 1, k)});
    }
  for (int k = 0; k < n; ++k) {
    m.triangles.push_back({bottom, at(0, k + 1), at(0, k)});
    m.triangles.push_back({top, at(rings, k), at(rings, k + 1)});
  }
  return m;
}

/// Area of the regular n-gon of circumradius r, m^2: the prism's volume is this times its height.
inline double prism_area(double r, int n) { return 0.5 * n * r * r * std::sin(2.0 * std::numbers::pi / n); }

}  // namespace octocut::test
