#include "octocut/cutting/blade.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <queue>
#include <stdexcept>
#include <string>

namespace octocut::cutting {

using sim::Box3;
using sim::Vec3;

namespace {

using Tet = std::array<Vec3, 4>;

// Closed boxes meet (touching counts).
bool boxes_meet(const Box3& a, const Box3& b) {
  return (a.min.array() <= b.max.array()).all() && (b.min.array() <= a.max.array()).all();
}

Box3 inflated(const Box3& b, double e) { return Box3{b.min.array() - e, b.max.array() + e}; }

template <std::size_t N>
Box3 box_of(const std::array<Vec3, N>& p) {
  Box3 b{p[0], p[0]};
  for (std::size_t k = 1; k < N; ++k) {
    b.min = b.min.cwiseMin(p[k]);
    b.max = b.max.cwiseMax(p[k]);
  }
  return b;
}

// Squared distance from p to the closed box, m^2.
double box_distance2(const Box3& b, const Vec3& p) {
  const Vec3 d = (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0);
  return d.squaredNorm();
}

// Closest point to p on triangle abc (Ericson, Real-Time Collision Detection §5.1.5), by Voronoi regions.
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) return a;  // a degenerate triangle whose regions collapsed; a is one of its points
  const double v = vb / denom, w = vc / denom;
  return a + v * ab + w * ac;
}

// The separating-axis test on one axis: the point sets' projections are disjoint, with a relative slack so that
// touching sets whose projections round apart by a few ulps still count as meeting.
template <std::size_t N, std::size_t M>
bool separated_on(const Vec3& axis, const std::array<Vec3, N>& a, const std::array<Vec3, M>& b) {
  double amin = std::numeric_limits<double>::infinity(), amax = -amin, bmin = amin, bmax = -amin, mag = 0.0;
  for (const Vec3& p : a) {
    const double s = axis.dot(p);
    amin = std::min(amin, s);
    amax = std::max(amax, s);
    mag = std::max(mag, std::abs(s));
  }
  for (const Vec3& p : b) {
    const double s = axis.dot(p);
    bmin = std::min(bmin, s);
    bmax = std::max(bmax, s);
    mag = std::max(mag, std::abs(s));
  }
  const double slack = 1e-12 * mag;
  return amin > bmax + slack || bmin > amax + slack;
}

// Triangle (points relative to the box centre) against the box [-h, h]: the 13 axes of Akenine-Möller's test
// (3 box normals, the triangle normal, 9 edge cross products).
bool triangle_meets_centered_box(const std::array<Vec3, 3>& t, const Vec3& h) {
  auto separated = [&](const Vec3& u) {
    const double p0 = u.dot(t[0]), p1 = u.dot(t[1]), p2 = u.dot(t[2]);
    const double r = h.x() * std::abs(u.x()) + h.y() * std::abs(u.y()) + h.z() * std::abs(u.z());
    const double lo = std::min({p0, p1, p2}), hi = std::max({p0, p1, p2});
    const double slack = 1e-12 * std::max({std::abs(lo), std::abs(hi), r});
    return lo > r + slack || hi < -r - slack;
  };
  // Box normals: the bounding boxes (checked by the caller) already overlap, but the test is cheap and complete.
  for (int a = 0; a < 3; ++a)
    if (separated(Vec3::Unit(a))) return false;
  const std::array<Vec3, 3> e{t[1] - t[0], t[2] - t[1], t[0] - t[2]};
  if (separated(e[0].cross(e[1]))) return false;
  for (const Vec3& edge : e)
    for (int a = 0; a < 3; ++a)
      if (separated(Vec3::Unit(a).cross(edge))) return false;
  return true;
}

// A tetrahedron prepared for many triangle tests: corners relative to corner 0, edges, face normals with the tet's
// extent along them, and for a tet with volume the four inner half-spaces n_k · x <= c_k.
struct TetSat {
  Vec3 o;                            // corner 0, m
  std::array<Vec3, 4> v;             // corners relative to o, m
  std::array<Vec3, 6> e;             // edges, m
  std::array<Vec3, 4> fn;            // face normals (unnormalised; zero for a degenerate tet)
  std::array<double, 4> lo{}, hi{};  // extent of the tet along each face normal
  bool solid = false;                // the tet has volume (|6 V| > 1e-9 L^3, L its longest edge)
  std::array<Vec3, 4> n;             // outward normal of the face opposite corner k (solid tets)
  std::array<double, 4> c{};         // plane offsets: the tet is n_k · x <= c_k + tol_k (solid tets)
  std::array<double, 4> tol{};       // 1e-12 L |n_k|: touching counts

