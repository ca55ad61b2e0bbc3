#pragma once
// The linear octree T (SPEC §2.1, paper §4.4): leaves addressed on the finest integer grid, kept in Morton order.
#include <array>
#include <optional>
#include <vector>

#include "octocut/sim/types.hpp"

namespace octocut::sim {

/// Deepest octree level; cells and nodes are addressed on a grid of 2^kMaxDepth cells per axis.
inline constexpr int kMaxDepth = 20;
/// Number of finest-grid cells per axis.
inline constexpr std::uint32_t kGridCells = 1u << kMaxDepth;

/// Interleaves the low 21 bits of x, y, z into a 63-bit Morton (Z-curve) code, x in the lowest bit.
std::uint64_t morton_encode(std::uint32_t x, std::uint32_t y, std::uint32_t z);

/// An integer point on the finest grid (a cell anchor or a node), each coordinate in [0, 2^20].
struct GridPoint {
  std::uint32_t x = 0, y = 0, z = 0;
  friend bool operator==(const GridPoint&, const GridPoint&) = default;
};

/// Packs a grid point into one 64-bit key (21 bits per axis); ordering the keys orders by z, then y, then x.
inline std::uint64_t node_key(const GridPoint& p) {
  return (std::uint64_t(p.z) << 42) | (std::uint64_t(p.y) << 21) | std::uint64_t(p.x);
}
inline GridPoint node_from_key(std::uint64_t k) {
  return {std::uint32_t(k & 0x1FFFFF), std::uint32_t((k >> 21) & 0x1FFFFF), std::uint32_t((k >> 42) & 0x1FFFFF)};
}

/// An octree cell: its anchor (minimum corner) on the finest grid and its level (0 = root).
struct Cell {
  GridPoint anchor;
  int level = 0;
  /// Edge length in finest-grid units.
  [[nodiscard]] std::uint32_t size() const { return kGridCells >> level; }
  /// The node at corner k, with corner bits (k&1, k>>1&1, k>>2&1) along x, y, z.
  [[nodiscard]] GridPoint corner(int k) const {
    const std::uint32_t s = size();
    return {anchor.x + ((k & 1) ? s : 0), anchor.y + ((k & 2) ? s : 0), anchor.z + ((k & 4) ? s : 0)};
  }
  /// Child c (same bit convention as corners).
  [[nodiscard]] Cell child(int c) const {
    const std::uint32_t s = size() / 2;
    return {{anchor.x + ((c & 1) ? s : 0), anchor.y + ((c & 2) ? s : 0), anchor.z + ((c & 4) ? s : 0)}, level + 1};
  }
  /// True when grid point p lies in the closed cell.
  [[nodiscard]] bool contains(const GridPoint& p) const {
    const std::uint32_t s = size();
    return p.x >= anchor.x && p.x <= anchor.x + s && p.y >= anchor.y && p.y <= anchor.y + s && p.z >= anchor.z &&
           p.z <= anchor.z + s;
  }
  /// True when finest cell with anchor p lies inside this cell.
  [[nodiscard]] bool contains_cell(const GridPoint& p) const {
    const std::uint32_t s = size();
    return p.x >= anchor.x && p.x < anchor.x + s && p.y >= anchor.y && p.y < anchor.y + s && p.z >= anchor.z &&
           p.z < anchor.z + s;
  }
  /// True when p is one of the 8 corners.
  [[nodiscard]] bool has_corner(const GridPoint& p) const {
    const std::uint32_t s = size();
    auto on = [s](std::uint32_t v, std::uint32_t a) { return v == a || v == a + s; };
    return on(p.x, anchor.x) && on(p.y, anchor.y) && on(p.z, anchor.z);
  }
  /// Local coordinates of grid point p in this cell, [0,1]^3 inside it (outside points give values beyond).
  [[nodiscard]] Vec3 local(const GridPoint& p) const {
    const double s = double(size());
    return {(double(p.x) - double(anchor.x)) / s, (double(p.y) - double(anchor.y)) / s,
            (double(p.z) - double(anchor.z)) / s};
  }
  [[nodiscard]] std::uint64_t morton() const { return morton_encode(anchor.x, anchor.y, anchor.z); }
  friend bool operator==(const Cell&, const Cell&) = default;
};

/// Trilinear weights of the 8 cell corners (corner bits as in Cell::corner) at local coordinates u; they sum to 1.
inline std::array<double, 8> trilinear_weights(const Vec3& u) {
  std::array<double, 8> w{};
  for (int k = 0; k < 8; ++k)
    w[std::size_t(k)] = ((k & 1) ? u.x() : 1.0 - u.x()) * ((k & 2) ? u.y() : 1.0 - u.y()) *
                        ((k & 4) ? u.z() : 1.0 - u.z());
  return w;
}

/// Geometry of the root cube: maps finest-grid coordinates to metres.
struct RootGeometry {
  Vec3 min = Vec3::Zero();  ///< root cube lower corner, m
  double size = 1.0;        ///< root cube edge, m

  [[nodiscard]] double unit() const { return size / double(kGridCells); }  ///< finest-cell edge, m
  [[nodiscard]] Vec3 to_world(const GridPoint& p) const {
    return min + unit() * Vec3(double(p.x), double(p.y), double(p.z));
  }
  [[nodiscard]] Box3 cell_box(const Cell& c) const {
    return {to_world(c.anchor), to_world(c.corner(7))};
  }
  [[nodiscard]] double cell_edge(const Cell& c) const { return size / double(1u << c.level); }
};

/// The set of leaves of an unrestricted octree, sorted by the Morton code of their anchors. Leaves never overlap;
/// leaves that hold no material are simply absent. Neighbouring leaves may differ by any number of levels.
class Octree {
 public:
  Octree() = default;
  /// Takes any set of non-overlapping cells and sorts it into Morton order.
  explicit Octree(std::vector<Cell> leaves);

  [[nodiscard]] const std::vector<Cell>& leaves() const { return m_leaves; }
  [[nodiscard]] int size() const { return int(m_leaves.size()); }
  [[nodiscard]] const Cell& leaf(int i) const { return m_leaves[std::size_t(i)]; }

  /// Index of the leaf containing the finest cell anchored at p, or -1. Binary search on the Morton codes.
  [[nodiscard]] int locate_cell(const GridPoint& p) const;
  /// Index of the leaf whose closed box holds the grid point p, preferring the leaf that contains the finest cell
  /// anchored at p, then its neighbours in -x, -y, -z order; -1 when no leaf touches p.
  [[nodiscard]] int locate_point(const GridPoint& p) const;
  /// Index of leaf c, or -1.
  [[nodiscard]] int find(const Cell& c) const;

 private:
  std::vector<Cell> m_leaves;            ///< leaves in Morton order (num_leaves)
  std::vector<std::uint64_t> m_codes;    ///< Morton code of each leaf anchor (num_leaves)
};

}  // namespace octocut::sim
