// The local surface boolean S \ B' (SPEC §4 stage 2). The only translation unit of the surface cut that sees CGAL.
//
// Algorithm:
//  1. The faces of S whose bounding box meets the grown bounding box G of the blade come from S's FaceGrid (the cells
//     G meets, then a box test). Of those, the patch P is the faces that may touch the blade (a conservative
//     plane-side test against the blade triangles near them); the others lie strictly inside
//     or strictly outside the blade, are grouped through shared vertices and classified with one exact point query
//     per group: the inside ones go whole, the outside ones stay. A face outside G cannot touch the blade, so P's
//     boundary edges stay untouched. Where P's faces would form several fans around a vertex, the faces around it
//     are added (the grid lists them), so every vertex of P is one CGAL vertex.
//  2. P is copied into a Surface_mesh and corefined with the blade (PMP::corefine, exact predicates), marking the
//     intersection edges as constrained and recording, through a visitor, which input face each piece lies in.
//  3. P and the blade are cut into regions along the constrained edges. A P region is removed when a point inside it
//     is inside the blade (Side_of_triangle_mesh), taking the face centroid farthest from the blade; when every
//     centroid lies within 1e-9 x the blade's size of the blade (coplanar up to the rounding of constructed points),
//     it is removed when the normals of the input faces agree and kept when they are opposite. A blade region is
//     kept (reversed) when, at a constrained edge where exactly one P face is kept, its halfedge runs in the same
//     direction as that P face's, and discarded when the opposite halfedge does; conflicting votes fail the cut. A
//     region without votes is discarded when it lies on P (coplanar), and otherwise kept when an exact ray-parity
//     test (axis rays, orientation predicates on S's input coordinates, retried on grazing rays) puts it inside S.
//     Where options.removable rejects a region's test point, a P region is kept and a blade region without votes is
//     discarded (the pipeline's restriction of B'_i to the material of component i).
//  4. The kept pieces are written back into S in place (SurfaceEditor: journaled, the grid kept up to date): P's
//     original vertices keep their indices, new vertices are matched between the two meshes by identical
//     coordinates and appended, the pieces fill P's slots and the rest are appended or the leftover slots removed.
//     The result is verified locally (verify_local and verify_self_intersections, with the unchanged neighbours
//     from the grid), and V(S) - V(S') is summed over the changed faces only. Nothing is a pass over S: even the
//     ray-parity test of step 3 takes the faces from the grid cells along its ray.
#include "octocut/cutting/surface_cut.hpp"

#include "cgal_exact.hpp"  // first: the exact number type of Epeck

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/corefinement.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/AABB_face_graph_triangle_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/box_intersection_d.h>
#include <CGAL/boost/graph/helpers.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <exception>
#include <limits>
#include <numeric>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "octocut/sim/disjoint_sets.hpp"

namespace octocut::cutting {
namespace {

namespace PMP = CGAL::Polygon_mesh_processing;
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Point2 = Kernel::Point_2;
using Mesh = CGAL::Surface_mesh<Point>;
using VI = Mesh::Vertex_index;
using FI = Mesh::Face_index;
using EI = Mesh::Edge_index;
using HI = Mesh::Halfedge_index;
using sim::Vec3;
using Tri = std::array<int32_t, 3>;

// A failure with a reason; caught at the API boundary and turned into SurfaceCutStatus::failed.
struct CutFailure {
  std::string reason;
};

Point to_point(const Vec3& p) { return {p.x(), p.y(), p.z()}; }
Vec3 to_vec(const Point& p) { return {p.x(), p.y(), p.z()}; }

// Hash key of a point: the bit patterns of its coordinates (identical coordinates <=> identical key).
struct PointKey {
  std::array<uint64_t, 3> bits{};
  explicit PointKey(const Point& p)
      : bits{std::bit_cast<uint64_t>(p.x() + 0.0), std::bit_cast<uint64_t>(p.y() + 0.0),
             std::bit_cast<uint64_t>(p.z() + 0.0)} {}  // + 0.0 folds -0 into +0
  friend bool operator==(const PointKey&, const PointKey&) = default;
};
struct PointKeyHash {
  std::size_t operator()(const PointKey& k) const {
    uint64_t h = 1469598103934665603ull;
    for (const uint64_t b : k.bits) h = (h ^ b) * 1099511628211ull ^ (b >> 29);
    return static_cast<std::size_t>(h);
  }
};
struct EdgeKey {
  PointKey a, b;
  friend bool operator==(const EdgeKey&, const EdgeKey&) = default;
};
struct EdgeKeyHash {
  std::size_t operator()(const EdgeKey& k) const { return PointKeyHash{}(k.a) * 31 + PointKeyHash{}(k.b); }
};

// Signed volume contribution of triangle abc relative to origin o (divergence theorem), m^3.
double tet_volume(const Vec3& o, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (a - o).dot((b - o).cross(c - o)) / 6.0;
}

bool finite(const Vec3& p) { return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()); }

// The directed edge (a, b) as one sortable number.
uint64_t directed_edge_key(int32_t a, int32_t b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(b);
}

// Checks coordinates and indices of a mesh; throws CutFailure naming the first offender.
void check_input(const sim::TriMesh& mesh, const char* name) {
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!finite(mesh.vertices[v])) {
      throw CutFailure{std::string(name) + " vertex " + std::to_string(v) + " has a non-finite coordinate"};
    }
  }
  const auto nv = static_cast<int64_t>(mesh.vertices.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (const int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= nv) {
        throw CutFailure{std::string(name) + " triangle " + std::to_string(f) + " has vertex index " +
                         std::to_string(v) + ", outside [0, " + std::to_string(nv) + ")"};
      }
    }
  }
}

// Records, for every piece of a split face, the input face it lies in (a face of S for P, of the blade for B).
struct OriginVisitor : PMP::Corefinement::Default_visitor<Mesh> {
  const Mesh* patch = nullptr;
  Mesh::Property_map<FI, int32_t>* origin = nullptr;    // on the patch
  Mesh::Property_map<FI, int32_t>* b_origin = nullptr;  // on the blade
  int32_t current = -1;
  int32_t b_current = -1;
  void before_subface_creations(FI f, Mesh& tm) {
    if (&tm == patch) current = (*origin)[f];
    else b_current = (*b_origin)[f];
  }
  void after_subface_created(FI f, Mesh& tm) {
    if (&tm == patch) (*origin)[f] = current;
    else (*b_origin)[f] = b_current;
  }
};

// Regions of a mesh: faces connected across edges that are neither constrained nor on the border.
int label_regions(const Mesh& mesh, const Mesh::Property_map<EI, bool>& constrained,
                  Mesh::Property_map<FI, int>& region) {
  int count = 0;
  std::vector<FI> stack;
  for (const FI f : mesh.faces()) region[f] = -1;
  for (const FI seed : mesh.faces()) {
    if (region[seed] >= 0) continue;
    region[seed] = count;
    stack.push_back(seed);
    while (!stack.empty()) {
      const FI f = stack.back();
      stack.pop_back();
      for (const HI h : CGAL::halfedges_around_face(mesh.halfedge(f), mesh)) {
        if (constrained[mesh.edge(h)]) continue;
        const FI g = mesh.face(mesh.opposite(h));
        if (g == Mesh::null_face() || region[g] >= 0) continue;
        region[g] = count;
        stack.push_back(g);
      }
    }
    ++count;
  }
  return count;
}

std::array<Point, 3> face_points(const Mesh& mesh, FI f) {
  const HI h = mesh.halfedge(f);
  return {mesh.point(mesh.source(h)), mesh.point(mesh.target(h)), mesh.point(mesh.target(mesh.next(h)))};
}

