#pragma once
// The phases of the local surface boolean S \ B' (SPEC §4 stage 2), private to cutting/src. surface_cut.cpp runs them
// in order (cut_surface_in_place):
//  1. find_patch (surface_cut_patch.cpp, no CGAL): the faces of S near the blade, from S's FaceGrid;
//  2. make_exact_blade, faces_inside_blade, corefine_and_classify (surface_cut_corefine.cpp, the only CGAL translation
//     unit of the boolean itself): corefinement of the patch with the blade and the classification of the pieces;
//  3. write_back (surface_cut_write_back.cpp, no CGAL): the kept pieces written into S through the SurfaceEditor;
//  4. verify_result (surface_cut_verify.cpp, CGAL predicates only): the local checks of the result.
// No CGAL type appears here: the exact blade is an opaque handle, and the phases pass plain arrays.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "octocut/cutting/surface_cut.hpp"
#include "octocut/cutting/surface_editor.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::cutting::surface_cut_detail {

using Tri = std::array<int32_t, 3>;

/// A failure with a reason; caught at the API boundary (cut_surface_in_place) and turned into
/// SurfaceCutStatus::failed.
struct CutFailure {
  std::string reason;
};

/// Whether every coordinate of p is finite.
inline bool finite(const sim::Vec3& p) { return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()); }

/// The smallest interior angle of triangle (a, b, c), rad: atan2(|u x v|, u . v) at each corner, accurate for the
/// tiniest angles of slivers.
inline double smallest_angle(const sim::Vec3& a, const sim::Vec3& b, const sim::Vec3& c) {
  const auto at = [](const sim::Vec3& p, const sim::Vec3& q, const sim::Vec3& r) {
    const sim::Vec3 u = q - p, v = r - p;
    return std::atan2(u.cross(v).norm(), u.dot(v));
  };
  return std::min({at(a, b, c), at(b, c, a), at(c, a, b)});
}

/// The directed edge (a, b) as one sortable number.
inline uint64_t directed_edge_key(int32_t a, int32_t b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(b);
}

/// Hash key of a point (m): the bit patterns of its coordinates (identical coordinates <=> identical key; -0 == +0).
struct PointKey {
  std::array<uint64_t, 3> bits{};
  explicit PointKey(const sim::Vec3& p)
      : bits{std::bit_cast<uint64_t>(p.x() + 0.0), std::bit_cast<uint64_t>(p.y() + 0.0),
             std::bit_cast<uint64_t>(p.z() + 0.0)} {}  // + 0.0 folds -0 into +0
  friend bool operator==(const PointKey&, const PointKey&) = default;
};
struct PointKeyHash {
  std::size_t operator()(const PointKey& k) const {
    uint64_t h = 1469598103934665603ull;
    for (const uint64_t b : k.bits) h = (h ^ b) * 1099511628211ull ^ (b >> 29);
    return static_cast<std::size_t>(h);
  }
};

/// Vertex -> number of open fans that some faces form around it (only the vertices on their boundary appear).
using FanCounts = std::unordered_map<int32_t, int>;

/// The number of open fans that `faces` (face indices of `surface`) form around each vertex where they form any (the
/// vertices on their boundary). Defined in surface_cut_patch.cpp.
FanCounts open_fans(const sim::TriMesh& surface, const std::vector<int32_t>& faces);

// ---- Phase 1: the patch (surface_cut_patch.cpp) ----

/// G: the blade's bounding box, grown by a margin; every face of S that may touch the blade has its box in G.
struct BladeBox {
  sim::Vec3 lo = sim::Vec3::Zero();      ///< lower corner, m
  sim::Vec3 hi = sim::Vec3::Zero();      ///< upper corner, m
  double margin = 0.0;                   ///< growth of the blade's boxes, m
  sim::Vec3 centre = sim::Vec3::Zero();  ///< centre of G, the origin of the local volume sums, m
};

/// G for `blade` (at least one triangle, finite coordinates): its box grown by `margin` (m), or by 1e-6 of its
/// diagonal when margin <= 0 (SurfaceCutOptions::margin).
BladeBox grown_blade_box(const sim::TriMesh& blade, double margin);

