#pragma once
// The world: builds the simulation of a scene and runs its timeline, writing report.json (SPEC §5, §8).
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "octocut/engine/scene.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/simulator.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// Most steps one run may take (duration / dt); more is bad input, not a run that never ends.
inline constexpr long kMaxSteps = 1'000'000'000;

/// Number of steps of a scene's timeline, ceil(duration / dt). Throws SceneError past kMaxSteps.
long step_count(const Scene& scene);

/// A scene's deformable object: its model, its rest surface S and, for mesh surfaces, its material graph M.
struct SceneObject {
  sim::ObjectModel model;
  sim::TriMesh surface;                                ///< rest surface S, m; a box primitive's is its 12 triangles
  std::shared_ptr<const sim::MaterialGraph> graph;     ///< M; null for a box primitive (exact box material)
  bool graph_from_cache = false;                       ///< M was read from the disk cache
  double graph_ms = 0.0;                               ///< time to obtain M, ms
  std::vector<std::string> warnings;                   ///< from loading the mesh and the cache
};

/// Builds the object of a scene. A mesh surface is loaded (assimp), validated, scaled to metres, and meshed into M
/// (CGAL Mesh_3, cached on disk); a box surface is an exact box material. Then the octree: root given, or the
/// bounding box of S made cubic and grown by 5%; base level, refine regions, handles. Throws SceneError naming the
/// file and JSON pointer for inputs that only fail once built (a bad mesh file, a probe outside the material).
SceneObject build_scene_object(const Scene& scene);

/// Loads and validates the render props' meshes (`render.props`), scaled to metres, in order. Throws SceneError naming
/// the file and `/render/props/<i>/mesh` for a bad mesh.
std::vector<sim::TriMesh> load_render_props(const Scene& scene);

/// The model of build_scene_object, for callers that need no surface.
sim::ObjectModel build_object(const Scene& scene);

/// The simulator options a scene asks for.
sim::SimulatorOptions simulator_options(const Scene& scene);

/// How `octocut run` runs a scene.
struct RunOptions {
  std::string out_dir = "out";  ///< report.json and outputs go here (created if missing)
  bool no_render = false;       ///< never touch EGL, whatever the scene says
  bool progress = false;        ///< print a progress line to stderr
};

/// Names of the timed parts of a cut in CutSummary::ms: the stages of SPEC §4, then the total.
inline constexpr std::array<const char*, 8> kCutStageKeys = {
    "back_transform", "surface", "material_graph", "refine", "node_split", "embedding", "solver_update", "total"};

/// One cut event of a run (the report's `cuts[]`, SPEC §8).
struct CutSummary {
  double t = 0.0;                  ///< time of the cut, s
  std::string tool;                ///< the tool's name
  std::string status;              ///< "ok" | "skipped" | "no-op"
  std::string reason;              ///< why skipped or no-op; empty when ok
  int components = 0;              ///< material components the blade touched
  int restricted_components = 0;   ///< of those, the ones whose rest-space blade left other material alone
  int unrestricted_components = 0; ///< of those, the ones whose restriction could not close up and was dropped
  double removed_volume_m3 = 0.0;  ///< V(S) - V(S') of the boolean, m^3
  int tets_removed = 0;            ///< tets of M removed
  int leaves_refined = 0;          ///< refine operations
  int fragments_removed = 0;       ///< loose pieces removed
  double fragment_volume_m3 = 0.0; ///< their material volume, m^3
  long elements_after = 0, dofs_after = 0, surface_vertices_after = 0;
  std::array<double, 8> ms{};      ///< per kCutStageKeys, ms
};

/// What a run ended with.
struct RunResult {
  int exit_code = 0;        ///< 0 ok, 1 the run failed (report written), 2 bad input
  std::string report_path;  ///< where report.json was written
  std::string error;        ///< the failure, when exit_code != 0
  std::vector<CutSummary> cuts;  ///< every cut event, in order
};

/// Runs a loaded scene to its duration and writes DIR/report.json atomically, also when the run fails part-way.
/// Bad input that is only detected while building (exit 2) is returned, not thrown.
RunResult run_scene(const Scene& scene, const RunOptions& options);

}  // namespace octocut::engine
