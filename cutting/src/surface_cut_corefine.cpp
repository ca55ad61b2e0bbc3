// Phase 2 of the surface boolean S \ B' (surface_cut_phases.hpp): the exact blade, the classification of the clear
// faces, and the corefinement of the patch P with the blade and the classification of the pieces. The only translation
// unit of the boolean that builds CGAL meshes (the verification, surface_cut_verify.cpp, uses CGAL's predicates only).
//
//  - P is copied into a Surface_mesh and corefined with the blade (PMP::corefine, exact predicates), marking the
//    intersection edges as constrained and recording, through a visitor, which input face each piece lies in.
//  - P and the blade are cut into regions along the constrained edges. A P region is removed when a point inside it
//    is inside the blade (Side_of_triangle_mesh), taking the face centroid farthest from the blade; when every
//    centroid lies within 1e-9 x the blade's size of the blade (coplanar up to the rounding of constructed points),
//    it is removed when the normals of the input faces agree and kept when they are opposite (of the region's faces,
//    the one most nearly parallel to its closest blade face decides). A blade region is kept
//    (reversed) when, at a constrained edge where exactly one P face is kept, its halfedge runs in the same direction
//    as that P face's, and discarded when the opposite halfedge does; conflicting votes fail the cut. A region without
//    votes is discarded when it lies on P (coplanar), and otherwise kept when an exact ray-parity test (axis rays,
//    orientation predicates on S's input coordinates, retried on grazing rays) puts it inside S. Where
//    options.removable rejects a region's test point, a P region is kept and a blade region without votes is
//    discarded (the pipeline's restriction of B'_i to the material of component i).
//  Nothing is a pass over S: even the ray-parity test takes the faces from the grid cells along its ray.
#include "cgal_exact.hpp"  // first: the exact number type of Epeck

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/corefinement.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/AABB_face_graph_triangle_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/boost/graph/helpers.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "surface_cut_phases.hpp"

