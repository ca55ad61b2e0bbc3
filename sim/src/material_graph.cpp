#include "octocut/sim/material_graph.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace octocut::sim {

namespace {

using Tet = std::array<Vec3, 4>;

double signed_tet_volume(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  return (b - a).dot((c - a).cross(d - a)) / 6.0;
}

double tet_volume(const Tet& t) { return std::abs(signed_tet_volume(t[0], t[1], t[2], t[3])); }

// The point where segment (a, b) crosses the plane x[axis] = c, given the signed distances da <= 0 < db; the
// coordinate along the axis is set exactly to c so that pieces on either side share their cut face.
Vec3 crossing(const Vec3& a, const Vec3& b, double da, double db, int axis, double c) {
  const double t = da / (da - db);
  Vec3 p = a + t * (b - a);
  p[axis] = c;
  return p;
}

// Keeps the part of each tet on the side sign * (x[axis] − c) <= 0 of the plane. A tet cut by the plane becomes
// one tet (1 vertex inside) or a prism of 3 tets (2 or 3 vertices inside).
void clip_tets(const std::vector<Tet>& in, std::vector<Tet>& out, int axis, double c, double sign) {
  out.clear();
  for (const Tet& t : in) {
    std::array<double, 4> d{};
    std::array<int, 4> inside{}, outside{};
    int ni = 0, no = 0;
    for (int k = 0; k < 4; ++k) {
      d[std::size_t(k)] = sign * (t[std::size_t(k)][axis] - c);
      if (d[std::size_t(k)] <= 0.0) inside[std::size_t(ni++)] = k;
      else outside[std::size_t(no++)] = k;
    }
    if (ni == 0) continue;
    if (no == 0) {
      out.push_back(t);
      continue;
    }
    auto X = [&](int i, int o) {
      return crossing(t[std::size_t(i)], t[std::size_t(o)], d[std::size_t(i)], d[std::size_t(o)], axis, c);
    };
    // A prism with triangles (p0, p1, p2) and (q0, q1, q2), pi joined to qi by planar quads, as three tets.
    auto prism = [&](const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& q0, const Vec3& q1,
                     const Vec3& q2) {
      out.push_back({p0, p1, p2, q0});
      out.push_back({p1, p2, q0, q1});
      out.push_back({p2, q0, q1, q2});
    };
    if (ni == 1) {
      const int a = inside[0];
      out.push_back({t[std::size_t(a)], X(a, outside[0]), X(a, outside[1]), X(a, outside[2])});
    } else if (ni == 3) {
      const int o = outside[0];
      prism(t[std::size_t(inside[0])], t[std::size_t(inside[1])], t[std::size_t(inside[2])], X(inside[0], o),
            X(inside[1], o), X(inside[2], o));
    } else {
      const int a = inside[0], b = inside[1], c0 = outside[0], c1 = outside[1];
      prism(t[std::size_t(a)], X(a, c0), X(a, c1), t[std::size_t(b)], X(b, c0), X(b, c1));
    }
  }
}

// Area of a convex polygon in 2D by the shoelace formula (any orientation).
template <class Points>
double polygon_area(const Points& p, std::size_t n) {
  double s = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const auto& a = p[i];
    const auto& b = p[(i + 1) % n];
    s += a.x() * b.y() - a.y() * b.x();
  }
  return 0.5 * std::abs(s);
}

// A convex polygon of at most 8 vertices in 2D (a tet's section has at most 4; each clip by a line adds at most 1).
struct Polygon {
  std::array<Eigen::Vector2d, 8> p;
  std::size_t n = 0;
  void push(const Eigen::Vector2d& v) { p[n++] = v; }
};

// Keeps the part of a convex polygon with sign * (p[k] − c) <= 0 (Sutherland–Hodgman against one line).
Polygon clip_polygon(const Polygon& poly, int k, double c, double sign) {
  Polygon out;
  const std::size_t n = poly.n;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& a = poly.p[i];
    const Eigen::Vector2d& b = poly.p[(i + 1) % n];
    const double da = sign * (a[k] - c), db = sign * (b[k] - c);
    if (da <= 0.0) out.push(a);
    if ((da <= 0.0) != (db <= 0.0)) {
      Eigen::Vector2d q = a + (da / (da - db)) * (b - a);
      q[k] = c;
      out.push(q);
    }
  }
  return out;
}

}  // namespace

