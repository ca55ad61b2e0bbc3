// The Z-curve list (SPEC §2.4, paper §4.5): Morton codes of the finest cells that hold the rest vertices, kept
// sorted, so that the vertices of a cell are one range; updated after a cut by deletion and insertion or merge.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "embedding_internal.hpp"
#include "octocut/sim/embedding.hpp"

namespace octocut::sim {

GridPoint zcurve_cell(const RootGeometry& root, const Vec3& rest) {
  // Fixed point on the finest grid, floored and clamped to the last cell, so the upper root faces stay inside.
  const Vec3 g = (rest - root.min) / root.unit();
  auto to_int = [](double v) {
    return std::uint32_t(std::clamp(std::floor(v), 0.0, double(kGridCells - 1)));
  };
  return {to_int(g.x()), to_int(g.y()), to_int(g.z())};
}

std::uint64_t zcurve_code(const RootGeometry& root, const Vec3& rest) {
  const GridPoint c = zcurve_cell(root, rest);
  return morton_encode(c.x, c.y, c.z);
}

ZCurveList::ZCurveList(const RootGeometry& root, std::span<const Vec3> rest) : m_root(root) {
  detail::check_finite(rest, "vertex");
  // Encode every vertex, then sort by (code, vertex).
  m_entries.resize(rest.size());
  for (std::size_t i = 0; i < rest.size(); ++i) m_entries[i] = {zcurve_code(root, rest[i]), std::int32_t(i)};
  std::sort(m_entries.begin(), m_entries.end());
}

std::span<const ZEntry> ZCurveList::in_cell(const Cell& c) const {
  // A cell covers the Morton codes [code(anchor), code(anchor) + size^3).
  const std::uint64_t s = c.size();
  const std::uint64_t lo = c.morton(), hi = lo + s * s * s;
  const auto by_code = [](const ZEntry& e, std::uint64_t code) { return e.code < code; };
  const auto b = std::lower_bound(m_entries.begin(), m_entries.end(), lo, by_code);
  const auto e = std::lower_bound(b, m_entries.end(), hi, by_code);
  return {m_entries.data() + (b - m_entries.begin()), std::size_t(e - b)};
}

std::vector<int> ZCurveList::update(std::span<const int> removed, std::span<const Vec3> inserted_rest) {
  std::vector<int> map;
  update(removed, inserted_rest, map);
  return map;
}

void ZCurveList::update(std::span<const int> removed, std::span<const Vec3> inserted_rest, std::vector<int>& map) {
  detail::check_finite(inserted_rest, "inserted vertex");
  // All buffers are reused from call to call, so an update allocates nothing in steady state.
  removal_map(removed, m_entries.size(), map);
  erase_and_renumber(map);

  // The new entries, numbered after the kept vertices.
  const std::size_t n = m_entries.size(), n_new = inserted_rest.size();
  m_added.resize(n_new);
  for (std::size_t i = 0; i < n_new; ++i)
    m_added[i] = {zcurve_code(m_root, inserted_rest[i]), std::int32_t(n + i)};
  std::sort(m_added.begin(), m_added.end());

  // Paper §4.5: one by one when n' < n / (log2 n - 1), else sort the batch and merge.
  const double denom = std::log2(double(std::max<std::size_t>(n, 2))) - 1.0;
  const bool one_by_one = denom <= 0.0 || double(n_new) < double(n) / denom;
  m_merged = !one_by_one;
  if (one_by_one)
    insert_one_by_one();
  else
    merge_batch();
}

void ZCurveList::removal_map(std::span<const int> removed, std::size_t n_old, std::vector<int>& map) {
  // Bad and repeated indices are found before anything changes; kept vertices keep their relative order.
  map.assign(n_old, 0);
  for (std::size_t i = 0; i < removed.size(); ++i) {
    const int v = removed[i];
    if (v < 0 || std::size_t(v) >= n_old)
      throw std::invalid_argument("removed_vertices[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is out of range [0, " + std::to_string(n_old) + ")");
    if (map[std::size_t(v)] < 0)
      throw std::invalid_argument("removed_vertices[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is listed twice");
    map[std::size_t(v)] = -1;
  }
  int next = 0;
  for (int& m : map) m = m < 0 ? -1 : next++;
}

void ZCurveList::erase_and_renumber(std::span<const int> map) {
  // One stable pass; the map is monotone, so the list stays sorted by (code, vertex).
  std::size_t out = 0;
  for (std::size_t i = 0; i < m_entries.size(); ++i) {
    const int v = map[std::size_t(m_entries[i].vertex)];
    if (v < 0) continue;
    m_entries[out++] = {m_entries[i].code, v};
  }
  m_entries.resize(out);
}

void ZCurveList::insert_one_by_one() {
  // Each new entry finds its place by binary search (O(log n) each, on the part of the list not yet passed); the
  // list then opens all gaps in one backward pass, so no element moves more than once.
  const std::size_t n = m_entries.size(), n_new = m_added.size();
  m_at.resize(n_new);
  std::size_t from = 0;
  for (std::size_t i = 0; i < n_new; ++i) {
    from = std::size_t(std::upper_bound(m_entries.begin() + std::ptrdiff_t(from), m_entries.end(), m_added[i]) -
                       m_entries.begin());
    m_at[i] = from;
  }
  m_entries.resize(n + n_new);
  std::size_t end = n;
  for (std::size_t i = n_new; i-- > 0;) {
    // Shift the block [at[i], end) up by i + 1 places, then drop the new entry in front of it.
    std::move_backward(m_entries.begin() + std::ptrdiff_t(m_at[i]), m_entries.begin() + std::ptrdiff_t(end),
                       m_entries.begin() + std::ptrdiff_t(end + i + 1));
    m_entries[m_at[i] + i] = m_added[i];
    end = m_at[i];
  }
}

void ZCurveList::merge_batch() {
  // From the back into the grown list: no second buffer.
  const std::size_t n = m_entries.size(), n_new = m_added.size();
  m_entries.resize(n + n_new);
  std::size_t a = n, b = n_new, o = n + n_new;
  while (b > 0) {
    if (a > 0 && m_added[b - 1] < m_entries[a - 1]) m_entries[--o] = m_entries[--a];
    else m_entries[--o] = m_added[--b];
  }
}

}  // namespace octocut::sim