namespace octocut::cutting::surface_cut_detail {
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
using SideOfBlade = CGAL::Side_of_triangle_mesh<Mesh, Kernel>;
using FaceTree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, CGAL::AABB_face_graph_triangle_primitive<Mesh>>>;

Point to_point(const Vec3& p) { return {p.x(), p.y(), p.z()}; }
Vec3 to_vec(const Point& p) { return {p.x(), p.y(), p.z()}; }

// A directed edge by the coordinates of its ends.
struct EdgeKey {
  PointKey a, b;
  friend bool operator==(const EdgeKey&, const EdgeKey&) = default;
};
struct EdgeKeyHash {
  std::size_t operator()(const EdgeKey& k) const { return PointKeyHash{}(k.a) * 31 + PointKeyHash{}(k.b); }
};
EdgeKey edge_key(const Mesh& mesh, HI h) {
  return EdgeKey{PointKey(to_vec(mesh.point(mesh.source(h)))), PointKey(to_vec(mesh.point(mesh.target(h))))};
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

// P and the blade in phase 2, with their properties: the input face each face lies in (a face of S for P, of the
// blade for B), the constrained (intersection) edges, and each face's region.
struct Meshes {
  explicit Meshes(Mesh& blade) : b(blade) {}
  Meshes(const Meshes&) = delete;  // the property maps point into the meshes
  Meshes& operator=(const Meshes&) = delete;

  Mesh p;
  Mesh& b;
  Mesh::Property_map<FI, int32_t> p_origin, b_origin;
  Mesh::Property_map<EI, bool> p_constrained, b_constrained;
  Mesh::Property_map<FI, int> p_region, b_region;
  int p_regions = 0, b_regions = 0;
  std::size_t p_initial_vertices = 0;  // |Patch::vertices|
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

// The faces of each region (count), in face order.
std::vector<std::vector<FI>> faces_by_region(const Mesh& mesh, const Mesh::Property_map<FI, int>& region, int count) {
  std::vector<std::vector<FI>> out(static_cast<std::size_t>(count));
  for (const FI f : mesh.faces()) out[static_cast<std::size_t>(region[f])].push_back(f);
  return out;
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

// The normal (not unit, m^2) of input triangle f of `mesh`: exact inputs, unlike the pieces' own normals, which
// suffer from rounded vertices.
Vec3 input_normal(const sim::TriMesh& mesh, int32_t f) {
  const Tri& t = mesh.triangles[static_cast<std::size_t>(f)];
  return (mesh.vertices[static_cast<std::size_t>(t[1])] - mesh.vertices[static_cast<std::size_t>(t[0])])
      .cross(mesh.vertices[static_cast<std::size_t>(t[2])] - mesh.vertices[static_cast<std::size_t>(t[0])]);
}

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

// P copied into m.p (its local vertices, then its faces, each face's origin the face of S it copies), the blade's
// faces (m.b) given their own indices as origins, and the constrained-edge maps added to both.
void copy_patch(const sim::TriMesh& surface, const Patch& patch, Meshes& m) {
  for (const int32_t v : patch.vertices) m.p.add_vertex(to_point(surface.vertices[static_cast<std::size_t>(v)]));
  m.p_origin = m.p.add_property_map<FI, int32_t>("f:origin", -1).first;
  for (std::size_t i = 0; i < patch.faces.size(); ++i) {
    const Tri& t = patch.triangles[i];
    const auto v = [&](int k) { return VI(static_cast<Mesh::size_type>(t[static_cast<std::size_t>(k)])); };
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] ||
        CGAL::collinear(m.p.point(v(0)), m.p.point(v(1)), m.p.point(v(2)))) {
      throw CutFailure{"surface triangle " + std::to_string(patch.faces[i]) + " is degenerate"};
    }
    const FI f = m.p.add_face(v(0), v(1), v(2));
    if (f == Mesh::null_face()) {
      throw CutFailure{"surface triangle " + std::to_string(patch.faces[i]) + " makes the surface non-manifold"};
    }
    m.p_origin[f] = patch.faces[i];
  }
  m.p_initial_vertices = static_cast<std::size_t>(m.p.number_of_vertices());
  m.b_origin = m.b.add_property_map<FI, int32_t>("f:origin", -1).first;
  for (const FI f : m.b.faces()) m.b_origin[f] = static_cast<int32_t>(f.idx());
  m.p_constrained = m.p.add_property_map<EI, bool>("e:constrained", false).first;
  m.b_constrained = m.b.add_property_map<EI, bool>("e:constrained", false).first;
}

// Corefines P with the blade (the intersection edges become constrained in both, the pieces keep their faces'
// origins), checks that the rounded intersection points are finite, and labels the regions of both meshes.
void corefine(Meshes& m, const SurfaceCutOptions& options) {
  if (m.p.number_of_faces() > 0) {  // P is not empty
    OriginVisitor visitor;
    visitor.patch = &m.p;
    visitor.origin = &m.p_origin;
    visitor.b_origin = &m.b_origin;
    PMP::corefine(m.p, m.b,
                  PMP::parameters::edge_is_constrained_map(m.p_constrained)
                      .visitor(visitor)
                      .throw_on_self_intersection(options.check_surface_self_intersection),
                  PMP::parameters::edge_is_constrained_map(m.b_constrained));
  }
  // The intersection points, rounded from their exact values, must be finite (a defect of the exact number type's
  // conversion would show here first).
  for (const Mesh* mesh : {&m.p, &m.b}) {
    for (const VI v : mesh->vertices()) {
      const Point& p = mesh->point(v);
      if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
        throw CutFailure{"an intersection point is not finite"};
      }
    }
  }
  m.p_region = m.p.add_property_map<FI, int>("f:region", -1).first;
  m.b_region = m.b.add_property_map<FI, int>("f:region", -1).first;
  m.p_regions = label_regions(m.p, m.p_constrained, m.p_region);
  m.b_regions = label_regions(m.b, m.b_constrained, m.b_region);
}

// Whether each region of P is kept (p_regions): those outside the blade; a region on the blade (every face centroid
// within eps, eps2 = eps^2 in m^2) is coplanar with a blade face and goes when the normals agree. The face farthest
// from the blade decides. Material that options.removable protects stays.
std::vector<char> classify_patch_regions(const Meshes& m, const sim::TriMesh& surface, const sim::TriMesh& blade,
                                         double eps2, const SurfaceCutOptions& options) {
  std::vector<char> p_keep(static_cast<std::size_t>(m.p_regions), 1);
  if (m.p_regions == 0) return p_keep;
  const SideOfBlade::AABB_tree b_tree(m.b.faces().begin(), m.b.faces().end(), m.b);
  const SideOfBlade inside_blade(b_tree);
  const auto p_faces = faces_by_region(m.p, m.p_region, m.p_regions);
  const std::vector<FI> rep = region_representatives(m.p, m.p_region, m.p_regions);
  for (int r = 0; r < m.p_regions; ++r) {
    const auto& faces = p_faces[static_cast<std::size_t>(r)];
    Point q = centroid(face_points(m.p, rep[static_cast<std::size_t>(r)]));
    double d2 = b_tree.squared_distance(q);
    for (std::size_t i = 0; d2 <= eps2 && i < faces.size(); ++i) {
      const Point c = centroid(face_points(m.p, faces[i]));
      const double e2 = b_tree.squared_distance(c);
      if (e2 > d2) {
        d2 = e2;
        q = c;
      }
    }
    char& keep = p_keep[static_cast<std::size_t>(r)];
    if (d2 > eps2) {
      keep = inside_blade(q) == CGAL::ON_BOUNDED_SIDE ? 0 : 1;
    } else {
      // On the blade: the region goes when it faces the way the blade face it lies on does. The face pair that
      // decides is the region's face most nearly parallel to its closest blade face: a sliver of the region along a
      // crease of the blade (a floor face whose centroid lies on the blade's wall) is perpendicular to its closest
      // blade face, and the sign of that product would be rounding noise.
      double best = -1.0, product = 0.0;
      for (const FI f : faces) {
        const FI g = b_tree.closest_point_and_primitive(centroid(face_points(m.p, f))).second;
        const Vec3 a = input_normal(surface, m.p_origin[f]), b = input_normal(blade, m.b_origin[g]);
        const double cosine = std::abs(a.dot(b)) / (a.norm() * b.norm());
        if (cosine > best) best = cosine, product = a.dot(b);
      }
      keep = product > 0.0 ? 0 : 1;
    }
    if (!keep && options.removable && !options.removable(to_vec(q))) keep = 1;
  }
  return p_keep;
}

// The votes on the blade's regions (b_regions: +1 keep, -1 discard, 2 conflict, 0 none) at the constrained edges
// where exactly one P face is kept (`p_keep` per P region): the blade region whose halfedge runs along the kept P
// face's is kept, the one across it discarded.
std::vector<int> vote_blade_regions(const Meshes& m, const std::vector<char>& p_keep) {
  std::vector<int> b_vote(static_cast<std::size_t>(m.b_regions), 0);
  std::unordered_map<EdgeKey, HI, EdgeKeyHash> b_halfedge;
  for (const EI e : m.b.edges()) {
    if (!m.b_constrained[e]) continue;
    for (const HI h : {m.b.halfedge(e), m.b.opposite(m.b.halfedge(e))}) b_halfedge.emplace(edge_key(m.b, h), h);
  }
  const auto p_kept = [&](FI f) {
    return f != Mesh::null_face() && p_keep[static_cast<std::size_t>(m.p_region[f])] != 0;
  };
  const auto vote = [&](FI g, int v) {
    if (g == Mesh::null_face()) return;
    int& slot = b_vote[static_cast<std::size_t>(m.b_region[g])];
    if (slot == 0) slot = v;
    else if (slot != v) slot = 2;
  };
  for (const EI e : m.p.edges()) {
    if (!m.p_constrained[e]) continue;
    const HI h = m.p.halfedge(e);
    const HI o = m.p.opposite(h);
    const bool kh = p_kept(m.p.face(h)), ko = p_kept(m.p.face(o));
    if (kh == ko) continue;
    const HI k = kh ? h : o;
    const auto it = b_halfedge.find(edge_key(m.p, k));
    if (it == b_halfedge.end()) {
      throw CutFailure{"an intersection edge of surface triangle " + std::to_string(m.p_origin[m.p.face(k)]) +
                       " has no twin on the blade"};
    }
    vote(m.b.face(it->second), 1);
    vote(m.b.face(m.b.opposite(it->second)), -1);
  }
  return b_vote;
}

// A blade region without votes (`faces`, `rep` its largest) inside or outside S, by an exact ray test from a point
// inside one of its faces; several points are tried when a ray grazes an edge or a vertex of S. Points within eps of
// P (eps2 = eps^2, m^2; p_tree: P's faces, null when P is empty) are skipped. `at` becomes the point that decided.
Side blade_region_side(const Mesh& b, const std::vector<FI>& faces, FI rep, const sim::TriMesh& surface,
                       FaceGrid& grid, const FaceTree* p_tree, double eps2, Point& at) {
  static constexpr std::array<std::array<double, 3>, 3> kWeights{
      {{1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0}, {0.2913, 0.3527, 0.3560}, {0.6181, 0.2011, 0.1808}}};
  Side side = Side::degenerate;
  std::vector<FI> tries{rep};
  for (std::size_t i = 0; i < faces.size() && tries.size() < 8; i += std::max<std::size_t>(1, faces.size() / 7)) {
    tries.push_back(faces[i]);
  }
  for (const FI f : tries) {
    for (const auto& w : kWeights) {
      const auto p = face_points(b, f);
      const Point q(w[0] * p[0].x() + w[1] * p[1].x() + w[2] * p[2].x(),
                    w[0] * p[0].y() + w[1] * p[1].y() + w[2] * p[2].y(),
                    w[0] * p[0].z() + w[1] * p[1].z() + w[2] * p[2].z());
      if (p_tree != nullptr && p_tree->squared_distance(q) <= eps2) continue;
      side = point_in_surface(surface, grid, q);
      at = q;
      if (side == Side::inside || side == Side::outside) return side;
    }
  }
  return side;
}

// Whether each region of the blade is kept (b_regions): by its votes (`b_vote`); without votes, discarded when it
// lies on P (every face centroid within eps, eps2 = eps^2 in m^2), else kept when inside S and removable there.
// Conflicting votes count as none.
std::vector<char> classify_blade_regions(const Meshes& m, const std::vector<int>& b_vote, const sim::TriMesh& surface,
                                         FaceGrid& grid, double eps2, const SurfaceCutOptions& options) {
  std::vector<char> b_keep(static_cast<std::size_t>(m.b_regions), 0);
  const auto b_faces = faces_by_region(m.b, m.b_region, m.b_regions);
  const std::vector<FI> rep = region_representatives(m.b, m.b_region, m.b_regions);
  const bool patch_empty = m.p.number_of_faces() == 0;
  std::optional<FaceTree> p_tree;  // built at the first region without votes
  for (int r = 0; r < m.b_regions; ++r) {
    // Conflicting votes (the rounding of the intersection points can pair a constrained edge with the wrong
    // blade halfedge, or tip a sliver region of P to the wrong side) are decided like no votes, by the region's own
    // exact ray test; a result that then does not close up fails the verification.
    const int v = b_vote[static_cast<std::size_t>(r)];
    if (v == 1 || v == -1) {
      b_keep[static_cast<std::size_t>(r)] = v > 0 ? 1 : 0;
      continue;
    }
    // No vote: coplanar with P (every face centroid within eps of it) is discarded.
    const auto& faces = b_faces[static_cast<std::size_t>(r)];
    if (!patch_empty) {
      if (!p_tree) p_tree.emplace(m.p.faces().begin(), m.p.faces().end(), m.p);
      double d2 = p_tree->squared_distance(centroid(face_points(m.b, rep[static_cast<std::size_t>(r)])));
      for (std::size_t i = 0; d2 <= eps2 && i < faces.size(); ++i) {
        d2 = std::max(d2, p_tree->squared_distance(centroid(face_points(m.b, faces[i]))));
      }
      if (d2 <= eps2) continue;
    }
    Point at(0.0, 0.0, 0.0);
    const Side side = blade_region_side(m.b, faces, rep[static_cast<std::size_t>(r)], surface, grid,
                                        p_tree ? &*p_tree : nullptr, eps2, at);
    if (side != Side::inside && side != Side::outside) {
      throw CutFailure{"cannot decide whether blade region " + std::to_string(r) + " is inside the surface"};
    }
    b_keep[static_cast<std::size_t>(r)] =
        side == Side::inside && (!options.removable || options.removable(to_vec(at))) ? 1 : 0;
  }
  return b_keep;
}

// The kept pieces of both meshes and their vertices, as plain arrays.
Corefinement kept_pieces(const Meshes& m, const std::vector<char>& p_keep, const std::vector<char>& b_keep) {
  Corefinement c;
  const auto index = [](VI v) { return static_cast<int32_t>(v.idx()); };
  c.p_points.reserve(m.p.number_of_vertices());
  for (Mesh::size_type k = 0; k < m.p.number_of_vertices(); ++k) c.p_points.push_back(to_vec(m.p.point(VI(k))));
  c.b_points.reserve(m.b.number_of_vertices());
  for (Mesh::size_type k = 0; k < m.b.number_of_vertices(); ++k) c.b_points.push_back(to_vec(m.b.point(VI(k))));
  for (const FI f : m.p.faces()) {
    if (!p_keep[static_cast<std::size_t>(m.p_region[f])]) continue;
    const HI h = m.p.halfedge(f);
    c.p_pieces.push_back({index(m.p.source(h)), index(m.p.target(h)), index(m.p.target(m.p.next(h)))});
    c.p_origin.push_back(m.p_origin[f]);
  }
  for (const FI f : m.b.faces()) {
    if (!b_keep[static_cast<std::size_t>(m.b_region[f])]) continue;
    const HI h = m.b.halfedge(f);
    c.b_pieces.push_back({index(m.b.source(h)), index(m.b.target(m.b.next(h))), index(m.b.target(h))});
  }
  const bool p_all_kept = std::all_of(p_keep.begin(), p_keep.end(), [](char k) { return k != 0; });
  const bool b_none_kept = std::none_of(b_keep.begin(), b_keep.end(), [](char k) { return k != 0; });
  c.changes = !(p_all_kept && b_none_kept);
  return c;
}

}  // namespace

