#pragma once
// The Z-curve surface embedding (SPEC §2.4, paper §4.5, Fig. 5): every rest vertex of S carries the Morton code of the
// finest grid cell that holds it; the (code, vertex) pairs are kept sorted, so the vertices of a leaf are one
// contiguous range found by two binary searches. Each vertex is bound to a leaf by 8 trilinear weights, which are
// precomposed through the prolongation P into a short list of (DOF, weight) pairs.
//
// The fallback rule (SPEC §2.4). A vertex whose rest position lies in no leaf (M is coarser than S, or a cut removed
// the material around it) is bound to the nearest leaf of its material component. Two elements share a material
// component when they share a DOF (the transitive closure of "some slot of each reaches the same DOF through P"), so
// the two sides of a cut are different components. The component of a fallback vertex is that of its anchor: the
// regularly bound vertex (one that lies in a leaf) nearest to it along the triangle edges of S, fewest edges first,
// the lowest vertex index among equals; the component is the one of the anchor's leaf. A fallback vertex whose
// connected part of S has no regular vertex falls back to the nearest leaf of any component. "Nearest" is the
// Euclidean distance from the rest point to the closed leaf box, ties going to the lower leaf index. A cut face's
// vertices sitting in the gap the cut opened thus follow their own side, even where a leaf across the cut is nearer.
#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "octocut/sim/object.hpp"
#include "octocut/sim/octree.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/surface.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::sim {

namespace detail {
/// A std::vector whose copies keep the source's capacity, for the arrays that a cut lengthens: a copied embedding
/// has the same spare room for the next cuts as the original, so that its first update() does not move those arrays
/// into fresh pages.
template <class T>
class RoomyVector : public std::vector<T> {
 public:
  using std::vector<T>::operator=;
  RoomyVector() = default;
  RoomyVector(std::vector<T>&& v) noexcept : std::vector<T>(std::move(v)) {}
  RoomyVector(const RoomyVector& other) : std::vector<T>() {
    this->reserve(other.capacity());
    this->insert(this->end(), other.begin(), other.end());
  }
  RoomyVector(RoomyVector&&) noexcept = default;
  RoomyVector& operator=(const RoomyVector& other) {
    if (this == &other) return *this;
    if (this->capacity() < other.capacity()) {
      std::vector<T>().swap(*this);
      this->reserve(other.capacity());
    }
    this->assign(other.begin(), other.end());
    return *this;
  }
  RoomyVector& operator=(RoomyVector&&) noexcept = default;
  ~RoomyVector() = default;
};
}  // namespace detail

/// One entry of the Z-curve list: a vertex and the Morton code of the finest grid cell that holds its rest position.
struct ZEntry {
  std::uint64_t code = 0;  ///< 63-bit Morton code, 21 bits per axis, same convention as Cell::morton()
  std::int32_t vertex = 0; ///< vertex index
  friend bool operator==(const ZEntry&, const ZEntry&) = default;
  friend bool operator<(const ZEntry& a, const ZEntry& b) {
    return a.code < b.code || (a.code == b.code && a.vertex < b.vertex);
  }
};

/// The finest grid cell that holds rest point X (m): floor of its fixed-point coordinates, clamped into the root.
GridPoint zcurve_cell(const RootGeometry& root, const Vec3& rest);
/// Morton code of zcurve_cell(root, rest).
std::uint64_t zcurve_code(const RootGeometry& root, const Vec3& rest);

/// The sorted list of (Morton code, vertex) pairs of a vertex set.
class ZCurveList {
 public:
  ZCurveList() = default;
  /// Encodes and sorts the rest positions (|V|), m. Throws std::invalid_argument naming the first non-finite vertex.
  ZCurveList(const RootGeometry& root, std::span<const Vec3> rest);

  /// The entries sorted by (code, vertex) (|V|).
  [[nodiscard]] const std::vector<ZEntry>& entries() const { return m_entries; }
  [[nodiscard]] int size() const { return int(m_entries.size()); }
  [[nodiscard]] const RootGeometry& root() const { return m_root; }
  /// The entries whose finest cell lies inside cell c: a contiguous range, found by two binary searches.
  [[nodiscard]] std::span<const ZEntry> in_cell(const Cell& c) const;

