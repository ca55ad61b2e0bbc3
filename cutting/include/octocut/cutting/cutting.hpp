#pragma once
// The cut pipeline (SPEC §4, paper §3–4): one volumetric, non-progressive cut of a deformable object by a closed
// blade, in five timed stages, as one transaction. No CGAL type appears here; the exact surface boolean lives in
// cutting/src/surface_cut*.cpp (one file per phase).
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "octocut/cutting/surface_editor.hpp"
#include "octocut/sim/embedding.hpp"
#include "octocut/sim/simulator.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::cutting {

/// What happens to material that a cut separates from every handle.
enum class FragmentPolicy {
  all,    ///< every loose piece is removed from the simulation
  small,  ///< only loose pieces below CutOptions::fragment_volume are removed
  none,   ///< loose pieces stay (they fall freely)
};

/// The default minimum feature size of cuts, m (the scene key cutting.min_feature): 0.3 mm, half the finest
/// material-graph cell of the shipped scenes (0.6 mm; M, which the simulation's material is, resolves nothing finer)
/// and below the 0.5 mm advance of overlapping bites, but above the tens to hundreds of micrometres by which a
/// re-punch at one spot of a sagging slab lands beside the wall the last one left (docs/RESULTS.md, issue 18).
inline constexpr double kDefaultMinFeature = 3e-4;

/// The edges at new vertices of a cut's result shorter than this fraction of CutOptions::min_feature collapse where
/// the exact checks allow (SurfaceCutOptions::tiny_edge): 3 um at the default. The surface moves by less than that
/// where one does, so the removed volume stays exact to within it times the new faces' area; 1e-3 left new edges of
/// 0.3-0.7 um and smallest new angles of 0.02 deg on the overlapping bites, 0.1 cost 0.5 ms of a 50k bite
/// (docs/RESULTS.md, "Where meniscus_punch's contact time goes").
inline constexpr double kTinyEdgeFraction = 0.01;

struct CutOptions {
  double max_condition = 10.0;                  ///< shape matching: blend towards the rotation above this cond(A)
  FragmentPolicy fragments = FragmentPolicy::all;
  double fragment_volume = 1e-9;                ///< m^3; the threshold of FragmentPolicy::small
  bool verify = true;                           ///< check S after the boolean (closed, manifold, no self-intersection)
  double min_feature = kDefaultMinFeature;      ///< m; material that a blade would remove only within this depth
                                                ///< below its surface is a sub-feature shell, kept whole: the cut
                                                ///< is a no-op (removes_only_subfeature), and a rest-space blade
                                                ///< within it of an earlier cut's snaps onto that (snap_target);
                                                ///< 0: off
};

/// The FaceGrid of CutObject::surface and the sizes of S it matches. A copy starts empty: the copy's grid is built
/// for its own surface when that is first cut.
struct SurfaceGrid {
  std::unique_ptr<FaceGrid> grid;
  std::size_t vertices = 0, triangles = 0;  ///< |V| and |F| of the surface it was built or last updated for
  /// S's rest-space bounds (m), once a cut has needed them (a blade that may snap); kept exact from cut to cut
  /// without a pass over S (a cut only adds vertices inside them and removes others), and dropped when a cut
  /// removes a vertex on one of them. Empty until needed and after index_surface.
  mutable std::optional<sim::Box3> bounds;

  SurfaceGrid() = default;
  SurfaceGrid(const SurfaceGrid&) {}
  SurfaceGrid& operator=(const SurfaceGrid& other) {
    if (this != &other) *this = SurfaceGrid{};
    return *this;
  }
  SurfaceGrid(SurfaceGrid&&) noexcept = default;
  SurfaceGrid& operator=(SurfaceGrid&&) noexcept = default;
  ~SurfaceGrid() = default;
};

/// The parts of one deformable object that cuts edit, besides the simulator and the embedding. M is not here: the
/// simulator's model owns it (sim::ObjectModel::material_graph()), and a cut hands M' over with the new revision.
struct CutObject {
  sim::TriMesh surface;         ///< S in rest space, m: its one copy. The grid and the sim::SurfaceEmbedding index it
                                ///< and are given it; apply_cut edits it in place
  std::vector<char> cut_faces;  ///< 1 for a triangle of S that came from a blade (|F|)
  bool surface_checked = false;  ///< S is known to be closed, manifold and free of self-intersections (checked when
                                 ///< it was loaded). Cuts then skip CGAL's own self-intersection check of S near the
                                 ///< blade; a cut with CutOptions::verify keeps this true (its changed faces are
                                 ///< checked), one without sets it false. Leave it false for an unchecked S
  SurfaceGrid grid;  ///< the grid over S's triangles that finds those near a blade; apply_cut keeps it up to date.
                     ///< Call index_surface after setting or changing `surface` yourself (else the next cut builds
                     ///< it, an O(|S|) cost in its surface stage)
  std::vector<sim::TriMesh> recent_blades;  ///< rest-space blades (m) of the latest cuts that changed S, oldest first
                                            ///< (at most kRecentBlades): a new rest-space blade within min_feature
                                            ///< of one of them snaps onto it (snap_target)
  std::vector<char> recent_whole;  ///< per recent blade: 1 when a cut removed all the material under it (not
                                   ///< restricted to a component), so that S holds none inside it: a cut whose
                                   ///< every rest-space blade is such a blade is a no-op without a boolean
};