// The face of each region with the largest area (its centroid is the best-conditioned inner point).
std::vector<FI> region_representatives(const Mesh& mesh, const Mesh::Property_map<FI, int>& region, int count) {
  std::vector<FI> best(static_cast<std::size_t>(count), Mesh::null_face());
  std::vector<double> area(static_cast<std::size_t>(count), -1.0);
  for (const FI f : mesh.faces()) {
    const auto p = face_points(mesh, f);
    const double a = (to_vec(p[1]) - to_vec(p[0])).cross(to_vec(p[2]) - to_vec(p[0])).squaredNorm();
    const auto r = static_cast<std::size_t>(region[f]);
    if (a > area[r]) {
      area[r] = a;
      best[r] = f;
    }
  }
  return best;
}

Point centroid(const std::array<Point, 3>& p) { return CGAL::centroid(p[0], p[1], p[2]); }

enum class Side { inside, outside, boundary, degenerate };

// Exact parity of the crossings of S by the ray from q along +-axis `axis` (dir = +1 or -1), over `faces` (those
// whose boxes meet the ray). Every decision is an exact orientation predicate on input coordinates; a ray through an
// edge or a vertex, or q on S, is reported.
Side ray_parity(const sim::TriMesh& s, const std::vector<int32_t>& faces, const Point& q, int axis, int dir) {
  const int u = (axis + 1) % 3;
  const int v = (axis + 2) % 3;
  const double qa = q[axis], qu = q[u], qv = q[v];
  const Point2 q2(qu, qv);
  int crossings = 0;
  for (const int32_t f : faces) {
    const Tri& t = s.triangles[static_cast<std::size_t>(f)];
    const Vec3& a = s.vertices[static_cast<std::size_t>(t[0])];
    const Vec3& b = s.vertices[static_cast<std::size_t>(t[1])];
    const Vec3& c = s.vertices[static_cast<std::size_t>(t[2])];
    // Bounding-box prefilter: the ray's line must meet the triangle's projection, ahead of q.
    if (std::max({a[u], b[u], c[u]}) < qu || std::min({a[u], b[u], c[u]}) > qu) continue;
    if (std::max({a[v], b[v], c[v]}) < qv || std::min({a[v], b[v], c[v]}) > qv) continue;
    if (dir > 0 ? std::max({a[axis], b[axis], c[axis]}) < qa : std::min({a[axis], b[axis], c[axis]}) > qa) continue;
    const Point2 a2(a[u], a[v]), b2(b[u], b[v]), c2(c[u], c[v]);
    const CGAL::Orientation n = CGAL::orientation(a2, b2, c2);  // sign of the normal's axis component
    if (n == CGAL::COLLINEAR) {
      // The triangle contains the ray direction; the line touches it only on its boundary edges, which the
      // neighbouring triangles see, unless q's line lies in its plane over it.
      if (CGAL::orientation(to_point(a), to_point(b), to_point(c), q) == CGAL::COPLANAR) {
        const Point pa = to_point(a), pb = to_point(b), pc = to_point(c);
        if (CGAL::do_intersect(Kernel::Triangle_3(pa, pb, pc), q)) return Side::boundary;
        // The line lies in the triangle's plane; whether it meets the triangle ahead is degenerate for parity.
        const Kernel::Ray_3 ray(q, Kernel::Direction_3(axis == 0 ? dir : 0, axis == 1 ? dir : 0,
                                                       axis == 2 ? dir : 0));
        if (CGAL::do_intersect(ray, Kernel::Triangle_3(pa, pb, pc))) return Side::degenerate;
      }
      continue;
    }
    const int sn = static_cast<int>(n);
    const int o1 = static_cast<int>(CGAL::orientation(a2, b2, q2));
    const int o2 = static_cast<int>(CGAL::orientation(b2, c2, q2));
    const int o3 = static_cast<int>(CGAL::orientation(c2, a2, q2));
    if (o1 == -sn || o2 == -sn || o3 == -sn) continue;  // the line misses the triangle
    // The line meets the triangle (interior, or boundary when some orientation is zero).
    const CGAL::Orientation side = CGAL::orientation(to_point(a), to_point(b), to_point(c), q);
    if (side == CGAL::COPLANAR) return Side::boundary;
    // Ahead of q iff q lies behind the plane with respect to the ray direction: sign(side) == -sign(n * dir).
    if (static_cast<int>(side) != -sn * dir) continue;  // the crossing lies behind q
    if (o1 == 0 || o2 == 0 || o3 == 0) return Side::degenerate;
    ++crossings;
  }
  return (crossings % 2 == 1) ? Side::inside : Side::outside;
}

// Point q against the solid bounded by S: tries the six axis directions until one is not degenerate. The faces a
// ray may cross come from S's grid (the cells along the ray).
Side point_in_surface(const sim::TriMesh& s, FaceGrid& grid, const Point& q) {
  const Vec3 at = to_vec(q);
  for (int axis = 0; axis < 3; ++axis) {
    for (const int dir : {1, -1}) {
      Vec3 lo = at, hi = at;  // the ray's box, m
      (dir > 0 ? hi : lo)[axis] = dir * std::numeric_limits<double>::infinity();
      const Side side = ray_parity(s, grid.query(s, lo, hi), q, axis, dir);
      if (side != Side::degenerate) return side;
    }
  }
  return Side::degenerate;
}

// Whether two triangles of the output mesh intersect other than in a shared vertex or a shared edge (the rules of
// PMP::self_intersections, on vertex indices).
bool triangles_intersect(const sim::TriMesh& m, const Tri& s, const Tri& t) {
  const auto P = [&](int32_t i) { return to_point(m.vertices[static_cast<std::size_t>(i)]); };
  int shared = 0;
  std::array<int, 2> si{}, ti{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (s[i] == t[j]) {
        if (shared < 2) {
          si[shared] = i;
          ti[shared] = j;
        }
        ++shared;
      }
    }
  }
  if (shared >= 3) return true;  // the same triangle twice
  if (shared == 2) {
    // Shared edge (a, b): they overlap when the four points are coplanar and the third vertices lie on one side.
    const int sc = 3 - si[0] - si[1];
    const int tc = 3 - ti[0] - ti[1];
    const Point a = P(s[si[0]]), b = P(s[si[1]]), c = P(s[sc]), d = P(t[tc]);
    return CGAL::coplanar(a, b, c, d) && CGAL::coplanar_orientation(a, b, c, d) == CGAL::POSITIVE;
  }
  const Kernel::Triangle_3 ts(P(s[0]), P(s[1]), P(s[2]));
  const Kernel::Triangle_3 tt(P(t[0]), P(t[1]), P(t[2]));
  if (shared == 1) {
    // Shared vertex: they intersect when the edge opposite it in one triangle meets the other triangle.
    const int i = si[0], j = ti[0];
    const Kernel::Segment_3 es(P(s[(i + 1) % 3]), P(s[(i + 2) % 3]));
    const Kernel::Segment_3 et(P(t[(j + 1) % 3]), P(t[(j + 2) % 3]));
    return CGAL::do_intersect(ts, et) || CGAL::do_intersect(tt, es);
  }
  return CGAL::do_intersect(ts, tt);
}

// The number of open fans that `faces` (face indices of `surface`) form around each vertex where they form any (the
// vertices on their boundary).
std::unordered_map<int32_t, int> open_fans(const sim::TriMesh& surface, const std::vector<int32_t>& faces) {
  std::vector<std::array<int32_t, 3>> corners;  // (vertex, next, previous)
  corners.reserve(faces.size() * 3);
  for (const int32_t f : faces) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
    for (int k = 0; k < 3; ++k) corners.push_back({t[k], t[(k + 1) % 3], t[(k + 2) % 3]});
  }
  std::sort(corners.begin(), corners.end());
  std::unordered_map<int32_t, int> fans;
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

// The vertices around which the faces `patch` form more than one fan, ascending.
std::vector<int32_t> pinched_vertices(const sim::TriMesh& surface, const std::vector<int32_t>& patch) {
  std::vector<int32_t> pinched;
  for (const auto& [v, fans] : open_fans(surface, patch)) {
    if (fans > 1) pinched.push_back(v);
  }
  std::sort(pinched.begin(), pinched.end());
  return pinched;
}