  /// Deletes the vertices `removed` (old indices, any order, no duplicates), renumbers the kept vertices in their
  /// old order to 0..k-1, and inserts `inserted_rest` (m) as vertices k, k+1, ... If their number n' is below
  /// n / (log2 n - 1), n being the number of kept entries, each is inserted by binary search; otherwise they are
  /// sorted and merged. Returns the old-to-new index map, -1 for a removed vertex (old size). Throws
  /// std::invalid_argument for an index out of range, a duplicate, or a non-finite inserted point.
  std::vector<int> update(std::span<const int> removed, std::span<const Vec3> inserted_rest);
  /// The same, writing the map into `map` (resized), so that a long-lived caller allocates nothing per update.
  void update(std::span<const int> removed, std::span<const Vec3> inserted_rest, std::vector<int>& map);
  /// True when the last update() took the sort-and-merge branch.
  [[nodiscard]] bool last_update_merged() const { return m_merged; }

 private:
  // update(): the old-to-new map into `map` (n_old), -1 for a removed vertex; throws for a bad or repeated index.
  static void removal_map(std::span<const int> removed, std::size_t n_old, std::vector<int>& map);
  // update(): deletes the entries of the removed vertices and renumbers the others by `map`.
  void erase_and_renumber(std::span<const int> map);
  // update(): inserts the sorted m_added into the entries, each at the place a binary search finds.
  void insert_one_by_one();
  // update(): merges the sorted m_added into the entries from the back.
  void merge_batch();

  RootGeometry m_root;
  detail::RoomyVector<ZEntry> m_entries;  ///< sorted by (code, vertex) (|V|)
  bool m_merged = false;
  std::vector<ZEntry> m_added;       ///< scratch of update(): the new entries, sorted (n')
  std::vector<std::size_t> m_at;     ///< scratch of update(): insertion points (n')
};

/// A rest point bound to a leaf by 8 weights of the leaf's corners (corner bits as in Cell::corner).
struct VertexEmbedding {
  int leaf = -1;                       ///< leaf index in the tree
  std::array<double, 8> weights{};     ///< trilinear weights, dimensionless, sum 1
  bool fallback = false;               ///< true when the point lies in no leaf and was bound by the fallback rule
  friend bool operator==(const VertexEmbedding&, const VertexEmbedding&) = default;
};

/// Smallest and largest weight a fallback vertex may carry.
inline constexpr double kFallbackWeightMin = -0.5;
inline constexpr double kFallbackWeightMax = 1.5;

/// Binds rest point X (m) to the leaf that contains its finest cell, with trilinear weights. A point in no leaf
/// falls back to the nearest leaf (distance from X to the leaf box; ties go to the lower leaf index) with
/// extrapolated trilinear weights, projected onto [kFallbackWeightMin, kFallbackWeightMax]^8 with sum 1 (a common
/// shift, then clamping). This free function does NOT apply the material-component restriction of SPEC §2.4: a lone
/// point has no triangles, hence no surface neighbour to take a component from, so it goes to the nearest leaf of
/// any component. It scans all leaves. SurfaceEmbedding finds the same leaf on a bucket grid for fallback vertices
/// whose connected part of S has no regular vertex, and the nearest leaf of the anchor's component otherwise (see
/// the top of this file). Throws std::invalid_argument when the tree has no leaf.
VertexEmbedding embed_vertex(const Octree& tree, const RootGeometry& root, const Vec3& rest);

/// Projects weights onto {w in [kFallbackWeightMin, kFallbackWeightMax]^8, sum w = 1}; weights already inside are
/// returned unchanged.
std::array<double, 8> clamp_fallback_weights(const std::array<double, 8>& w);

/// How a cut changed S, for SurfaceEmbedding::update: S itself already holds the new vertices and triangles.
struct SurfaceEdit {
  std::vector<int> removed_vertices;  ///< indices before the change, any order, no duplicates
  int inserted = 0;                   ///< vertices added: the last `inserted` vertices of S, after the k kept ones
  std::vector<int> changed_leaves;    ///< leaves of the new tree whose vertices must be re-embedded
};

