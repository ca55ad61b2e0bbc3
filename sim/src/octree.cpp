#include "octocut/sim/octree.hpp"

#include <algorithm>
#include <numeric>
#include <stdexcept>

namespace octocut::sim {

namespace {
// Spreads the low 21 bits of v so that there are two zero bits between consecutive bits.
std::uint64_t spread_bits(std::uint64_t v) {
  v &= 0x1FFFFF;
  v = (v | (v << 32)) & 0x1F00000000FFFFull;
  v = (v | (v << 16)) & 0x1F0000FF0000FFull;
  v = (v | (v << 8)) & 0x100F00F00F00F00Full;
  v = (v | (v << 4)) & 0x10C30C30C30C30C3ull;
  v = (v | (v << 2)) & 0x1249249249249249ull;
  return v;
}
}  // namespace

std::uint64_t morton_encode(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return spread_bits(x) | (spread_bits(y) << 1) | (spread_bits(z) << 2);
}

Octree::Octree(std::vector<Cell> leaves) {
  m_codes.resize(leaves.size());
  for (std::size_t i = 0; i < leaves.size(); ++i) m_codes[i] = leaves[i].morton();
  // Sort by the Morton code of the anchor, unless the cells already come in that order (refinement keeps it).
  if (std::is_sorted(m_codes.begin(), m_codes.end())) {
    m_leaves = std::move(leaves);
  } else {
    std::vector<std::size_t> order(leaves.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return m_codes[a] < m_codes[b]; });
    std::vector<std::uint64_t> codes(leaves.size());
    m_leaves.reserve(leaves.size());
    for (std::size_t k = 0; k < order.size(); ++k) {
      m_leaves.push_back(leaves[order[k]]);
      codes[k] = m_codes[order[k]];
    }
    m_codes = std::move(codes);
  }
  // Non-overlapping cells have distinct anchors.
  for (std::size_t i = 1; i < m_codes.size(); ++i) {
    if (m_codes[i] == m_codes[i - 1]) throw std::invalid_argument("Octree: two leaves share an anchor");
  }
}

int Octree::locate_cell(const GridPoint& p) const {
  if (p.x >= kGridCells || p.y >= kGridCells || p.z >= kGridCells) return -1;
  // A leaf covers the contiguous Morton range starting at its anchor: the candidate is the last anchor <= code(p).
  const std::uint64_t code = morton_encode(p.x, p.y, p.z);
  auto it = std::upper_bound(m_codes.begin(), m_codes.end(), code);
  if (it == m_codes.begin()) return -1;
  const int i = int(it - m_codes.begin()) - 1;
  return m_leaves[std::size_t(i)].contains_cell(p) ? i : -1;
}

int Octree::locate_point(const GridPoint& p) const {
  // Try the finest cell anchored at p, then the cells on the negative side of each grid plane through p.
  for (int k = 0; k < 8; ++k) {
    const bool dx = k & 1, dy = k & 2, dz = k & 4;
    if ((dx && p.x == 0) || (dy && p.y == 0) || (dz && p.z == 0)) continue;
    const GridPoint q{p.x - (dx ? 1u : 0u), p.y - (dy ? 1u : 0u), p.z - (dz ? 1u : 0u)};
    const int i = locate_cell(q);
    if (i >= 0) return i;
  }
  return -1;
}

int Octree::find(const Cell& c) const {
  const int i = locate_cell(c.anchor);
  return (i >= 0 && m_leaves[std::size_t(i)] == c) ? i : -1;
}

}  // namespace octocut::sim
