#pragma once
// The blade as a solid (SPEC §4, paper §4.1, §4.3, §4.4.1): inside tests and overlap tests against octree cells,
// deformed hexahedra and the tets of the material graph M, plus the inscribed-sphere radius that sets the refinement
// oracle l_e = r / √3. Plain double arithmetic with a bounding volume hierarchy; no CGAL.
#include <array>
#include <cstdint>
#include <vector>

#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/surface.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::cutting {

/// A closed, outward-oriented triangle mesh seen as a solid (the blade B in physical space or B' in rest space), with
/// a bounding volume hierarchy over its triangles for the queries. All queries treat the solid as closed: a point on
/// the surface is inside, and solids that only touch overlap. Immutable after construction; queries are const and
/// may run concurrently.
///
/// Overlap of the solid with a cell X (box, tet, or the tets of a hexahedron) is decided as: some blade triangle
/// meets X, or else X lies wholly inside or wholly outside the solid, which one point of X decides (X is connected
/// and does not meet the surface). A blade that lies inside X is caught by the triangle test. Triangle–box: the 13
/// separating axes of Akenine-Möller. Triangle–tet: the triangle clipped by the tet's four half-spaces, or
/// separating axes when the tet has no volume. Near-touching configurations (within ~1e-12 relative) count as
/// meeting, so rounding errs towards overlap.
class BladeVolume {
 public:
  /// Takes the blade surface. Closedness and orientation are the caller's contract (cutting/mesh_check.hpp and
  /// sim::check_surface test them); here only the data is checked. Throws std::invalid_argument for a mesh without
  /// triangles, a vertex index out of range or a non-finite coordinate.
  explicit BladeVolume(sim::TriMesh mesh);

  /// The blade surface, m.
  [[nodiscard]] const sim::TriMesh& mesh() const { return m_mesh; }
  /// Axis-aligned bounding box of the blade, m.
  [[nodiscard]] sim::Box3 bounds() const { return m_bounds; }

  /// True when p (m) is inside the closed solid. Points within 1e-10 of the blade's bounding-box diagonal of the
  /// surface count as inside. Ray parity with watertight edge tests (each edge's side of the ray is computed once,
  /// in a canonical vertex order); a ray that passes through an edge or a vertex, up to rounding, is retried along the
  /// next of a fixed list of 8 directions (the winding number decides if all 8 are degenerate), so the answer is
  /// deterministic.
  [[nodiscard]] bool contains(const sim::Vec3& p) const;

  /// Unsigned distance from p to the blade surface, m.
  [[nodiscard]] double distance(const sim::Vec3& p) const;

  /// True when the solid meets the closed axis-aligned box (a box with zero extent along some axes is allowed; a box
  /// with min > max on some axis is empty).
  [[nodiscard]] bool overlaps_box(const sim::Box3& box) const;

  /// True when the solid meets the closed tetrahedron `tet` (corners in m, any orientation, degenerate allowed); a
  /// tet with a non-finite corner meets nothing.
  [[nodiscard]] bool overlaps_tet(const std::array<sim::Vec3, 4>& tet) const;

  /// True when the solid meets the deformed hexahedron with corners `corners` (m, 8; corner k has the bits x = k&1,
  /// y = k>>1&1, z = k>>2&1), taken as the union of its six tetrahedra around the diagonal 0–7. Inverted and
  /// degenerate hexahedra are answered by the same rule and never fail; a hexahedron with a non-finite corner meets
  /// nothing.
  [[nodiscard]] bool overlaps_hexahedron(const std::array<sim::Vec3, 8>& corners) const;

 private:
  /// A BVH node: an inner node has two children (first child at `first`, second at `first + 1`, count 0); a leaf
  /// holds triangles m_order[first, first + count).
  struct Node {
    sim::Box3 box;  ///< bounds of the node's triangles, m
    int first = 0;  ///< first child node, or first entry of m_order for a leaf
    int count = 0;  ///< number of triangles of a leaf; 0 for an inner node
  };

  // Builds the subtree for m_order[begin, end) into node `n`.
  void build(int n, int begin, int end);
  // Depth-first over the nodes whose box passes node_test(box), calling visit(triangle) for the triangles of the
  // leaves reached; stops and returns true as soon as visit returns true.
  template <class NodeTest, class Visit>
  bool traverse(NodeTest&& node_test, Visit&& visit) const;
  // Calls visit(triangle) for the triangles whose bounding box meets `box`, until one returns true.
  template <class Visit>
  bool any_triangle_near(const sim::Box3& box, Visit&& visit) const;
  // Ray parity along direction k of the fixed list: 1 inside, 0 outside, -1 when the ray meets an edge or a vertex.
  int parity(const sim::Vec3& p, int k) const;
  // Sum of the triangles' solid angles seen from p over 4π (the winding number), the last resort of contains().
  double winding_number(const sim::Vec3& p) const;

  sim::TriMesh m_mesh;
  sim::Box3 m_bounds;                      ///< bounding box of the vertices, m
  double m_eps = 0.0;                      ///< on-surface tolerance, m (1e-10 of the bounds' diagonal)
  std::vector<std::array<sim::Vec3, 3>> m_tri;  ///< triangle corners, m (|F|)
  std::vector<sim::Box3> m_tri_box;        ///< triangle bounding boxes, m (|F|)
  std::vector<int> m_order;                ///< triangle indices in BVH leaf order (|F|)
  std::vector<Node> m_nodes;               ///< BVH nodes, root at 0 (< 2 |F|)
};

/// Radius of the largest ball inside the closed mesh, m: the r of paper §4.4.1 (refinement edge l_e = r / √3).
/// Maximises the signed distance to the surface (positive inside), first by best-first branch and bound over an
/// octree of cells (the signed distance is 1-Lipschitz, so a cell of centre c and half-diagonal δ holds no value
/// above f(c) + δ) until the bound is within 0.5% or 10000 cells are evaluated, then polishes the 4 best points by
/// compass search in the 26 lattice directions down to steps of 1e-7 of the bounding-box diagonal. The result is a
/// value attained inside the solid, so it never overestimates (beyond the on-surface tolerance); on cylinders,
/// boxes, sphere meshes and star prisms, rotated or not, it matches the analytic value to 1e-7 relative. Costs
/// about 10–40 ms for 40–1000 triangles: compute it once per blade. Throws std::invalid_argument as BladeVolume
/// does.
double inscribed_radius(const sim::TriMesh& closed_mesh);

/// Indices of the live tets of M that meet the blade solid, ascending (candidates from MaterialGraph::tets_near on
/// the blade's bounds, then BladeVolume::overlaps_tet).
std::vector<int> tets_touched(const sim::MaterialGraph& graph, const BladeVolume& blade);

}  // namespace octocut::cutting