/// The surface S bound to an object model (constant per model revision; the deformed DOF positions come per step).
///
/// An index over S, as FaceGrid is one: it keeps no copy of S's vertices or triangles. Every call that reads S is
/// given it (`surface`: rest vertices |V|, m, and triangles |F|), and between calls S changes only as update() is
/// then told. Each such call checks that S still has the |V| and |F| the embedding was built or last updated for
/// and throws std::invalid_argument otherwise.
class SurfaceEmbedding {
 public:
  /// Embeds the rest vertices and triangles of `surface` in `model`; vertices in no leaf follow the fallback rule at
  /// the top of this file (material components from model.dofs(), anchors along the triangles). Throws
  /// std::invalid_argument naming the offending vertex or triangle for a non-finite vertex or a triangle index out
  /// of range, or when the model has no leaf.
  SurfaceEmbedding(const ObjectModel& model, const TriMesh& surface);

  /// Number of vertices of the surface it is bound to, |V|.
  [[nodiscard]] int num_vertices() const { return int(m_embedding.size()); }
  /// Number of triangles of the surface it is bound to, |F|.
  [[nodiscard]] int num_triangles() const { return int(m_tri.size() / 3); }
  /// Whether `surface` has the |V| and |F| this embedding is built for (what every call taking S checks).
  [[nodiscard]] bool matches(const TriMesh& surface) const;
  [[nodiscard]] const ZCurveList& zcurve() const { return m_zcurve; }
  /// The Z-curve entries of the vertices inside leaf `leaf` of the current model's tree.
  [[nodiscard]] std::span<const ZEntry> vertices_in_leaf(int leaf) const;
  [[nodiscard]] const std::vector<VertexEmbedding>& embeddings() const { return m_embedding; }  ///< (|V|)
  /// Number of vertices bound by the fallback rule.
  [[nodiscard]] int num_fallback() const;
  /// Composed weights, CSR over vertices: vertex v is sum of weight[i] * x[dof[i]] for i in [begin[v], begin[v+1]).
  [[nodiscard]] const std::vector<int>& dof_begin() const { return m_begin; }      ///< (|V| + 1)
  [[nodiscard]] const std::vector<int>& dof_index() const { return m_dof; }        ///< (nnz)
  [[nodiscard]] const std::vector<double>& dof_weight() const { return m_weight; } ///< dimensionless (nnz)

  /// Deformed vertex positions (|V|, m) from DOF positions (num_dofs, m), parallel over vertices.
  void deformed_positions(const std::vector<Vec3>& x_dofs, std::vector<Vec3>& positions, Executor& exec) const;
  /// Area-weighted unit vertex normals (|V|) of `surface`'s triangles at `positions` (|V|, m), parallel over
  /// vertices; equal bit for bit to sim::vertex_normals(positions, surface.triangles).
  void deformed_normals(const TriMesh& surface, const std::vector<Vec3>& positions, std::vector<Vec3>& normals,
                        Executor& exec) const;
  /// The same with a caller-owned scratch array for the face normals (|F|, m^2), which saves its allocation per step.
  void deformed_normals(const TriMesh& surface, const std::vector<Vec3>& positions, std::vector<Vec3>& normals,
                        Executor& exec, std::vector<Vec3>& face_normals) const;

  /// Follows a cut. `surface` is S after the cut: the vertices kept from the S this embedding is built for, in their
  /// old order, then edit.inserted new ones, and the complete new triangle list. Removes and inserts vertices
  /// (ZCurveList::update), re-embeds only the new vertices, the vertices of leaves that are new in `new_model` or
  /// listed in edit.changed_leaves, the vertices whose old leaf is gone, and all fallback vertices (their anchors and
  /// components depend on the new surface and the new DOFs). A vertex that keeps its leaf and weights keeps its
  /// composed row, DOFs renumbered, when the 8 rows of P of its leaf are the same up to that renumbering; the others
  /// are composed anew through the new P. The result equals a fresh SurfaceEmbedding of `surface` in `new_model`.
  /// Returns the old-to-new vertex map (-1 for a removed vertex). Throws std::invalid_argument for bad indices, a
  /// surface whose |V| is not the old one less the removed plus the inserted, or a model with another root cube or
  /// no leaf; the embedding is unchanged then.
  /// With `exec` (may be null: serial), independent parts run side by side and the re-embedding is parallel over
  /// vertices; the result is the same bit for bit whatever the thread count.
  std::vector<int> update(const ObjectModel& new_model, const TriMesh& surface, const SurfaceEdit& edit,
                          Executor* exec = nullptr);
  /// Moves to a new revision of the model with the same surface (refinement). Throws std::invalid_argument when
  /// `surface` does not match this embedding, or as update() does.
  void rebind(const ObjectModel& new_model, const TriMesh& surface);