double clip_tet_box_volume(const Tet& tet, const Box3& box) {
  // Fast paths: the tet's bounding box inside the box, or apart from it.
  Vec3 lo = tet[0], hi = tet[0];
  for (int k = 1; k < 4; ++k) {
    lo = lo.cwiseMin(tet[std::size_t(k)]);
    hi = hi.cwiseMax(tet[std::size_t(k)]);
  }
  if ((lo.array() >= box.min.array()).all() && (hi.array() <= box.max.array()).all()) return tet_volume(tet);
  if ((hi.array() <= box.min.array()).any() || (lo.array() >= box.max.array()).any()) return 0.0;

  // Clip by each of the six planes that actually cuts the tet, in two buffers per thread that keep their storage
  // from call to call (a refinement measures thousands of leaves, most of them cut by a plane or two).
  thread_local std::vector<Tet> a, b;
  a.assign(1, tet);
  for (int axis = 0; axis < 3; ++axis) {
    if (lo[axis] < box.min[axis]) {
      clip_tets(a, b, axis, box.min[axis], -1.0);
      a.swap(b);
    }
    if (hi[axis] > box.max[axis]) {
      clip_tets(a, b, axis, box.max[axis], 1.0);
      a.swap(b);
    }
    if (a.empty()) return 0.0;
  }
  double v = 0.0;
  for (const Tet& t : a) v += tet_volume(t);
  return v;
}

double tet_face_section_area(const Tet& tet, const Box3& face, int axis) {
  const double c = face.min[axis];
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  // Section points: vertices on the plane and crossings of edges with vertices strictly on either side.
  std::array<double, 4> d{};
  for (int k = 0; k < 4; ++k) d[std::size_t(k)] = tet[std::size_t(k)][axis] - c;
  Polygon pts;
  for (int k = 0; k < 4; ++k)
    if (d[std::size_t(k)] == 0.0) pts.push({tet[std::size_t(k)][u], tet[std::size_t(k)][w]});
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) {
      const double di = d[std::size_t(i)], dj = d[std::size_t(j)];
      if ((di < 0.0 && dj > 0.0) || (di > 0.0 && dj < 0.0)) {
        const Vec3 p = tet[std::size_t(i)] + (di / (di - dj)) * (tet[std::size_t(j)] - tet[std::size_t(i)]);
        pts.push({p[u], p[w]});
      }
    }
  }
  if (pts.n < 3) return 0.0;
  // Order the (at most four, convex) section points by angle about their centroid.
  Eigen::Vector2d m = Eigen::Vector2d::Zero();
  for (std::size_t k = 0; k < pts.n; ++k) m += pts.p[k];
  m /= double(pts.n);
  std::array<std::pair<double, Eigen::Vector2d>, 4> by_angle;
  for (std::size_t k = 0; k < pts.n; ++k)
    by_angle[k] = {std::atan2(pts.p[k].y() - m.y(), pts.p[k].x() - m.x()), pts.p[k]};
  std::sort(by_angle.begin(), by_angle.begin() + std::ptrdiff_t(pts.n),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  for (std::size_t k = 0; k < pts.n; ++k) pts.p[k] = by_angle[k].second;
  // Restrict to the face rectangle.
  pts = clip_polygon(pts, 0, face.min[u], -1.0);
  if (pts.n >= 3) pts = clip_polygon(pts, 0, face.max[u], 1.0);
  if (pts.n >= 3) pts = clip_polygon(pts, 1, face.min[w], -1.0);
  if (pts.n >= 3) pts = clip_polygon(pts, 1, face.max[w], 1.0);
  return pts.n >= 3 ? polygon_area(pts.p, pts.n) : 0.0;
}

