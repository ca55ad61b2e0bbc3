#pragma once
// The material graph M (SPEC §2.2, paper §3 and §4.3): a tetrahedral mesh of the object's interior in rest space.
// It tells the octree which cells hold material (exact tet–box clipping) and which faces connect (tets meeting a
// face in positive area). Generation by CGAL Mesh_3 lives in cutting/; this header knows no CGAL.
#include <array>
#include <cstdint>
#include <vector>

#include "octocut/sim/material.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::sim {

/// A tetrahedral mesh. Tets are positively oriented: (b−a)·((c−a)×(d−a)) > 0.
struct TetMesh {
  std::vector<Vec3> vertices;                 ///< rest positions, m (|V|)
  std::vector<std::array<int32_t, 4>> tets;   ///< vertex indices (|T|)
};

/// Volume of the tetrahedron (a, b, c, d) that lies inside `box`, m^3: the tet is clipped by the box's six planes
/// and the pieces summed. Exact up to floating-point rounding, for any tet orientation.
double clip_tet_box_volume(const std::array<Vec3, 4>& tet, const Box3& box);

/// Area of the section of the tetrahedron with the plane x[axis] = face.min[axis], restricted to the axis-aligned
/// rectangle `face` (zero extent along axis), m^2. Zero when the tet only touches the rectangle along an edge or
/// at a point.
double tet_face_section_area(const std::array<Vec3, 4>& tet, const Box3& face, int axis);

/// M as a material source: occupancy and connectivity of octree cells, answered through a uniform grid over the
/// tets. Immutable once built; a cut (the cutting issue) makes a new graph without the removed tets.
class MaterialGraph final : public MaterialSource {
 public:
  /// Takes the mesh; reorients negatively oriented tets and drops tets of zero volume. Throws
  /// std::invalid_argument for an empty mesh, an index out of range or non-finite coordinates.
  explicit MaterialGraph(TetMesh mesh);

  [[nodiscard]] double occupancy(const Box3& box) const override;
  [[nodiscard]] bool face_connected(const Box3& face, int axis) const override;
  [[nodiscard]] Box3 bounds() const override { return m_bounds; }

  [[nodiscard]] const TetMesh& mesh() const { return m_mesh; }
  [[nodiscard]] int num_tets() const { return int(m_mesh.tets.size()); }
  /// Sum of the tet volumes, m^3.
  [[nodiscard]] double volume() const { return m_volume; }
  /// Indices of the tets whose bounding box overlaps `box` (closed boxes), ascending.
  [[nodiscard]] std::vector<int> tets_near(const Box3& box) const;
  [[nodiscard]] std::array<Vec3, 4> tet(int t) const;

 private:
  // Grid cells overlapped by a box, clamped to the grid: [lo, hi] per axis.
  void cell_range(const Box3& box, std::array<int, 3>& lo, std::array<int, 3>& hi) const;
  // Calls visit(t) once for each tet whose bounding box overlaps `box` (closed boxes), in grid order, until visit
  // returns true; returns whether it did.
  template <class Visit>
  bool visit_tets_near(const Box3& box, Visit&& visit) const;

  TetMesh m_mesh;
  std::vector<Box3> m_tet_box;        ///< bounding box of each tet, m (|T|)
  std::vector<double> m_tet_volume;   ///< m^3 (|T|)
  double m_volume = 0.0;              ///< m^3
  Box3 m_bounds;                      ///< m
  std::array<int, 3> m_dims{1, 1, 1}; ///< grid cells per axis
  Vec3 m_cell = Vec3::Ones();         ///< grid cell edge per axis, m
  std::vector<int> m_cell_begin;      ///< CSR offsets into m_cell_tets (cells + 1)
  std::vector<int> m_cell_tets;       ///< tet indices per grid cell
  std::vector<std::array<int, 3>> m_tet_cell;  ///< lowest grid cell of each tet's range, per axis (|T|)
};

}  // namespace octocut::sim