struct ExactBlade {
  Mesh mesh;  // the blade: closed, manifold, outward oriented, free of self-intersections
};

void ExactBladeDelete::operator()(ExactBlade* blade) const noexcept { delete blade; }

ExactBladePtr make_exact_blade(const sim::TriMesh& blade, const SurfaceCutOptions& options) {
  ExactBladePtr exact(new ExactBlade);
  Mesh& bmesh = exact->mesh;
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
  return exact;
}

std::vector<int32_t> faces_inside_blade(const sim::TriMesh& surface, const ClearFaces& clear, const ExactBlade& blade,
                                        const SurfaceCutOptions& options) {
  std::vector<int32_t> gone;
  if (clear.faces.empty()) return gone;
  const Mesh& bmesh = blade.mesh;
  const SideOfBlade::AABB_tree tree(bmesh.faces().begin(), bmesh.faces().end(), bmesh);
  const SideOfBlade inside_blade(tree);
  std::vector<char> side(clear.group_vertex.size(), 0);  // per group: 1 inside (goes), 2 outside (stays)
  for (std::size_t i = 0; i < clear.faces.size(); ++i) {
    const auto g = static_cast<std::size_t>(clear.group[i]);
    if (side[g] == 0) {
      const int32_t v = clear.group_vertex[g];
      const Vec3& at = surface.vertices[static_cast<std::size_t>(v)];
      const CGAL::Bounded_side b = inside_blade(to_point(at));
      if (b == CGAL::ON_BOUNDARY) {
        throw CutFailure{"surface vertex " + std::to_string(v) +
                         " lies on the blade although its faces were found clear of it"};
      }
      // Inside, but where the caller does not let this blade remove material, the group stays.
      side[g] = b == CGAL::ON_BOUNDED_SIDE && (!options.removable || options.removable(at)) ? 1 : 2;
    }
    if (side[g] == 1) gone.push_back(clear.faces[i]);
  }
  return gone;
}