  explicit TetSat(const Tet& t) : o(t[0]), v{Vec3::Zero(), t[1] - t[0], t[2] - t[0], t[3] - t[0]} {
    e = {v[1], v[2], v[3], v[2] - v[1], v[3] - v[1], v[3] - v[2]};
    fn = {e[0].cross(e[1]), e[0].cross(e[2]), e[1].cross(e[2]), e[3].cross(e[4])};
    double L = 0.0;
    for (const Vec3& g : e) L = std::max(L, g.norm());
    for (std::size_t k = 0; k < 4; ++k) {
      lo[k] = std::numeric_limits<double>::infinity();
      hi[k] = -lo[k];
      for (const Vec3& p : v) {
        lo[k] = std::min(lo[k], fn[k].dot(p));
        hi[k] = std::max(hi[k], fn[k].dot(p));
      }
    }
    const double det = v[1].dot(v[2].cross(v[3]));
    solid = std::abs(det) > 1e-9 * L * L * L;
    if (!solid) return;
    static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
    for (std::size_t k = 0; k < 4; ++k) {
      const Vec3& a = v[std::size_t(kFace[k][0])];
      Vec3 nk = (v[std::size_t(kFace[k][1])] - a).cross(v[std::size_t(kFace[k][2])] - a);
      if (nk.dot(v[k] - a) > 0.0) nk = -nk;  // the opposite corner lies inside
      n[k] = nk;
      c[k] = nk.dot(a);
      tol[k] = 1e-12 * L * nk.norm();
    }
  }
};

// True when the closed triangle t (m) meets the closed tet. A tet with volume clips the triangle by its four inner
// half-spaces (Sutherland–Hodgman; the triangle meets the tet iff something is left). A degenerate tet (flat, a
// segment or a point) is tested by separating axes instead: the triangle's normal and in-plane edge normals, the
// tet's face normals, the edge–edge cross products, and the triangle normal crossed with the tet's edges (the
// in-plane normals of a flat tet lying in the triangle's plane).
bool triangle_meets_tet(const std::array<Vec3, 3>& t, const TetSat& T) {
  if (T.solid) {
    std::array<Vec3, 8> poly{t[0] - T.o, t[1] - T.o, t[2] - T.o}, next{};
    std::array<double, 8> d{};
    int m = 3;
    for (std::size_t k = 0; k < 4; ++k) {
      bool any_in = false, any_out = false;
      for (int i = 0; i < m; ++i) {
        d[std::size_t(i)] = T.n[k].dot(poly[std::size_t(i)]) - T.c[k] - T.tol[k];
        (d[std::size_t(i)] <= 0.0 ? any_in : any_out) = true;
      }
      if (!any_in) return false;
      if (!any_out) continue;
      int r = 0;
      for (int i = 0; i < m; ++i) {
        const int j = (i + 1) % m;
        const double di = d[std::size_t(i)], dj = d[std::size_t(j)];
        if (di <= 0.0) next[std::size_t(r++)] = poly[std::size_t(i)];
        if ((di <= 0.0) != (dj <= 0.0))
          next[std::size_t(r++)] = poly[std::size_t(i)] + (di / (di - dj)) * (poly[std::size_t(j)] - poly[std::size_t(i)]);
      }
      poly.swap(next);
      m = r;
    }
    return m > 0;
  }
  const std::array<Vec3, 3> a{t[0] - T.o, t[1] - T.o, t[2] - T.o};
  const std::array<Vec3, 3> te{a[1] - a[0], a[2] - a[1], a[0] - a[2]};
  const Vec3 n = te[0].cross(te[1]);
  if (separated_on(n, a, T.v)) return false;
  for (std::size_t k = 0; k < 4; ++k) {
    const double p0 = T.fn[k].dot(a[0]), p1 = T.fn[k].dot(a[1]), p2 = T.fn[k].dot(a[2]);
    const double tmin = std::min({p0, p1, p2}), tmax = std::max({p0, p1, p2});
    const double slack = 1e-12 * std::max({std::abs(tmin), std::abs(tmax), std::abs(T.lo[k]), std::abs(T.hi[k])});
    if (tmin > T.hi[k] + slack || tmax < T.lo[k] - slack) return false;
  }
  for (const Vec3& g : te)
    if (separated_on(n.cross(g), a, T.v)) return false;
  for (const Vec3& g : T.e) {
    for (const Vec3& f : te)
      if (separated_on(f.cross(g), a, T.v)) return false;
    if (separated_on(n.cross(g), a, T.v)) return false;
  }
  return true;
}