/// The faces of S in G that are not in the patch, grouped through shared vertices: each group lies strictly on one
/// side of the blade's surface, so one point of it decides the side of all its faces.
struct ClearFaces {
  std::vector<int32_t> faces;         ///< (n) face indices of S, ascending
  std::vector<int32_t> group;         ///< (n) the group of each face, numbered by first appearance in `faces`
  std::vector<int32_t> group_vertex;  ///< (groups) the vertex of S that decides each group's side (its smallest)
};

/// The patch P: the faces of S that may touch the blade, closed around pinched vertices, as a local mesh with one
/// vertex per fan of P around each vertex of S (after the closure, one per vertex unless 32 rounds did not suffice).
struct Patch {
  std::vector<int32_t> faces;     ///< (|P|) face indices of S, ascending
  std::vector<int32_t> vertices;  ///< (|V_P|) the vertex of S each local vertex copies, in order of first use
                                  ///< by the corners sorted by (vertex of S, position in `faces`, corner)
  std::vector<Tri> triangles;     ///< (|P|) the faces of P in local vertex indices (indices into `vertices`)
  FanCounts arcs;                 ///< open fans of P around each vertex of S on P's boundary
  ClearFaces clear;               ///< the faces in G that are not in P
};

/// Phase 1, no CGAL and no pass over S: the faces whose boxes meet G come from S's grid; of those, P is the faces
/// that may touch the blade (a conservative plane-side test against the blade triangles near them), closed around
/// the vertices where P's faces would form several fans (adding the faces around them, which the grid lists). The
/// other faces in G are `clear`: strictly inside or strictly outside the blade. `surface` is S, `blade` B' (m).
Patch find_patch(const sim::TriMesh& surface, FaceGrid& grid, const sim::TriMesh& blade, const BladeBox& g);

// ---- Phase 2: corefinement and classification (surface_cut_corefine.cpp, CGAL) ----

/// The blade as CGAL's Surface_mesh, checked (opaque here; defined in surface_cut_corefine.cpp).
struct ExactBlade;
struct ExactBladeDelete {
  void operator()(ExactBlade* blade) const noexcept;
};
using ExactBladePtr = std::unique_ptr<ExactBlade, ExactBladeDelete>;

/// The blade (finite coordinates, indices in range, at least one triangle) as an exact mesh. Throws CutFailure when
/// a triangle is degenerate, the blade is not closed, manifold and consistently oriented, intersects itself (when
/// options.check_blade_self_intersection) or is not outward oriented (signed volume <= 0).
ExactBladePtr make_exact_blade(const sim::TriMesh& blade, const SurfaceCutOptions& options);

/// The clear faces that go whole: those of the groups whose deciding vertex is inside the blade (an exact point
/// query per group) and removable there (options.removable). Face indices of S, ascending (|gone|). Throws
/// CutFailure when a deciding vertex lies on the blade.
std::vector<int32_t> faces_inside_blade(const sim::TriMesh& surface, const ClearFaces& clear, const ExactBlade& blade,
                                        const SurfaceCutOptions& options);

/// P and the blade after corefinement, cut into pieces along their intersection, with the pieces that S' keeps.
/// Vertex positions are the exact ones rounded to doubles.
struct Corefinement {
  std::vector<sim::Vec3> p_points;  ///< m (|V_P'|): P's vertices, Patch::vertices first (same order), then the
                                    ///< intersection points the corefinement added to P
  std::vector<sim::Vec3> b_points;  ///< m (|V_B'|): the blade's vertices, its input vertices first (same order),
                                    ///< then the intersection points the corefinement added to it
  std::vector<Tri> p_pieces;        ///< (k) the kept pieces of P, indices into p_points, in CGAL's face order
  std::vector<int32_t> p_origin;    ///< (k) the face of S each kept piece of P lies in
  std::vector<Tri> b_pieces;        ///< the kept pieces of the blade, reversed (facing out of S'), indices into
                                    ///< b_points, in CGAL's face order
  bool changes = false;             ///< whether a piece of P goes or a piece of the blade is kept
};

