#pragma once
// The surface S as the cut pipeline edits it in place (SPEC §4 stage 2): a uniform grid over its triangles finds the
// faces near a blade without a pass over S, and a journal undoes the edits of a cut that fails later (the cut is a
// transaction). Nothing here costs O(|S|) per cut except FaceGrid::build. No third-party types.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "octocut/sim/surface.hpp"

namespace octocut::cutting {

/// A uniform grid over the triangles of a mesh whose vertex positions never change once added (S in rest space):
/// each cell lists the triangles whose bounding boxes meet it. Cells outside the grid's box are clamped to its
/// border cells, so a triangle that leaves the box (by rounding, or a blade face) is still found.
class FaceGrid {
 public:
  /// Builds the grid over `mesh`: about two cells per triangle, cell edge at least twice the mean bounding-box edge
  /// of the triangles. O(|S|). Throws std::invalid_argument naming the first non-finite vertex or the first triangle
  /// with an index out of range.
  void build(const sim::TriMesh& mesh);
  /// Whether build() has run.
  [[nodiscard]] bool built() const { return !m_cells.empty(); }
  /// Adds triangle f of `mesh` (its current vertices) to the cells its box meets.
  void insert(const sim::TriMesh& mesh, int32_t f);
  /// Removes triangle f of `mesh` (which must still hold the vertices it was inserted with).
  void erase(const sim::TriMesh& mesh, int32_t f);
  /// Renames triangle `from` to `to` in the cells of triangle t's box (t: its vertices in `mesh`).
  void rename(const sim::TriMesh& mesh, const std::array<int32_t, 3>& t, int32_t from, int32_t to);
  /// The triangles of `mesh` whose bounding boxes meet [lo, hi] (m), ascending, each once.
  [[nodiscard]] std::vector<int32_t> query(const sim::TriMesh& mesh, const sim::Vec3& lo, const sim::Vec3& hi);
  /// The triangles of `mesh` that have vertex v, ascending.
  [[nodiscard]] std::vector<int32_t> around(const sim::TriMesh& mesh, int32_t v);
  /// Cell edge, m.
  [[nodiscard]] double cell_size() const { return m_cell; }
  /// Number of cells along x, y, z.
  [[nodiscard]] std::array<int, 3> dims() const { return m_dims; }

 private:
  [[nodiscard]] std::array<int, 3> cell_of(const sim::Vec3& p) const;  // clamped to the grid
  template <class Visit>
  void for_cells(const sim::Vec3& lo, const sim::Vec3& hi, Visit&& visit);

  sim::Vec3 m_origin = sim::Vec3::Zero();         ///< lower corner of the grid, m
  double m_cell = 1.0;                             ///< cell edge, m
  std::array<int, 3> m_dims{0, 0, 0};              ///< cells along x, y, z
  std::vector<std::vector<int32_t>> m_cells;       ///< triangles per cell (dims product), unordered
  std::vector<uint32_t> m_stamp;                   ///< per triangle: the last query that listed it (grows with |F|)
  uint32_t m_query = 0;                            ///< queries so far
};

/// Per-triangle values that follow the triangles of an edited surface.
struct FaceAttributes {
  char cut = 0;         ///< 1 for a triangle that came from a blade (CutObject::cut_faces)
  int32_t origin = -1;  ///< the index, in the mesh as it was before the first edit, of the triangle it lies in (-1:
                        ///< a blade triangle)
};

/// In-place edits of a mesh, with its FaceGrid kept up to date and a journal to undo them. Vertices are only ever
/// appended (a vertex that no triangle uses any more stays until the owner compacts the mesh); a triangle is
/// overwritten, appended, or removed by moving the last one into its place.
class SurfaceEditor {
 public:
  /// Edits `mesh`, whose grid is `grid` (built over it). `cut` and `origin`, when given, hold one value per triangle
  /// (|F|) and follow the triangles.
  SurfaceEditor(sim::TriMesh& mesh, FaceGrid& grid, std::vector<char>* cut = nullptr,
                std::vector<int32_t>* origin = nullptr);

  [[nodiscard]] const sim::TriMesh& mesh() const { return m_mesh; }
  [[nodiscard]] FaceGrid& grid() { return m_grid; }
  [[nodiscard]] FaceAttributes attributes(int32_t f) const;

  /// Appends a vertex (finite, m); returns its index.
  int32_t add_vertex(const sim::Vec3& p);
  /// Replaces triangle f.
  void set_face(int32_t f, const std::array<int32_t, 3>& t, FaceAttributes a);
  /// Appends a triangle; returns its index.
  int32_t add_face(const std::array<int32_t, 3>& t, FaceAttributes a);
  /// Removes triangle f by moving the last triangle into its place. Returns the old index of the triangle that
  /// moved to f, or -1 when f was the last.
  int32_t remove_face(int32_t f);
  /// Removes the triangles `ascending` (indices, ascending, no duplicates), from the last down: the triangle that
  /// moves into a removed one's place is then always one that stays.
  void remove_faces(std::span<const int32_t> ascending);

  /// A point in the journal to roll back to.
  [[nodiscard]] std::size_t mark() const { return m_journal.size(); }
  /// Undoes every edit since `mark`, in reverse: the mesh, the attributes and the grid are as they were then.
  void rollback(std::size_t mark);
  /// Forgets the journal (the edits stay).
  void commit() { m_journal.clear(); }

 private:
  enum class Op : uint8_t { set_face, add_face, remove_last_face, move_last_face, add_vertex };
  struct Entry {
    Op op;
    int32_t face;                   // set_face, move_last_face: the triangle overwritten
    std::array<int32_t, 3> old{};   // set_face, remove_last_face, move_last_face: the triangle before
    FaceAttributes old_attributes;  // likewise
  };
  void write_face(int32_t f, const std::array<int32_t, 3>& t, FaceAttributes a);  // no journal
  void push_face(const std::array<int32_t, 3>& t, FaceAttributes a);
  void pop_face();

  sim::TriMesh& m_mesh;
  FaceGrid& m_grid;
  std::vector<char>* m_cut;
  std::vector<int32_t>* m_origin;
  std::vector<Entry> m_journal;
};

}  // namespace octocut::cutting
