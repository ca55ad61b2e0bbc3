// Phase 1 of the surface boolean S \ B' (surface_cut_phases.hpp): the patch P, the faces of S near the blade, found
// through S's persistent FaceGrid. No CGAL, and no pass over S.
//
// The faces of S whose bounding box meets the grown bounding box G of the blade come from the grid (the cells G
// meets, then a box test). Of those, P is the faces that may touch the blade (a conservative plane-side test against
// the blade triangles near them); the others lie strictly inside or strictly outside the blade and are grouped
// through shared vertices, for phase 2 to classify with one exact point query per group. A face outside G cannot
// touch the blade, so P's boundary edges stay untouched. Where P's faces would form several fans around a vertex, the
// faces around it are added (the grid lists them), so every vertex of P is one CGAL vertex.
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <iterator>
#include <utility>
#include <vector>

#include "octocut/sim/disjoint_sets.hpp"
#include "surface_cut_phases.hpp"

namespace octocut::cutting::surface_cut_detail {
namespace {

using sim::Vec3;

// A blade triangle as the plane-side test sees it.
struct BladeTriangle {
  Vec3 lo, hi, n;  // grown box, m; normal (not unit), m^2
  double d, tol;   // plane offset n.p, m^3; the bound on the plane test's rounding per metre of scale, m^2
};

// The plane of triangle abc: n = (b - a) x (c - a) (m^2), d = n.a (m^3), and tol (m^2). The plane test n.x - d in
// doubles errs by a few ulps of |n| |x| (the dot products) plus |b - a| |c - a| |x - a| (the rounded cross product,
// which matters for slivers, whose |n| is far below |b - a| |c - a|): tol bounds both with a margin of a million, per
// metre of |x| and |x - a|.
void plane(const Vec3& a, const Vec3& b, const Vec3& c, Vec3& n, double& d, double& tol) {
  n = (b - a).cross(c - a);
  d = n.dot(a);
  tol = 1e-9 * (n.norm() + (b - a).norm() * (c - a).norm());
}

// Whether a, b, c (m) lie strictly on one side of the plane n.x = d, beyond tol (m^3).
bool one_side(const Vec3& n, double d, double tol, const Vec3& a, const Vec3& b, const Vec3& c) {
  const double x = n.dot(a) - d, y = n.dot(b) - d, z = n.dot(c) - d;
  return (x > tol && y > tol && z > tol) || (x < -tol && y < -tol && z < -tol);
}

// The blade's triangles (|F_B|) with their boxes grown by `margin` (m) and their planes.
std::vector<BladeTriangle> blade_triangles(const sim::TriMesh& blade, double margin) {
  std::vector<BladeTriangle> bts;
  bts.reserve(blade.triangles.size());
  for (const Tri& t : blade.triangles) {
    const Vec3& a = blade.vertices[static_cast<std::size_t>(t[0])];
    const Vec3& b = blade.vertices[static_cast<std::size_t>(t[1])];
    const Vec3& c = blade.vertices[static_cast<std::size_t>(t[2])];
    BladeTriangle bt;
    bt.lo = a.cwiseMin(b).cwiseMin(c).array() - margin;
    bt.hi = a.cwiseMax(b).cwiseMax(c).array() + margin;
    plane(a, b, c, bt.n, bt.d, bt.tol);
    bts.push_back(bt);
  }
  return bts;
}

// Of `candidates` (faces of S in G, ascending), those that may touch the blade: no blade triangle whose grown box
// meets the face's box has the face strictly on one side of its plane, or lies strictly on one side of the face's.
std::vector<int32_t> faces_touching_blade(const sim::TriMesh& surface, const sim::TriMesh& blade,
                                          const std::vector<int32_t>& candidates, const BladeBox& g) {
  const std::vector<BladeTriangle> bts = blade_triangles(blade, g.margin);
  // Distances and coordinate magnitudes in play for the blade (G), m; a face adds its own.
  const double g_scale = (g.hi - g.lo).norm() + std::max(g.lo.cwiseAbs().maxCoeff(), g.hi.cwiseAbs().maxCoeff());
  std::vector<int32_t> touching;
  for (const int32_t f : candidates) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
    const Vec3& a = surface.vertices[static_cast<std::size_t>(t[0])];
    const Vec3& b = surface.vertices[static_cast<std::size_t>(t[1])];
    const Vec3& c = surface.vertices[static_cast<std::size_t>(t[2])];
    const Vec3 lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
    Vec3 n;
    double d = 0.0, tol = 0.0;
    plane(a, b, c, n, d, tol);
    const double scale = g_scale + (hi - lo).norm() + std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
    bool may_touch = false;
    for (const BladeTriangle& bt : bts) {
      if ((hi.array() < bt.lo.array()).any() || (lo.array() > bt.hi.array()).any()) continue;
      if (one_side(bt.n, bt.d, bt.tol * scale, a, b, c)) continue;
      const Tri& u = blade.triangles[static_cast<std::size_t>(&bt - bts.data())];
      if (one_side(n, d, tol * scale, blade.vertices[static_cast<std::size_t>(u[0])],
                   blade.vertices[static_cast<std::size_t>(u[1])], blade.vertices[static_cast<std::size_t>(u[2])])) {
        continue;
      }
      may_touch = true;
      break;
    }
    if (may_touch) touching.push_back(f);
  }
  return touching;
}

// Closes `patch` (face indices of S, ascending) around the vertices where its faces form more than one fan (a pinched
// vertex would need one copy per fan, and corefinement's self-intersection check would then see distinct vertices
// touching): adds the faces around them (clear faces, or faces outside G; the grid lists them), until no vertex is
// pinched or 32 rounds have passed. Returns the open fans of the closed patch.
FanCounts close_pinched_vertices(const sim::TriMesh& surface, FaceGrid& grid, std::vector<int32_t>& patch) {
  FanCounts fans = open_fans(surface, patch);
  for (int round = 0; round < 32; ++round) {
    std::vector<int32_t> pinched;  // ascending
    for (const auto& [v, n] : fans) {
      if (n > 1) pinched.push_back(v);
    }
    if (pinched.empty()) break;
    std::sort(pinched.begin(), pinched.end());
    for (const int32_t v : pinched) {
      for (const int32_t f : grid.around(surface, v)) patch.push_back(f);
    }
    std::sort(patch.begin(), patch.end());
    patch.erase(std::unique(patch.begin(), patch.end()), patch.end());
    fans = open_fans(surface, patch);
  }
  return fans;
}

// The faces of `region` (faces of S in G, ascending) that are not in `patch` (ascending), grouped through shared
// vertices.
ClearFaces clear_faces(const sim::TriMesh& surface, const std::vector<int32_t>& region,
                       const std::vector<int32_t>& patch) {
  ClearFaces clear;
  std::set_difference(region.begin(), region.end(), patch.begin(), patch.end(), std::back_inserter(clear.faces));
  if (clear.faces.empty()) return clear;
  std::vector<int32_t> vertices;  // of the clear faces, ascending
  vertices.reserve(clear.faces.size() * 3);
  for (const int32_t f : clear.faces) {
    for (const int32_t v : surface.triangles[static_cast<std::size_t>(f)]) vertices.push_back(v);
  }
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  const auto local = [&](int32_t v) {
    return static_cast<int32_t>(std::lower_bound(vertices.begin(), vertices.end(), v) - vertices.begin());
  };
  sim::DisjointSets groups(vertices.size());
  for (const int32_t f : clear.faces) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
    groups.unite(local(t[0]), local(t[1]));
    groups.unite(local(t[0]), local(t[2]));
  }
  // Groups numbered by first appearance; a group's root is its smallest local index, i.e. its smallest vertex.
  std::vector<int32_t> group_of_root(vertices.size(), -1);
  clear.group.reserve(clear.faces.size());
  for (const int32_t f : clear.faces) {
    const int32_t r = groups.find(local(surface.triangles[static_cast<std::size_t>(f)][0]));
    int32_t& g = group_of_root[static_cast<std::size_t>(r)];
    if (g < 0) {
      g = static_cast<int32_t>(clear.group_vertex.size());
      clear.group_vertex.push_back(vertices[static_cast<std::size_t>(r)]);
    }
    clear.group.push_back(g);
  }
  return clear;
}