/// Phase 2: P (as a Surface_mesh) corefined with the blade, the intersection edges constrained, both cut into regions
/// along them, and each region classified. A P region goes when a point inside it is inside the blade (the face
/// centroid farthest from the blade); a region within 1e-9 of G's diagonal (`g`) of the blade everywhere is coplanar
/// with it and goes when the normals of the input faces agree. A blade region is kept when, at a constrained edge
/// where one P face is kept, it runs along with that face's halfedge (conflicting votes fail); without votes it is
/// discarded when coplanar with P, and otherwise kept when an exact ray-parity test on S (its faces from `grid`)
/// puts it inside S. Where options.removable rejects a region's test point, a P region is kept and a blade region
/// without votes discarded. Consumes `exact` (its mesh is corefined). Throws CutFailure (or a CGAL exception).
Corefinement corefine_and_classify(const sim::TriMesh& surface, FaceGrid& grid, const sim::TriMesh& blade,
                                   ExactBlade& exact, const Patch& patch, const BladeBox& g,
                                   const SurfaceCutOptions& options);

/// Where q (m) lies against the solid bounded by S: 1 inside, 0 outside, -1 on S or undecided (an exact ray-parity
/// test along the axes, the faces from `grid`). Used by removes_only_subfeature (surface_cut_feature.cpp).
int point_in_solid(const sim::TriMesh& surface, FaceGrid& grid, const sim::Vec3& q);

// ---- Phase 3: writing back (surface_cut_write_back.cpp, no CGAL) ----

/// The faces that change, as write_back takes them: P and the faces that go whole.
struct ChangingFaces {
  std::vector<int32_t> faces;  ///< (|P| + |gone|) face indices of S, ascending: the slots the new triangles fill
  std::vector<int32_t> patch_vertices;  ///< (|V_P|) Patch::vertices: the vertex of S of each initial P vertex
  std::vector<int32_t> gone;            ///< (|gone|) the faces that go whole (no pieces), ascending
  FanCounts arcs;                       ///< open fans of `faces` around each vertex of S on their boundary
};

/// What write_back changed, as verify_result checks it (indices into S after the edit).
struct WrittenPatch {
  std::vector<int32_t> changed;          ///< (c) the triangles built from the corefinement (P's pieces, the blade's)
  std::vector<char> changed_whole;       ///< (c) 1 for a face of S kept whole (one piece, its own vertices)
  std::vector<char> constructed;         ///< (|V_new|) per vertex added (from first_inserted on): 1 for an
                                         ///< intersection point (made by CGAL), 0 for a copy of an input vertex
  std::vector<std::array<int32_t, 2>> boundary_edges;  ///< the directed edges (vertex pairs) of the unchanged faces
                                                       ///< that border the changed ones (only with boundary edges
                                                       ///< asked for)
  bool intersections_checked = false;    ///< the repair (phase 3a) ran and its last round found no two written
                                         ///< triangles intersecting, nor one and a face of S near them
};

/// Phase 3: writes the kept pieces into S in place through `editor` (journaled; the grid follows). P's vertices keep
/// their indices; new vertices (matched between P and the blade by identical coordinates) are appended; the pieces
/// of each changing face (inheriting its attributes), then the blade's (cut = 1, origin = -1), fill the slots of
/// `changing.faces` in order, the rest are appended or the leftover slots removed. Sets result.removed_vertices,
/// result.blade_triangles_kept and result.removed_volume (m^3, over the changed faces, relative to `centre` (m)).
/// `blade_input_vertices` is the blade's |V| before corefinement.
/// With `repair`, the pieces first go through phase 3a (repair_rounding with `tiny_edge`, m; result.collapses counts
/// its collapses), so that V(S) - V(S') is the volume of what is written.
WrittenPatch write_back(SurfaceEditor& editor, const ChangingFaces& changing, const Corefinement& core,
                        std::size_t blade_input_vertices, const sim::Vec3& centre, bool boundary_edges, bool repair,
                        double tiny_edge, SurfaceEditResult& result);

// ---- Phase 3a: the rounding repair (surface_cut_verify.cpp, CGAL predicates) ----

