#pragma once
// Stage 2 of the cut pipeline (SPEC §4): the exact, local surface boolean S' = S \ B'. Only the faces of S near the
// blade take part in the CGAL corefinement; the result is stitched back into S in place. CGAL stays inside
// surface_cut_corefine.cpp and surface_cut_verify.cpp (cutting/src/surface_cut_phases.hpp lists the phases).
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "octocut/cutting/surface_editor.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::cutting {

/// How cut_surface works.
struct SurfaceCutOptions {
  double margin = 0.0;  ///< growth of the blade's bounding box that selects the patch, m; 0 = automatic (1e-6 times
                        ///< the blade's bounding-box diagonal)
  bool verify = true;   ///< check the result locally (closed, edge- and vertex-manifold, oriented, no degenerate
                        ///< triangle, no self-intersection among changed faces and their neighbours); before that,
                        ///< repair what rounding the exact result to doubles broke (collapses with exact checks)
  double tiny_edge = 0.0;  ///< with verify, an edge of the result at a new vertex shorter than this collapses too
                           ///< where the exact checks allow, m (0: only the rounding's defects are repaired)
  bool check_blade_self_intersection = true;  ///< reject a self-intersecting blade (0.3 ms for 128 triangles);
                                              ///< a caller that checked the blade once may turn this off
  bool check_surface_self_intersection = true;  ///< reject S when its faces near the blade intersect each other
                                                ///< (CGAL checks them during the corefinement: 0.5-0.8 ms at 50k
                                                ///< vertices). Only a caller that knows S is free of
                                                ///< self-intersections may turn this off: the corefinement is
                                                ///< undefined on such input and may crash
  /// Where the blade may remove material (rest point, m -> true); empty: everywhere. A region of S inside the
  /// blade whose test point this rejects is kept, and so is S there: a region of the blade inside S whose test
  /// point it rejects is left out. The cut pipeline restricts B'_i to the material of component i with it.
  std::function<bool(const sim::Vec3&)> removable;
};

/// What cut_surface did.
enum class SurfaceCutStatus {
  ok,     ///< S changed; `mesh` is S'
  no_op,  ///< the blade does not change S (it misses it, or only touches it); `mesh` is a copy of S
  failed  ///< the cut could not be done exactly and watertight; `mesh` is empty, S must stay as it was
};

/// The result of S \ B'.
struct SurfaceCutResult {
  SurfaceCutStatus status = SurfaceCutStatus::failed;
  std::string reason;                        ///< why no_op or failed (human readable, names the first offending thing)
  sim::TriMesh mesh;                         ///< S' when ok (a copy of S when no_op, empty when failed). Kept vertices
                                             ///< keep their old relative order, renumbered 0..k-1; new vertices are
                                             ///< appended after them
  std::vector<int> removed_vertices;         ///< old indices of vertices not in S', ascending
  std::vector<sim::Vec3> inserted_vertices;  ///< == mesh.vertices[k..], m
  std::vector<int32_t> triangle_origin;      ///< (|F'|) old triangle index each new triangle lies in, or -1 for a
                                             ///< triangle of the blade (a cut face). The triangles are in the order
                                             ///< of the in-place edit (see cut_surface_in_place)
  double removed_volume = 0.0;               ///< V(S) - V(S'), m^3, computed from the changed faces only (divergence
                                             ///< theorem)
  int patch_triangles = 0;                   ///< triangles of S handed to CGAL
  int blade_triangles_kept = 0;              ///< triangles of the blade (after corefinement) that are in S'
  int new_triangles = 0;                     ///< triangles of S' that are not faces of S
  double min_angle_deg = 0.0;                ///< smallest interior angle among them, degrees (0 when none)
  double min_edge = 0.0;                     ///< shortest edge among them, m (0 when none)
  int collapses = 0;                         ///< edge collapses of the rounding repair (SurfaceCutOptions::verify)
  double ms = 0.0;                           ///< wall time of the call, ms
};

/// What cut_surface_in_place did.
struct SurfaceEditResult {
  SurfaceCutStatus status = SurfaceCutStatus::failed;
  std::string reason;                 ///< why no_op or failed (human readable, names the first offending thing)
  std::vector<int32_t> removed_vertices;  ///< vertices of S that no triangle uses any more, ascending. They stay in
                                          ///< S.vertices (unused) until the owner compacts S
  int32_t first_inserted = 0;         ///< S.vertices[first_inserted..] are the vertices this cut added
  double removed_volume = 0.0;        ///< V(S) - V(S'), m^3, from the changed faces only
  int patch_triangles = 0;            ///< triangles of S handed to CGAL
  int blade_triangles_kept = 0;       ///< triangles of the blade (after corefinement) that are in S'
  int new_triangles = 0;              ///< triangles of S' that are not faces of S (pieces of cut faces, the blade's)
  double min_angle_deg = 0.0;         ///< smallest interior angle among the new triangles, degrees (0 when none)
  double min_edge = 0.0;              ///< shortest edge among the new triangles, m (0 when none)
  int collapses = 0;                  ///< edge collapses of the rounding repair (SurfaceCutOptions::verify)
  double ms = 0.0;                    ///< wall time of the call, ms
};