// P as a local mesh: one local vertex per fan of P's faces around each vertex of S (after the closure, one per
// vertex, unless 32 rounds did not suffice), created in the order of the corners sorted by (vertex, face, corner).
void index_patch_vertices(const sim::TriMesh& surface, Patch& patch) {
  struct Corner {
    int32_t v, out, in;  // the vertex of S, the one after it in the face, the one before it
    int face, k;         // position in patch.faces, corner 0..2
  };
  std::vector<Corner> corners;
  corners.reserve(patch.faces.size() * 3);
  for (std::size_t i = 0; i < patch.faces.size(); ++i) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(patch.faces[i])];
    for (int k = 0; k < 3; ++k) {
      corners.push_back({t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)],
                         t[static_cast<std::size_t>((k + 2) % 3)], static_cast<int>(i), k});
    }
  }
  std::sort(corners.begin(), corners.end(), [](const Corner& x, const Corner& y) {
    return x.v < y.v || (x.v == y.v && (x.face < y.face || (x.face == y.face && x.k < y.k)));
  });
  patch.triangles.assign(patch.faces.size(), Tri{-1, -1, -1});
  std::vector<int32_t> copy_of_root;
  for (std::size_t i = 0; i < corners.size();) {
    std::size_t j = i;
    while (j < corners.size() && corners[j].v == corners[i].v) ++j;
    const auto n = static_cast<int32_t>(j - i);
    // The corners around one vertex joined into fans: a corner's outgoing edge is another's incoming one.
    sim::DisjointSets fans(static_cast<std::size_t>(n));
    for (int32_t a = 0; a < n; ++a) {
      for (int32_t b = 0; b < n; ++b) {
        if (a != b && corners[i + static_cast<std::size_t>(a)].out == corners[i + static_cast<std::size_t>(b)].in) {
          fans.unite(a, b);
        }
      }
    }
    copy_of_root.assign(static_cast<std::size_t>(n), -1);
    for (int32_t a = 0; a < n; ++a) {
      int32_t& copy = copy_of_root[static_cast<std::size_t>(fans.find(a))];
      if (copy < 0) {
        copy = static_cast<int32_t>(patch.vertices.size());
        patch.vertices.push_back(corners[i].v);
      }
      const Corner& c = corners[i + static_cast<std::size_t>(a)];
      patch.triangles[static_cast<std::size_t>(c.face)][static_cast<std::size_t>(c.k)] = copy;
    }
    i = j;
  }
}

}  // namespace