// Local verification of S': `changed` are the triangles built from the corefined patch and the blade (indices into
// out.triangles); `boundary_edges` are the directed edges (new indices) of the unchanged faces that border the
// patch; `boundary_arcs[v]` is the number of fans the patch had around vertex v (new index), 0 when v was inside.
// Throws CutFailure naming the first defect.
void verify_local(const sim::TriMesh& out, const std::vector<int32_t>& changed,
                  const std::vector<std::array<int32_t, 2>>& boundary_edges,
                  const std::unordered_map<int32_t, int>& boundary_arcs) {
  // Degenerate triangles.
  for (const int32_t f : changed) {
    const Tri& t = out.triangles[static_cast<std::size_t>(f)];
    for (const int32_t v : t) {
      if (!finite(out.vertices[static_cast<std::size_t>(v)])) {
        throw CutFailure{"result vertex " + std::to_string(v) + " is not finite"};
      }
    }
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] ||
        CGAL::collinear(to_point(out.vertices[static_cast<std::size_t>(t[0])]),
                        to_point(out.vertices[static_cast<std::size_t>(t[1])]),
                        to_point(out.vertices[static_cast<std::size_t>(t[2])]))) {
      throw CutFailure{"result triangle " + std::to_string(f) + " is degenerate"};
    }
  }

  // Closed, edge-manifold, oriented: every directed edge once, and its reverse once (a sorted list of the directed
  // edges; the first offender in that order is reported).
  std::vector<uint64_t> directed;
  directed.reserve(changed.size() * 3 + boundary_edges.size());
  const auto key = directed_edge_key;
  for (const int32_t f : changed) {
    const Tri& t = out.triangles[static_cast<std::size_t>(f)];
    for (int k = 0; k < 3; ++k) directed.push_back(key(t[k], t[(k + 1) % 3]));
  }
  for (const auto& e : boundary_edges) directed.push_back(key(e[0], e[1]));
  std::sort(directed.begin(), directed.end());
  const auto uses = [&](uint64_t k) {
    const auto [lo, hi] = std::equal_range(directed.begin(), directed.end(), k);
    return static_cast<int>(hi - lo);
  };
  for (std::size_t i = 0; i < directed.size();) {
    const uint64_t k = directed[i];
    std::size_t j = i;
    while (j < directed.size() && directed[j] == k) ++j;
    const int n = static_cast<int>(j - i);
    i = j;
    const auto a = static_cast<int32_t>(k >> 32);
    const auto b = static_cast<int32_t>(k & 0xffffffffu);
    const int back = uses(key(b, a));
    if (n != 1 || back != 1) {
      throw CutFailure{"result edge (" + std::to_string(a) + ", " + std::to_string(b) + ") is used " +
                       std::to_string(n) + " times in this direction and " + std::to_string(back) +
                       " times in the other (not closed, manifold and oriented)"};
    }
  }

  // Vertex-manifold: around each vertex, the changed faces form one closed fan (inside the patch) or as many open
  // fans as the patch had there (on its boundary, where the unchanged faces close the ring).
  std::vector<std::pair<int32_t, int32_t>> corners;  // (vertex, triangle)
  corners.reserve(changed.size() * 3);
  for (const int32_t f : changed) {
    for (const int32_t v : out.triangles[static_cast<std::size_t>(f)]) corners.emplace_back(v, f);
  }
  std::sort(corners.begin(), corners.end());
  std::vector<int> parent;
  for (std::size_t i = 0; i < corners.size();) {
    std::size_t j = i;
    while (j < corners.size() && corners[j].first == corners[i].first) ++j;
    const int32_t v = corners[i].first;
    const int n = static_cast<int>(j - i);
    parent.assign(static_cast<std::size_t>(n), 0);
    std::iota(parent.begin(), parent.end(), 0);
    const auto find = [&](int x) {
      while (parent[static_cast<std::size_t>(x)] != x) x = parent[static_cast<std::size_t>(x)];
      return x;
    };
    // out(c): the vertex after v in the corner's triangle; in(c): the vertex before it.
    const auto next_of = [&](std::size_t c, int step) {
      const Tri& t = out.triangles[static_cast<std::size_t>(corners[c].second)];
      const int k = t[0] == v ? 0 : (t[1] == v ? 1 : 2);
      return t[static_cast<std::size_t>((k + step) % 3)];
    };
    int components = n;
    int open_ends = 0;
    for (int a = 0; a < n; ++a) {
      const int32_t out_a = next_of(i + static_cast<std::size_t>(a), 1);
      bool matched = false;
      for (int b = 0; b < n; ++b) {
        if (b == a || next_of(i + static_cast<std::size_t>(b), 2) != out_a) continue;
        matched = true;
        const int ra = find(a), rb = find(b);
        if (ra != rb) {
          parent[static_cast<std::size_t>(ra)] = rb;
          --components;
        }
      }
      if (!matched) ++open_ends;
    }
    const auto it = boundary_arcs.find(v);
    const int expected_arcs = it == boundary_arcs.end() ? 0 : it->second;
    const bool good = expected_arcs == 0 ? (components == 1 && open_ends == 0)
                                         : (components == expected_arcs && open_ends == expected_arcs);
    if (!good) {
      throw CutFailure{"result vertex " + std::to_string(v) + " is not manifold (" + std::to_string(components) +
                       " fans of changed faces, " + std::to_string(open_ends) + " open)"};
    }
    i = j;
  }
}

// Self-intersections among the changed faces and between them and their unchanged neighbours: the faces of S kept
// whole in the patch (`whole`, per entry of `changed`) and the faces outside it that share a vertex with it. Pairs of
// unchanged faces are skipped (S had no self-intersection), and so are pairs of faces without a constructed vertex
// (see below; `constructed_inserted` flags the vertices from `first_inserted` on that are intersection points).
// Throws CutFailure naming the smallest pair found.
void verify_self_intersections(const sim::TriMesh& out, const std::vector<int32_t>& changed,
                               const std::vector<char>& whole, int32_t first_inserted,
                               const std::vector<char>& constructed_inserted,
                               const std::vector<int32_t>& neighbours) {
  using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, int32_t>;
  std::vector<Box> boxes, changed_boxes;  // all of them; those of the changed triangles
  boxes.reserve(changed.size() + neighbours.size());
  // A box's info is 2 f + 1 for a changed triangle f, 2 f for a neighbour.
  const auto add = [&](int32_t f, int32_t changed_bit) {
    const Tri& t = out.triangles[static_cast<std::size_t>(f)];
    const Vec3& a = out.vertices[static_cast<std::size_t>(t[0])];
    const Vec3& b = out.vertices[static_cast<std::size_t>(t[1])];
    const Vec3& c = out.vertices[static_cast<std::size_t>(t[2])];
    const Vec3 lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
    double l[3] = {lo.x(), lo.y(), lo.z()}, h[3] = {hi.x(), hi.y(), hi.z()};
    boxes.emplace_back(Box(l, h, 2 * f + changed_bit));
    if (changed_bit) changed_boxes.push_back(boxes.back());
  };
  // Only a face with a constructed vertex (an intersection point, rounded to doubles) can take part in an
  // intersection: two faces whose vertices are all input vertices of S or of the blade did not intersect before the
  // rounding (S had no self-intersection, the blade none, and the corefinement splits S and the blade wherever they
  // meet), and nothing moved them. The others count as unchanged.
  const auto constructed = [&](int32_t f) {
    const Tri& t = out.triangles[static_cast<std::size_t>(f)];
    return std::any_of(t.begin(), t.end(), [&](int32_t v) {
      return v >= first_inserted && constructed_inserted[static_cast<std::size_t>(v - first_inserted)] != 0;
    });
  };
  for (std::size_t i = 0; i < changed.size(); ++i) add(changed[i], !whole[i] && constructed(changed[i]) ? 1 : 0);
  for (const int32_t f : neighbours) add(f, 0);
  // The changed faces against all of them (pairs of unchanged faces are never enumerated); a pair of two changed
  // faces comes twice and is tested once, and a face against itself is skipped. Below kScanCutoff boxes CGAL goes
  // straight to its sorted two-way scan instead of building its segment tree first (a few hundred boxes per cut:
  // 0.1-0.35 ms less; the same pairs).
  constexpr std::ptrdiff_t kScanCutoff = 2048;
  bool found = false;
  std::array<int32_t, 2> best{};
  CGAL::box_intersection_d(changed_boxes.begin(), changed_boxes.end(), boxes.begin(), boxes.end(),
                           [&](const Box& x, const Box& y) {
    const int32_t f = x.info() / 2, g = y.info() / 2;
    if (f == g || ((y.info() & 1) != 0 && g < f)) return;
    if (triangles_intersect(out, out.triangles[static_cast<std::size_t>(f)],
                            out.triangles[static_cast<std::size_t>(g)])) {
      const std::array<int32_t, 2> pair{std::min(f, g), std::max(f, g)};
      if (!found || pair < best) best = pair;
      found = true;
    }
  }, kScanCutoff);
  if (found) {
    throw CutFailure{"result triangles " + std::to_string(best[0]) + " and " + std::to_string(best[1]) +
                     " intersect"};
  }
}

