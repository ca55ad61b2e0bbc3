#include "octocut/sim/surface_check.hpp"

#include "octocut/sim/disjoint_sets.hpp"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace octocut::sim {
namespace {

/// One use of an undirected edge by a triangle.
struct EdgeUse {
  int32_t lo = 0;        ///< smaller vertex index
  int32_t hi = 0;        ///< larger vertex index
  int32_t triangle = 0;  ///< the triangle that uses the edge
  bool forward = false;  ///< the triangle runs lo -> hi (false: hi -> lo)
};

/// True when the triangle names one vertex twice; such a triangle has no proper edges.
bool has_repeated_vertex(const std::array<int32_t, 3>& t) { return t[0] == t[1] || t[1] == t[2] || t[0] == t[2]; }

/// Fills an offender record from a run [first, last) of uses of one edge.
EdgeOffender offender(const std::vector<EdgeUse>& uses, std::size_t first, std::size_t last, int32_t other) {
  EdgeOffender o;
  o.edge = {uses[first].lo, uses[first].hi};
  o.triangle = uses[first].triangle;
  o.other_triangle = other;
  o.uses = static_cast<int32_t>(last - first);
  return o;
}

}  // namespace

SurfaceCheck check_surface(const TriMesh& mesh) {
  SurfaceCheck check;
  const auto num_vertices = static_cast<int64_t>(mesh.vertices.size());

  // Reject out-of-range indices before anything indexes with them.
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (const int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= num_vertices) {
        throw std::invalid_argument("triangle " + std::to_string(f) + " has vertex index " + std::to_string(v) +
                                    ", outside [0, " + std::to_string(num_vertices) + ")");
      }
    }
  }

  // Every proper edge use, sorted so that the uses of one undirected edge are adjacent and in triangle order.
  std::vector<EdgeUse> uses;
  uses.reserve(mesh.triangles.size() * 3);
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    if (has_repeated_vertex(t)) continue;
    for (int k = 0; k < 3; ++k) {
      const int32_t a = t[static_cast<std::size_t>(k)];
      const int32_t b = t[static_cast<std::size_t>((k + 1) % 3)];
      uses.push_back({std::min(a, b), std::max(a, b), static_cast<int32_t>(f), a < b});
    }
  }
  std::sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
    if (x.lo != y.lo) return x.lo < y.lo;
    if (x.hi != y.hi) return x.hi < y.hi;
    if (x.triangle != y.triangle) return x.triangle < y.triangle;
    return x.forward < y.forward;
  });

  // Classify each undirected edge by how many triangles use it and in which directions.
  for (std::size_t first = 0; first < uses.size();) {
    std::size_t last = first + 1;
    while (last < uses.size() && uses[last].lo == uses[first].lo && uses[last].hi == uses[first].hi) ++last;
    const std::size_t count = last - first;
    if (count != 2) check.closed = false;
    if (count == 1 && !check.boundary_edge.found()) check.boundary_edge = offender(uses, first, last, -1);
    if (count > 2) {
      check.edge_manifold = false;
      if (!check.nonmanifold_edge.found()) {
        check.nonmanifold_edge = offender(uses, first, last, uses[first + 1].triangle);
      }
    }
    if (count == 2 && uses[first].forward == uses[first + 1].forward) {
      check.oriented = false;
      if (!check.misoriented_edge.found()) {
        check.misoriented_edge = offender(uses, first, last, uses[first + 1].triangle);
      }
    }
    first = last;
  }

  // Triangles incident to each vertex (compressed rows), proper triangles only.
  const auto nv = static_cast<std::size_t>(num_vertices);
  std::vector<int32_t> row_start(nv + 1, 0);
  for (const auto& t : mesh.triangles) {
    if (has_repeated_vertex(t)) continue;
    for (const int32_t v : t) ++row_start[static_cast<std::size_t>(v) + 1];
  }
  std::partial_sum(row_start.begin(), row_start.end(), row_start.begin());
  std::vector<int32_t> incident(static_cast<std::size_t>(row_start[nv]));
  {
    std::vector<int32_t> fill(row_start.begin(), row_start.end() - 1);
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
      const auto& t = mesh.triangles[f];
      if (has_repeated_vertex(t)) continue;
      for (const int32_t v : t) {
        incident[static_cast<std::size_t>(fill[static_cast<std::size_t>(v)]++)] = static_cast<int32_t>(f);
      }
    }
  }

  // Around each vertex, link triangles that share a second vertex (an edge at v); one fan means one linked group.
  std::vector<std::pair<int32_t, int32_t>> spokes;  // (other vertex, local triangle index)
  for (std::size_t v = 0; v < nv; ++v) {
    const int32_t begin = row_start[v];
    const int32_t end = row_start[v + 1];
    if (end - begin < 2) continue;
    spokes.clear();
    for (int32_t i = begin; i < end; ++i) {
      const auto& t = mesh.triangles[static_cast<std::size_t>(incident[static_cast<std::size_t>(i)])];
      for (const int32_t u : t) {
        if (u != static_cast<int32_t>(v)) spokes.emplace_back(u, i - begin);
      }
    }
    std::sort(spokes.begin(), spokes.end());
    DisjointSets fans(static_cast<std::size_t>(end - begin));
    for (std::size_t s = 1; s < spokes.size(); ++s) {
      if (spokes[s].first == spokes[s - 1].first) fans.unite(spokes[s].second, spokes[s - 1].second);
    }
    int32_t count = 0;
    for (int32_t i = 0; i < end - begin; ++i) count += fans.find(i) == i ? 1 : 0;
    if (count > 1) {
      check.vertex_manifold = false;
      check.nonmanifold_vertex = static_cast<int32_t>(v);
      check.nonmanifold_vertex_fans = count;
      break;
    }
  }

  // Connected components: vertices joined by triangles, counted over the vertices that some triangle uses.
  DisjointSets parts(nv);
  std::vector<char> used(nv, 0);
  for (const auto& t : mesh.triangles) {
    for (const int32_t v : t) used[static_cast<std::size_t>(v)] = 1;
    parts.unite(t[0], t[1]);
    parts.unite(t[1], t[2]);
  }
  for (std::size_t v = 0; v < nv; ++v) {
    if (used[v] && parts.find(static_cast<int32_t>(v)) == static_cast<int32_t>(v)) ++check.components;
  }
  return check;
}

}  // namespace octocut::sim
