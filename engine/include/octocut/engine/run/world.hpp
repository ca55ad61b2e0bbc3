#pragma once
// engine::World: one running scene (SPEC §5). It owns everything a scene needs while it runs: the simulator (model
// and state), the cut object (S, M and the index that finds S's faces near a blade), the surface embedding, the
// tools and their blades, the render props, and the timeline of cut events. A run loop, a benchmark, a study and an
// interactive viewer all drive it through the same small API:
//
//   World world(scene, {.render = false});     // throws SceneError for bad input, before any output is touched
//   while (!world.done()) world.step();        // one dt, then the cut events that are due
//   world.cut_now(0);                          // a cut that is not on the timeline
//   Report report = world.report();            // the report so far
//
// World writes no file and starts no renderer: `render_scene()` returns the GL-free description of what is to be
// drawn, and run_scene (run.hpp) adds the renderer, the frame writer and the files of `octocut run`.
#include <array>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "octocut/engine/render/render_scene.hpp"
#include "octocut/engine/run/report.hpp"
#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/pose.hpp"
#include "octocut/sim/simulator.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// How a World is built, besides its scene.
struct WorldOptions {
  /// Build what drawing needs (render props' and tools' meshes, the camera) when the scene has `render.enabled`.
  /// False for `--no-render`, benchmarks and studies: render_scene() then throws.
  bool render = true;
  /// Build what cuts need even when no tool has cut events on the timeline: a material graph for a box primitive,
  /// and the index over S from the start. Set it when tools will be cut with by hand (cut_now in a viewer).
  bool cuttable = false;
};

/// What one World::step() did.
struct StepResult {
  double t = 0.0;                 ///< simulated time after the step, s
  std::vector<CutSummary> cuts;   ///< the cut events that ran during the step, in order (also in report().cuts)
  double ms = 0.0;                ///< wall time of the step, its cuts included, ms
};

/// The contact force on one colliding tool or rigid body after a step (contact_forces.csv's row).
struct ContactForce {
  std::string name;
  bool tool = false;                     ///< a tool (else a rigid body)
  std::array<double, 3> force_n{};       ///< the force the tissue exerts on it in the last step, N (3)
  double max_penetration_m = 0.0;        ///< deepest sample in it at the start of the last step, m
};

/// Where the contact time of the last step went, ms.
struct ContactTiming {
  double queries = 0.0;  ///< sample positions, the bounding-box prefilter and Bullet's distance queries
  double terms = 0.0;    ///< the contact terms added to the implicit system and their forces afterwards
  double rigid = 0.0;    ///< forces onto the bodies and Bullet's step
  long box_queries = 0;  ///< samples whose distance the queries took from Bullet's box queries (not certified)
  long triangles = 0;    ///< triangles of mesh colliders the queries tested for the nearest point
};

/// True when every DOF position and velocity of `state` is finite.
bool state_finite(const sim::SimState& state);

/// One running scene. Not copyable; movable. Not thread-safe: one thread drives it (a viewer copies render_scene()
/// under its own lock).
class World {
 public:
  /// Builds the world of a validated scene: the object (mesh loading, the material graph from the cache or the
  /// mesher), the simulator, the surface embedding, the tools' blades (for tools with cut events), and, when drawing
  /// is asked for, the meshes of the render props and tools. Cut events at t = 0 run in the first step(). Throws
  /// SceneError (file and JSON pointer) for bad input found while building; writes nothing.
  explicit World(const Scene& scene, const WorldOptions& options = {});
  ~World();
  World(World&&) noexcept;
  World& operator=(World&&) noexcept;
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  /// Runs the cut events that are due at the current time and have not run (those at t = 0 before the first step),
  /// advances the simulation by one dt (an object cut away entirely only advances time), then runs the cut events
  /// that are due at the new time. Never throws for numerical or geometric trouble: the simulator recovers from a
  /// failed step and counts it, a cut that fails is skipped, and both are in the report.
  StepResult step();
  /// Simulated time, s.
  [[nodiscard]] double time() const;
  /// Steps taken so far.
  [[nodiscard]] long steps() const;
  /// Steps of the scene's timeline, ceil(duration / dt).
  [[nodiscard]] long total_steps() const;
  /// True once total_steps() steps have been taken.
  [[nodiscard]] bool done() const;