// The whole cut; throws CutFailure.
void cut(SurfaceEditor& editor, const sim::TriMesh& blade, const SurfaceCutOptions& options,
         SurfaceEditResult& result) {
  const sim::TriMesh& surface = editor.mesh();
  FaceGrid& grid = editor.grid();
  if (!grid.built()) throw CutFailure{"the surface has no face grid"};
  check_input(blade, "blade");
  if (blade.triangles.empty()) throw CutFailure{"blade has no triangles"};
  const auto nv = static_cast<int32_t>(surface.vertices.size());

  // Blade: a closed, manifold, outward-oriented, self-intersection-free Surface_mesh.
  Mesh bmesh;
  for (const Vec3& p : blade.vertices) bmesh.add_vertex(to_point(p));
  for (std::size_t f = 0; f < blade.triangles.size(); ++f) {
    const Tri& t = blade.triangles[f];
    const auto v = [&](int k) { return VI(static_cast<Mesh::size_type>(t[static_cast<std::size_t>(k)])); };
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] ||
        CGAL::collinear(bmesh.point(v(0)), bmesh.point(v(1)), bmesh.point(v(2)))) {
      throw CutFailure{"blade triangle " + std::to_string(f) + " is degenerate"};
    }
    if (bmesh.add_face(v(0), v(1), v(2)) == Mesh::null_face()) {
      throw CutFailure{"blade triangle " + std::to_string(f) + " makes the blade non-manifold or misoriented"};
    }
  }
  if (!CGAL::is_closed(bmesh)) throw CutFailure{"blade is not closed"};
  if (options.check_blade_self_intersection && PMP::does_self_intersect(bmesh)) {
    throw CutFailure{"blade intersects itself"};
  }
  if (sim::signed_volume(blade) <= 0.0) throw CutFailure{"blade is not outward oriented (volume <= 0)"};

  // G: the blade's bounding box, grown.
  Vec3 gmin = blade.vertices[static_cast<std::size_t>(blade.triangles[0][0])], gmax = gmin;
  for (const Tri& t : blade.triangles) {
    for (const int32_t v : t) {
      gmin = gmin.cwiseMin(blade.vertices[static_cast<std::size_t>(v)]);
      gmax = gmax.cwiseMax(blade.vertices[static_cast<std::size_t>(v)]);
    }
  }
  const double margin = options.margin > 0.0 ? options.margin : 1e-6 * (gmax - gmin).norm();
  gmin.array() -= margin;
  gmax.array() += margin;
  const Vec3 centre = 0.5 * (gmin + gmax);  // origin of the local volume sums, m

  // P: the faces of S whose bounding box meets G, from the grid (no pass over S).
  std::vector<int32_t> patch = grid.query(surface, gmin, gmax);  // face indices of S, ascending
  std::vector<int32_t> region = patch;  // the faces whose box meets G, ascending
  {
    struct BladeTriangle {
      Vec3 lo, hi, n;    // grown box, m; normal (not unit), m^2
      double d, tol;     // plane offset n.p, m^3; the bound on the plane test's rounding per metre of scale, m^2
    };
    // Distances and coordinate magnitudes in play for the blade (G), m; a face adds its own.
    const double g_scale = (gmax - gmin).norm() + std::max(gmin.cwiseAbs().maxCoeff(), gmax.cwiseAbs().maxCoeff());
    // The plane test n.x - d in doubles errs by a few ulps of |n| |x| (the dot products) plus |b - a| |c - a| |x - a|
    // (the rounded cross product, which matters for slivers, whose |n| is far below |b - a| |c - a|): tol bounds both
    // with a margin of a million, per metre of |x| and |x - a|.
    const auto plane = [&](const Vec3& a, const Vec3& b, const Vec3& c, Vec3& n, double& d, double& tol) {
      n = (b - a).cross(c - a);
      d = n.dot(a);
      tol = 1e-9 * (n.norm() + (b - a).norm() * (c - a).norm());
    };
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
    // Whether a, b, c lie strictly on one side of the plane n.x = d.
    const auto one_side = [](const Vec3& n, double d, double tol, const Vec3& a, const Vec3& b, const Vec3& c) {
      const double x = n.dot(a) - d, y = n.dot(b) - d, z = n.dot(c) - d;
      return (x > tol && y > tol && z > tol) || (x < -tol && y < -tol && z < -tol);
    };
    std::vector<int32_t> touching;
    for (const int32_t f : patch) {
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
    patch.swap(touching);
  }
  // Close P around the vertices where its faces form more than one fan (a pinched vertex would need one copy per
  // fan, and corefinement's self-intersection check would then see distinct vertices touching): add the faces
  // around them (clear faces, or faces outside G; the grid lists them), until no vertex is pinched.
  for (int round = 0; round < 32; ++round) {
    const std::vector<int32_t> pinched = pinched_vertices(surface, patch);
    if (pinched.empty()) break;
    for (const int32_t v : pinched) {
      for (const int32_t f : grid.around(surface, v)) patch.push_back(f);
    }
    std::sort(patch.begin(), patch.end());
    patch.erase(std::unique(patch.begin(), patch.end()), patch.end());
  }
  result.patch_triangles = static_cast<int>(patch.size());

  // The clear faces (in G, not in P): connected through shared vertices, each group lies strictly on one side of
  // the blade's surface; one exact point query per group decides. Those inside go whole (`gone`); those outside
  // stay untouched and count among the faces near P.
  std::vector<int32_t> gone;  // faces of S strictly inside the blade, ascending
  {
    std::vector<int32_t> clear;
    std::set_difference(region.begin(), region.end(), patch.begin(), patch.end(), std::back_inserter(clear));
    if (!clear.empty()) {
      std::vector<int32_t> vertices;  // of the clear faces, ascending
      vertices.reserve(clear.size() * 3);
      for (const int32_t f : clear) {
        for (const int32_t v : surface.triangles[static_cast<std::size_t>(f)]) vertices.push_back(v);
      }
      std::sort(vertices.begin(), vertices.end());
      vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
      const auto local = [&](int32_t v) {
        return static_cast<int>(std::lower_bound(vertices.begin(), vertices.end(), v) - vertices.begin());
      };
      sim::DisjointSets groups(vertices.size());
      for (const int32_t f : clear) {
        const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
        groups.unite(local(t[0]), local(t[1]));
        groups.unite(local(t[0]), local(t[2]));
      }
      using Side_of = CGAL::Side_of_triangle_mesh<Mesh, Kernel>;
      const Side_of::AABB_tree tree(bmesh.faces().begin(), bmesh.faces().end(), bmesh);
      const Side_of inside_blade(tree);
      std::vector<char> side(vertices.size(), 0);  // per root: 1 inside, 2 outside
      for (const int32_t f : clear) {
        const int r = groups.find(local(surface.triangles[static_cast<std::size_t>(f)][0]));
        char& sr = side[static_cast<std::size_t>(r)];
        if (sr == 0) {
          const CGAL::Bounded_side b = inside_blade(to_point(surface.vertices[static_cast<std::size_t>(vertices[static_cast<std::size_t>(r)])]));
          if (b == CGAL::ON_BOUNDARY) {
            throw CutFailure{"surface vertex " + std::to_string(vertices[static_cast<std::size_t>(r)]) +
                             " lies on the blade although its faces were found clear of it"};
          }
          // Inside, but where the caller does not let this blade remove material, the group stays.
          const Vec3& at = surface.vertices[static_cast<std::size_t>(vertices[static_cast<std::size_t>(r)])];
          sr = b == CGAL::ON_BOUNDED_SIDE && (!options.removable || options.removable(at)) ? 1 : 2;
        }
        if (sr == 1) gone.push_back(f);
      }
    }
  }

  // Copy P into a Surface_mesh. After the closure above no vertex is pinched; were one left (32 rounds did not
  // suffice), it would get one copy per fan.
  Mesh pmesh;
  std::vector<int32_t> p_old;  // old vertex index of each initial P vertex (|V_P|)
  std::vector<std::array<VI, 3>> p_face_vertices(patch.size());
  std::unordered_map<int32_t, int> patch_arcs;  // old vertex -> open fans of P around it (only on P's boundary)
  {
    struct Corner {
      int32_t v, out, in;
      int face, k;
    };
    std::vector<Corner> corners;
    corners.reserve(patch.size() * 3);
    for (std::size_t i = 0; i < patch.size(); ++i) {
      const Tri& t = surface.triangles[static_cast<std::size_t>(patch[i])];
      for (int k = 0; k < 3; ++k) {
        corners.push_back({t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)],
                           t[static_cast<std::size_t>((k + 2) % 3)], static_cast<int>(i), k});
      }
    }
    std::sort(corners.begin(), corners.end(), [](const Corner& x, const Corner& y) {
      return x.v < y.v || (x.v == y.v && (x.face < y.face || (x.face == y.face && x.k < y.k)));
    });
    std::vector<int> parent;
    std::vector<VI> copy_of_root;
    for (std::size_t i = 0; i < corners.size();) {
      std::size_t j = i;
      while (j < corners.size() && corners[j].v == corners[i].v) ++j;
      const int n = static_cast<int>(j - i);
      parent.assign(static_cast<std::size_t>(n), 0);
      std::iota(parent.begin(), parent.end(), 0);
      const auto find = [&](int x) {
        while (parent[static_cast<std::size_t>(x)] != x) x = parent[static_cast<std::size_t>(x)];
        return x;
      };
      int open = 0;
      for (int a = 0; a < n; ++a) {
        bool matched = false;
        for (int b = 0; b < n; ++b) {
          if (a == b || corners[i + static_cast<std::size_t>(a)].out != corners[i + static_cast<std::size_t>(b)].in) continue;
          matched = true;
          const int ra = find(a), rb = find(b);
          if (ra != rb) parent[static_cast<std::size_t>(std::max(ra, rb))] = std::min(ra, rb);
        }
        if (!matched) ++open;
      }
      if (open > 0) patch_arcs[corners[i].v] = open;
      copy_of_root.assign(static_cast<std::size_t>(n), Mesh::null_vertex());
      for (int a = 0; a < n; ++a) {
        const int r = find(a);
        if (copy_of_root[static_cast<std::size_t>(r)] == Mesh::null_vertex()) {
          copy_of_root[static_cast<std::size_t>(r)] =
              pmesh.add_vertex(to_point(surface.vertices[static_cast<std::size_t>(corners[i].v)]));
          p_old.push_back(corners[i].v);
        }
        const Corner& c = corners[i + static_cast<std::size_t>(a)];
        p_face_vertices[static_cast<std::size_t>(c.face)][static_cast<std::size_t>(c.k)] =
            copy_of_root[static_cast<std::size_t>(r)];
      }
      i = j;
    }
  }
  auto origin = pmesh.add_property_map<FI, int32_t>("f:origin", -1).first;
  for (std::size_t i = 0; i < patch.size(); ++i) {
    const auto& v = p_face_vertices[i];
    if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2] ||
        CGAL::collinear(pmesh.point(v[0]), pmesh.point(v[1]), pmesh.point(v[2]))) {
      throw CutFailure{"surface triangle " + std::to_string(patch[i]) + " is degenerate"};
    }
    const FI f = pmesh.add_face(v[0], v[1], v[2]);
    if (f == Mesh::null_face()) {
      throw CutFailure{"surface triangle " + std::to_string(patch[i]) + " makes the surface non-manifold"};
    }
    origin[f] = patch[i];
  }
  const auto p_initial_vertices = static_cast<std::size_t>(pmesh.number_of_vertices());
  auto b_origin = bmesh.add_property_map<FI, int32_t>("f:origin", -1).first;
  for (const FI f : bmesh.faces()) b_origin[f] = static_cast<int32_t>(f.idx());
  // Normals of the input triangles (exact inputs; the pieces' own normals suffer from rounded vertices).
  const auto s_normal = [&](int32_t f) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(f)];
    return (surface.vertices[static_cast<std::size_t>(t[1])] - surface.vertices[static_cast<std::size_t>(t[0])])
        .cross(surface.vertices[static_cast<std::size_t>(t[2])] - surface.vertices[static_cast<std::size_t>(t[0])]);
  };
  const auto b_normal = [&](int32_t f) {
    const Tri& t = blade.triangles[static_cast<std::size_t>(f)];
    return (blade.vertices[static_cast<std::size_t>(t[1])] - blade.vertices[static_cast<std::size_t>(t[0])])
        .cross(blade.vertices[static_cast<std::size_t>(t[2])] - blade.vertices[static_cast<std::size_t>(t[0])]);
  };

  // Corefine P with the blade; the intersection edges become constrained in both.
  auto p_constrained = pmesh.add_property_map<EI, bool>("e:constrained", false).first;
  auto b_constrained = bmesh.add_property_map<EI, bool>("e:constrained", false).first;
  if (!patch.empty()) {
    OriginVisitor visitor;
    visitor.patch = &pmesh;
    visitor.origin = &origin;
    visitor.b_origin = &b_origin;
    PMP::corefine(pmesh, bmesh,
                  PMP::parameters::edge_is_constrained_map(p_constrained).visitor(visitor).throw_on_self_intersection(options.check_surface_self_intersection),
                  PMP::parameters::edge_is_constrained_map(b_constrained));
  }

  // The intersection points, rounded from their exact values, must be finite (a defect of the exact number type's
  // conversion would show here first).
  for (const Mesh* m : {&pmesh, &bmesh}) {
    for (const VI v : m->vertices()) {
      const Point& p = m->point(v);
      if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
        throw CutFailure{"an intersection point is not finite"};
      }
    }
  }

  // Regions of both meshes.
  auto p_region = pmesh.add_property_map<FI, int>("f:region", -1).first;
  auto b_region = bmesh.add_property_map<FI, int>("f:region", -1).first;
  const int p_regions = label_regions(pmesh, p_constrained, p_region);
  const int b_regions = label_regions(bmesh, b_constrained, b_region);

  // Faces of each region.
  const auto faces_by_region = [](const Mesh& mesh, const Mesh::Property_map<FI, int>& region, int count) {
    std::vector<std::vector<FI>> out(static_cast<std::size_t>(count));
    for (const FI f : mesh.faces()) out[static_cast<std::size_t>(region[f])].push_back(f);
    return out;
  };
  // Distances below eps are rounding of the constructed intersection points (coordinates are rounded to doubles,
  // about 1e-16 relative); such a region is taken as coplanar with the other mesh.
  const double eps2 = std::pow(1e-9 * (gmax - gmin).norm(), 2);  // m^2

  // Classify P's regions against the blade: keep those outside; a region on the blade (every face centroid within
  // eps) is coplanar with a blade face and goes when the normals agree. The face farthest from the blade decides.
  std::vector<char> p_keep(static_cast<std::size_t>(p_regions), 1);
  if (p_regions > 0) {
    using Side_of = CGAL::Side_of_triangle_mesh<Mesh, Kernel>;
    const Side_of::AABB_tree b_tree(bmesh.faces().begin(), bmesh.faces().end(), bmesh);
    const Side_of inside_blade(b_tree);
    const auto p_faces = faces_by_region(pmesh, p_region, p_regions);
    const std::vector<FI> rep = region_representatives(pmesh, p_region, p_regions);
    for (int r = 0; r < p_regions; ++r) {
      const auto& faces = p_faces[static_cast<std::size_t>(r)];
      Point q = centroid(face_points(pmesh, rep[static_cast<std::size_t>(r)]));
      double d2 = b_tree.squared_distance(q);
      FI at = rep[static_cast<std::size_t>(r)];
      for (std::size_t i = 0; d2 <= eps2 && i < faces.size(); ++i) {
        const Point c = centroid(face_points(pmesh, faces[i]));
        const double e2 = b_tree.squared_distance(c);
        if (e2 > d2) {
          d2 = e2;
          q = c;
          at = faces[i];
        }
      }
      if (d2 > eps2) {
        const CGAL::Bounded_side side = inside_blade(q);
        p_keep[static_cast<std::size_t>(r)] = side == CGAL::ON_BOUNDED_SIDE ? 0 : 1;
      } else {
        const auto [closest, primitive] = b_tree.closest_point_and_primitive(q);
        const FI g = primitive;
        p_keep[static_cast<std::size_t>(r)] = s_normal(origin[at]).dot(b_normal(b_origin[g])) > 0.0 ? 0 : 1;
      }
      // Material the caller does not let this blade remove stays.
      if (!p_keep[static_cast<std::size_t>(r)] && options.removable && !options.removable(to_vec(q))) {
        p_keep[static_cast<std::size_t>(r)] = 1;
      }
    }
  }
  const auto p_kept = [&](FI f) { return f != Mesh::null_face() && p_keep[static_cast<std::size_t>(p_region[f])] != 0; };

  // Classify the blade's regions: votes at the constrained edges where exactly one P face is kept.
  std::vector<int> b_vote(static_cast<std::size_t>(b_regions), 0);  // +1 keep, -1 discard, 2 conflict
  {
    std::unordered_map<EdgeKey, HI, EdgeKeyHash> b_halfedge;
    for (const EI e : bmesh.edges()) {
      if (!b_constrained[e]) continue;
      for (const HI h : {bmesh.halfedge(e), bmesh.opposite(bmesh.halfedge(e))}) {
        b_halfedge.emplace(EdgeKey{PointKey(bmesh.point(bmesh.source(h))), PointKey(bmesh.point(bmesh.target(h)))}, h);
      }
    }
    const auto vote = [&](FI g, int v) {
      if (g == Mesh::null_face()) return;
      int& slot = b_vote[static_cast<std::size_t>(b_region[g])];
      if (slot == 0) slot = v;
      else if (slot != v) slot = 2;
    };
    for (const EI e : pmesh.edges()) {
      if (!p_constrained[e]) continue;
      const HI h = pmesh.halfedge(e);
      const HI o = pmesh.opposite(h);
      const bool kh = p_kept(pmesh.face(h)), ko = p_kept(pmesh.face(o));
      if (kh == ko) continue;
      const HI k = kh ? h : o;
      const auto it = b_halfedge.find(
          EdgeKey{PointKey(pmesh.point(pmesh.source(k))), PointKey(pmesh.point(pmesh.target(k)))});
      if (it == b_halfedge.end()) {
        throw CutFailure{"an intersection edge of surface triangle " + std::to_string(origin[pmesh.face(k)]) +
                         " has no twin on the blade"};
      }
      vote(bmesh.face(it->second), 1);
      vote(bmesh.face(bmesh.opposite(it->second)), -1);
    }
  }
  std::vector<char> b_keep(static_cast<std::size_t>(b_regions), 0);
  {
    const auto b_faces = faces_by_region(bmesh, b_region, b_regions);
    const std::vector<FI> rep = region_representatives(bmesh, b_region, b_regions);
    using Primitive = CGAL::AABB_face_graph_triangle_primitive<Mesh>;
    using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;
    std::optional<Tree> p_tree;
    for (int r = 0; r < b_regions; ++r) {
      const int v = b_vote[static_cast<std::size_t>(r)];
      if (v == 2) throw CutFailure{"blade region " + std::to_string(r) + " is both inside and outside the surface"};
      if (v != 0) {
        b_keep[static_cast<std::size_t>(r)] = v > 0 ? 1 : 0;
        continue;
      }
      // No vote: coplanar with P (every face centroid within eps of it) is discarded.
      const auto& faces = b_faces[static_cast<std::size_t>(r)];
      if (!patch.empty()) {
        if (!p_tree) p_tree.emplace(pmesh.faces().begin(), pmesh.faces().end(), pmesh);
        double d2 = p_tree->squared_distance(centroid(face_points(bmesh, rep[static_cast<std::size_t>(r)])));
        for (std::size_t i = 0; d2 <= eps2 && i < faces.size(); ++i) {
          d2 = std::max(d2, p_tree->squared_distance(centroid(face_points(bmesh, faces[i]))));
        }
        if (d2 <= eps2) continue;
      }
      // Otherwise inside or outside S by an exact ray test from a point inside one of its faces (several points are
      // tried when a ray grazes an edge or a vertex of S).
      static constexpr std::array<std::array<double, 3>, 3> kWeights{
          {{1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0}, {0.2913, 0.3527, 0.3560}, {0.6181, 0.2011, 0.1808}}};
      Side side = Side::degenerate;
      Point at(0.0, 0.0, 0.0);  // the point that decided
      std::vector<FI> tries{rep[static_cast<std::size_t>(r)]};
      for (std::size_t i = 0; i < faces.size() && tries.size() < 8; i += std::max<std::size_t>(1, faces.size() / 7)) {
        tries.push_back(faces[i]);
      }
      for (const FI f : tries) {
        for (const auto& w : kWeights) {
          const auto p = face_points(bmesh, f);
          const Point q(w[0] * p[0].x() + w[1] * p[1].x() + w[2] * p[2].x(),
                        w[0] * p[0].y() + w[1] * p[1].y() + w[2] * p[2].y(),
                        w[0] * p[0].z() + w[1] * p[1].z() + w[2] * p[2].z());
          if (!patch.empty() && p_tree->squared_distance(q) <= eps2) continue;
          side = point_in_surface(surface, grid, q);
          at = q;
          if (side == Side::inside || side == Side::outside) break;
        }
        if (side == Side::inside || side == Side::outside) break;
      }
      if (side != Side::inside && side != Side::outside) {
        throw CutFailure{"cannot decide whether blade region " + std::to_string(r) + " is inside the surface"};
      }
      b_keep[static_cast<std::size_t>(r)] =
          side == Side::inside && (!options.removable || options.removable(to_vec(at))) ? 1 : 0;
    }
  }

  // Nothing changes: every P region kept, every blade region discarded.
  const bool p_all_kept = std::all_of(p_keep.begin(), p_keep.end(), [](char k) { return k != 0; });
  const bool b_none_kept = std::none_of(b_keep.begin(), b_keep.end(), [](char k) { return k != 0; });
  if (p_all_kept && b_none_kept && gone.empty()) {
    result.status = SurfaceCutStatus::no_op;
    result.reason = "blade does not remove material from the surface (it misses it or only touches it)";
    return;
  }

  // From here on, P is the faces that change: the CGAL patch and the gone faces (which have no pieces).
  if (!gone.empty()) {
    std::vector<int32_t> all;
    all.reserve(patch.size() + gone.size());
    std::merge(patch.begin(), patch.end(), gone.begin(), gone.end(), std::back_inserter(all));
    patch.swap(all);
    patch_arcs = open_fans(surface, patch);
  }

  // Node ids: old vertex o -> o; new P vertex k (P index >= p_initial_vertices) -> nv + (k - p_initial); blade
  // vertex -> the P vertex with identical coordinates, else nv + n_new_p + its blade index.
  const auto n_p = static_cast<std::size_t>(pmesh.number_of_vertices());
  const auto n_new_p = static_cast<int32_t>(n_p - p_initial_vertices);
  std::vector<int32_t> p_node(n_p);
  std::unordered_map<PointKey, int32_t, PointKeyHash> node_at;
  node_at.reserve(n_p);
  for (std::size_t k = 0; k < n_p; ++k) {
    p_node[k] = k < p_initial_vertices ? p_old[k] : nv + static_cast<int32_t>(k - p_initial_vertices);
    node_at.emplace(PointKey(pmesh.point(VI(static_cast<Mesh::size_type>(k)))), p_node[k]);
  }
  const auto b_node = [&](VI v) {
    const auto it = node_at.find(PointKey(bmesh.point(v)));
    return it != node_at.end() ? it->second : nv + n_new_p + static_cast<int32_t>(v.idx());
  };

  // The kept pieces in node ids: P faces bucketed by the S face they lie in, then the reversed blade faces.
  std::vector<int> bucket_begin(patch.size() + 1, 0);
  std::vector<std::pair<Tri, int32_t>> p_pieces;  // (nodes, origin), grouped by patch position
  {
    std::vector<std::vector<Tri>> by_patch(patch.size());
    for (const FI f : pmesh.faces()) {
      if (!p_kept(f)) continue;
      const HI h = pmesh.halfedge(f);
      const Tri t{p_node[pmesh.source(h).idx()], p_node[pmesh.target(h).idx()],
                  p_node[pmesh.target(pmesh.next(h)).idx()]};
      const auto pos = std::lower_bound(patch.begin(), patch.end(), origin[f]) - patch.begin();
      by_patch[static_cast<std::size_t>(pos)].push_back(t);
    }
    for (std::size_t i = 0; i < patch.size(); ++i) {
      bucket_begin[i + 1] = bucket_begin[i] + static_cast<int>(by_patch[i].size());
      for (const Tri& t : by_patch[i]) p_pieces.emplace_back(t, patch[i]);
    }
  }
  std::vector<Tri> b_pieces;
  for (const FI f : bmesh.faces()) {
    if (!b_keep[static_cast<std::size_t>(b_region[f])]) continue;
    const HI h = bmesh.halfedge(f);
    b_pieces.push_back({b_node(bmesh.source(h)), b_node(bmesh.target(bmesh.next(h))), b_node(bmesh.target(h))});
  }
  result.blade_triangles_kept = static_cast<int>(b_pieces.size());

  // Which old P vertices survive; removed ones are those of P used by no kept piece.
  std::vector<char> used_old;  // indexed like p_old's distinct values, via a sorted list
  std::vector<int32_t> p_old_sorted(p_old.begin(), p_old.begin() + static_cast<std::ptrdiff_t>(p_initial_vertices));
  for (const int32_t f : gone) {
    for (const int32_t v : surface.triangles[static_cast<std::size_t>(f)]) p_old_sorted.push_back(v);
  }
  std::sort(p_old_sorted.begin(), p_old_sorted.end());
  p_old_sorted.erase(std::unique(p_old_sorted.begin(), p_old_sorted.end()), p_old_sorted.end());
  used_old.assign(p_old_sorted.size(), 0);
  std::vector<char> used_new(static_cast<std::size_t>(n_new_p) + bmesh.number_of_vertices(), 0);
  const auto mark = [&](const Tri& t) {
    for (const int32_t n : t) {
      if (n < nv) {
        const auto it = std::lower_bound(p_old_sorted.begin(), p_old_sorted.end(), n);
        if (it != p_old_sorted.end() && *it == n) used_old[static_cast<std::size_t>(it - p_old_sorted.begin())] = 1;
      } else {
        used_new[static_cast<std::size_t>(n - nv)] = 1;
      }
    }
  };
  for (const auto& [t, o] : p_pieces) mark(t);
  for (const Tri& t : b_pieces) mark(t);
  // A vertex of P is also kept when a face outside P uses it (P's boundary vertices always are).
  for (const auto& [v, arcs] : patch_arcs) {
    const auto it = std::lower_bound(p_old_sorted.begin(), p_old_sorted.end(), v);
    used_old[static_cast<std::size_t>(it - p_old_sorted.begin())] = 1;
  }
  for (std::size_t i = 0; i < p_old_sorted.size(); ++i) {
    if (!used_old[i]) result.removed_vertices.push_back(p_old_sorted[i]);
  }

  // The old triangles of P, their attributes and their share of the volume, read before anything is written.
  std::vector<Tri> old_tris(patch.size());
  std::vector<FaceAttributes> old_attributes(patch.size());
  double volume_before = 0.0, volume_after = 0.0;  // m^3, over the changed faces, relative to `centre`
  std::vector<char> whole(patch.size(), 0);  // per P face: kept whole (one piece with its own nodes): unchanged
  for (std::size_t pi = 0; pi < patch.size(); ++pi) {
    const Tri& t = surface.triangles[static_cast<std::size_t>(patch[pi])];
    old_tris[pi] = t;
    old_attributes[pi] = editor.attributes(patch[pi]);
    const int begin = bucket_begin[pi], end = bucket_begin[pi + 1];
    if (end - begin == 1) {
      const Tri& only = p_pieces[static_cast<std::size_t>(begin)].first;
      whole[pi] = only[0] < nv && only[1] < nv && only[2] < nv ? 1 : 0;
    }
    if (!whole[pi]) {
      volume_before += tet_volume(centre, surface.vertices[static_cast<std::size_t>(t[0])],
                                  surface.vertices[static_cast<std::size_t>(t[1])],
                                  surface.vertices[static_cast<std::size_t>(t[2])]);
    }
  }
  // The directed edges of the unchanged faces along P's boundary (vertex indices do not change in place).
  std::vector<std::array<int32_t, 2>> boundary_edges;
  if (options.verify) {
    std::vector<uint64_t> p_directed;  // sorted
    p_directed.reserve(old_tris.size() * 3);
    const auto key = directed_edge_key;
    for (const Tri& t : old_tris) {
      for (int k = 0; k < 3; ++k) p_directed.push_back(key(t[k], t[(k + 1) % 3]));
    }
    std::sort(p_directed.begin(), p_directed.end());
    for (const Tri& t : old_tris) {
      for (int k = 0; k < 3; ++k) {
        if (!std::binary_search(p_directed.begin(), p_directed.end(), key(t[(k + 1) % 3], t[k]))) {
          boundary_edges.push_back({t[(k + 1) % 3], t[k]});
        }
      }
    }
  }

  // From here on S is edited in place (the caller rolls the edits back when this throws). New vertices are appended:
  // the new P vertices, then the new blade vertices.
  std::vector<int32_t> new_to_out(used_new.size(), -1);
  std::vector<char> constructed_inserted;  // per inserted vertex: 1 for an intersection point (made by CGAL)
  const std::size_t blade_input_vertices = blade.vertices.size();
  for (std::size_t k = 0; k < used_new.size(); ++k) {
    if (!used_new[k]) continue;
    constructed_inserted.push_back(
        k < static_cast<std::size_t>(n_new_p) || k - static_cast<std::size_t>(n_new_p) >= blade_input_vertices ? 1 : 0);
    const Point p = k < static_cast<std::size_t>(n_new_p)
                        ? pmesh.point(VI(static_cast<Mesh::size_type>(p_initial_vertices + k)))
                        : bmesh.point(VI(static_cast<Mesh::size_type>(k - static_cast<std::size_t>(n_new_p))));
    new_to_out[k] = editor.add_vertex(to_vec(p));
  }
  const sim::TriMesh& out = editor.mesh();
  const auto out_index = [&](int32_t n) { return n < nv ? n : new_to_out[static_cast<std::size_t>(n - nv)]; };

  // The new triangles: each P face's kept pieces (which inherit its attributes), then the blade's. They fill P's
  // slots in order; the rest are appended, or the slots left over are removed (the last triangles move into them).
  std::vector<int32_t> changed;     // triangles built from the corefinement (P's pieces and the blade's)
  std::vector<char> changed_whole;  // per entry of `changed`: 1 for a face of S kept whole (not really changed)
  {
    std::size_t slot = 0;
    const auto place = [&](const Tri& n, FaceAttributes a, char kept_whole) {
      const Tri o{out_index(n[0]), out_index(n[1]), out_index(n[2])};
      int32_t f = 0;
      if (slot < patch.size()) {
        f = patch[slot++];
        editor.set_face(f, o, a);
      } else {
        f = editor.add_face(o, a);
      }
      changed.push_back(f);
      changed_whole.push_back(kept_whole);
      if (!kept_whole) {
        volume_after += tet_volume(centre, out.vertices[static_cast<std::size_t>(o[0])],
                                   out.vertices[static_cast<std::size_t>(o[1])],
                                   out.vertices[static_cast<std::size_t>(o[2])]);
      }
    };
    for (std::size_t pi = 0; pi < patch.size(); ++pi) {
      for (int k = bucket_begin[pi]; k < bucket_begin[pi + 1]; ++k) {
        place(p_pieces[static_cast<std::size_t>(k)].first, old_attributes[pi], whole[pi]);
      }
    }
    for (const Tri& n : b_pieces) place(n, FaceAttributes{1, -1}, 0);
    editor.remove_faces(std::span<const int32_t>(patch).subspan(slot));
  }
  result.removed_volume = volume_before - volume_after;

  if (options.verify) {
    verify_local(out, changed, boundary_edges, patch_arcs);
    // The unchanged neighbours: faces that are not changed and have a vertex on P's boundary (found in the grid,
    // which follows the edits: a face moved into a removed slot is found at its new index).
    std::vector<int32_t> changed_sorted = changed;
    std::sort(changed_sorted.begin(), changed_sorted.end());
    std::vector<int32_t> boundary_vertices;
    boundary_vertices.reserve(patch_arcs.size());
    for (const auto& [v, arcs] : patch_arcs) boundary_vertices.push_back(v);
    std::sort(boundary_vertices.begin(), boundary_vertices.end());
    std::vector<int32_t> neighbours;
    for (const int32_t v : boundary_vertices) {
      for (const int32_t f : grid.around(out, v)) {
        if (!std::binary_search(changed_sorted.begin(), changed_sorted.end(), f)) neighbours.push_back(f);
      }
    }
    std::sort(neighbours.begin(), neighbours.end());
    neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
    verify_self_intersections(out, changed, changed_whole, nv, constructed_inserted, neighbours);
  }
  result.status = SurfaceCutStatus::ok;
}

}  // namespace