  /// True when the last update() merged a sorted batch instead of inserting one by one.
  [[nodiscard]] bool last_update_merged() const { return m_zcurve.last_update_merged(); }
  /// Number of vertices the last update() or rebind() re-embedded.
  [[nodiscard]] int last_reembedded() const { return m_last_reembedded; }

 private:
  // What update() keeps from the old model revision: its leaves that are leaves of the new tree too, and which of
  // those have the same 8 rows of P up to the DOF renumbering.
  struct KeptLeaves;
  // Throws unless `surface` matches this embedding; `who` names the caller.
  void check_matches(const TriMesh& surface, const char* who) const;
  // update(): validates the edit against the model and the surface, touching only scratch (the triangles' corner
  // counts); throws std::invalid_argument.
  void check_update(const ObjectModel& new_model, const TriMesh& surface, const SurfaceEdit& edit);
  // update(): which leaves and rows of P `new_model` keeps from the bound model.
  [[nodiscard]] KeptLeaves match_kept_leaves(const ObjectModel& new_model) const;
  // update(): moves the kept vertices' embeddings down to their new indices (map: old to new), renumbers their
  // leaves, and flags those to re-embed: the fallback ones, those whose leaf is gone, and the `inserted` new ones.
  // Vertices before `first_removed` stay in place; the others move down in runs.
  void move_kept_vertices(std::span<const int> map, std::size_t first_removed, std::size_t inserted,
                          const KeptLeaves& kept);
  // update(): flags the vertices of the leaves of `tree` that are new (not kept) or listed in `changed`.
  void flag_leaves(const Octree& tree, const KeptLeaves& kept, std::span<const int> changed);
  // update(): marks vertex k (new index) for re-embedding, once; it composes its row anew.
  void flag(std::size_t k);
  // A kept fallback vertex as update() found it: what it was bound to, in the new numbering.
  struct FallbackHint {
    int vertex = -1;      ///< new index
    int leaf = -1;        ///< its leaf in the new tree, -1 when that leaf is gone
    int anchor = -1;      ///< its anchor's new index, -1 when it had none
    int reuse_from = -1;  ///< its old index when the 8 rows of P of `leaf` are kept, else -1
  };
  // update(): the hints of the kept fallback vertices (m_fallback_anchor renumbered by `map`, their leaves by `kept`),
  // into m_hints, ascending by vertex. Call after move_kept_vertices.
  void fallback_hints(std::span<const int> map, const KeptLeaves& kept);
  // Re-embeds the vertices listed in `redo` (ascending vertex indices) in m_tree, or all of them when `all` is set.
  // Every other vertex must be regularly bound, and the adjacency must be built for surface.triangles (fallback
  // anchors). Parallel over vertices with `exec` (may be null).
  // `hints` (ascending by vertex) and `kept_new` (one entry per leaf, 1 for a leaf of the old tree; empty when the
  // tree is the old one): a hinted fallback vertex keeps its leaf without a search when its anchor is the same, its
  // leaf is kept and in its anchor's component, and no new leaf is as near (the kept leaves of a component were in
  // one component before: a cut never joins material). It then takes the hint's reuse_from.
  void embed(const ObjectModel& model, const TriMesh& surface, std::span<const int> redo, bool all,
             Executor* exec = nullptr, std::span<const FallbackHint> hints = {}, std::span<const char> kept_new = {});
  // Composes every vertex through P into the CSR and keeps P's rows for the next update(). Vertex v with
  // reuse_from[v] >= 0 takes the current row of that (old) vertex with its DOFs renumbered by dof_map (old num_dofs),
  // which the caller has shown to equal the row composed anew; empty reuse_from composes all anew. reuse_from must
  // be increasing on the vertices that reuse a row (kept vertices keep their order): the kept rows then stay in the
  // current CSR, moved in runs, and only the new rows are composed.
  void compose(const DofMap& P, std::span<const int> reuse_from, std::span<const int> dof_map);
  // compose() with empty reuse_from: every row anew, in vertex order.
  void compose_all(const DofMap& P);
  // compose() with reuse_from: the kept rows moved in runs inside the CSR, the others composed anew.
  void compose_reusing(const DofMap& P, std::span<const int> reuse_from, std::span<const int> dof_map);
  // Validates `triangles` against `num_vertices` (throws as check_triangles does) and counts the corners at each
  // vertex into m_next_tri_begin, the first step of build_adjacency(); touches no other member.
  void count_corners(const std::vector<std::array<int32_t, 3>>& triangles, std::size_t num_vertices);
  // Builds the vertex-to-triangle CSR of `triangles` (|V| vertices) from the counts of count_corners(triangles, |V|).
  void build_adjacency(const std::vector<std::array<int32_t, 3>>& triangles, std::size_t num_vertices);
  static void check_triangles(const std::vector<std::array<int32_t, 3>>& triangles, std::size_t num_vertices);

