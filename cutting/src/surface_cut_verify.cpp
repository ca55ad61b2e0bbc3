// Phase 4 of the surface boolean S \ B' (surface_cut_phases.hpp): the local verification of S' after the write-back.
// Uses CGAL's exact predicates (collinearity, triangle intersections) and its box intersection, but builds no CGAL
// mesh. Nothing is a pass over S: the unchanged neighbours of the changed faces come from the grid.
#include "cgal_exact.hpp"  // first: the exact number type of Epeck

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <iterator>
#include <limits>
#include <map>
#include <tuple>
#include <unordered_map>
#include <string>
#include <utility>
#include <vector>

#include "octocut/sim/disjoint_sets.hpp"
#include "surface_cut_phases.hpp"

namespace octocut::cutting::surface_cut_detail {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using sim::Vec3;

Point to_point(const Vec3& p) { return {p.x(), p.y(), p.z()}; }

// The changed triangles (indices into out.triangles) have finite vertices and are not degenerate (two equal indices,
// or three exactly collinear points).
void check_changed_triangles(const sim::TriMesh& out, const std::vector<int32_t>& changed) {
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
}

// The changed triangles with the directed edges of the unchanged faces around them (`boundary_edges`) are closed,
// edge-manifold and oriented: every directed edge once, and its reverse once (a sorted list of the directed edges;
// the first offender in that order is reported).
void check_edges(const sim::TriMesh& out, const std::vector<int32_t>& changed,
                 const std::vector<std::array<int32_t, 2>>& boundary_edges) {
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
}

// Vertex-manifold: around each vertex, the changed faces form one closed fan (inside the patch) or as many open fans
// as the patch had there (`arcs`, on its boundary, where the unchanged faces close the ring).
void check_vertex_fans(const sim::TriMesh& out, const std::vector<int32_t>& changed, const FanCounts& arcs) {
  std::vector<std::pair<int32_t, int32_t>> corners;  // (vertex, triangle)
  corners.reserve(changed.size() * 3);
  for (const int32_t f : changed) {
    for (const int32_t v : out.triangles[static_cast<std::size_t>(f)]) corners.emplace_back(v, f);
  }
  std::sort(corners.begin(), corners.end());
  for (std::size_t i = 0; i < corners.size();) {
    std::size_t j = i;
    while (j < corners.size() && corners[j].first == corners[i].first) ++j;
    const int32_t v = corners[i].first;
    const auto n = static_cast<int32_t>(j - i);
    // step 1: the vertex after v in the corner's triangle; step 2: the vertex before it.
    const auto next_of = [&](std::size_t c, int step) {
      const Tri& t = out.triangles[static_cast<std::size_t>(corners[c].second)];
      const int k = t[0] == v ? 0 : (t[1] == v ? 1 : 2);
      return t[static_cast<std::size_t>((k + step) % 3)];
    };
    sim::DisjointSets fans(static_cast<std::size_t>(n));
    int components = n;
    int open_ends = 0;
    for (int32_t a = 0; a < n; ++a) {
      const int32_t out_a = next_of(i + static_cast<std::size_t>(a), 1);
      bool matched = false;
      for (int32_t b = 0; b < n; ++b) {
        if (b == a || next_of(i + static_cast<std::size_t>(b), 2) != out_a) continue;
        matched = true;
        if (fans.find(a) != fans.find(b)) {
          fans.unite(a, b);
          --components;
        }
      }
      if (!matched) ++open_ends;
    }
    const auto it = arcs.find(v);
    const int expected_arcs = it == arcs.end() ? 0 : it->second;
    const bool good = expected_arcs == 0 ? (components == 1 && open_ends == 0)
                                         : (components == expected_arcs && open_ends == expected_arcs);
    if (!good) {
      throw CutFailure{"result vertex " + std::to_string(v) + " is not manifold (" + std::to_string(components) +
                       " fans of changed faces, " + std::to_string(open_ends) + " open)"};
    }
    i = j;
  }
}

// The orientation of the 2D points a, b, c (doubles, exact inputs): decided in plain doubles when Shewchuk's error
// bound for orient2d (ccwerrboundA) proves the sign, else by CGAL's exact predicate.
CGAL::Orientation orientation_2(const Kernel::Point_2& a, const Kernel::Point_2& b, const Kernel::Point_2& c) {
  constexpr double kEps = std::numeric_limits<double>::epsilon() / 2.0;  // 2^-53
  constexpr double kBound = (3.0 + 16.0 * kEps) * kEps;
  const double left = (a.x() - c.x()) * (b.y() - c.y());
  const double right = (a.y() - c.y()) * (b.x() - c.x());
  const double det = left - right;
  const double bound = kBound * (std::abs(left) + std::abs(right));
  if (det > bound) return CGAL::LEFT_TURN;
  if (-det > bound) return CGAL::RIGHT_TURN;
  return CGAL::orientation(a, b, c);
}

// CGAL::orientation(p, q, r, s) (the sign of det[q - p, r - p, s - p]), decided in plain doubles when Shewchuk's error
// bound for orient3d (o3derrboundA) proves the sign, else by CGAL's exact predicate. Shewchuk's determinant
// det[p - s, q - s, r - s] has the opposite sign.
CGAL::Orientation orientation_3(const Point& p, const Point& q, const Point& r, const Point& s) {
  constexpr double kEps = std::numeric_limits<double>::epsilon() / 2.0;  // 2^-53
  constexpr double kBound = (7.0 + 56.0 * kEps) * kEps;
  const double adx = p.x() - s.x(), bdx = q.x() - s.x(), cdx = r.x() - s.x();
  const double ady = p.y() - s.y(), bdy = q.y() - s.y(), cdy = r.y() - s.y();
  const double adz = p.z() - s.z(), bdz = q.z() - s.z(), cdz = r.z() - s.z();
  const double bdxcdy = bdx * cdy, cdxbdy = cdx * bdy;
  const double cdxady = cdx * ady, adxcdy = adx * cdy;
  const double adxbdy = adx * bdy, bdxady = bdx * ady;
  const double det = adz * (bdxcdy - cdxbdy) + bdz * (cdxady - adxcdy) + cdz * (adxbdy - bdxady);
  const double permanent = (std::abs(bdxcdy) + std::abs(cdxbdy)) * std::abs(adz) +
                           (std::abs(cdxady) + std::abs(adxcdy)) * std::abs(bdz) +
                           (std::abs(adxbdy) + std::abs(bdxady)) * std::abs(cdz);
  const double bound = kBound * permanent;
  if (det > bound) return CGAL::NEGATIVE;
  if (-det > bound) return CGAL::POSITIVE;
  return CGAL::orientation(p, q, r, s);
}

// A sufficient, exact test that triangles s and t meet at most in the vertices they share (by id) and in an edge they
// share: projected along the axis that s's normal (in doubles) leans on most, with an exact 2D orientation, some
// edge line of one triangle has that triangle's third corner strictly on one side and every corner of the other
// strictly on the other side or on the edge itself (a shared corner of it). The projections then meet only in
// shared corners or the shared edge, and since the first triangle projects one to one, a common point of the two
// triangles is such a corner or lies on that edge. Dropping a coordinate is exact, so the answer is exact whatever
// the axis; pieces of one face of S or of one blade facet, nearly coplanar after rounding, end here instead of in
// the exact arithmetic of the 3D predicates. False says nothing.
template <class Pos>
bool separated_in_projection(const Pos& P, const Tri& s, const Tri& t) {
  using Point2 = Kernel::Point_2;
  const Point a = P(s[0]), b = P(s[1]), c = P(s[2]);
  const Vec3 n = Vec3(b.x() - a.x(), b.y() - a.y(), b.z() - a.z())
                     .cross(Vec3(c.x() - a.x(), c.y() - a.y(), c.z() - a.z()))
                     .cwiseAbs();
  const int axis = n.x() >= n.y() && n.x() >= n.z() ? 0 : (n.y() >= n.z() ? 1 : 2);
  const auto drop = [&](int32_t id) {
    const Point p = P(id);
    return axis == 0 ? Point2(p.y(), p.z()) : (axis == 1 ? Point2(p.z(), p.x()) : Point2(p.x(), p.y()));
  };
  const std::array<Point2, 3> sp{drop(s[0]), drop(s[1]), drop(s[2])};
  const std::array<Point2, 3> tp{drop(t[0]), drop(t[1]), drop(t[2])};
  const auto separates = [](const Tri& x, const std::array<Point2, 3>& xp, const Tri& y,
                            const std::array<Point2, 3>& yp) {
    for (int k = 0; k < 3; ++k) {
      const int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
      const CGAL::Orientation own = orientation_2(xp[k], xp[k1], xp[k2]);
      if (own == CGAL::COLLINEAR) return false;  // x projects onto a segment: no edge line separates
      bool all = true;
      for (int j = 0; j < 3 && all; ++j) {
        if (y[j] == x[k] || y[j] == x[k1]) continue;
        all = orientation_2(xp[k], xp[k1], yp[j]) == -own;
      }
      if (all) return true;
    }
    return false;
  };
  return separates(s, sp, t, tp) || separates(t, tp, s, sp);
}

// Whether two triangles intersect other than in a shared vertex or a shared edge (the rules of
// PMP::self_intersections, on vertex ids; P(id) gives a vertex's point).
template <class Pos>
bool ids_intersect(const Pos& P, const Tri& s, const Tri& t) {
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
  if (separated_in_projection(P, s, t)) return false;
  if (shared == 2) {
    // Shared edge (a, b): they overlap when the four points are coplanar and the third vertices lie on one side.
    const int sc = 3 - si[0] - si[1];
    const int tc = 3 - ti[0] - ti[1];
    const Point a = P(s[si[0]]), b = P(s[si[1]]), c = P(s[sc]), d = P(t[tc]);
    // Not coplanar: the two planes meet in the line of the shared edge, so the triangles meet in that edge alone.
    if (orientation_3(a, b, c, d) != CGAL::COPLANAR) return false;
    // A triangle whose third corner lies on the line of the shared edge is a segment on that line: it meets the other
    // triangle (which touches that line only along the edge) in the shared edge alone. (Degenerate triangles are
    // reported by their own test; coplanar_orientation requires a, b, c not collinear.)
    if (CGAL::collinear(a, b, c) || CGAL::collinear(a, b, d)) return false;
    return CGAL::coplanar_orientation(a, b, c, d) == CGAL::POSITIVE;  // coplanar: decided exactly above
  }
  if (shared == 1) {
    // Shared vertex v: when the other two corners of one triangle lie strictly on one side of the other's plane, the
    // first meets that plane (so the other triangle) in v alone. Most neighbours end here, with two orientations.
    const int i = si[0], j = ti[0];
    const Point v = P(s[i]), s1 = P(s[(i + 1) % 3]), s2 = P(s[(i + 2) % 3]);
    const Point t1 = P(t[(j + 1) % 3]), t2 = P(t[(j + 2) % 3]);
    const CGAL::Orientation a = orientation_3(v, s1, s2, t1);
    if (a != CGAL::COPLANAR && a == orientation_3(v, s1, s2, t2)) return false;
    const CGAL::Orientation b = orientation_3(v, t1, t2, s1);
    if (b != CGAL::COPLANAR && b == orientation_3(v, t1, t2, s2)) return false;
  }
  // A degenerate triangle (collinear corners) is reported by the degenerate test, not as an intersection; CGAL's
  // triangle predicates below require non-degenerate triangles (a debug build asserts it).
  const auto flat = [&](const Tri& x) { return CGAL::collinear(P(x[0]), P(x[1]), P(x[2])); };
  if (flat(s) || flat(t)) return false;
  const Kernel::Triangle_3 ts(P(s[0]), P(s[1]), P(s[2]));
  const Kernel::Triangle_3 tt(P(t[0]), P(t[1]), P(t[2]));
  if (shared == 1) {
    // Otherwise they intersect when the edge opposite v in one triangle meets the other triangle.
    const int i = si[0], j = ti[0];
    const Kernel::Segment_3 es(P(s[(i + 1) % 3]), P(s[(i + 2) % 3]));
    const Kernel::Segment_3 et(P(t[(j + 1) % 3]), P(t[(j + 2) % 3]));
    return CGAL::do_intersect(ts, et) || CGAL::do_intersect(tt, es);
  }
  return CGAL::do_intersect(ts, tt);
}

// Whether two triangles of the output mesh intersect other than in a shared vertex or a shared edge.
bool triangles_intersect(const sim::TriMesh& m, const Tri& s, const Tri& t) {
  return ids_intersect([&](int32_t i) { return to_point(m.vertices[static_cast<std::size_t>(i)]); }, s, t);
}

// ---- Phase 3a: the rounding repair ----

// The state of repair_rounding: the pieces, which pieces each node is in, and S's faces near a box.
class Repair {
 public:
  Repair(PieceMesh& mesh, FaceGrid& grid, double tiny_edge)
      : m_(mesh), grid_(grid), tiny_(tiny_edge), tiny2_(tiny_edge * tiny_edge) {
    for (std::size_t t = 0; t < m_.tris.size(); ++t) {
      // Where two exact nodes rounded to one point (one node), the rounding collapsed the edge between them: the
      // pieces along that edge, now with a node twice, vanish as they do in a collapse.
      const Tri& x = m_.tris[t];
      if (x[0] == x[1] || x[1] == x[2] || x[0] == x[2]) {
        m_.alive[t] = 0;
        ++merged_;
      }
      if (!m_.alive[t]) continue;
      for (const int32_t n : m_.tris[t]) around_[n].push_back(static_cast<int32_t>(t));
    }
    if (tiny_edge > 0.0) drop_double_covers();
    build_piece_grid();
  }

