#pragma once
// Primitives as meshes: boxes (the closed surface S and the material graph M of a box object that tools cut, the
// faces a box is drawn with) and cylinders (blades, punches).
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::sim {

/// The closed surface of `box` (m) as a welded grid with about `cells` cells along its longest edge and at least one
/// along every edge: outward-oriented, manifold, vertices shared along the box's edges. The grid coordinates on
/// the box's upper faces are the box's own bounds, so that faces meet exactly.
TriMesh closed_box_grid(const Box3& box, int cells);

/// The six faces of `box` (m) as the same grids as closed_box_grid, but each face with its own vertices (nothing is
/// shared along the box's edges), so that the box keeps sharp edges when shaded. Outward, counter-clockwise.
TriMesh box_face_grids(const Box3& box, int cells);

/// A closed, outward-oriented cylinder of `segments` sides about the z axis, centred on the origin: z spans
/// [-height/2, height/2], the rim vertices lie on the circle of `radius` (m). Vertices: the bottom ring (0..n-1, the
/// first on +x), the top ring (n..2n-1), the bottom centre (2n), the top centre (2n+1); 4n triangles. Its volume is
/// n/2 r^2 sin(2 pi / n) h. Throws std::invalid_argument for a radius or height that is not a positive finite
/// number, or segments < 3.
TriMesh cylinder_mesh(double radius, double height, int segments);

/// A conforming tetrahedral mesh of `box` (m) at about `cell` (m): a grid of ceil(edge / cell) cubes per axis, each
/// split into 6 positively oriented tets around its main diagonal (Kuhn). Its material is exactly the box.
TetMesh box_tet_mesh(const Box3& box, double cell);

}  // namespace octocut::sim