  /// Cuts now with tool `tool`'s blade where the tool is now (its keyframes, or the pose set by set_tool_pose): a cut
  /// event that is not on the timeline. The cut is reported like any other. A box primitive can only be cut when it
  /// has a material graph (WorldOptions::cuttable, or cut events on the timeline); otherwise the cut is skipped with
  /// that reason. Throws std::out_of_range for a bad index;
  /// SceneError when the tool's blade file is bad (blades of tools without cut events load on their first cut).
  CutSummary cut_now(std::size_t tool);
  /// Overrides the keyframes of tool `tool` with `pose` (tool coordinates to world) from now on: a tool that a
  /// person drives. Throws std::out_of_range for a bad index.
  void set_tool_pose(std::size_t tool, const sim::Pose& pose);
  /// Gives tool `tool` back to its keyframes.
  void release_tool(std::size_t tool);
  /// A person takes tool `tool` in hand (the viewer): its cut events still on the timeline are dropped, and it
  /// stays where it is now until set_tool_pose moves it; everything else keeps its keyframes. Its blade is loaded
  /// now. Throws std::out_of_range for a bad index, SceneError for a bad blade file.
  void hold_tool(std::size_t tool);
  /// Where tool `tool` is now (tool coordinates to world).
  [[nodiscard]] sim::Pose tool_pose(std::size_t tool) const;
  /// The index of the tool named `name`, or nullopt.
  [[nodiscard]] std::optional<std::size_t> tool_index(const std::string& name) const;

  /// Changes the object's material from now on (E, nu, density, Rayleigh damping, the element; an empty element
  /// keeps the object's): the model gets a new revision with the same leaves and DOFs, the state carries over.
  /// Throws std::invalid_argument for values outside the scene schema's ranges (E > 0, 0 <= nu < 0.5, density > 0,
  /// damping >= 0, element "bbar" or "trilinear"), leaving the world untouched.
  void set_material(const Material& material);
  /// The object's material now (the scene's, or the last set_material).
  [[nodiscard]] const Material& material() const;
  /// The debug overlays render_scene() draws from now on (the scene's render.overlays at the start).
  void set_overlays(const OverlaySettings& overlays);
  /// True when the scene collides (a tool or prop collides, or it has rigid bodies): a Bullet world is built.
  [[nodiscard]] bool has_contact() const;
  /// The force the tissue exerted on tool `tool` in the last step, N: for a haptic device. Zero for a tool that
  /// does not collide, and before the first step. Throws std::out_of_range for a bad index.
  [[nodiscard]] std::array<double, 3> tool_contact_force(std::size_t tool) const;
  /// The contact force on every colliding tool and rigid body after the last step (tools first, in scene order);
  /// empty without contact.
  [[nodiscard]] std::vector<ContactForce> contact_forces() const;
  /// Where the contact time of the last step went (zero without contact).
  [[nodiscard]] ContactTiming contact_timing() const;
  /// Kinetic plus gravitational potential energy of the dynamic rigid bodies (potential zero at the world origin),
  /// J; 0 without any.
  [[nodiscard]] double rigid_body_energy() const;

  /// True when this world draws: the scene has render.enabled and WorldOptions::render is set.
  [[nodiscard]] bool renders() const;
  /// The GL-free description of the current frame: the deformed tissue (cut faces marked), the props and tools at
  /// their poses now, the camera (following its tool), and the overlays. Throws std::logic_error when !renders().
  [[nodiscard]] RenderScene render_scene() const;

  /// The report so far: counts of the current model and of S, the cuts, probes, energies, stability counters,
  /// warnings, the step timings and the subsystems built. Run-loop fields (frames, render timings, wall time,
  /// renderer and frame writer) are left for the run loop to fill in. O(|S|) (it checks S's topology and volume):
  /// an interactive loop calls it now and then, not every frame.
  [[nodiscard]] Report report() const;

  /// The scene this world runs (defaults filled in).
  [[nodiscard]] const Scene& scene() const;
  /// The simulator: the current model revision and state.
  [[nodiscard]] const sim::Simulator& simulator() const;
  /// The rest surface S now (after the cuts so far), m. Its only copy in the world.
  [[nodiscard]] const sim::TriMesh& rest_surface() const;
  /// The deformed positions of S's vertices after the last step (|V|, m); empty once the object is cut away. Computed
  /// at the first call after a step or a cut (steps do not compute it), so, like step(), not to be called from
  /// another thread while one runs.
  [[nodiscard]] const std::vector<sim::Vec3>& deformed_vertices() const;
  /// S deformed, for writing (positions of deformed_vertices(), triangles of rest_surface()).
  [[nodiscard]] sim::TriMesh deformed_surface() const;
  /// True once every element has been cut away.
  [[nodiscard]] bool object_removed() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m;
};

}  // namespace octocut::engine