int point_in_solid(const sim::TriMesh& surface, FaceGrid& grid, const sim::Vec3& q) {
  const Side side = point_in_surface(surface, grid, to_point(q));
  return side == Side::inside ? 1 : (side == Side::outside ? 0 : -1);
}

Corefinement corefine_and_classify(const sim::TriMesh& surface, FaceGrid& grid, const sim::TriMesh& blade,
                                   ExactBlade& exact, const Patch& patch, const BladeBox& g,
                                   const SurfaceCutOptions& options) {
  Meshes m(exact.mesh);
  copy_patch(surface, patch, m);
  corefine(m, options);
  // Distances below eps are rounding of the constructed intersection points (coordinates are rounded to doubles,
  // about 1e-16 relative); such a region is taken as coplanar with the other mesh.
  const double eps2 = std::pow(1e-9 * (g.hi - g.lo).norm(), 2);  // m^2
  const std::vector<char> p_keep = classify_patch_regions(m, surface, blade, eps2, options);
  const std::vector<int> b_vote = vote_blade_regions(m, p_keep);
  const std::vector<char> b_keep = classify_blade_regions(m, b_vote, surface, grid, eps2, options);
  return kept_pieces(m, p_keep, b_keep);
}

}  // namespace octocut::cutting::surface_cut_detail