// Generic directions for the parity rays: no two coplanar with a coordinate axis, none parallel to a face of an
// axis-aligned or 45°-rotated mesh.
constexpr int kNumDirections = 8;
const std::array<Vec3, kNumDirections>& ray_directions() {
  static const std::array<Vec3, kNumDirections> dirs = [] {
    std::array<Vec3, kNumDirections> d{Vec3(0.5377, 0.8346, 0.1184), Vec3(-0.3133, 0.2571, 0.9142),
                                       Vec3(0.7152, -0.4385, 0.5443), Vec3(-0.6203, -0.7019, 0.3499),
                                       Vec3(0.1627, -0.2913, -0.9427), Vec3(-0.8761, 0.3917, -0.2812),
                                       Vec3(0.4411, 0.6072, -0.6608), Vec3(-0.2294, -0.8851, -0.4052)};
    for (Vec3& v : d) v.normalize();
    return d;
  }();
  return dirs;
}

}  // namespace

BladeVolume::BladeVolume(sim::TriMesh mesh) : m_mesh(std::move(mesh)) {
  // Check the data.
  if (m_mesh.triangles.empty()) throw std::invalid_argument("blade: the mesh has no triangles");
  const auto nv = static_cast<int32_t>(m_mesh.vertices.size());
  for (std::size_t i = 0; i < m_mesh.vertices.size(); ++i)
    if (!m_mesh.vertices[i].allFinite())
      throw std::invalid_argument("blade: vertex " + std::to_string(i) + " is not finite");
  for (std::size_t f = 0; f < m_mesh.triangles.size(); ++f)
    for (int32_t i : m_mesh.triangles[f])
      if (i < 0 || i >= nv)
        throw std::invalid_argument("blade: triangle " + std::to_string(f) + " has a vertex index out of range");

  // Triangle corners and boxes; the blade's bounds are those of the vertices used.
  const std::size_t nf = m_mesh.triangles.size();
  m_tri.resize(nf);
  m_tri_box.resize(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto& t = m_mesh.triangles[f];
    m_tri[f] = {m_mesh.vertices[std::size_t(t[0])], m_mesh.vertices[std::size_t(t[1])],
                m_mesh.vertices[std::size_t(t[2])]};
    m_tri_box[f] = box_of(m_tri[f]);
  }
  m_bounds = m_tri_box[0];
  for (const Box3& b : m_tri_box) {
    m_bounds.min = m_bounds.min.cwiseMin(b.min);
    m_bounds.max = m_bounds.max.cwiseMax(b.max);
  }
  const double diag = (m_bounds.max - m_bounds.min).norm();
  if (!(diag > 0.0)) throw std::invalid_argument("blade: the mesh has no extent");
  m_eps = 1e-10 * diag;

  // Bounding volume hierarchy: median splits on the longest axis of the centroids, up to 4 triangles per leaf.
  m_order.resize(nf);
  for (std::size_t f = 0; f < nf; ++f) m_order[f] = int(f);
  m_nodes.reserve(2 * nf);
  m_nodes.emplace_back();
  build(0, 0, int(nf));
}

void BladeVolume::build(int n, int begin, int end) {
  Box3 box = m_tri_box[std::size_t(m_order[std::size_t(begin)])];
  Box3 cbox{box.min + box.max, box.min + box.max};  // twice the centroids' bounds
  for (int i = begin; i < end; ++i) {
    const Box3& b = m_tri_box[std::size_t(m_order[std::size_t(i)])];
    box.min = box.min.cwiseMin(b.min);
    box.max = box.max.cwiseMax(b.max);
    cbox.min = cbox.min.cwiseMin(b.min + b.max);
    cbox.max = cbox.max.cwiseMax(b.min + b.max);
  }
  m_nodes[std::size_t(n)].box = box;
  if (end - begin <= 4) {
    m_nodes[std::size_t(n)].first = begin;
    m_nodes[std::size_t(n)].count = end - begin;
    return;
  }
  // Split at the median centroid along the longest axis; ties are broken by triangle index (deterministic).
  int axis = 0;
  (cbox.max - cbox.min).maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(m_order.begin() + begin, m_order.begin() + mid, m_order.begin() + end, [&](int a, int b) {
    const double ca = m_tri_box[std::size_t(a)].min[axis] + m_tri_box[std::size_t(a)].max[axis];
    const double cb = m_tri_box[std::size_t(b)].min[axis] + m_tri_box[std::size_t(b)].max[axis];
    return ca < cb || (ca == cb && a < b);
  });
  const int child = int(m_nodes.size());
  m_nodes[std::size_t(n)].first = child;
  m_nodes[std::size_t(n)].count = 0;
  m_nodes.emplace_back();
  m_nodes.emplace_back();
  build(child, begin, mid);
  build(child + 1, mid, end);
}