  RootGeometry m_root;
  Octree m_tree;                                   ///< the tree of the model the vertices are bound to
  ZCurveList m_zcurve;                             ///< (|V|)
  detail::RoomyVector<VertexEmbedding> m_embedding;  ///< (|V|)
  std::vector<int> m_begin;                        ///< CSR row starts of the composed weights (|V| + 1)
  detail::RoomyVector<int> m_dof;                  ///< DOF of each entry (nnz)
  detail::RoomyVector<double> m_weight;            ///< weight of each entry, dimensionless (nnz)
  std::vector<int> m_tri_begin;                    ///< vertex-to-triangle CSR row starts (|V| + 1)
  detail::RoomyVector<int> m_tri;                  ///< incident triangles of each vertex, ascending (3 |F|)
  int m_num_dofs = 0;                              ///< DOFs of the bound model
  // The bound model's P and DOF nodes, kept so that update() can tell the leaves whose rows of P a new revision
  // leaves unchanged (up to DOF numbering) and keep their vertices' composed rows.
  std::vector<int> m_slot_begin;                   ///< CSR row starts of P (8 num_leaves + 1)
  std::vector<int> m_slot_dof;                     ///< DOF of each entry of P (nnz(P))
  std::vector<double> m_slot_weight;               ///< weight of each entry of P, dimensionless (nnz(P))
  std::vector<std::uint64_t> m_dof_node;           ///< node_key() of each DOF's node (num_dofs)
  // Scratch of compose(): the next row starts, swapped with the current ones (the entries are moved in place).
  std::vector<int> m_next_begin;                   ///< (|V| + 1)
  // Scratch of update(), kept from call to call so that a cut allocates little and faults in few fresh pages.
  std::vector<int> m_next_tri_begin;               ///< corner counts, then the adjacency's row starts (|V| + 2)
  std::vector<char> m_redo;                        ///< 1 for each vertex to re-embed (|V|)
  std::vector<int> m_redo_list;                    ///< the vertices to re-embed, ascending (<= |V|)
  std::vector<int> m_reuse_from;                   ///< old vertex whose composed row a vertex keeps, or -1 (|V|)
  std::vector<int> m_new_dof;                      ///< compose(): DOFs of the rows composed anew (entries)
  std::vector<double> m_new_weight;                ///< compose(): their weights, dimensionless (entries)
  std::vector<int> m_anchor;                       ///< embed(): each vertex's anchor, -1 for none (|V|)
  std::vector<int> m_depth;                        ///< embed(): breadth-first depth of each vertex (|V|)
  std::vector<FallbackHint> m_hints;               ///< update(): the kept fallback vertices (<= fallback vertices)
  /// (vertex, anchor) of each fallback vertex, ascending by vertex; anchor -1 for none (the fallback vertices)
  std::vector<std::pair<int, int>> m_fallback_anchor;
  int m_last_reembedded = 0;
};

}  // namespace octocut::sim
