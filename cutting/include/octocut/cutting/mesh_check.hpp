#pragma once
// Self-intersection test for triangle surfaces (SPEC §2.4, §4). CGAL stays inside mesh_check.cpp; no CGAL type
// appears here.
#include <array>
#include <optional>

#include "octocut/sim/surface.hpp"

namespace octocut::cutting {

/// Finds two triangles of `mesh` that intersect other than through a shared vertex or a shared edge, with exact
/// predicates (CGAL, Exact_predicates_inexact_constructions_kernel). Returns the pair {a, b}, a < b, that is
/// lexicographically smallest among all intersecting pairs, so the answer does not depend on traversal order; or
/// nothing when the surface does not self-intersect. The mesh must be edge- and vertex-manifold with no degenerate
/// triangles (sim::check_surface and the loader's validation check this first); otherwise std::invalid_argument
/// names the offending triangle.
std::optional<std::array<int, 2>> find_self_intersection(const sim::TriMesh& mesh);

}  // namespace octocut::cutting