/// How many rest-space blades of earlier cuts CutObject::recent_blades keeps.
inline constexpr std::size_t kRecentBlades = 8;

/// Builds object.grid over object.surface: O(|S|), once after loading S. Throws std::invalid_argument naming the
/// first non-finite vertex or triangle index out of range.
void index_surface(CutObject& object);

/// Whether object.grid matches object.surface (the same |V| and |F|; apply_cut keeps them in step).
[[nodiscard]] bool surface_indexed(const CutObject& object);

/// One cut event: the blade where it is when the cut happens.
struct CutRequest {
  sim::TriMesh blade;              ///< closed, outward-oriented, in world (deformed) space, m
  double inscribed_radius = 0.0;   ///< radius of the blade's largest inscribed sphere, m (paper §4.4.1's r)
};

/// Wall time of each stage, ms, in the order of SPEC §4 (the report's `cuts[].ms`, SPEC §8), and the total.
struct CutStageMs {
  double back_transform = 0.0, surface = 0.0, material_graph = 0.0, refine = 0.0, node_split = 0.0,
         embedding = 0.0, solver_update = 0.0, total = 0.0;
  /// Not a stage: what the model thread spent preparing the first step's bridge solve (sim::PreparedModel::bridge_ms)
  /// while the surface stage still ran, ms. Work of the step after the cut done ahead of it, so not in solver_update;
  /// in the total only as far as the cut waited for it.
  double bridge = 0.0;
};

/// What one cut did (the report's `cuts[]` entry, SPEC §8).
struct CutOutcome {
  std::string status = "skipped";     ///< "ok" | "skipped" | "no-op"
  std::string reason;                 ///< why the cut was skipped or was a no-op; empty when ok
  int components = 0;                 ///< connected material components the blade touched (one transform each)
  int restricted_components = 0;      ///< components whose rest-space blade also covered other material, which it
                                      ///< left alone (SPEC §4 stage 2: B'_i cuts only component i's material)
  double removed_volume = 0.0;        ///< V(S) - V(S'), m^3: the blade's share, fragments not included
  int tets_removed = 0;               ///< tets of M the blade touched
  int leaves_refined = 0;             ///< refine operations
  int fragments_removed = 0;          ///< loose pieces removed from the simulation
  double fragment_volume = 0.0;       ///< their material volume, m^3
  double max_blend = 0.0;             ///< largest shape-matching blend towards the rotation (0: none)
  int perturbed = 0;                  ///< blades moved by 1e-9, 1e-7 or 1e-5 of their size to leave a degenerate case
  double blade_shift = 0.0;           ///< the largest of those moves, relative to the blade's size (0: none)
  int snapped = 0;                    ///< rest-space blades replaced by an earlier cut's within min_feature of them
                                      ///< (near-coincident walls snap together: snap_target)
  int unrestricted = 0;               ///< of the restricted components, those whose restricted boolean could not be
                                      ///< closed up: their blade cut all the material under it
  int collapses = 0;                  ///< edge collapses of the rounding repair (what rounding to doubles broke)
  int new_triangles = 0;              ///< triangles the surface boolean made (pieces of cut faces and of the blades)
  double min_angle_deg = 0.0;         ///< smallest interior angle among them, degrees (0 when none)
  double min_edge = 0.0;              ///< shortest edge among them, m (0 when none)
  CutStageMs ms;
};

/// Runs one cut on an object (SPEC §4):
/// 1. back_transform: the leaves whose deformed hexahedra meet the blade, grouped into face- and material-connected
///    components; per component a shape-matching affine map maps the blade into rest space (B'_i).
/// 2. surface: S <- S \ B'_i, an exact local boolean.
/// 3. material_graph: the tets of M that meet B'_i are removed.
/// 4. refine (leaves meeting B'_i with edge > r / sqrt(3), within max_level), then node_split (occupancy and
///    connectivity of the touched leaves, DOFs by node splitting), then loose fragments per `options`.
/// 5. embedding: S compacted in place (the vertices no triangle uses go), the embedding updated for it, then the
///    solver's symbolic analysis.
/// The simulator's model must hold M as its material (sim::ObjectModel::material_graph()); the cut is skipped
/// otherwise. `embedding` must be the embedding of object.surface in the simulator's model.
/// The cut is a transaction: on any failure (a stage throws, the boolean fails its checks, numerical trouble) the
/// object, the simulator and the embedding are left exactly as they were and the outcome is "skipped" with the reason.
/// A blade that changes nothing is a "no-op". Never throws for geometric or numerical trouble.
CutOutcome apply_cut(CutObject& object, sim::Simulator& simulator, sim::SurfaceEmbedding& embedding,
                     const CutRequest& request, const CutOptions& options);

}  // namespace octocut::cutting
