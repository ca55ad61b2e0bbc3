// The minimum feature size of the surface boolean (cutting.min_feature): a conservative test, before any exact
// arithmetic, that a blade can remove from the solid bounded by S no material deeper than min_feature below the
// blade's surface. Such a cut would only shave a sub-feature shell off S (a blade landing a few micrometres from the
// wall an earlier cut left, or exactly on it), which the exact boolean would turn into slivers; the cut pipeline keeps
// that shell whole instead (a no-op). No CGAL here but the exact point query of surface_cut_corefine.cpp.
//
// The test, for a convex blade B (the others never pass it): E = {x : n_i . x <= d_i - m} over B's face planes (unit
// outward normals n_i) is B eroded by a ball of radius m (m slightly below min_feature, see kShrink). When no face of S
// meets E (each face of S near B is clipped against E's half-spaces and nothing is left) and a point of E lies outside
// the solid, all of E lies outside it (E is connected), so every point of material in B is within m of B's surface.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "octocut/cutting/surface_cut.hpp"
#include "surface_cut_phases.hpp"

namespace octocut::cutting {
namespace {

using sim::Vec3;
using surface_cut_detail::Tri;

// A face plane of the blade: n . x <= d inside, n a unit vector.
struct Plane {
  Vec3 n;    // unit outward normal
  double d;  // offset, m
};

// The distinct face planes of `blade` when it is convex and outward oriented (every vertex on or inside every face
// plane, within tol m); empty otherwise.
std::vector<Plane> convex_planes(const sim::TriMesh& blade, double tol) {
  std::vector<Plane> planes;
  for (const Tri& t : blade.triangles) {
    const Vec3& a = blade.vertices[static_cast<std::size_t>(t[0])];
    const Vec3 n = (blade.vertices[static_cast<std::size_t>(t[1])] - a)
                       .cross(blade.vertices[static_cast<std::size_t>(t[2])] - a);
    const double len = n.norm();
    if (!(len > 0.0) || !std::isfinite(len)) return {};
    const Plane p{n / len, n.dot(a) / len};
    const bool known = std::any_of(planes.begin(), planes.end(), [&](const Plane& q) {
      return (q.n - p.n).norm() < 1e-12 && std::abs(q.d - p.d) <= tol;
    });
    if (!known) planes.push_back(p);
  }
  for (const Plane& p : planes) {
    for (const Vec3& v : blade.vertices) {
      if (p.n.dot(v) - p.d > tol) return {};
    }
  }
  return planes;
}

// Whether triangle abc (m) meets the convex body {x : n_i . x <= d_i - m} (m in m): the triangle clipped against
// each half-space in turn (Sutherland-Hodgman); it meets the body when something is left.
bool meets(const std::vector<Plane>& planes, double m, const Vec3& a, const Vec3& b, const Vec3& c) {
  std::vector<Vec3> poly{a, b, c}, next;
  for (const Plane& p : planes) {
    next.clear();
    const double d = p.d - m;
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Vec3& u = poly[i];
      const Vec3& v = poly[(i + 1) % poly.size()];
      const double su = p.n.dot(u) - d, sv = p.n.dot(v) - d;  // m; <= 0 inside
      if (su <= 0.0) next.push_back(u);
      if ((su < 0.0 && sv > 0.0) || (su > 0.0 && sv < 0.0)) next.push_back(u + (su / (su - sv)) * (v - u));
    }
    poly.swap(next);
    if (poly.empty()) return false;
  }
  return true;
}

}  // namespace

bool removes_only_subfeature(const sim::TriMesh& surface, FaceGrid& grid, const sim::TriMesh& blade,
                             double min_feature) {
  if (!(min_feature > 0.0) || blade.triangles.empty() || blade.vertices.empty() || !grid.built()) return false;
  // The erosion depth: a millionth below min_feature, far above the rounding of the clipping (about 1e-16 of the
  // coordinates), so that a face found clear of E is clear of the erosion by min_feature itself.
  constexpr double kShrink = 1.0 - 1e-6;
  const double m = kShrink * min_feature;  // m
  Vec3 lo = blade.vertices[0], hi = lo, centre = Vec3::Zero();
  for (const Vec3& v : blade.vertices) {
    if (!surface_cut_detail::finite(v)) return false;
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
    centre += v;
  }
  centre /= static_cast<double>(blade.vertices.size());
  const double tol = 1e-9 * (hi - lo).norm();  // m: flatness of the blade's faces, convexity
  if (sim::signed_volume(blade) <= 0.0) return false;
  const std::vector<Plane> planes = convex_planes(blade, tol);
  if (planes.empty()) return false;
  // The blade's vertex centroid must lie in E, clear of its planes (a blade thinner than 2 min_feature never passes:
  // the material it removes is a real cut, not a shell).
  for (const Plane& p : planes) {
    if (p.n.dot(centre) - (p.d - m) > -tol) return false;
  }
  for (const int32_t f : grid.query(surface, lo, hi)) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
    if (meets(planes, m, surface.vertices[static_cast<std::size_t>(t[0])],
              surface.vertices[static_cast<std::size_t>(t[1])], surface.vertices[static_cast<std::size_t>(t[2])])) {
      return false;
    }
  }
  return surface_cut_detail::point_in_solid(surface, grid, centre) == 0;
}

}  // namespace octocut::cutting
