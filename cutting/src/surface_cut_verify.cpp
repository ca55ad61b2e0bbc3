// Phase 4 of the surface boolean S \ B' (surface_cut_phases.hpp): the local verification of S' after the write-back.
// Uses CGAL's exact predicates (collinearity, triangle intersections) and its box intersection, but builds no CGAL
// mesh. Nothing is a pass over S: the unchanged neighbours of the changed faces come from the grid.
#include "cgal_exact.hpp"  // first: the exact number type of Epeck

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
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
  check_self_intersections(out, written, first_inserted, unchanged_neighbours(out, grid, written.changed, arcs));
}

}  // namespace octocut::cutting::surface_cut_detail