  // Rounds of detection and collapses until nothing is found (the number of collapses), or a defect is left. The
  // first round checks every piece with a new node; a later one only the pieces that the last round moved or left
  // bad: two pieces neither of which changed since a round that found neither bad still do not intersect.
  int run() {
    int collapses = merged_;
    collapses += merge_ulp_pairs();
    std::vector<char> dirty;  // (|tris|) the pieces to check this round; empty: all
    std::vector<int32_t> bad;
    for (int round = 0; round < 16; ++round) {
      bad = detect(dirty);
      if (bad.empty()) return collapses;
      moved_.assign(m_.tris.size(), 0);
      int made = 0;
      for (const int32_t t : bad) {
        if (m_.alive[static_cast<std::size_t>(t)] && is_bad(t) && mend(t)) ++made;
      }
      if (made == 0) break;
      collapses += made;
      dirty = moved_;
      for (const int32_t t : bad) dirty[static_cast<std::size_t>(t)] = 1;
    }
    // Tiny edges and narrow pieces that no collapse can take are left; a defect is not.
    for (const int32_t t : bad) {
      if (m_.alive[static_cast<std::size_t>(t)] && defect(t)) {
        throw CutFailure{"result piece " + std::to_string(t) +
                         " is degenerate or intersects another after rounding, and no collapse mends it"};
      }
    }
    return collapses;
  }