template <class NodeTest, class Visit>
bool BladeVolume::traverse(NodeTest&& node_test, Visit&& visit) const {
  // The tree is balanced (median splits), so its depth is about log2(|F| / 4) + 1; 64 entries are ample.
  std::array<int, 64> stack{};
  int top = 0;
  stack[std::size_t(top++)] = 0;
  while (top > 0) {
    const Node& node = m_nodes[std::size_t(stack[std::size_t(--top)])];
    if (!node_test(node.box)) continue;
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i)
        if (visit(m_order[std::size_t(i)])) return true;
    } else {
      stack[std::size_t(top++)] = node.first + 1;
      stack[std::size_t(top++)] = node.first;
    }
  }
  return false;
}

template <class Visit>
bool BladeVolume::any_triangle_near(const Box3& box, Visit&& visit) const {
  return traverse([&](const Box3& b) { return boxes_meet(b, box); },
                  [&](int f) { return boxes_meet(m_tri_box[std::size_t(f)], box) && visit(f); });
}

double BladeVolume::distance(const Vec3& p) const {
  // Branch and bound: nearer child first, nodes farther than the best triangle so far are skipped.
  double best2 = std::numeric_limits<double>::infinity();
  std::array<int, 64> stack{};
  int top = 0;
  stack[std::size_t(top++)] = 0;
  while (top > 0) {
    const Node& node = m_nodes[std::size_t(stack[std::size_t(--top)])];
    if (box_distance2(node.box, p) >= best2) continue;
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i) {
        const auto& t = m_tri[std::size_t(m_order[std::size_t(i)])];
        best2 = std::min(best2, (closest_on_triangle(p, t[0], t[1], t[2]) - p).squaredNorm());
      }
    } else {
      const int a = node.first, b = node.first + 1;
      const bool a_first = box_distance2(m_nodes[std::size_t(a)].box, p) <= box_distance2(m_nodes[std::size_t(b)].box, p);
      stack[std::size_t(top++)] = a_first ? b : a;
      stack[std::size_t(top++)] = a_first ? a : b;
    }
  }
  return std::sqrt(best2);
}

int BladeVolume::parity(const Vec3& p, int k) const {
  const Vec3& d = ray_directions()[std::size_t(k)];
  const Vec3 q = p + 2.0 * (m_bounds.max - m_bounds.min).norm() * d;  // beyond the bounds: p is within them
  const Vec3 inv = d.cwiseInverse();
  // Segment p–q against a node box (slab test, boxes grown by the surface tolerance).
  auto segment_meets = [&](const Box3& b) {
    double t0 = 0.0, t1 = 1.0;
    const double len = (q - p).norm();
    for (int a = 0; a < 3; ++a) {
      const double lo = b.min[a] - m_eps, hi = b.max[a] + m_eps;
      if (d[a] == 0.0) {
        if (p[a] < lo || p[a] > hi) return false;
        continue;
      }
      double ta = (lo - p[a]) * inv[a] / len, tb = (hi - p[a]) * inv[a] / len;
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
      if (t0 > t1) return false;
    }
    return true;
  };
  // Side of the line (p, d) on which edge (i, j) passes, computed once per edge in ascending vertex order so that
  // the two triangles sharing the edge see exactly opposite values (watertightness). Values within rounding of zero
  // are reported as 0: the line runs (nearly) through the edge or one of its vertices, where floating-point signs
  // of the edges around a vertex need not be consistent with any position of the line.
  auto side = [&](int32_t i, int32_t j) {
    const bool flip = i > j;
    if (flip) std::swap(i, j);
    const Vec3 a = m_mesh.vertices[std::size_t(i)] - p, b = m_mesh.vertices[std::size_t(j)] - p;
    double s = d.dot(a.cross(b));
    if (std::abs(s) <= 1e-10 * a.norm() * b.norm()) s = 0.0;
    return flip ? -s : s;
  };
  int crossings = 0;
  bool degenerate = false;
  traverse(segment_meets, [&](int f) {
    const auto& t = m_mesh.triangles[std::size_t(f)];
    const double s0 = side(t[0], t[1]), s1 = side(t[1], t[2]), s2 = side(t[2], t[0]);
    const bool any_pos = s0 > 0.0 || s1 > 0.0 || s2 > 0.0, any_neg = s0 < 0.0 || s1 < 0.0 || s2 < 0.0;
    if (any_pos && any_neg) return false;  // the line misses the triangle
    if (s0 == 0.0 || s1 == 0.0 || s2 == 0.0) {
      degenerate = true;  // through an edge or a vertex, or in the triangle's plane
      return true;
    }
    // The line pierces the triangle's interior; count it when p and q lie on either side of its plane.
    const auto& c = m_tri[std::size_t(f)];
    const Vec3 n = (c[1] - c[0]).cross(c[2] - c[0]);
    const double op = n.dot(p - c[0]), oq = n.dot(q - c[0]);
    if (std::abs(op) <= 1e-12 * n.norm() * (p - c[0]).norm()) {
      degenerate = true;  // p (nearly) in the plane of a triangle the line pierces
      return true;
    }
    if ((op > 0.0) != (oq > 0.0)) ++crossings;
    return false;
  });
  if (degenerate) return -1;
  return crossings & 1;
}