SurfaceEditResult cut_surface_in_place(SurfaceEditor& editor, const sim::TriMesh& blade,
                                       const SurfaceCutOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t mark = editor.mark();
  SurfaceEditResult result;
  result.first_inserted = static_cast<int32_t>(editor.mesh().vertices.size());
  const auto fail = [&](std::string reason) {
    editor.rollback(mark);
    const int patch = result.patch_triangles;
    const int32_t first = result.first_inserted;
    result = SurfaceEditResult{};
    result.status = SurfaceCutStatus::failed;
    result.reason = std::move(reason);
    result.patch_triangles = patch;
    result.first_inserted = first;
  };
  try {
    cut(editor, blade, options, result);
  } catch (const CutFailure& e) {
    fail(e.reason);
  } catch (const std::exception& e) {
    fail(std::string("CGAL: ") + e.what());
  } catch (...) {
    fail("unknown exception");
  }
  result.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

namespace {

// Moves a blade by 1e-9 (attempt 1) or 1e-7 (attempt 2) of its bounding-box diagonal along a fixed generic direction.
sim::TriMesh perturbed(const sim::TriMesh& blade, int attempt) {
  const sim::Box3 bb = sim::bounds(blade);
  const Vec3 direction = Vec3(0.5377, 0.8314, 0.1410).normalized();
  const Vec3 shift = (attempt == 1 ? 1e-9 : 1e-7) * (bb.max - bb.min).norm() * direction;  // m
  sim::TriMesh moved = blade;
  for (Vec3& p : moved.vertices) p += shift;
  return moved;
}

// The retries of cut_surface_perturbing around any cut function of a blade.
template <class Result, class Cut>
std::pair<Result, int> perturbing(sim::TriMesh& blade, Cut&& cut_with) {
  Result first = cut_with(blade);
  if (first.status != SurfaceCutStatus::failed || blade.vertices.empty()) return {std::move(first), 0};
  for (int attempt = 1; attempt <= 2; ++attempt) {
    sim::TriMesh moved = perturbed(blade, attempt);
    Result again = cut_with(moved);
    if (again.status != SurfaceCutStatus::failed) {
      blade = std::move(moved);
      again.ms += first.ms;
      return {std::move(again), attempt};
    }
    first.ms += again.ms;
  }
  first.reason += " (also with the blade moved by 1e-9 and 1e-7 of its size)";
  return {std::move(first), 0};
}

}  // namespace

std::pair<SurfaceEditResult, int> cut_surface_in_place_perturbing(SurfaceEditor& editor, sim::TriMesh& blade,
                                                                  const SurfaceCutOptions& options) {
  return perturbing<SurfaceEditResult>(
      blade, [&](const sim::TriMesh& b) { return cut_surface_in_place(editor, b, options); });
}

SurfaceCutResult cut_surface(const sim::TriMesh& surface, const sim::TriMesh& blade, const SurfaceCutOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  SurfaceCutResult result;
  const auto elapsed = [&] {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  };
  // A copy of S with its grid (whose build checks S's coordinates and indices), edited in place, then compacted.
  sim::TriMesh work = surface;
  FaceGrid grid;
  try {
    grid.build(work);
  } catch (const std::invalid_argument& e) {
    result.status = SurfaceCutStatus::failed;
    result.reason = e.what();
    result.ms = elapsed();
    return result;
  }
  std::vector<int32_t> origin(surface.triangles.size());
  std::iota(origin.begin(), origin.end(), 0);
  SurfaceEditor editor(work, grid, nullptr, &origin);
  SurfaceEditResult e = cut_surface_in_place(editor, blade, options);
  result.status = e.status;
  result.reason = std::move(e.reason);
  result.removed_volume = e.removed_volume;
  result.patch_triangles = e.patch_triangles;
  result.blade_triangles_kept = e.blade_triangles_kept;
  if (e.status == SurfaceCutStatus::no_op) {
    result.mesh = surface;
    result.triangle_origin = std::move(origin);
  } else if (e.status == SurfaceCutStatus::ok) {
    result.removed_vertices.assign(e.removed_vertices.begin(), e.removed_vertices.end());
    std::vector<int32_t> old_to_new(work.vertices.size(), -1);
    std::size_t r = 0;
    int32_t next = 0;
    for (std::size_t v = 0; v < work.vertices.size(); ++v) {
      if (r < e.removed_vertices.size() && e.removed_vertices[r] == static_cast<int32_t>(v)) {
        ++r;
        continue;
      }
      old_to_new[v] = next++;
      result.mesh.vertices.push_back(work.vertices[v]);
    }
    result.inserted_vertices.assign(work.vertices.begin() + e.first_inserted, work.vertices.end());
    result.mesh.triangles = std::move(work.triangles);
    for (Tri& t : result.mesh.triangles) {
      for (int32_t& v : t) v = old_to_new[static_cast<std::size_t>(v)];
    }
    result.triangle_origin = std::move(origin);
  }
  result.ms = elapsed();
  return result;
}

std::pair<SurfaceCutResult, int> cut_surface_perturbing(const sim::TriMesh& surface, sim::TriMesh& blade,
                                                        const SurfaceCutOptions& options) {
  return perturbing<SurfaceCutResult>(blade, [&](const sim::TriMesh& b) { return cut_surface(surface, b, options); });
}

}  // namespace octocut::cutting
