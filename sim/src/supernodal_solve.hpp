#pragma once
// Triangular solves with a supernodal Cholesky factor L (CHOLMOD's structure; values stored in single precision, or
// in half precision with a power-of-two scale per column; arithmetic in single precision) on two threads.
// Private to sim/src: the preconditioner's solves, which PCG applies once per iteration. With a factor that fits the
// caches they are bound by the latency of many small dense kernels, not by memory bandwidth (one core streams
// 20 GB/s here, the solves reached 9 with Eigen's and OpenBLAS's kernels), so they gain from a second core and from
// our own kernels (supernode_kernels.hpp: whole 16-float vectors over columns padded with zeros, no call per
// supernode into a library); a factor too large for the caches streams from memory, and half precision halves its
// bytes. The supernodal elimination
// tree is cut into disjoint subtrees, dealt to two parts of about equal work, and the supernodes above them (the
// "top") are solved by one thread: in the forward solve after the parts, in the backward solve before them.
#include <array>
#include <cstdint>
#include <vector>

namespace octocut::sim {

class Executor;

/// The symbolic structure of a supernodal factor (CHOLMOD's): supernode s holds columns super[s] .. super[s + 1) as
/// a column-major nsrow x nscol block at values + px[s], its rows listed at rows[pi[s]] .. rows[pi[s + 1]) (the
/// first nscol are its own columns). Supernodes are postordered: every subtree of the elimination tree is a
/// contiguous range of supernodes ending at its root.
struct SupernodalStructure {
  int n = 0;                   ///< columns
  int nsuper = 0;              ///< supernodes
  const int* super = nullptr;  ///< first column of each supernode (nsuper + 1)
  const int* pi = nullptr;     ///< start of each supernode's rows in `rows` (nsuper + 1)
  const int* px = nullptr;     ///< start of each supernode's values (nsuper + 1)
  const int* rows = nullptr;   ///< row indices (pi[nsuper])
};

/// The structure of a supernodal cholmod_factor (any type with its members n, nsuper, super, pi, px, s; this
/// header does not include CHOLMOD's), viewed, not copied.
template <class Factor>
[[nodiscard]] SupernodalStructure supernodal_structure_of(const Factor& f) {
  SupernodalStructure L;
  L.n = int(f.n);
  L.nsuper = int(f.nsuper);
  L.super = static_cast<const int*>(f.super);
  L.pi = static_cast<const int*>(f.pi);
  L.px = static_cast<const int*>(f.px);
  L.rows = static_cast<const int*>(f.s);
  return L;
}

/// Makes room for n elements in v: its storage when it is large enough, else storage an eighth larger than asked
/// (v's contents are then dropped). A factor's large buffers are kept from one analysis to the next (a cut adds a few
/// percent of entries): memory the process has not touched before costs a page fault per 4 KiB, 2.3 ms for a
/// factor's 5 MB on the machine of docs/RESULTS.md against 0.05 ms to write it again.
template <class T>
void reserve_with_room(std::vector<T>& v, std::size_t n) {
  if (v.capacity() >= n) return;
  v.clear();
  v.reserve(n + n / 8);
}
/// v = n copies of `value`, in storage kept or grown as reserve_with_room keeps or grows it.
template <class T>
void assign_with_room(std::vector<T>& v, std::size_t n, const T& value) {
  reserve_with_room(v, n);
  v.assign(n, value);
}
/// The same with the values of [first, last).
template <class T>
void assign_with_room(std::vector<T>& v, const T* first, const T* last) {
  reserve_with_room(v, std::size_t(last - first));
  v.assign(first, last);
}

/// L's values as the solves read them (SupernodalSolvePlan::pack; the encodings: supernode_kernels.hpp): in single
/// precision, or in half precision with a scale per column.
struct PackedFactor {
  std::vector<float> values;         ///< single precision: each supernode's columns at its padded leading dimension
  std::vector<std::uint16_t> codes;  ///< half precision: the same layout
  std::vector<float> diag_inv;       ///< the reciprocal of each column's diagonal entry (n)
  std::vector<float> scale;          ///< each column's scale, a power of two (n; all 1 in single precision)
  [[nodiscard]] bool half() const { return !codes.empty(); }
  [[nodiscard]] std::size_t size() const { return half() ? codes.size() : values.size(); }
};

/// How the solves split the elimination tree between two threads, the layout of L's values that the solves read
/// (each supernode's columns padded with zeros for whole vectors: supernode_kernels.hpp), and the solves themselves.
/// The arithmetic is the same whatever the executor's thread count (the parts' updates of the top columns are
/// gathered per part and applied in part order), so results are bit-identical with one thread and with two.
class SupernodalSolvePlan {
 public:
  /// Partitions the tree of `L` (see the file comment): splits the heaviest subtree at its root while that shortens
  /// the longer part plus the top, in work counted as entries of L.
  void build(const SupernodalStructure& L);
  /// L's values `x` (CHOLMOD's layout, px[nsuper]) in the solves' layout, in half precision if `half`, else in
  /// single: each column's entries below the diagonal (packed_size() in all), then zeros to the padded leading
  /// dimension; the diagonal blocks' upper triangles and diagonals are zeros; the diagonal entries' reciprocals and
  /// the columns' scales apart.
  void pack(const SupernodalStructure& L, const double* x, bool half, PackedFactor& packed) const;
  /// The same from values in single precision (SupernodalFactorizer's).
  void pack(const SupernodalStructure& L, const float* x, bool half, PackedFactor& packed) const;
  /// The values the solves use, in CHOLMOD's layout (px[nsuper], the upper triangles zero): what pack() kept of x.
  [[nodiscard]] std::vector<double> unpack(const SupernodalStructure& L, const PackedFactor& packed) const;
  [[nodiscard]] std::size_t packed_size() const { return m_px.empty() ? 0 : std::size_t(m_px.back()); }
  /// y = L^-1 y in place (n), with L's values as pack() gave them.
  void forward(const SupernodalStructure& L, const PackedFactor& packed, float* y, Executor* executor);
  /// y = L^-T y in place (n).
  void backward(const SupernodalStructure& L, const PackedFactor& packed, float* y, Executor* executor);
  /// Entries of L in each part's subtrees and in the top (for tests and benchmarks).
  [[nodiscard]] std::array<double, 3> work() const { return m_work; }

 private:
  struct Part {
    std::vector<int> roots;      ///< roots of the part's subtrees, ascending
    std::vector<float> updates;  ///< forward: the part's updates of top columns (n; zero between solves)
    std::vector<float> w;        ///< work: a supernode's rows (its padded leading dimension)
  };
  void forward_range(const SupernodalStructure& L, const PackedFactor& packed, float* y, int first, int last,
                     int root, Part* part);
  void backward_range(const SupernodalStructure& L, const PackedFactor& packed, float* y, int first, int last,
                      std::vector<float>& w);
  [[nodiscard]] static int leading_dimension(int nsrow);
  template <class T>
  void pack_values(const SupernodalStructure& L, const T* x, bool half, PackedFactor& packed) const;

  std::vector<long> m_px;       ///< start of each supernode's values in the packed layout (nsuper + 1)
  std::vector<int> m_super_of;  ///< supernode of each column (n)
  std::vector<int> m_first;     ///< first supernode of each supernode's subtree (nsuper)
  std::vector<int> m_top;       ///< supernodes in no part's subtree, ascending
  std::vector<int> m_top_cols;  ///< the columns of the top supernodes that the parts update, ascending
  std::array<Part, 2> m_parts;
  std::vector<float> m_w;       ///< work of the top's solves
  std::array<double, 3> m_work{};
};

}  // namespace octocut::sim