double BladeVolume::winding_number(const Vec3& p) const {
  // Van Oosterom–Strackee solid angle of each triangle seen from p.
  double sum = 0.0;
  for (const auto& t : m_tri) {
    const Vec3 a = t[0] - p, b = t[1] - p, c = t[2] - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    sum += 2.0 * std::atan2(num, den);
  }
  return sum / (4.0 * std::numbers::pi);
}

bool BladeVolume::contains(const Vec3& p) const {
  if (!m_bounds.contains(p, m_eps)) return false;
  // On the surface, within the tolerance: inside.
  const double eps2 = m_eps * m_eps;
  const Box3 probe = inflated(Box3{p, p}, m_eps);
  if (any_triangle_near(probe, [&](int f) {
        const auto& t = m_tri[std::size_t(f)];
        return (closest_on_triangle(p, t[0], t[1], t[2]) - p).squaredNorm() <= eps2;
      }))
    return true;
  // Ray parity along the first direction whose ray meets no edge and no vertex.
  for (int k = 0; k < kNumDirections; ++k) {
    const int r = parity(p, k);
    if (r >= 0) return r == 1;
  }
  // Every ray was degenerate (not met in practice): the winding number decides.
  return winding_number(p) > 0.5;
}

bool BladeVolume::overlaps_box(const Box3& box) const {
  if ((box.min.array() > box.max.array()).any() || !boxes_meet(box, m_bounds)) return false;
  const Vec3 c = 0.5 * (box.min + box.max), h = 0.5 * (box.max - box.min);
  // Some blade triangle meets the box (this also catches a blade that lies inside the box) ...
  if (any_triangle_near(box, [&](int f) {
        const auto& t = m_tri[std::size_t(f)];
        return triangle_meets_centered_box({t[0] - c, t[1] - c, t[2] - c}, h);
      }))
    return true;
  // ... or else the box lies wholly inside or wholly outside the solid.
  return contains(c);
}

bool BladeVolume::overlaps_tet(const Tet& tet) const {
  for (const Vec3& c : tet)
    if (!c.allFinite()) return false;
  const Box3 tb = box_of(tet);
  if (!boxes_meet(tb, m_bounds)) return false;
  const TetSat sat(tet);
  if (any_triangle_near(tb, [&](int f) { return triangle_meets_tet(m_tri[std::size_t(f)], sat); })) return true;
  return contains(0.25 * (tet[0] + tet[1] + tet[2] + tet[3]));
}

