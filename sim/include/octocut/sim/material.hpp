#pragma once
// Where material is (SPEC §2.2): occupancy of octree cells and connectivity across their faces. The octree and the
// DOF construction only see this interface; the tetrahedral material graph of the geometry issue implements it too.
#include <memory>

#include "octocut/sim/types.hpp"

namespace octocut::sim {

/// Leaves whose occupancy is below this fraction are empty and dropped (SPEC §2.2).
inline constexpr double kEmptyOccupancy = 1e-9;

/// The material of one object in rest space.
class MaterialSource {
 public:
  virtual ~MaterialSource() = default;
  /// Fraction in [0, 1] of the box's volume that holds material.
  [[nodiscard]] virtual double occupancy(const Box3& box) const = 0;
  /// True when material meets the axis-aligned rectangle `face` (zero extent along `axis`) in a region of positive
  /// area, so that the two leaves on either side are connected.
  [[nodiscard]] virtual bool face_connected(const Box3& face, int axis) const = 0;
  /// Bounding box of the material, m.
  [[nodiscard]] virtual Box3 bounds() const = 0;
};

/// Exact box primitive: material fills one axis-aligned box. Occupancy of cells that cut the box is the exact
/// fraction of their volume.
class BoxMaterial final : public MaterialSource {
 public:
  explicit BoxMaterial(const Box3& box) : m_box(box) {}
  [[nodiscard]] double occupancy(const Box3& box) const override;
  [[nodiscard]] bool face_connected(const Box3& face, int axis) const override;
  [[nodiscard]] Box3 bounds() const override { return m_box; }

 private:
  Box3 m_box;  ///< the material, m
};

/// Material given as a union of disjoint boxes (tests and hand-built connectivity patterns).
class BoxSetMaterial final : public MaterialSource {
 public:
  explicit BoxSetMaterial(std::vector<Box3> boxes) : m_boxes(std::move(boxes)) {}
  [[nodiscard]] double occupancy(const Box3& box) const override;
  [[nodiscard]] bool face_connected(const Box3& face, int axis) const override;
  [[nodiscard]] Box3 bounds() const override;

 private:
  std::vector<Box3> m_boxes;  ///< pairwise interior-disjoint boxes, m
};

}  // namespace octocut::sim
