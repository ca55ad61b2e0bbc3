// CGAL Mesh_3 behind cutting::mesh_interior. This is one of the few translation units that include CGAL.
#include "octocut/cutting/material_mesher.hpp"

#include "cgal_exact.hpp"  // first: the exact number type of Epeck

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Polyhedral_mesh_domain_3.h>
#include <CGAL/Random.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/make_mesh_3.h>

#include <unordered_map>

namespace octocut::cutting {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using SurfaceMesh = CGAL::Surface_mesh<Point>;
using Domain = CGAL::Polyhedral_mesh_domain_3<SurfaceMesh, Kernel>;
using Triangulation = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using Complex = CGAL::Mesh_complex_3_in_triangulation_3<Triangulation>;
using Criteria = CGAL::Mesh_criteria_3<Triangulation>;

}  // namespace

sim::TetMesh mesh_interior(const sim::TriMesh& surface, double h) {
  if (!(h > 0.0) || !std::isfinite(h))
    throw MeshingError("material graph: cell_size must be positive and finite");
  if (surface.triangles.empty()) throw MeshingError("material graph: the surface has no triangles");
  try {
    // The surface as a CGAL mesh.
    SurfaceMesh sm;
    std::vector<SurfaceMesh::Vertex_index> vi;
    vi.reserve(surface.vertices.size());
    for (const sim::Vec3& p : surface.vertices) vi.push_back(sm.add_vertex(Point(p.x(), p.y(), p.z())));
    for (const auto& t : surface.triangles) {
      if (sm.add_face(vi[std::size_t(t[0])], vi[std::size_t(t[1])], vi[std::size_t(t[2])]) ==
          SurfaceMesh::null_face())
        throw MeshingError("material graph: the surface is not a manifold mesh");
    }

    // Mesh the interior with a fixed seed so that the result is reproducible.
    CGAL::Random rng(0);
    Domain domain(sm, &rng);
    using namespace CGAL::parameters;
    Criteria criteria(facet_angle = 25.0, facet_size = h, facet_distance = 0.1 * h, cell_radius_edge_ratio = 3.0,
                      cell_size = h);
    const Complex c3t3 = CGAL::make_mesh_3<Complex>(domain, criteria, no_perturb(), no_exude());

    // Collect the tets in the complex, numbering vertices in order of first use.
    sim::TetMesh out;
    std::unordered_map<Triangulation::Vertex_handle, int32_t> index;
    for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c) {
      std::array<int32_t, 4> tet{};
      for (int k = 0; k < 4; ++k) {
        const auto v = c->vertex(k);
        auto [it, inserted] = index.try_emplace(v, int32_t(out.vertices.size()));
        if (inserted) {
          const auto& p = v->point();
          out.vertices.emplace_back(CGAL::to_double(p.x()), CGAL::to_double(p.y()), CGAL::to_double(p.z()));
        }
        tet[std::size_t(k)] = it->second;
      }
      // Positive orientation: (b−a)·((c−a)×(d−a)) > 0.
      const sim::Vec3& a = out.vertices[std::size_t(tet[0])];
      const double v = (out.vertices[std::size_t(tet[1])] - a)
                           .dot((out.vertices[std::size_t(tet[2])] - a).cross(out.vertices[std::size_t(tet[3])] - a));
      if (v < 0.0) std::swap(tet[2], tet[3]);
      out.tets.push_back(tet);
    }
    if (out.tets.empty())
      throw MeshingError("material graph: Mesh_3 produced no tetrahedra (is the surface closed, and is cell_size "
                         "small enough for the object?)");
    return out;
  } catch (const CGAL::Failure_exception& e) {
    throw MeshingError(std::string("material graph: CGAL failed: ") + e.what());
  }
}

}  // namespace octocut::cutting
