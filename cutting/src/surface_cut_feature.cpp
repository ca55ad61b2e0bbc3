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
#include <limits>
#include <map>
#include <numeric>
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

// Whether some vertex of `mesh` lies more than tol (m) outside one of `planes`: every plane against every vertex, as
// a search down a tree of vertex boxes that passes over the boxes wholly within tol of the plane (a margin for the
// rounding of the box's bound), so that a blade with thousands of distinct face planes (a smooth, finely tessellated
// tip) costs about |planes| log |V| tests instead of |planes| |V|. Every vertex it does test is tested as
// n . v - d > tol, so the answer is that of testing them all.
bool some_vertex_outside(const std::vector<Plane>& planes, const sim::TriMesh& mesh, double tol) {
  struct Node {
    Vec3 lo, hi;            // the box of its vertices, m
    int begin, end, right;  // its vertices order[begin, end); a leaf when right < 0, else children this + 1, right
  };
  std::vector<int> order(mesh.vertices.size());
  std::iota(order.begin(), order.end(), 0);
  std::vector<Node> nodes;
  double scale = 0.0;  // m
  for (const Vec3& v : mesh.vertices) scale = std::max(scale, v.cwiseAbs().maxCoeff());
  const auto vertex = [&](int v) -> const Vec3& { return mesh.vertices[static_cast<std::size_t>(v)]; };
  const auto build = [&](const auto& self, int begin, int end) -> void {
    const auto at = [&](int i) -> const Vec3& { return vertex(order[static_cast<std::size_t>(i)]); };
    Vec3 lo = at(begin), hi = lo;
    for (int i = begin + 1; i < end; ++i) {
      lo = lo.cwiseMin(at(i));
      hi = hi.cwiseMax(at(i));
    }
    const auto n = nodes.size();
    nodes.push_back({lo, hi, begin, end, -1});
    if (end - begin <= 8) return;
    int axis = 0;
    (hi - lo).maxCoeff(&axis);
    const int mid = begin + (end - begin) / 2;
    std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end, [&](int a, int b) {
      const double xa = vertex(a)[axis], xb = vertex(b)[axis];
      return xa != xb ? xa < xb : a < b;
    });
    self(self, begin, mid);
    nodes[n].right = static_cast<int>(nodes.size());
    self(self, mid, end);
  };
  if (mesh.vertices.empty()) return false;
  build(build, 0, static_cast<int>(order.size()));
  std::vector<int> stack;
  for (const Plane& p : planes) {
    const double margin = 1e-12 * (3.0 * scale + std::abs(p.d));  // m: the rounding of the box's bound
    stack.assign(1, 0);
    while (!stack.empty()) {
      const Node& node = nodes[static_cast<std::size_t>(stack.back())];
      const int self_index = stack.back();
      stack.pop_back();
      double bound = 0.0;  // max of n . x over the box
      for (int a = 0; a < 3; ++a) bound += std::max(p.n[a] * node.lo[a], p.n[a] * node.hi[a]);
      if (bound - p.d <= tol - margin) continue;
      if (node.right < 0) {
        for (int i = node.begin; i < node.end; ++i)
          if (p.n.dot(vertex(order[static_cast<std::size_t>(i)])) - p.d > tol) return true;
        continue;
      }
      stack.push_back(node.right);
      stack.push_back(self_index + 1);
    }
  }
  return false;
}