 private:
  Point P(int32_t n) const { return to_point(m_.point(n)); }
  bool is_new(int32_t n) const { return n >= m_.nv; }
  bool changing(int32_t f) const { return std::binary_search(m_.changing->begin(), m_.changing->end(), f); }
  const Tri& tri(int32_t t) const { return m_.tris[static_cast<std::size_t>(t)]; }

  std::array<Vec3, 2> box_of(const Tri& t) const {
    const Vec3 &a = m_.point(t[0]), &b = m_.point(t[1]), &c = m_.point(t[2]);
    return {a.cwiseMin(b).cwiseMin(c), a.cwiseMax(b).cwiseMax(c)};
  }
  static bool overlap(const std::array<Vec3, 2>& x, const std::array<Vec3, 2>& y) {
    return (x[0].array() <= y[1].array()).all() && (y[0].array() <= x[1].array()).all();
  }

  bool degenerate(const Tri& t) const {
    return t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || CGAL::collinear(P(t[0]), P(t[1]), P(t[2]));
  }
  // An edge at a new node shorter than the tiny edge.
  bool tiny(const Tri& t) const {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = t[k], b = t[(k + 1) % 3];
      if ((is_new(a) || is_new(b)) && (m_.point(a) - m_.point(b)).squaredNorm() < tiny2_) return true;
    }
    return false;
  }
  // Whether triangle `t` (node ids, not necessarily a piece) intersects a live piece other than those of `skip`, or a
  // face of S that the pieces do not replace.
  bool intersects_any(const Tri& t, const std::vector<int32_t>& skip) const {
    const auto box = box_of(t);
    const auto pos = [&](int32_t n) { return P(n); };
    ++stamp_;
    bool hit = false;
    for_cells(box, [&](std::size_t cell) {
      for (const int32_t u : cells_[cell]) {
        if (hit || seen_[static_cast<std::size_t>(u)] == stamp_) continue;
        seen_[static_cast<std::size_t>(u)] = stamp_;
        if (!m_.alive[static_cast<std::size_t>(u)] || std::find(skip.begin(), skip.end(), u) != skip.end()) continue;
        const Tri& x = tri(u);
        hit = overlap(box, box_of(x)) && ids_intersect(pos, t, x);
      }
    });
    if (hit) return true;
    for (const int32_t f : grid_.query(*m_.surface, box[0], box[1])) {
      if (changing(f)) continue;
      const Tri& g = m_.surface->triangles[static_cast<std::size_t>(f)];
      if (overlap(box, box_of(g)) && ids_intersect(pos, t, g)) return true;
    }
    return false;
  }
  // A piece narrower than the tiny edge: its height over its longest edge (twice its area over that edge's length)
  // is below it. Caps (a corner almost on the opposite edge) and needles both are.
  bool narrow(const Tri& t) const {
    if (tiny2_ == 0.0) return false;
    const Vec3 &a = m_.point(t[0]), &b = m_.point(t[1]), &c = m_.point(t[2]);
    const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
    const double area2 = (b - a).cross(c - a).squaredNorm();  // (twice the area)^2
    return area2 < tiny2_ * longest2;
  }
  bool defect(int32_t t) const { return degenerate(tri(t)) || intersects_any(tri(t), {t}); }
  bool is_bad(int32_t t) const {
    const Tri& x = tri(t);
    return tiny(x) || narrow(x) || defect(t);
  }