// The immutable part of M, shared by all revisions made by without().
struct MaterialGraph::Geometry {
  TetMesh mesh;
  std::vector<Box3> tet_box;        ///< bounding box of each tet, m (|T|)
  std::vector<double> tet_volume;   ///< m^3 (|T|)
  Box3 bounds;                      ///< bounding box of all tets, m; the grid's origin
  std::array<int, 3> dims{1, 1, 1}; ///< grid cells per axis
  Vec3 cell = Vec3::Ones();         ///< grid cell edge per axis, m
  std::vector<int> cell_begin;      ///< CSR offsets into cell_tets (cells + 1)
  std::vector<int> cell_tets;       ///< tet indices per grid cell, ascending within a cell
  std::vector<std::array<int, 3>> tet_cell;  ///< lowest grid cell of each tet's range, per axis (|T|)

  [[nodiscard]] Tet tet(int t) const {
    const auto& q = mesh.tets[std::size_t(t)];
    return {mesh.vertices[std::size_t(q[0])], mesh.vertices[std::size_t(q[1])], mesh.vertices[std::size_t(q[2])],
            mesh.vertices[std::size_t(q[3])]};
  }
};

MaterialGraph::MaterialGraph(TetMesh mesh) {
  auto geo = std::make_shared<Geometry>();
  geo->mesh = std::move(mesh);
  TetMesh& m = geo->mesh;
  const int nv = int(m.vertices.size());
  for (std::size_t i = 0; i < m.vertices.size(); ++i)
    if (!m.vertices[i].allFinite())
      throw std::invalid_argument("material graph: vertex " + std::to_string(i) + " is not finite");

  // Orient every tet positively and drop tets without volume.
  std::vector<std::array<int32_t, 4>> kept;
  kept.reserve(m.tets.size());
  for (std::size_t t = 0; t < m.tets.size(); ++t) {
    auto tet = m.tets[t];
    for (int32_t i : tet)
      if (i < 0 || i >= nv)
        throw std::invalid_argument("material graph: tet " + std::to_string(t) + " has a vertex index out of range");
    const double v = signed_tet_volume(m.vertices[std::size_t(tet[0])], m.vertices[std::size_t(tet[1])],
                                       m.vertices[std::size_t(tet[2])], m.vertices[std::size_t(tet[3])]);
    if (v == 0.0) continue;
    if (v < 0.0) std::swap(tet[2], tet[3]);
    kept.push_back(tet);
  }
  m.tets = std::move(kept);
  if (m.tets.empty()) throw std::invalid_argument("material graph: no tetrahedra with volume");

  // Per-tet bounds and volumes.
  const std::size_t nt = m.tets.size();
  geo->tet_box.resize(nt);
  geo->tet_volume.resize(nt);
  geo->bounds.min = Vec3::Constant(std::numeric_limits<double>::infinity());
  geo->bounds.max = -geo->bounds.min;
  for (std::size_t t = 0; t < nt; ++t) {
    const Tet p = geo->tet(int(t));
    Box3 b{p[0], p[0]};
    for (int k = 1; k < 4; ++k) {
      b.min = b.min.cwiseMin(p[std::size_t(k)]);
      b.max = b.max.cwiseMax(p[std::size_t(k)]);
    }
    geo->tet_box[t] = b;
    geo->tet_volume[t] = sim::tet_volume(p);
    geo->bounds.min = geo->bounds.min.cwiseMin(b.min);
    geo->bounds.max = geo->bounds.max.cwiseMax(b.max);
  }

  // Uniform grid with cells about as big as a tet's bounding box: the cube root of the bounding volume per tet,
  // or the mean largest extent of the tets' boxes when that is bigger (a box holds ~6x its tet's volume). Finer
  // cells would file every tet in dozens of cells, and each query would gather that many duplicates.
  const Vec3 ext = (geo->bounds.max - geo->bounds.min).cwiseMax(1e-12);
  double mean_extent = 0.0;
  for (const Box3& b : geo->tet_box) mean_extent += (b.max - b.min).maxCoeff();
  mean_extent /= double(nt);
  const double h = std::max(std::cbrt(ext.prod() / double(nt)), mean_extent);
  for (int a = 0; a < 3; ++a) {
    geo->dims[std::size_t(a)] = std::clamp(int(std::ceil(ext[a] / h)), 1, 256);
    geo->cell[a] = ext[a] / geo->dims[std::size_t(a)];
  }
  m_geo = geo;  // cell_range reads the grid through m_geo
  const auto& dims = geo->dims;
  const std::size_t ncells = std::size_t(dims[0]) * std::size_t(dims[1]) * std::size_t(dims[2]);
  auto cell_index = [&](int i, int j, int k) {
    return (std::size_t(k) * std::size_t(dims[1]) + std::size_t(j)) * std::size_t(dims[0]) + std::size_t(i);
  };
  // Two passes (count, fill) build the CSR lists; tets appear in ascending order in every cell.
  geo->cell_begin.assign(ncells + 1, 0);
  geo->tet_cell.resize(nt);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<int> fill;
    if (pass == 1) {
      for (std::size_t c = 0; c < ncells; ++c) geo->cell_begin[c + 1] += geo->cell_begin[c];
      geo->cell_tets.resize(std::size_t(geo->cell_begin[ncells]));
      fill.assign(geo->cell_begin.begin(), geo->cell_begin.end() - 1);
    }
    for (std::size_t t = 0; t < nt; ++t) {
      std::array<int, 3> lo{}, hi{};
      cell_range(geo->tet_box[t], lo, hi);
      if (pass == 0) geo->tet_cell[t] = lo;
      for (int k = lo[2]; k <= hi[2]; ++k)
        for (int j = lo[1]; j <= hi[1]; ++j)
          for (int i = lo[0]; i <= hi[0]; ++i) {
            const std::size_t c = cell_index(i, j, k);
            if (pass == 0) ++geo->cell_begin[c + 1];
            else geo->cell_tets[std::size_t(fill[c]++)] = int(t);
          }
    }
  }

  // Every tet is alive in the first revision.
  m_alive.assign(nt, 1);
  update_live_totals();
}

