#pragma once
// The material graph M (SPEC §2.2, paper §3 and §4.3): a tetrahedral mesh of the object's interior in rest space.
// It tells the octree which cells hold material (exact tet–box clipping) and which faces connect (tets meeting a
// face in positive area). Generation by CGAL Mesh_3 lives in cutting/; this header knows no CGAL.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
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
/// tets. Immutable once built. A cut (SPEC §4 stage 3) makes a new graph with `without()`: the geometry (tets,
/// their bounding boxes and volumes, the grid) is shared between the revisions and only a per-tet alive mask is
/// copied. Tet indices refer to the original mesh in every revision; dead tets take no part in any query.
class MaterialGraph final : public MaterialSource {
  struct Geometry;
  // Passkey: only members can name and construct it, so only without() calls the revision constructor.
  struct Key {
    explicit Key() = default;
  };

 public:
  /// Takes the mesh; reorients negatively oriented tets and drops tets of zero volume. Throws
  /// std::invalid_argument for an empty mesh, an index out of range or non-finite coordinates.
  explicit MaterialGraph(TetMesh mesh);

  [[nodiscard]] double occupancy(const Box3& box) const override;
  [[nodiscard]] bool face_connected(const Box3& face, int axis) const override;
  /// Bounding box of the live tets, m. With no live tet left, the bounding box of all tets (never inverted).
  [[nodiscard]] Box3 bounds() const override { return m_bounds; }

  /// The whole mesh as built, dead tets included (tet t of the mesh is tet t of every query).
  [[nodiscard]] const TetMesh& mesh() const;
  /// A copy of the mesh with the live tets only (all vertices kept, unused ones included), in ascending order.
  [[nodiscard]] TetMesh live_mesh() const;
  /// Number of live tets.
  [[nodiscard]] int num_tets() const { return m_num_alive; }
  /// Number of tets in the mesh as built, live or dead; tet indices run over [0, num_tets_total()).
  [[nodiscard]] int num_tets_total() const;
  /// True when tet t (in [0, num_tets_total())) has not been removed.
  [[nodiscard]] bool alive(int t) const { return m_alive[std::size_t(t)] != 0; }
  /// Sum of the volumes of the live tets, m^3 (summed in ascending tet order).
  [[nodiscard]] double volume() const { return m_volume; }
  /// Indices of the live tets whose bounding box overlaps `box` (closed boxes), ascending.
  [[nodiscard]] std::vector<int> tets_near(const Box3& box) const;
  /// Corner positions of tet t (live or dead), m, positively oriented.
  [[nodiscard]] std::array<Vec3, 4> tet(int t) const;
  /// Volume of tet t (live or dead), m^3.
  [[nodiscard]] double tet_volume(int t) const;

  /// A new revision of M without the tets `tets` (indices into the mesh as built, any order, duplicates and tets
  /// already dead allowed). Shares the geometry with this graph, so the cost is O(|T|) bytes copied plus the
  /// removal list; this graph is unchanged. Throws std::invalid_argument for an index out of range.
  [[nodiscard]] std::shared_ptr<const MaterialGraph> without(std::span<const int> tets) const;

  /// Revision constructor used by without(); not for general use (Key is private).
  MaterialGraph(Key, std::shared_ptr<const Geometry> geometry, std::vector<uint8_t> alive);

 private:
  // Grid cells overlapped by a box, clamped to the grid: [lo, hi] per axis.
  void cell_range(const Box3& box, std::array<int, 3>& lo, std::array<int, 3>& hi) const;
  // Calls visit(t) once for each live tet whose bounding box overlaps `box` (closed boxes), in grid order, until
  // visit returns true; returns whether it did.
  template <class Visit>
  bool visit_tets_near(const Box3& box, Visit&& visit) const;
  // Recomputes the live count, volume and bounds from the alive mask.
  void update_live_totals();

  std::shared_ptr<const Geometry> m_geo;  ///< immutable geometry shared by all revisions
  std::vector<uint8_t> m_alive;           ///< 1 for a live tet, 0 for a removed one (|T| as built)
  int m_num_alive = 0;                    ///< number of live tets
  double m_volume = 0.0;                  ///< volume of the live tets, m^3
  Box3 m_bounds;                          ///< bounding box of the live tets, m
};

}  // namespace octocut::sim
