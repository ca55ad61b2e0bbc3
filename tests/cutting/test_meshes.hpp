#pragma once
// Small closed meshes with known volumes for the mesh I/O and mesh check tests, and a brute-force triangle
// intersection test that serves as independent truth for the CGAL self-intersection query.
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <tuple>
#include <vector>

#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::test {

/// The regular octahedron with vertices at distance `r` on the axes, outward oriented. Volume 4 r^3 / 3.
inline sim::TriMesh octahedron(double r = 1.0) {
  sim::TriMesh mesh;
  mesh.vertices = {{r, 0, 0}, {0, r, 0}, {0, 0, r}, {-r, 0, 0}, {0, -r, 0}, {0, 0, -r}};
  // One triangle per octant, on the axis vertices of that octant, flipped where its normal points inwards.
  for (int octant = 0; octant < 8; ++octant) {
    const int ix = (octant & 1) ? 3 : 0;
    const int iy = (octant & 2) ? 4 : 1;
    const int iz = (octant & 4) ? 5 : 2;
    std::array<int32_t, 3> t{ix, iy, iz};
    const sim::Vec3& a = mesh.vertices[static_cast<std::size_t>(t[0])];
    const sim::Vec3& b = mesh.vertices[static_cast<std::size_t>(t[1])];
    const sim::Vec3& c = mesh.vertices[static_cast<std::size_t>(t[2])];
    if ((b - a).cross(c - a).dot(a + b + c) < 0.0) std::swap(t[1], t[2]);
    mesh.triangles.push_back(t);
  }
  return mesh;
}

/// The surface of the box [origin, origin + edge]^3 with each face cut into n x n squares of two triangles,
/// outward oriented, vertices shared (sim::closed_box_grid). |V| = 6 n^2 + 2, |F| = 12 n^2, volume edge^3.
inline sim::TriMesh grid_cube(int n, double edge = 1.0, const sim::Vec3& origin = sim::Vec3::Zero()) {
  return sim::closed_box_grid({origin, origin + sim::Vec3::Constant(edge)}, n);
}

/// grid_cube(n) centred at the origin and pushed out onto the sphere of radius `r`: a closed, convex, outward
/// oriented sphere mesh with 6 n^2 + 2 vertices.
inline sim::TriMesh cube_sphere(int n, double r = 1.0) {
  sim::TriMesh mesh = grid_cube(n, 2.0, sim::Vec3(-1, -1, -1));
  for (sim::Vec3& p : mesh.vertices) p = r * p.normalized();
  return mesh;
}

/// Concatenates two meshes (b's indices shifted), without welding.
inline sim::TriMesh merged(const sim::TriMesh& a, const sim::TriMesh& b) {
  sim::TriMesh out = a;
  const auto shift = static_cast<int32_t>(a.vertices.size());
  out.vertices.insert(out.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto t : b.triangles) out.triangles.push_back({t[0] + shift, t[1] + shift, t[2] + shift});
  return out;
}

/// V - E + F of a closed triangle mesh (E = 3F/2): 2 per sphere-like component, 0 per torus.
inline long euler_characteristic(const sim::TriMesh& m) {
  return long(m.vertices.size()) - long(m.triangles.size()) * 3 / 2 + long(m.triangles.size());
}

/// True when the segment pq crosses the triangle abc (Möller–Trumbore, in double; for generic inputs only).
inline bool segment_hits_triangle(const sim::Vec3& p, const sim::Vec3& q, const sim::Vec3& a, const sim::Vec3& b,
                                  const sim::Vec3& c) {
  const sim::Vec3 d = q - p;
  const sim::Vec3 e1 = b - a, e2 = c - a;
  const sim::Vec3 h = d.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) < 1e-14) return false;
  const sim::Vec3 s = p - a;
  const double u = s.dot(h) / det;
  if (u < 0.0 || u > 1.0) return false;
  const sim::Vec3 qv = s.cross(e1);
  const double v = d.dot(qv) / det;
  if (v < 0.0 || u + v > 1.0) return false;
  const double t = e2.dot(qv) / det;
  return t >= 0.0 && t <= 1.0;
}

/// Brute-force test of two triangles of `mesh` that share no vertex: they intersect when an edge of one crosses the
/// other. Exact enough for generic (non-coplanar, non-touching) configurations, which is how the tests use it.
inline bool triangles_intersect(const sim::TriMesh& mesh, std::size_t f, std::size_t g) {
  const auto& s = mesh.triangles[f];
  const auto& t = mesh.triangles[g];
  const auto p = [&](int32_t i) { return mesh.vertices[static_cast<std::size_t>(i)]; };
  for (int k = 0; k < 3; ++k) {
    if (segment_hits_triangle(p(s[k]), p(s[(k + 1) % 3]), p(t[0]), p(t[1]), p(t[2]))) return true;
    if (segment_hits_triangle(p(t[k]), p(t[(k + 1) % 3]), p(s[0]), p(s[1]), p(s[2]))) return true;
  }
  return false;
}

}  // namespace octocut::test