  std::vector<int32_t> detect(const std::vector<char>& dirty) const;
  std::vector<int32_t> neighbours(int32_t n) const;
  void drop_double_covers();
  int merge_ulp_pairs();
  // A uniform grid of cells over the pieces for intersects_any: a piece is listed in every cell its box meets, and
  // again after each edit that moves it (entries left from before are skipped by the box test).
  void build_piece_grid();
  void grid_insert(int32_t t);
  // Calls f(index into cells_) for each cell of the grid that `box` meets.
  template <class F>
  void for_cells(const std::array<Vec3, 2>& box, F&& f) const;
  std::vector<int32_t> sheet(int32_t seed, const std::map<std::pair<int32_t, int32_t>, std::vector<int32_t>>& edges,
                             std::vector<std::pair<int32_t, int32_t>>& rim) const;
  bool collapse(int32_t u, int32_t w, double max_move, bool check = true);
  bool collapse_cluster(int32_t t);
  bool cancel_twin(int32_t t);
  bool flip_cap(int32_t t);
  bool mend(int32_t t);

  // What a collapse overwrote, for collapse_cluster to roll back: pieces (id, nodes, alive) and node -> |around_|.
  struct Journal {
    std::vector<std::tuple<int32_t, Tri, char>> pieces;
    std::vector<std::pair<int32_t, std::size_t>> around;
  };

  PieceMesh& m_;
  FaceGrid& grid_;
  double tiny_;   // m
  double tiny2_;  // m^2
  int merged_ = 0;  // pieces gone before the rounds: with a node twice (rounding), or a pillow's side
  std::unordered_map<int32_t, std::vector<int32_t>> around_;  // node -> the pieces it was ever in
  std::vector<char> moved_;  // (|tris|) the pieces a collapse of this round rewrote
  Journal* journal_ = nullptr;  // set while collapse_cluster tries its collapses
  Vec3 cells_lo_ = Vec3::Zero();     // m, the grid's corner
  double cell_ = 1.0;                // m, its cells' edge
  std::array<int, 3> cells_n_{1, 1, 1};
  std::vector<std::vector<int32_t>> cells_;  // (nx * ny * nz) pieces per cell
  mutable std::vector<uint32_t> seen_;       // (|tris|) the query that last met each piece
  mutable uint32_t stamp_ = 0;
};

// The live pieces with a new node that are degenerate, have a tiny edge, are narrow or intersect a piece or a face of S
// (boxes first, then exact tests), and those of old vertices only that are narrow, ascending; only those flagged in
// `dirty` (and the pieces they intersect) unless it is empty.
std::vector<int32_t> Repair::detect(const std::vector<char>& dirty) const {
  using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, int32_t>;
  std::vector<char> bad(m_.tris.size(), 0), suspect(m_.tris.size(), 0);
  std::vector<Box> suspects, all;
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  const auto make = [&](const Tri& t, int32_t info) {
    const auto b = box_of(t);
    double l[3] = {b[0].x(), b[0].y(), b[0].z()}, h[3] = {b[1].x(), b[1].y(), b[1].z()};
    return Box(l, h, info);
  };
  for (std::size_t t = 0; t < m_.tris.size(); ++t) {
    if (!m_.alive[t]) continue;
    const Tri& x = m_.tris[t];
    // info: 2 t + 1 for a piece, 2 f for a face of S.
    all.push_back(make(x, static_cast<int32_t>(2 * t + 1)));
    if (m_.whole[t]) continue;
    if (std::none_of(x.begin(), x.end(), [&](int32_t n) { return is_new(n); })) {
      // A piece of old vertices only (a face of S split at its own vertices): a flip may mend it when it is narrow.
      if ((dirty.empty() || dirty[t]) && narrow(x)) bad[t] = 1;
      continue;
    }
    if (!dirty.empty() && !dirty[t]) continue;
    if (degenerate(x) || tiny(x) || narrow(x)) bad[t] = 1;
    suspect[t] = 1;
    suspects.push_back(all.back());
    const auto b = box_of(x);
    lo = lo.cwiseMin(b[0]);
    hi = hi.cwiseMax(b[1]);
  }
  if (!suspects.empty()) {
    for (const int32_t f : grid_.query(*m_.surface, lo, hi)) {
      if (!changing(f)) all.push_back(make(m_.surface->triangles[static_cast<std::size_t>(f)], 2 * f));
    }
    const auto pos = [&](int32_t n) { return P(n); };
    CGAL::box_intersection_d(suspects.begin(), suspects.end(), all.begin(), all.end(), [&](const Box& x, const Box& y) {
      if (x.info() == y.info()) return;
      const auto t = static_cast<std::size_t>(x.info() / 2);
      // Two suspects come as (x, y) and as (y, x); the test is symmetric and marks both, so it runs once.
      if ((y.info() & 1) && suspect[static_cast<std::size_t>(y.info() / 2)] && y.info() / 2 < x.info() / 2) return;
      const Tri& other = (y.info() & 1) ? m_.tris[static_cast<std::size_t>(y.info() / 2)]
                                        : m_.surface->triangles[static_cast<std::size_t>(y.info() / 2)];
      if (ids_intersect(pos, m_.tris[t], other)) {
        bad[t] = 1;
        if ((y.info() & 1) && !m_.whole[static_cast<std::size_t>(y.info() / 2)]) bad[static_cast<std::size_t>(y.info() / 2)] = 1;
      }
    }, std::ptrdiff_t(2048));
  }
  std::vector<int32_t> out;
  for (std::size_t t = 0; t < bad.size(); ++t) {
    if (bad[t]) out.push_back(static_cast<int32_t>(t));
  }
  return out;
}

