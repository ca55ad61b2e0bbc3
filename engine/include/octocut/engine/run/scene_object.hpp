#pragma once
// What a scene's inputs build before anything runs: the deformable object (model, rest surface S, material graph M),
// the render props' meshes, the simulator options, the number of steps. Bad input throws SceneError here, before
// any output is touched.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/object.hpp"
#include "octocut/sim/simulator.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// Most steps one run may take (duration / dt); more is bad input, not a run that never ends.
inline constexpr long kMaxSteps = 1'000'000'000;

/// Number of steps of a scene's timeline, ceil(duration / dt). Throws SceneError past kMaxSteps.
long step_count(const Scene& scene);

/// Where a scene's material graph M came from (the report's `subsystems.material_graph`).
enum class MaterialGraphSource {
  box,     ///< a box primitive: its exact material, or a Kuhn tet grid of it when tools cut it (no mesher)
  cache,   ///< a mesh surface whose M was read from the disk cache (no mesher call)
  meshed,  ///< a mesh surface meshed by CGAL Mesh_3 in this run
};

/// The report's name of a MaterialGraphSource: "box", "cache" or "meshed".
const char* to_string(MaterialGraphSource source);

/// A scene's deformable object: its model (which holds M: model.material_graph(), null for a box primitive that
/// nothing cuts) and its rest surface S.
struct SceneObject {
  sim::ObjectModel model;
  sim::TriMesh surface;                                ///< rest surface S, m; a box primitive's is its 12 triangles
  MaterialGraphSource graph_source = MaterialGraphSource::box;
  double graph_ms = 0.0;                               ///< time to obtain M, ms
  std::vector<std::string> warnings;                   ///< from loading the mesh and the cache
};

/// A scene's 3-vector as a sim vector (same units).
inline sim::Vec3 to_vec3(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }
/// A scene's box as a sim box, m.
inline sim::Box3 to_box3(const SceneBox& b) { return {to_vec3(b.min), to_vec3(b.max)}; }

/// The simulation's material parameters of a scene's material (same units), its hexahedron formulation included.
/// Throws std::invalid_argument for an element other than "bbar" or "trilinear".
sim::MaterialParams material_params(const Material& material);

/// True when some tool of the scene has cut events on its timeline.
bool scene_cuts(const Scene& scene);

/// Builds the object of a scene. A mesh surface is loaded (assimp), validated, scaled to metres, and meshed into M
/// (CGAL Mesh_3, cached on disk); a box surface is an exact box material, or a Kuhn tet grid of it when it is to be
/// cut (`cuttable`, or a tool has cut events), since a cut needs M. Then
/// the octree: root given, or the bounding box of S made cubic and grown by 5%; base level, refine regions, handles.
/// Throws SceneError naming the file and JSON pointer for inputs that only fail once built (a bad mesh file, a probe
/// outside the material).
SceneObject build_scene_object(const Scene& scene, bool cuttable = false);

/// Loads and validates the render props' meshes (`render.props`), scaled to metres, in order. Throws SceneError naming
/// the file and `/render/props/<i>/mesh` for a bad mesh.
std::vector<sim::TriMesh> load_render_props(const Scene& scene);

/// The simulator options a scene asks for.
sim::SimulatorOptions simulator_options(const Scene& scene);

}  // namespace octocut::engine