// The distinct face planes of `blade` when it is convex and outward oriented (every vertex on or inside every face
// plane, within tol m); empty otherwise. With `plane_of`, the index of each triangle's plane among them (|F|). A
// triangle's plane is the first one found before it whose unit normal is within 1e-12 and whose offset within tol;
// the candidates come from the planes sorted by the normal's x (within 2e-12 of this one's), so that distinct planes
// by the thousand are not each compared with all the others.
std::vector<Plane> convex_planes(const sim::TriMesh& blade, double tol, std::vector<int>* plane_of = nullptr) {
  std::vector<Plane> planes;
  std::multimap<double, int> by_x;  // n.x -> index in planes
  if (plane_of != nullptr) plane_of->clear();
  for (const Tri& t : blade.triangles) {
    const Vec3& a = blade.vertices[static_cast<std::size_t>(t[0])];
    const Vec3 n = (blade.vertices[static_cast<std::size_t>(t[1])] - a)
                       .cross(blade.vertices[static_cast<std::size_t>(t[2])] - a);
    const double len = n.norm();
    if (!(len > 0.0) || !std::isfinite(len)) return {};
    const Plane p{n / len, n.dot(a) / len};
    int known = static_cast<int>(planes.size());
    for (auto it = by_x.lower_bound(p.n.x() - 2e-12); it != by_x.end() && it->first <= p.n.x() + 2e-12; ++it) {
      const Plane& q = planes[static_cast<std::size_t>(it->second)];
      if (it->second < known && (q.n - p.n).norm() < 1e-12 && std::abs(q.d - p.d) <= tol) known = it->second;
    }
    if (plane_of != nullptr) plane_of->push_back(known);
    if (known == static_cast<int>(planes.size())) {
      by_x.emplace(p.n.x(), known);
      planes.push_back(p);
    }
  }
  if (some_vertex_outside(planes, blade, tol)) return {};
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

namespace {

// The corners of the convex body blade ∩ box (m): the corners of the blade's triangles clipped to the box
// (Sutherland-Hodgman), which include the blade's vertices in the box and the points where its edges cross the box's
// faces and its faces cross the box's edges, and the box's corners inside the blade (`planes`).
std::vector<Vec3> corners_in_box(const sim::TriMesh& blade, const std::vector<Plane>& planes, const sim::Box3& box) {
  std::vector<Vec3> corners, poly, next;
  for (const Tri& t : blade.triangles) {
    poly = {blade.vertices[static_cast<std::size_t>(t[0])], blade.vertices[static_cast<std::size_t>(t[1])],
            blade.vertices[static_cast<std::size_t>(t[2])]};
    for (int axis = 0; axis < 3 && !poly.empty(); ++axis) {
      for (const int side : {-1, 1}) {
        const double bound = side < 0 ? box.min[axis] : box.max[axis];
        next.clear();
        for (std::size_t i = 0; i < poly.size(); ++i) {
          const Vec3& u = poly[i];
          const Vec3& v = poly[(i + 1) % poly.size()];
          const double su = side * (u[axis] - bound), sv = side * (v[axis] - bound);  // <= 0 inside, m
          if (su <= 0.0) next.push_back(u);
          if ((su < 0.0 && sv > 0.0) || (su > 0.0 && sv < 0.0)) next.push_back(u + (su / (su - sv)) * (v - u));
        }
        poly.swap(next);
        if (poly.empty()) break;
      }
    }
    corners.insert(corners.end(), poly.begin(), poly.end());
  }
  for (int c = 0; c < 8; ++c) {
    const Vec3 q((c & 1) ? box.max.x() : box.min.x(), (c & 2) ? box.max.y() : box.min.y(),
                 (c & 4) ? box.max.z() : box.min.z());
    if (std::all_of(planes.begin(), planes.end(), [&](const Plane& p) { return p.n.dot(q) <= p.d; })) {
      corners.push_back(q);
    }
  }
  // Each vertex comes once per triangle at it: once is enough (the callers take the largest distance of any).
  const auto lexicographic = [](const Vec3& u, const Vec3& v) {
    return std::lexicographical_compare(u.data(), u.data() + 3, v.data(), v.data() + 3);
  };
  std::sort(corners.begin(), corners.end(), lexicographic);
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  return corners;
}

// The distance (m) from q to triangle abc (m): the closest point by the regions of the triangle (Ericson, Real-Time
// Collision Detection, 5.1.5).
double point_triangle_distance(const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = q - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return ap.norm();
  const Vec3 bp = q - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return bp.norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return (q - (a + (d1 / (d1 - d3)) * ab)).norm();
  const Vec3 cp = q - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return cp.norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return (q - (a + (d2 / (d2 - d6)) * ac)).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return (q - (b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b))).norm();
  }
  const double denom = 1.0 / (va + vb + vc);
  return (q - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
}

// A convex blade as the snapping measures it: its distinct face planes and each triangle's plane (n . x <= d inside),
// the triangles grouped by the distinct plane they lie in, and how far each group's triangle planes stray from it.
struct ConvexSolid {
  const sim::TriMesh* mesh = nullptr;
  std::vector<Plane> planes;           // distinct, unit normals
  std::vector<Plane> triangle_planes;  // (|F|) unnormalised normals
  std::vector<int> group_begin;        // (|planes| + 1) the triangles of plane g: group_triangles[begin[g], begin[g+1])
  std::vector<int> group_triangles;    // (|F|)
  std::vector<double> tilt, shift;     // (|planes|) max |n_t / |n_t| - n_g| over the group, max |d_t / |n_t| - d_g|, m
  double scale = 0.0;                  // the largest |v| of a vertex, m (the rounding of the plane tests)
};

ConvexSolid convex_solid(const sim::TriMesh& blade, double tol) {
  ConvexSolid c;
  c.mesh = &blade;
  if (sim::signed_volume(blade) <= 0.0) return c;
  std::vector<int> plane_of;
  c.planes = convex_planes(blade, tol, &plane_of);
  if (c.planes.empty()) return c;
  c.triangle_planes.reserve(blade.triangles.size());
  c.group_begin.assign(c.planes.size() + 1, 0);
  c.tilt.assign(c.planes.size(), 0.0);
  c.shift.assign(c.planes.size(), 0.0);
  for (std::size_t f = 0; f < blade.triangles.size(); ++f) {
    const Tri& t = blade.triangles[f];
    const Vec3& a = blade.vertices[static_cast<std::size_t>(t[0])];
    const Vec3 n = (blade.vertices[static_cast<std::size_t>(t[1])] - a)
                       .cross(blade.vertices[static_cast<std::size_t>(t[2])] - a);
    c.triangle_planes.push_back({n, n.dot(a)});
    const auto g = static_cast<std::size_t>(plane_of[f]);
    const double len = n.norm();
    c.tilt[g] = std::max(c.tilt[g], (n / len - c.planes[g].n).norm());
    c.shift[g] = std::max(c.shift[g], std::abs(n.dot(a) / len - c.planes[g].d));
    ++c.group_begin[g + 1];
  }
  for (std::size_t g = 0; g < c.planes.size(); ++g) c.group_begin[g + 1] += c.group_begin[g];
  for (const Vec3& v : blade.vertices) c.scale = std::max(c.scale, v.norm());
  c.group_triangles.resize(blade.triangles.size());
  std::vector<int> next(c.group_begin.begin(), c.group_begin.end() - 1);
  for (std::size_t f = 0; f < blade.triangles.size(); ++f)
    c.group_triangles[static_cast<std::size_t>(next[static_cast<std::size_t>(plane_of[f])]++)] = static_cast<int>(f);
  return c;
}

// The distance (m) from q to the convex solid `c` (0 inside, where no triangle's plane has q outside): the closest
// point lies on a triangle whose plane q is outside of, so only those are measured. A group of triangles whose
// distinct plane has q inside by more than its triangles' planes can stray from it (tilt |q| + shift, and a margin
// for the rounding of the dot products) has q inside each of them and is passed over, so that a blade with many
// triangles per face costs no more per point than one with few; the answer is the same.
double distance_to_convex(const Vec3& q, const ConvexSolid& c) {
  double best = 0.0;  // inside (or on the boundary up to rounding) unless some triangle's plane has q outside
  bool outside = false;
  const sim::TriMesh& m = *c.mesh;
  const double q_norm = q.norm();
  for (std::size_t g = 0; g < c.planes.size(); ++g) {
    const Plane& pg = c.planes[g];
    const double margin = c.tilt[g] * q_norm + c.shift[g] + 1e-12 * (q_norm + c.scale);
    if (pg.n.dot(q) - pg.d < -margin) continue;
    for (int i = c.group_begin[g]; i < c.group_begin[g + 1]; ++i) {
      const auto f = static_cast<std::size_t>(c.group_triangles[static_cast<std::size_t>(i)]);
      const Plane& p = c.triangle_planes[f];
      if (!(p.n.dot(q) > p.d)) continue;  // q is not outside this triangle's plane
      const Tri& t = m.triangles[f];
      if (!outside) best = std::numeric_limits<double>::infinity();
      outside = true;
      best = std::min(best, point_triangle_distance(q, m.vertices[static_cast<std::size_t>(t[0])],
                                                    m.vertices[static_cast<std::size_t>(t[1])],
                                                    m.vertices[static_cast<std::size_t>(t[2])]));
    }
  }
  return best;
}

// Whether every corner of `corners` lies within `limit` (m) of the convex solid `c`; the largest distance into `d`.
bool within(const std::vector<Vec3>& corners, const ConvexSolid& c, double limit, double& d) {
  for (const Vec3& q : corners) {
    d = std::max(d, distance_to_convex(q, c));
    if (!(d < limit)) return false;
  }
  return true;
}

// A bound on the Hausdorff distance, inside `region`, of the solids bounded by two meshes with the same triangles
// (the same blade mesh, mapped differently), for blades that are not convex. The straight-line homotopy from a's
// vertices to b's moves the point of a's triangle at barycentric coordinates l along d(l), the same combination of
// its vertices' moves b_v - a_v; a point p of one solid that the other lacks (their winding numbers about p differ)
// lies on such a path, within |d(l)| of its end. A path that meets the region starts within max_v |b_v - a_v| (the
// triangle's largest move) of it, so the bound is the largest |d| over the parts of a's triangles inside the region
// grown by their largest move (|d| is convex along a triangle: its largest value on the clipped polygon is at a
// corner). Negative when no such part exists (the blade does not reach into the region).
double correspondence_bound(const sim::TriMesh& a, const sim::TriMesh& b, const sim::Box3& region) {
  struct Corner {
    Vec3 p, d;  // m: a point of a's triangle and its move
  };
  double bound = -1.0;  // m
  std::vector<Corner> poly, next;
  for (const auto& t : a.triangles) {
    poly.clear();
    double reach = 0.0;  // m: the triangle's largest move
    for (int32_t v : t) {
      const Vec3& p = a.vertices[std::size_t(v)];
      poly.push_back({p, b.vertices[std::size_t(v)] - p});
      reach = std::max(reach, poly.back().d.norm());
    }
    // Clipped against the grown region's six half-spaces (Sutherland-Hodgman), the moves interpolated alike.
    for (int axis = 0; axis < 3 && !poly.empty(); ++axis) {
      for (const double side : {-1.0, 1.0}) {
        const double limit = side < 0 ? -(region.min[axis] - reach) : region.max[axis] + reach;  // side * x <= limit
        next.clear();
        for (std::size_t i = 0; i < poly.size(); ++i) {
          const Corner& u = poly[i];
          const Corner& w = poly[(i + 1) % poly.size()];
          const double fu = side * u.p[axis] - limit, fw = side * w.p[axis] - limit;
          if (fu <= 0.0) next.push_back(u);
          if ((fu < 0.0 && fw > 0.0) || (fu > 0.0 && fw < 0.0)) {
            const double s = fu / (fu - fw);
            next.push_back({u.p + s * (w.p - u.p), u.d + s * (w.d - u.d)});
          }
        }
        poly.swap(next);
        if (poly.empty()) break;
      }
    }
    // The clipped corners' moves, and the rounding of the interpolation (far below any min_feature).
    for (const Corner& c : poly) bound = std::max(bound, c.d.norm() * (1.0 + 1e-12) + 1e-15 * reach);
  }
  return bound;
}

// snap_target for a blade that is not convex: the latest earlier blade with the same mesh whose correspondence
// bound lies within min_feature.
int snap_target_by_correspondence(const sim::TriMesh& blade, const std::vector<sim::TriMesh>& earlier,
                                  const sim::Box3& region, double min_feature, double* distance) {
  for (std::size_t k = earlier.size(); k-- > 0;) {
    const sim::TriMesh& e = earlier[k];
    if (e.vertices.size() != blade.vertices.size() || e.triangles != blade.triangles) continue;
    const double d = correspondence_bound(blade, e, region);  // m
    if (d < 0.0 || !(d <= min_feature)) continue;
    if (distance != nullptr) *distance = d;
    return static_cast<int>(k);
  }
  return -1;
}

}  // namespace