FanCounts open_fans(const sim::TriMesh& surface, const std::vector<int32_t>& faces) {
  std::vector<std::array<int32_t, 3>> corners;  // (vertex, next, previous)
  corners.reserve(faces.size() * 3);
  for (const int32_t f : faces) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
    for (int k = 0; k < 3; ++k) corners.push_back({t[k], t[(k + 1) % 3], t[(k + 2) % 3]});
  }
  std::sort(corners.begin(), corners.end());
  FanCounts fans;
  for (std::size_t i = 0; i < corners.size();) {
    std::size_t j = i;
    while (j < corners.size() && corners[j][0] == corners[i][0]) ++j;
    // Each open fan starts at one corner whose next vertex is no corner's previous vertex.
    int open = 0;
    for (std::size_t a = i; a < j; ++a) {
      bool matched = false;
      for (std::size_t b = i; b < j && !matched; ++b) matched = b != a && corners[b][2] == corners[a][1];
      if (!matched) ++open;
    }
    if (open > 0) fans[corners[i][0]] = open;
    i = j;
  }
  return fans;
}

BladeBox grown_blade_box(const sim::TriMesh& blade, double margin) {
  BladeBox g;
  g.lo = blade.vertices[static_cast<std::size_t>(blade.triangles[0][0])];
  g.hi = g.lo;
  for (const Tri& t : blade.triangles) {
    for (const int32_t v : t) {
      g.lo = g.lo.cwiseMin(blade.vertices[static_cast<std::size_t>(v)]);
      g.hi = g.hi.cwiseMax(blade.vertices[static_cast<std::size_t>(v)]);
    }
  }
  g.margin = margin > 0.0 ? margin : 1e-6 * (g.hi - g.lo).norm();
  g.lo.array() -= g.margin;
  g.hi.array() += g.margin;
  g.centre = 0.5 * (g.lo + g.hi);
  return g;
}

Patch find_patch(const sim::TriMesh& surface, FaceGrid& grid, const sim::TriMesh& blade, const BladeBox& g) {
  Patch patch;
  const std::vector<int32_t> region = grid.query(surface, g.lo, g.hi);  // the faces whose box meets G, ascending
  patch.faces = faces_touching_blade(surface, blade, region, g);
  patch.arcs = close_pinched_vertices(surface, grid, patch.faces);
  patch.clear = clear_faces(surface, region, patch.faces);
  index_patch_vertices(surface, patch);
  return patch;
}

}  // namespace octocut::cutting::surface_cut_detail
