// Self-intersection test on a CGAL Surface_mesh. The only translation unit of the mesh checks that sees CGAL.
#include "octocut/cutting/mesh_check.hpp"

#include "cgal_exact.hpp"  // first: the exact number type of Epeck

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include <algorithm>
#include <iterator>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace octocut::cutting {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using Face = Mesh::Face_index;

}  // namespace

std::optional<std::array<int, 2>> find_self_intersection(const sim::TriMesh& mesh) {
  // Copy the vertices; Surface_mesh numbers them 0..|V|-1 in insertion order, like the input.
  Mesh surface;
  surface.reserve(static_cast<Mesh::size_type>(mesh.num_vertices()), 0,
                  static_cast<Mesh::size_type>(mesh.num_triangles()));
  std::vector<Mesh::Vertex_index> vertex;
  vertex.reserve(mesh.num_vertices());
  for (const sim::Vec3& p : mesh.vertices) vertex.push_back(surface.add_vertex(Point(p.x(), p.y(), p.z())));

  // Add the triangles in order, so that face index f is triangle f; reject what the predicates cannot take.
  const auto nv = static_cast<int64_t>(mesh.num_vertices());
  for (std::size_t f = 0; f < mesh.num_triangles(); ++f) {
    const auto& t = mesh.triangles[f];
    for (const int32_t v : t) {
      if (v < 0 || v >= nv) {
        throw std::invalid_argument("triangle " + std::to_string(f) + " has vertex index " + std::to_string(v) +
                                    ", outside [0, " + std::to_string(nv) + ")");
      }
    }
    const Point& a = surface.point(vertex[static_cast<std::size_t>(t[0])]);
    const Point& b = surface.point(vertex[static_cast<std::size_t>(t[1])]);
    const Point& c = surface.point(vertex[static_cast<std::size_t>(t[2])]);
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || CGAL::collinear(a, b, c)) {
      throw std::invalid_argument("triangle " + std::to_string(f) + " is degenerate");
    }
    const Face face = surface.add_face(vertex[static_cast<std::size_t>(t[0])], vertex[static_cast<std::size_t>(t[1])],
                                       vertex[static_cast<std::size_t>(t[2])]);
    if (face == Mesh::null_face()) {
      throw std::invalid_argument("triangle " + std::to_string(f) +
                                  " makes the surface non-manifold or inconsistently oriented");
    }
  }

  // Collect every intersecting pair, then return the smallest, which box_intersection_d's order cannot change.
  std::vector<std::pair<Face, Face>> pairs;
  CGAL::Polygon_mesh_processing::self_intersections(surface, std::back_inserter(pairs));
  if (pairs.empty()) return std::nullopt;
  std::array<int, 2> best{};
  bool first = true;
  for (const auto& [f, g] : pairs) {
    const int i = static_cast<int>(f.idx());
    const int j = static_cast<int>(g.idx());
    const std::array<int, 2> pair{std::min(i, j), std::max(i, j)};
    if (first || pair < best) best = pair;
    first = false;
  }
  return best;
}

}  // namespace octocut::cutting