bool BladeVolume::overlaps_hexahedron(const std::array<Vec3, 8>& corners) const {
  for (const Vec3& c : corners)
    if (!c.allFinite()) return false;
  const Box3 hb = box_of(corners);
  if (!boxes_meet(hb, m_bounds)) return false;
  // The six tets around the diagonal 0–7, one per order in which the axes are stepped.
  static constexpr int kPerms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  std::vector<TetSat> tets;
  std::array<Box3, 6> boxes{};
  tets.reserve(6);
  for (int s = 0; s < 6; ++s) {
    const int v1 = 1 << kPerms[s][0], v2 = v1 | (1 << kPerms[s][1]);
    const Tet t{corners[0], corners[std::size_t(v1)], corners[std::size_t(v2)], corners[7]};
    tets.emplace_back(t);
    boxes[std::size_t(s)] = box_of(t);
  }
  if (any_triangle_near(hb, [&](int f) {
        for (int s = 0; s < 6; ++s)
          if (boxes_meet(boxes[std::size_t(s)], m_tri_box[std::size_t(f)]) &&
              triangle_meets_tet(m_tri[std::size_t(f)], tets[std::size_t(s)]))
            return true;
        return false;
      }))
    return true;
  // No triangle meets the union of the tets, which is connected (all hold the diagonal): one point decides.
  return contains(0.5 * (corners[0] + corners[7]));
}

double inscribed_radius(const sim::TriMesh& closed_mesh) {
  const BladeVolume blade(closed_mesh);
  const Box3 b = blade.bounds();
  const double diag = (b.max - b.min).norm();
  // Signed distance: positive inside. 1-Lipschitz.
  auto signed_distance = [&](const Vec3& x) {
    const double d = blade.distance(x);
    return blade.contains(x) ? d : -d;
  };

  // Best-first branch and bound over an octree of cells; `upper` bounds the signed distance within the cell.
  struct Cell {
    Vec3 centre;          // m
    double half = 0.0;    // half edge, m
    double upper = 0.0;   // m
    std::uint64_t id = 0; // creation order, breaks ties deterministically
  };
  auto lower_priority = [](const Cell& x, const Cell& y) { return x.upper < y.upper || (x.upper == y.upper && x.id > y.id); };
  std::priority_queue<Cell, std::vector<Cell>, decltype(lower_priority)> queue(lower_priority);
  constexpr double kRelTol = 5e-3;
  constexpr int kBudget = 10000;
  double best = 0.0;
  std::vector<std::pair<double, Vec3>> seeds;  // the best few inside points, for the polish
  std::uint64_t next_id = 0;
  int evaluations = 0;
  auto consider = [&](const Vec3& centre, double half) {
    const double delta = std::sqrt(3.0) * half;
    const double d = blade.distance(centre);
    ++evaluations;
    if (d + delta <= best * (1.0 + kRelTol)) return;  // nothing in the cell can improve the answer enough
    const double f = blade.contains(centre) ? d : -d;
    if (f > best) {
      best = f;
      seeds.emplace_back(f, centre);
    }
    queue.push(Cell{centre, half, f + delta, next_id++});
  };
  const double half0 = 0.5 * (b.max - b.min).maxCoeff();
  consider(0.5 * (b.min + b.max), half0);
  double last_half = half0;
  while (!queue.empty() && evaluations < kBudget) {
    const Cell cell = queue.top();
    queue.pop();
    if (cell.upper <= best * (1.0 + kRelTol)) break;
    const double h = 0.5 * cell.half;
    last_half = h;
    for (int k = 0; k < 8; ++k)
      consider(cell.centre + h * Vec3((k & 1) ? 1.0 : -1.0, (k & 2) ? 1.0 : -1.0, (k & 4) ? 1.0 : -1.0), h);
  }

  // Polish the best few points by compass search over the 26 lattice directions, halving the step when stuck.
  std::sort(seeds.begin(), seeds.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  if (seeds.size() > 4) seeds.resize(4);
  std::array<Vec3, 26> dirs{};
  for (int k = 0, n = 0; k < 27; ++k)
    if (k != 13) dirs[std::size_t(n++)] = Vec3(k % 3 - 1, k / 3 % 3 - 1, k / 9 - 1).normalized();
  for (auto [f, x] : seeds) {
    double step = last_half;
    for (int it = 0; it < 500 && step > 1e-7 * diag; ++it) {
      double fbest = f;
      Vec3 xbest = x;
      for (const Vec3& u : dirs) {
        const Vec3 y = x + step * u;
        const double fy = signed_distance(y);
        if (fy > fbest) {
          fbest = fy;
          xbest = y;
        }
      }
      if (fbest > f) {
        f = fbest;
        x = xbest;
      } else {
        step *= 0.5;
      }
    }
    best = std::max(best, f);
  }
  return best;
}

std::vector<int> tets_touched(const sim::MaterialGraph& graph, const BladeVolume& blade) {
  std::vector<int> out;
  for (int t : graph.tets_near(blade.bounds()))
    if (blade.overlaps_tet(graph.tet(t))) out.push_back(t);
  return out;
}

}  // namespace octocut::cutting
