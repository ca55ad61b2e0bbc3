#pragma once
// Generation of the material graph M (SPEC §2.2) by CGAL Mesh_3. CGAL stays inside material_mesher.cpp.
#include <stdexcept>
#include <string>

#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::cutting {

/// Meshing failed (CGAL precondition, empty result). The message says why.
class MeshingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Version of the meshing recipe (criteria, options, CGAL's exact number type, cutting/src/cgal_exact.hpp). Part of
/// the cache key: changing the recipe must bump it. 2: Epeck's exact type became Quotient<Mpzf>.
inline constexpr int kMesherVersion = 2;

/// Tetrahedralises the interior of a closed, outward-oriented surface with CGAL Mesh_3 at `cell_size` (m):
/// facet size and tet size cell_size, facet distance cell_size / 10, facet angle 25°, radius–edge ratio 3; no
/// perturbation or exudation (M only needs to cover the volume). Deterministic: a fixed random seed, sequential.
/// Throws MeshingError.
sim::TetMesh mesh_interior(const sim::TriMesh& surface, double cell_size);

}  // namespace octocut::cutting
