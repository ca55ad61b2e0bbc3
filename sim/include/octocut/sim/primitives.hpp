#pragma once
// Box primitives as meshes: the closed surface S and the material graph M of a box object that tools cut.
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::sim {

/// The closed surface of `box` (m) as a welded grid with about `cells` cells along its longest edge and at least one
/// along every edge: outward-oriented, manifold, vertices shared along the box's edges. The grid coordinates on
/// the box's upper faces are the box's own bounds, so that faces meet exactly.
TriMesh closed_box_grid(const Box3& box, int cells);

/// A conforming tetrahedral mesh of `box` (m) at about `cell` (m): a grid of ceil(edge / cell) cubes per axis, each
/// split into 6 positively oriented tets around its main diagonal (Kuhn). Its material is exactly the box.
TetMesh box_tet_mesh(const Box3& box, double cell);

}  // namespace octocut::sim