MaterialGraph::MaterialGraph(Key, std::shared_ptr<const Geometry> geometry, std::vector<uint8_t> alive)
    : m_geo(std::move(geometry)), m_alive(std::move(alive)) {
  update_live_totals();
}

void MaterialGraph::update_live_totals() {
  // Ascending order, so the volume is the same whatever sequence of removals led here.
  m_num_alive = 0;
  m_volume = 0.0;
  m_bounds.min = Vec3::Constant(std::numeric_limits<double>::infinity());
  m_bounds.max = -m_bounds.min;
  for (std::size_t t = 0; t < m_alive.size(); ++t) {
    if (!m_alive[t]) continue;
    ++m_num_alive;
    m_volume += m_geo->tet_volume[t];
    m_bounds.min = m_bounds.min.cwiseMin(m_geo->tet_box[t].min);
    m_bounds.max = m_bounds.max.cwiseMax(m_geo->tet_box[t].max);
  }
  if (m_num_alive == 0) m_bounds = m_geo->bounds;
}

std::shared_ptr<const MaterialGraph> MaterialGraph::without(std::span<const int> tets) const {
  std::vector<uint8_t> alive = m_alive;
  for (int t : tets) {
    if (t < 0 || t >= num_tets_total())
      throw std::invalid_argument("material graph: tet " + std::to_string(t) + " to remove is out of range [0, " +
                                  std::to_string(num_tets_total()) + ")");
    alive[std::size_t(t)] = 0;
  }
  return std::make_shared<const MaterialGraph>(Key{}, m_geo, std::move(alive));
}

const TetMesh& MaterialGraph::mesh() const { return m_geo->mesh; }

TetMesh MaterialGraph::live_mesh() const {
  TetMesh out;
  out.vertices = m_geo->mesh.vertices;
  out.tets.reserve(std::size_t(m_num_alive));
  for (std::size_t t = 0; t < m_alive.size(); ++t)
    if (m_alive[t]) out.tets.push_back(m_geo->mesh.tets[t]);
  return out;
}

int MaterialGraph::num_tets_total() const { return int(m_geo->mesh.tets.size()); }

double MaterialGraph::tet_volume(int t) const { return m_geo->tet_volume[std::size_t(t)]; }

std::array<Vec3, 4> MaterialGraph::tet(int t) const { return m_geo->tet(t); }