/// The kept pieces before they are written, as the repair edits them: triangles over nodes, where a node below `nv`
/// is the vertex of S with that index and a node from nv on is new (new_points[node - nv]).
struct PieceMesh {
  const sim::TriMesh* surface = nullptr;  ///< S before the cut
  int32_t nv = 0;                         ///< |V| of S
  std::vector<sim::Vec3> new_points;      ///< m, the new nodes' positions (rounded from their exact values)
  std::vector<char> constructed;          ///< per new node: 1 for an intersection point (rounded), 0 for a blade vertex
  std::vector<Tri> tris;                  ///< the pieces (node ids); a collapse rewrites them
  std::vector<char> alive;                ///< (|tris|) 0 for a piece a collapse removed
  std::vector<char> whole;                ///< (|tris|) 1 for a face of S kept whole (never edited)
  std::vector<char> blade;                ///< (|tris|) 1 for a piece of the blade, 0 for a piece of a face of S
  const std::vector<int32_t>* changing = nullptr;  ///< ChangingFaces::faces (ascending): faces of S the pieces replace
  const FanCounts* arcs = nullptr;                 ///< ChangingFaces::arcs: the vertices of S on their boundary

  [[nodiscard]] const sim::Vec3& point(int32_t n) const {
    return n < nv ? surface->vertices[static_cast<std::size_t>(n)] : new_points[static_cast<std::size_t>(n - nv)];
  }
};

/// Phase 3a: the exact result rounded to doubles, made valid again where the rounding broke it, and cleaned of what
/// is finer than `tiny_edge` (m). Pieces that the rounding made degenerate (three exactly collinear corners) or that
/// intersect another piece or an unchanged neighbour of S (exact predicates on the rounded coordinates) are defects;
/// pieces with an edge shorter than `tiny_edge` at a new node, and pieces narrower than it (height over the longest
/// edge: caps and needles), are small. First, new nodes within a few units in the last place of a neighbour merge into
/// it (collapses without the intersection test; the rounds test what moved), and a sliver pillow kept on both sides
/// (pieces of S's faces and of the blade over the same polygon, turned the same way, within `tiny_edge` of each other)
/// loses its side of S. Each bad piece is mended by collapsing a new node along one of its edges onto its other end,
/// shortest edge first; for a small piece only where the surface moves by less than `tiny_edge` (the node's
/// distance from every moved piece's plane). A collapse is made only when it keeps the pieces closed and manifold
/// (the link condition, S's unchanged faces around the target included), makes no piece degenerate or turns none
/// over, and makes no piece intersect any other or an unchanged neighbour (exact tests). A defect that no single
/// collapse mends then loses a twin (a piece on the same three nodes turned the other way: a sliver bubble; both go)
/// or has its cluster collapsed at once (its nodes and those tiny edges join to them, checked after all moved, rolled
/// back otherwise); a narrow piece that no collapse mends has its longest edge flipped when that raises the smaller
/// angle of the two pieces and intersects nothing (a vertex of S a hair off a new edge). Rounds until nothing is
/// found; returns the number of edits. Throws CutFailure when a defect is left that nothing mends. `grid` is S's grid
/// (S not yet edited).
int repair_rounding(PieceMesh& mesh, FaceGrid& grid, double tiny_edge);

// ---- Phase 4: verification (surface_cut_verify.cpp, CGAL predicates) ----

/// Phase 4: the local checks of S' (`out`, S after write_back): the changed triangles are finite and not
/// degenerate; with the unchanged faces along their boundary they are closed, edge-manifold and oriented; around
/// each vertex they form one closed fan (inside) or as many open fans as `arcs` says (on the boundary); and no two
/// intersect, nor one and an unchanged neighbour (a face from `grid` around a boundary vertex). `first_inserted` is
/// the first vertex the cut added. Throws CutFailure naming the first defect. The intersection test is skipped when
/// written.intersections_checked: the repair's last round made the same exact test on the same rounded triangles
/// against a superset of these neighbours (every face of S in the box of the pieces with a new node), so a second
/// pass finds nothing new (about 1 ms of a 50k-triangle surface's cut).
void verify_result(const sim::TriMesh& out, FaceGrid& grid, const WrittenPatch& written, const FanCounts& arcs,
                   int32_t first_inserted);

}  // namespace octocut::cutting::surface_cut_detail