int snap_target(const sim::TriMesh& blade, const std::vector<sim::TriMesh>& earlier, const sim::Box3& region,
                double min_feature, double* distance) {
  if (distance != nullptr) *distance = std::numeric_limits<double>::infinity();
  if (!(min_feature > 0.0) || blade.triangles.empty()) return -1;
  const sim::Box3 bb = sim::bounds(blade);
  const double tol = 1e-9 * (bb.max - bb.min).norm();  // m: flatness of the blade's faces, convexity
  const ConvexSolid solid = convex_solid(blade, tol);
  if (solid.planes.empty()) return snap_target_by_correspondence(blade, earlier, region, min_feature, distance);
  const std::vector<Vec3> corners = corners_in_box(blade, solid.planes, region);
  if (corners.empty()) return -1;  // the blade does not reach into the region
  // The latest candidate within min_feature wins. The distance is the Hausdorff distance of the two solids within
  // the region: the distance to a convex solid is a convex function, so its largest value over a convex body
  // (blade ∩ region) is taken at one of its corners.
  // A cheap bound first: blade ∩ region reaching more than min_feature past the box of an earlier blade within the
  // region (which holds that blade ∩ region) along an axis has a corner farther than that from it.
  Vec3 lo = corners.front(), hi = lo;  // m: the box of blade ∩ region
  for (const Vec3& q : corners) {
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  for (std::size_t k = earlier.size(); k-- > 0;) {
    const sim::TriMesh& e = earlier[k];
    if (e.vertices.size() != blade.vertices.size() || e.triangles != blade.triangles) continue;
    const sim::Box3 eb = sim::bounds(e);
    const Vec3 elo = eb.min.cwiseMax(region.min), ehi = eb.max.cwiseMin(region.max);
    const bool clipped_empty = (elo.array() > ehi.array()).any();
    if (!clipped_empty && ((lo - elo).minCoeff() <= -(min_feature + tol) || (hi - ehi).maxCoeff() >= min_feature + tol))
      continue;
    const ConvexSolid other = convex_solid(e, tol);
    if (other.planes.empty()) continue;
    double d = 0.0;  // m
    if (!within(corners, other, min_feature, d)) continue;
    if (!within(corners_in_box(e, other.planes, region), solid, min_feature, d)) continue;
    if (distance != nullptr) *distance = d;
    return static_cast<int>(k);
  }
  return -1;
}

}  // namespace octocut::cutting