void MaterialGraph::cell_range(const Box3& box, std::array<int, 3>& lo, std::array<int, 3>& hi) const {
  const Geometry& g = *m_geo;
  for (int a = 0; a < 3; ++a) {
    const double l = std::floor((box.min[a] - g.bounds.min[a]) / g.cell[a]);
    const double u = std::floor((box.max[a] - g.bounds.min[a]) / g.cell[a]);
    lo[std::size_t(a)] = int(std::clamp(l, 0.0, double(g.dims[std::size_t(a)] - 1)));
    hi[std::size_t(a)] = int(std::clamp(u, 0.0, double(g.dims[std::size_t(a)] - 1)));
  }
}

template <class Visit>
bool MaterialGraph::visit_tets_near(const Box3& box, Visit&& visit) const {
  const Geometry& g = *m_geo;
  if (m_num_alive == 0) return false;
  if ((box.max.array() < m_bounds.min.array()).any() || (box.min.array() > m_bounds.max.array()).any()) return false;
  std::array<int, 3> lo{}, hi{};
  cell_range(box, lo, hi);
  const std::size_t cells = std::size_t(hi[0] - lo[0] + 1) * std::size_t(hi[1] - lo[1] + 1) *
                            std::size_t(hi[2] - lo[2] + 1);
  auto overlaps = [&](int t) {
    if (!m_alive[std::size_t(t)]) return false;
    const Box3& b = g.tet_box[std::size_t(t)];
    return (b.max.array() >= box.min.array()).all() && (b.min.array() <= box.max.array()).all();
  };
  // A box covering most of the grid: test every tet directly instead of walking the cells.
  if (cells * 4 > g.cell_begin.size()) {
    for (int t = 0; t < num_tets_total(); ++t)
      if (overlaps(t) && visit(t)) return true;
    return false;
  }
  // A tet filed in several cells of the range is visited once: from the first cell (lowest along each axis) that
  // its own range and the query's range share.
  for (int k = lo[2]; k <= hi[2]; ++k)
    for (int j = lo[1]; j <= hi[1]; ++j)
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const std::size_t c =
            (std::size_t(k) * std::size_t(g.dims[1]) + std::size_t(j)) * std::size_t(g.dims[0]) + std::size_t(i);
        for (int n = g.cell_begin[c]; n < g.cell_begin[c + 1]; ++n) {
          const int t = g.cell_tets[std::size_t(n)];
          const std::array<int, 3>& tlo = g.tet_cell[std::size_t(t)];
          if (std::max(tlo[0], lo[0]) != i || std::max(tlo[1], lo[1]) != j || std::max(tlo[2], lo[2]) != k) continue;
          if (overlaps(t) && visit(t)) return true;
        }
      }
  return false;
}

std::vector<int> MaterialGraph::tets_near(const Box3& box) const {
  std::vector<int> out;
  visit_tets_near(box, [&out](int t) {
    out.push_back(t);
    return false;
  });
  std::sort(out.begin(), out.end());
  return out;
}

double MaterialGraph::occupancy(const Box3& box) const {
  const double bv = box.volume();
  if (!(bv > 0.0)) return 0.0;
  double v = 0.0;
  // Live tets in ascending order: the sum is deterministic.
  for (int t : tets_near(box)) {
    const Box3& b = m_geo->tet_box[std::size_t(t)];
    if ((b.min.array() >= box.min.array()).all() && (b.max.array() <= box.max.array()).all())
      v += m_geo->tet_volume[std::size_t(t)];
    else
      v += clip_tet_box_volume(tet(t), box);
  }
  return std::clamp(v / bv, 0.0, 1.0);
}

bool MaterialGraph::face_connected(const Box3& face, int axis) const {
  // Positive area relative to the face, so that rounding in a crossing point cannot connect a mere edge contact.
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  const double threshold = 1e-12 * (face.max[u] - face.min[u]) * (face.max[w] - face.min[w]);
  // Any tet will do, so the tets are tried as the grid yields them, stopping at the first.
  return visit_tets_near(face, [&](int t) { return tet_face_section_area(tet(t), face, axis) > threshold; });
}

}  // namespace octocut::sim