// The nodes that share an edge with node n: through live pieces, and for a vertex of S on the pieces' boundary also
// through S's faces that stay.
std::vector<int32_t> Repair::neighbours(int32_t n) const {
  std::vector<int32_t> out;
  const auto add = [&](const Tri& t) {
    for (const int32_t x : t) {
      if (x != n && (t[0] == n || t[1] == n || t[2] == n)) out.push_back(x);
    }
  };
  if (const auto it = around_.find(n); it != around_.end()) {
    for (const int32_t t : it->second) {
      if (m_.alive[static_cast<std::size_t>(t)]) add(tri(t));
    }
  }
  if (!is_new(n) && m_.arcs->count(n) != 0) {
    for (const int32_t f : grid_.around(*m_.surface, n)) {
      if (!changing(f)) add(m_.surface->triangles[static_cast<std::size_t>(f)]);
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// Collapses new node u onto node w (an edge of a live piece) when that keeps the pieces valid (see repair_rounding)
// and u's old position lies within `max_move` (m) of the plane of every piece that moves; returns whether it did.
// Without `check`, the moved pieces are not tested for intersections (collapse_cluster tests them all at its end).
bool Repair::collapse(int32_t u, int32_t w, double max_move, bool check) {
  std::vector<int32_t> ring, gone, opposite;  // u's live pieces; those with edge uw; their third nodes
  // A piece can be listed twice: a flip can give a piece back a node it had lost.
  std::vector<int32_t> listed = around_[u];
  std::sort(listed.begin(), listed.end());
  listed.erase(std::unique(listed.begin(), listed.end()), listed.end());
  for (const int32_t t : listed) {
    if (!m_.alive[static_cast<std::size_t>(t)]) continue;
    const Tri& x = tri(t);
    if (x[0] != u && x[1] != u && x[2] != u) continue;
    ring.push_back(t);
    if (x[0] == w || x[1] == w || x[2] == w) {
      gone.push_back(t);
      for (const int32_t n : x) {
        if (n != u && n != w) opposite.push_back(n);
      }
    }
  }
  if (gone.empty() || gone.size() > 2) return false;
  // The link condition: the nodes adjacent to both are exactly the third nodes of the pieces along uw.
  const std::vector<int32_t> nu = neighbours(u), nw = neighbours(w);
  std::vector<int32_t> common;
  std::set_intersection(nu.begin(), nu.end(), nw.begin(), nw.end(), std::back_inserter(common));
  std::sort(opposite.begin(), opposite.end());
  if (common != opposite) return false;
  // The pieces that move: not degenerate, not turned over, intersecting nothing.
  std::vector<Tri> moved;
  std::vector<int32_t> moved_ids;
  for (const int32_t t : ring) {
    if (std::find(gone.begin(), gone.end(), t) != gone.end()) continue;
    Tri x = tri(t);
    const Vec3 &a0 = m_.point(x[0]), &b0 = m_.point(x[1]), &c0 = m_.point(x[2]);
    const Vec3 n0 = (b0 - a0).cross(c0 - a0);
    for (int32_t& n : x) {
      if (n == u) n = w;
    }
    if (degenerate(x)) return false;
    const Vec3 n1 = (m_.point(x[1]) - m_.point(x[0])).cross(m_.point(x[2]) - m_.point(x[0]));
    const double scale = std::max({(b0 - a0).squaredNorm(), (c0 - a0).squaredNorm(), (c0 - b0).squaredNorm()});
    if (n0.norm() > 1e-6 * scale && !(n0.dot(n1) > 0.0)) return false;
    // How far the surface moves there: u's distance from the moved piece's plane.
    if (std::isfinite(max_move) && !(std::abs(n1.dot(m_.point(u) - m_.point(w))) <= max_move * n1.norm())) return false;
    moved.push_back(x);
    moved_ids.push_back(t);
  }
  std::vector<int32_t> skip = ring;
  for (std::size_t i = 0; check && i < moved.size(); ++i) {
    if (intersects_any(moved[i], skip)) return false;
    for (std::size_t j = 0; j < i; ++j) {
      if (ids_intersect([&](int32_t n) { return P(n); }, moved[i], moved[j])) return false;
    }
  }
  if (journal_ != nullptr) {
    for (const int32_t t : ring) journal_->pieces.emplace_back(t, tri(t), m_.alive[static_cast<std::size_t>(t)]);
    journal_->around.emplace_back(w, around_[w].size());
  }
  for (const int32_t t : gone) m_.alive[static_cast<std::size_t>(t)] = 0;
  for (std::size_t i = 0; i < moved.size(); ++i) {
    m_.tris[static_cast<std::size_t>(moved_ids[i])] = moved[i];
    m_.whole[static_cast<std::size_t>(moved_ids[i])] = 0;
    moved_[static_cast<std::size_t>(moved_ids[i])] = 1;
    around_[w].push_back(moved_ids[i]);
    grid_insert(moved_ids[i]);
  }
  return true;
}

void Repair::build_piece_grid() {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Tri& t : m_.tris) {
    for (const int32_t n : t) {
      lo = lo.cwiseMin(m_.point(n));
      hi = hi.cwiseMax(m_.point(n));
    }
  }
  seen_.assign(m_.tris.size(), 0);
  if (m_.tris.empty()) return;
  // About one cell per piece, at most 32 along the longest side.
  const double extent = (hi - lo).maxCoeff();
  const int along = std::clamp(static_cast<int>(std::cbrt(static_cast<double>(m_.tris.size()))), 1, 32);
  cell_ = extent > 0.0 ? extent / along : 1.0;
  cells_lo_ = lo;
  for (int a = 0; a < 3; ++a) cells_n_[a] = std::clamp(static_cast<int>((hi[a] - lo[a]) / cell_) + 1, 1, along + 1);
  cells_.assign(static_cast<std::size_t>(cells_n_[0] * cells_n_[1] * cells_n_[2]), {});
  for (std::size_t t = 0; t < m_.tris.size(); ++t) {
    if (m_.alive[t]) grid_insert(static_cast<int32_t>(t));
  }
}

template <class F>
void Repair::for_cells(const std::array<Vec3, 2>& box, F&& f) const {
  std::array<int, 6> r{};  // lower, then upper cell index per axis
  for (int a = 0; a < 3; ++a) {
    const auto at = [&](double x) {
      const double c = std::floor((x - cells_lo_[a]) / cell_);
      return static_cast<int>(std::clamp(c, 0.0, static_cast<double>(cells_n_[a] - 1)));
    };
    r[a] = at(box[0][a]);
    r[a + 3] = at(box[1][a]);
  }
  for (int i = r[0]; i <= r[3]; ++i) {
    for (int j = r[1]; j <= r[4]; ++j) {
      for (int k = r[2]; k <= r[5]; ++k) f(static_cast<std::size_t>((i * cells_n_[1] + j) * cells_n_[2] + k));
    }
  }
}

void Repair::grid_insert(int32_t t) {
  for_cells(box_of(tri(t)), [&](std::size_t cell) { cells_[cell].push_back(t); });
}

// New nodes within a few units in the last place of a node they share an edge with are that node: each collapses onto
// it where the link condition holds and nothing turns over (the rounds then test what moved). Returns the collapses.
int Repair::merge_ulp_pairs() {
  if (tiny2_ == 0.0) return 0;
  int made = 0;
  moved_.assign(m_.tris.size(), 0);
  for (std::size_t t = 0; t < m_.tris.size(); ++t) {
    if (!m_.alive[t]) continue;
    const Tri x = m_.tris[t];
    for (int k = 0; k < 3; ++k) {
      const int32_t a = x[k], b = x[(k + 1) % 3];
      const Vec3 d = m_.point(a) - m_.point(b);
      const double ulp = 8.0 * std::numeric_limits<double>::epsilon() * m_.point(a).cwiseAbs().maxCoeff();
      if (!(d.cwiseAbs().maxCoeff() <= ulp)) continue;
      if ((is_new(a) && collapse(a, b, std::numeric_limits<double>::infinity(), false)) ||
          (is_new(b) && collapse(b, a, std::numeric_limits<double>::infinity(), false))) {
        ++made;
        break;
      }
    }
  }
  return made;
}

// The pieces of one kind (of S's faces, or of the blade) that piece `seed` reaches across edges used once in each
// direction, each time by a piece of that kind, and into `rim` the directed edges where it stops because the edge is
// used twice in this direction; empty when it reaches a piece of the other kind or an edge without a partner (a
// boundary edge of the patch). `edges` maps each directed edge to the live pieces that use it.
std::vector<int32_t> Repair::sheet(int32_t seed,
                                   const std::map<std::pair<int32_t, int32_t>, std::vector<int32_t>>& edges,
                                   std::vector<std::pair<int32_t, int32_t>>& rim) const {
  const char kind = m_.blade[static_cast<std::size_t>(seed)];
  std::vector<int32_t> out{seed};
  rim.clear();
  for (std::size_t i = 0; i < out.size(); ++i) {
    const Tri& x = tri(out[i]);
    for (int r = 0; r < 3; ++r) {
      const std::pair<int32_t, int32_t> e{x[r], x[(r + 1) % 3]};
      if (edges.at(e).size() > 1) {
        rim.push_back(e);
        continue;
      }
      const auto back = edges.find({e.second, e.first});
      if (back == edges.end() || back->second.size() != 1) return {};
      const int32_t u = back->second[0];
      // A piece of another kind, or one that an earlier pillow took (`edges` is from before): not this case.
      if (m_.blade[static_cast<std::size_t>(u)] != kind || !m_.alive[static_cast<std::size_t>(u)]) return {};
      if (std::find(out.begin(), out.end(), u) == out.end()) out.push_back(u);
      if (out.size() > 64) return {};
    }
  }
  return out;
}

// A sliver pillow that the classification kept on both sides: a few pieces of S's faces (a fan around a vertex of S
// that an earlier rounding left a hair off the blade's plane) and a few of the blade's cover the same polygon, turned
// the same way, so that every edge of its rim is used twice in one direction. Both sheets bound the same surface to
// within the collapse length; the pieces of S's faces go (the blade's stay), which leaves every rim edge used once each
// way. Only where the two sheets have the same rim and every corner of S's sheet lies within the collapse length of
// the blade sheet's planes.
void Repair::drop_double_covers() {
  // One pillow per pass, the edge map rebuilt after each (a pillow's pieces may border another's).
  for (int pass = 0; pass < 64; ++pass) {
    std::map<std::pair<int32_t, int32_t>, std::vector<int32_t>> edges;  // directed edge -> live pieces
    for (std::size_t t = 0; t < m_.tris.size(); ++t) {
      if (!m_.alive[t]) continue;
      const Tri& x = m_.tris[t];
      for (int r = 0; r < 3; ++r) edges[{x[r], x[(r + 1) % 3]}].push_back(static_cast<int32_t>(t));
    }
    bool dropped = false;
    for (const auto& [e, users] : edges) {
      if (users.size() != 2) continue;
      const auto from_blade = [&](int32_t t) { return m_.blade[static_cast<std::size_t>(t)] != 0; };
      if (from_blade(users[0]) == from_blade(users[1])) continue;
      const int32_t s_seed = from_blade(users[0]) ? users[1] : users[0];
      const int32_t b_seed = s_seed == users[0] ? users[1] : users[0];
      std::vector<std::pair<int32_t, int32_t>> s_rim, b_rim;
      const std::vector<int32_t> s_sheet = sheet(s_seed, edges, s_rim), b_sheet = sheet(b_seed, edges, b_rim);
      if (s_sheet.empty() || b_sheet.empty()) continue;
      std::sort(s_rim.begin(), s_rim.end());
      std::sort(b_rim.begin(), b_rim.end());
      if (s_rim != b_rim) continue;
      const auto near_blade = [&](int32_t n) {
        const Vec3& p = m_.point(n);
        for (const int32_t b : b_sheet) {
          const Tri& y = tri(b);
          const Vec3 normal = (m_.point(y[1]) - m_.point(y[0])).cross(m_.point(y[2]) - m_.point(y[0]));
          if (!(std::abs(normal.dot(p - m_.point(y[0]))) <= tiny_ * normal.norm())) return false;
        }
        return true;
      };
      bool thin = true;
      for (const int32_t t : s_sheet) {
        for (const int32_t n : tri(t)) thin = thin && near_blade(n);
      }
      if (!thin) continue;
      for (const int32_t t : s_sheet) m_.alive[static_cast<std::size_t>(t)] = 0;
      merged_ += static_cast<int>(s_sheet.size());
      dropped = true;
      break;
    }
    if (!dropped) return;
  }
}

// Collapses the cluster of defective piece t at once: its nodes and those joined to them by tiny edges (a few exact
// points that rounded to distinct doubles ulps apart), onto the cluster's vertex of S if it has one, else its first
// node. Single collapses can fail there where each leaves the cluster's other nodes folded over the moved pieces;
// the pieces are tested for degeneracy and intersections once all have moved, and the collapses are rolled back when
// that fails. Returns whether it collapsed the cluster.
bool Repair::collapse_cluster(int32_t t) {
  std::vector<int32_t> cluster(tri(t).begin(), tri(t).end());
  for (std::size_t i = 0; i < cluster.size(); ++i) {
    for (const int32_t n : neighbours(cluster[i])) {
      if ((m_.point(n) - m_.point(cluster[i])).squaredNorm() < tiny2_ &&
          std::find(cluster.begin(), cluster.end(), n) == cluster.end()) {
        cluster.push_back(n);
      }
    }
  }
  // Only t's nodes that are joined by tiny edges: drop the others (t's own long edges joined them).
  std::vector<int32_t> close;
  for (const int32_t n : cluster) {
    if (std::any_of(cluster.begin(), cluster.end(),
                    [&](int32_t m) { return m != n && (m_.point(n) - m_.point(m)).squaredNorm() < tiny2_; })) {
      close.push_back(n);
    }
  }
  const auto old_nodes = std::count_if(close.begin(), close.end(), [&](int32_t n) { return !is_new(n); });
  if (close.size() < 3 || old_nodes > 1) return false;
  const int32_t w = old_nodes == 1 ? *std::find_if(close.begin(), close.end(), [&](int32_t n) { return !is_new(n); })
                                   : *std::min_element(close.begin(), close.end());
  Journal journal;
  journal_ = &journal;
  std::vector<int32_t> left;
  for (const int32_t n : close) {
    if (n != w) left.push_back(n);
  }
  for (bool progress = true; progress && !left.empty();) {
    progress = false;
    for (auto it = left.begin(); it != left.end();) {
      if (collapse(*it, w, std::numeric_limits<double>::infinity(), false)) {
        it = left.erase(it);
        progress = true;
      } else {
        ++it;
      }
    }
  }
  journal_ = nullptr;
  bool ok = left.empty();
  for (std::size_t i = 0; ok && i < journal.pieces.size(); ++i) {
    const int32_t p = std::get<0>(journal.pieces[i]);
    if (m_.alive[static_cast<std::size_t>(p)]) ok = !defect(p);
  }
  if (ok) return true;
  for (auto it = journal.pieces.rbegin(); it != journal.pieces.rend(); ++it) {
    m_.tris[static_cast<std::size_t>(std::get<0>(*it))] = std::get<1>(*it);
    m_.alive[static_cast<std::size_t>(std::get<0>(*it))] = std::get<2>(*it);
  }
  for (auto it = journal.around.rbegin(); it != journal.around.rend(); ++it) around_[it->first].resize(it->second);
  return false;
}

// Removes defective piece t together with a live piece on the same three nodes turned the other way, when there is
// one: the two enclose no volume, and every edge of theirs loses one use in each direction, so the pieces around
// stay paired. (A sliver bubble whose exact nodes rounded to three points leaves such a pair.)
bool Repair::cancel_twin(int32_t t) {
  const Tri& x = tri(t);
  for (const int32_t u : around_[x[0]]) {
    if (u == t || !m_.alive[static_cast<std::size_t>(u)]) continue;
    const Tri& y = tri(u);
    for (int r = 0; r < 3; ++r) {
      if (y[0] == x[r] && y[1] == x[(r + 2) % 3] && y[2] == x[(r + 1) % 3]) {
        m_.alive[static_cast<std::size_t>(t)] = 0;
        m_.alive[static_cast<std::size_t>(u)] = 0;
        return true;
      }
    }
  }
  return false;
}

// Flips the longest edge (a, b) of narrow piece t = (a, b, v) with the piece (b, a, w) across it into (a, w, v) and
// (w, b, v), when that raises the smallest angle of the two, edge vw is not there yet, neither new piece turns against
// (b, a, w) and neither intersects anything. It moves no node: where v lies on ab within the tiny edge (a vertex of S
// that an earlier rounding left a hair off a new edge), the surface moves by less than v's height over ab.
bool Repair::flip_cap(int32_t t) {
  Tri x = tri(t);
  int k = 0;  // x[k] -> x[k + 1] is the longest edge
  double longest = -1.0;
  for (int i = 0; i < 3; ++i) {
    const double l2 = (m_.point(x[i]) - m_.point(x[(i + 1) % 3])).squaredNorm();
    if (l2 > longest) longest = l2, k = i;
  }
  const int32_t a = x[k], b = x[(k + 1) % 3], v = x[(k + 2) % 3];
  int32_t across = -1, w = -1;
  for (const int32_t u : around_[a]) {
    if (u == t || !m_.alive[static_cast<std::size_t>(u)]) continue;
    const Tri& y = tri(u);
    for (int r = 0; r < 3; ++r) {
      if (y[r] == b && y[(r + 1) % 3] == a) {
        if (across != -1 && across != u) return false;  // not manifold here: leave it
        across = u, w = y[(r + 2) % 3];
      }
    }
  }
  if (across == -1 || w == v) return false;
  const std::vector<int32_t> nv = neighbours(v);
  if (std::binary_search(nv.begin(), nv.end(), w)) return false;
  const Tri t1{a, w, v}, t2{w, b, v};
  if (degenerate(t1) || degenerate(t2)) return false;
  const Vec3 &pa = m_.point(a), &pb = m_.point(b), &pv = m_.point(v), &pw = m_.point(w);
  const Vec3 n = (pa - pb).cross(pw - pb);  // (b, a, w)'s normal
  if (!((pw - pa).cross(pv - pa).dot(n) > 0.0) || !((pb - pw).cross(pv - pw).dot(n) > 0.0)) return false;
  if (!(std::min(smallest_angle(pa, pw, pv), smallest_angle(pw, pb, pv)) >
        std::min(smallest_angle(pa, pb, pv), smallest_angle(pb, pa, pw)))) {
    return false;
  }
  const std::vector<int32_t> skip{t, across};
  if (intersects_any(t1, skip) || intersects_any(t2, skip)) return false;
  if (ids_intersect([&](int32_t node) { return P(node); }, t1, t2)) return false;
  m_.tris[static_cast<std::size_t>(t)] = t1;
  m_.tris[static_cast<std::size_t>(across)] = t2;
  for (const int32_t id : skip) {
    m_.whole[static_cast<std::size_t>(id)] = 0;
    moved_[static_cast<std::size_t>(id)] = 1;
  }
  around_[w].push_back(t);
  around_[v].push_back(across);
  grid_insert(t);
  grid_insert(across);
  return true;
}

// Tries the collapses along the edges of bad piece t that move a new node, shortest edge first, then (for a defect)
// the removal of a twin turned the other way and the collapse of its cluster, or (for a narrow piece) a flip. A piece
// that is only tiny or narrow (no defect) takes only collapses that move the surface by less than the tiny edge.
bool Repair::mend(int32_t t) {
  const Tri x = tri(t);
  const double max_move = defect(t) ? std::numeric_limits<double>::infinity() : tiny_;
  std::vector<std::pair<double, std::array<int32_t, 2>>> tries;  // (squared length, (u, w))
  for (int k = 0; k < 3; ++k) {
    const int32_t a = x[k], b = x[(k + 1) % 3];
    const double l2 = (m_.point(a) - m_.point(b)).squaredNorm();
    if (is_new(a)) tries.push_back({l2, {a, b}});
    if (is_new(b)) tries.push_back({l2, {b, a}});
  }
  std::sort(tries.begin(), tries.end());
  for (const auto& [l2, e] : tries) {
    if (collapse(e[0], e[1], max_move)) return true;
  }
  if (std::isinf(max_move)) return cancel_twin(t) || collapse_cluster(t);
  return narrow(x) && flip_cap(t);
}

}  // namespace

int repair_rounding(PieceMesh& mesh, FaceGrid& grid, double tiny_edge) {
  return Repair(mesh, grid, tiny_edge).run();
}

namespace {

// The unchanged neighbours of the changed faces: faces that are not changed and have a vertex on the patch's
// boundary (the vertices of `arcs`), ascending. They come from the grid, which follows the edits: a face moved into a
// removed slot is found at its new index.
std::vector<int32_t> unchanged_neighbours(const sim::TriMesh& out, FaceGrid& grid, const std::vector<int32_t>& changed,
                                          const FanCounts& arcs) {
  std::vector<int32_t> changed_sorted = changed;
  std::sort(changed_sorted.begin(), changed_sorted.end());
  std::vector<int32_t> boundary_vertices;
  boundary_vertices.reserve(arcs.size());
  for (const auto& [v, n] : arcs) boundary_vertices.push_back(v);
  std::sort(boundary_vertices.begin(), boundary_vertices.end());
  std::vector<int32_t> neighbours;
  for (const int32_t v : boundary_vertices) {
    for (const int32_t f : grid.around(out, v)) {
      if (!std::binary_search(changed_sorted.begin(), changed_sorted.end(), f)) neighbours.push_back(f);
    }
  }
  std::sort(neighbours.begin(), neighbours.end());
  neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
  return neighbours;
}

// Self-intersections among the changed faces and between them and their unchanged neighbours: the faces of S kept
// whole in the patch (written.changed_whole) and `neighbours`. Pairs of unchanged faces are skipped (S had no
// self-intersection), and so are pairs of faces without a constructed vertex (see below; written.constructed flags
// the vertices from `first_inserted` on that are intersection points). Throws CutFailure naming the smallest pair.
void check_self_intersections(const sim::TriMesh& out, const WrittenPatch& written, int32_t first_inserted,
                              const std::vector<int32_t>& neighbours) {
  using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, int32_t>;
  std::vector<Box> boxes, changed_boxes;  // all of them; those of the changed triangles
  boxes.reserve(written.changed.size() + neighbours.size());
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
      return v >= first_inserted && written.constructed[static_cast<std::size_t>(v - first_inserted)] != 0;
    });
  };
  for (std::size_t i = 0; i < written.changed.size(); ++i) {
    add(written.changed[i], !written.changed_whole[i] && constructed(written.changed[i]) ? 1 : 0);
  }
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

}  // namespace

void verify_result(const sim::TriMesh& out, FaceGrid& grid, const WrittenPatch& written, const FanCounts& arcs,
                   int32_t first_inserted) {
  check_changed_triangles(out, written.changed);
  check_edges(out, written.changed, written.boundary_edges);
  check_vertex_fans(out, written.changed, arcs);
  if (written.intersections_checked) return;
  check_self_intersections(out, written, first_inserted, unchanged_neighbours(out, grid, written.changed, arcs));
}

}  // namespace octocut::cutting::surface_cut_detail