/// S \ B' in place, as cut_surface computes it, on the surface `editor` edits (its grid built over it). The faces
/// near the blade come from the grid, and the result is written into S: the kept pieces of each patch triangle and
/// the kept blade triangles fill the patch triangles' slots in order, the rest are appended, and slots left over
/// are removed by moving the last triangles into them; pieces inherit their triangle's attributes, blade triangles
/// get cut = 1, origin = -1. New vertices are appended; vertices no longer used stay (result.removed_vertices).
/// Nothing in it is a pass over S: its cost depends on the faces near the blade, not on |S|.
/// When the result is not ok, S is exactly as it was (the editor's journal is rolled back); otherwise the edits stay
/// in the journal for the caller to roll back or commit.
SurfaceEditResult cut_surface_in_place(SurfaceEditor& editor, const sim::TriMesh& blade,
                                       const SurfaceCutOptions& options = {});

/// The shift of retry `attempt` (1, 2 or 3) of cut_surface_perturbing, relative to the blade's bounding-box diagonal:
/// 1e-9, 1e-7, 1e-5; 0 for attempt 0 (no move).
double blade_shift_fraction(int attempt);

/// cut_surface_in_place with the retries of cut_surface_perturbing.
std::pair<SurfaceEditResult, int> cut_surface_in_place_perturbing(SurfaceEditor& editor, sim::TriMesh& blade,
                                                                  const SurfaceCutOptions& options = {});

/// S \ B': removes the solid bounded by the closed, outward-oriented blade from the solid bounded by the closed,
/// outward-oriented, manifold surface, returning a new mesh: it copies S, builds a FaceGrid over the copy (O(|S|)),
/// runs cut_surface_in_place on it and compacts the result (kept vertices in order, new ones after them).
///
/// Outcomes: a blade that misses S, or only touches it from outside, gives no_op. A blade entirely inside S leaves a
/// cavity (an extra inner component, the reversed blade). A blade containing S gives ok with an empty mesh. Any
/// failure (bad input: non-finite coordinates, an index out of range, a blade that is not closed, manifold, outward
/// oriented or free of self-intersections; a CGAL exception; a result that fails the local verification) gives
/// failed with a reason; it never throws.
SurfaceCutResult cut_surface(const sim::TriMesh& surface, const sim::TriMesh& blade,
                             const SurfaceCutOptions& options = {});

/// cut_surface for blades in degenerate positions. The exact result is rounded to doubles, and in a degenerate
/// configuration two distinct intersection points can round to one (a blade vertex a few ulps from a surface edge,
/// say), which the cut then refuses. A failed cut is retried with the blade translated by 1e-9, then 1e-7, then 1e-5
/// (blade_shift_fraction) of its bounding-box diagonal along a fixed generic direction: simulation of simplicity in
/// its simplest form, deterministic, and far below any tissue scale (1e-5 of a 1 cm punch is 0.1 um, under the
/// rounding repair's collapse length). `blade` becomes the blade that was used, and the return value's second member
/// is the attempt that cut (0: none; 1, 2 or 3). When every attempt fails, the reason is the first attempt's.
std::pair<SurfaceCutResult, int> cut_surface_perturbing(const sim::TriMesh& surface, sim::TriMesh& blade,
                                                        const SurfaceCutOptions& options = {});

/// Whether `blade` (closed, outward oriented, m) can remove from the solid bounded by `surface` (S, with `grid` built
/// over it) only material within `min_feature` (m) of the blade's surface: a sub-feature shell, which a cut keeps whole
/// (cutting.min_feature). Conservative: true only when the blade is convex, its erosion by min_feature (its face planes
/// moved inwards by min_feature, to within a millionth of it) holds the blade's vertex centroid, no triangle of S meets
/// that erosion (triangles clipped against its half-spaces) and the centroid lies outside the solid (an exact ray
/// parity test). A blade thinner than 2 min_feature, a non-convex blade and min_feature <= 0 give false. Costs a
/// clipping of the faces of S in the blade's bounding box: no exact arithmetic but the one point query.
bool removes_only_subfeature(const sim::TriMesh& surface, FaceGrid& grid, const sim::TriMesh& blade,
                             double min_feature);

/// The earlier blade that `blade` snaps to (cutting.min_feature: near-coincident walls snap together), or -1: the
/// latest of `earlier` (rest-space blades of earlier cuts, m) that has the same triangles as `blade` (the same blade
/// mesh, mapped differently) and lies within `min_feature` (m) of it inside `region` (m; where material can be): the
/// Hausdorff distance of the two solids clipped to the region is below min_feature. For convex blades it is
/// computed exactly (the distance to a convex solid is convex, so the largest one over the other clipped solid is
/// taken at its corners); for others it is bounded through the vertices' correspondence (the largest move, from one
/// blade to the other, of a point of a triangle whose path meets the region). Replacing the blade by that one moves
/// every wall the cut makes by less than min_feature, exactly onto the wall the earlier blade left: the boolean then
/// meets coincident faces, not slivers beside them. `distance` (m), when given, receives the winner's distance
/// (infinity when none).
int snap_target(const sim::TriMesh& blade, const std::vector<sim::TriMesh>& earlier, const sim::Box3& region,
                double min_feature, double* distance = nullptr);

}  // namespace octocut::cutting
