#pragma once
// The viewer's simulation thread: it owns the World, applies the inputs that the window sends (queued, applied
// between steps), records them into a Session, and keeps simulated time on the wall clock. It never waits for the
// window: the window asks for a frame and takes the latest complete one. No GL or GLFW here.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "octocut/engine/render/render_scene.hpp"
#include "octocut/engine/run/report.hpp"
#include "octocut/engine/run/session.hpp"
#include "octocut/engine/run/world.hpp"

namespace octocut::engine {

/// What the panel shows of the simulation, copied out under the runner's lock.
struct SimStats {
  double t = 0.0;                  ///< simulated time, s
  long steps = 0;                  ///< steps of the current world
  double real_time_factor = 0.0;   ///< simulated s per wall s over the last half second (0 while paused)
  bool behind = false;             ///< the simulation cannot keep up with the wall clock: time runs slower
  bool paused = false;
  bool cutting = false;            ///< a cut is running now
  double step_ms = 0.0;            ///< mean wall time of the steps of the last half second, ms
  double last_step_ms = 0.0;       ///< ms
  std::optional<CutSummary> last_cut;  ///< the last cut made by hand, with its stage timings
  long cuts = 0;                   ///< cuts so far in this world
  long elements = 0, dofs = 0, surface_vertices = 0, surface_triangles = 0, tets = 0;
  Material material;               ///< the material now
  bool contact = false;            ///< the scene collides (World::has_contact)
  std::vector<ContactForce> contact_forces;  ///< per colliding tool and body after the last step
};

class SimRunner {
 public:
  /// Builds the world (throws SceneError for bad input, before the thread starts) and takes tool `hand` in hand.
  SimRunner(const Scene& scene, std::size_t hand, std::vector<std::string> sets);
  /// Stops the thread.
  ~SimRunner();
  SimRunner(const SimRunner&) = delete;
  SimRunner& operator=(const SimRunner&) = delete;

  /// Starts the simulation thread.
  void start();
  /// Stops the thread after the step in progress (a cut in progress finishes first). Idempotent.
  void stop();

  // Inputs, queued and applied by the simulation thread before its next step (recorded then).
  void set_tool_pose(const sim::Pose& pose);
  void cut();
  void set_material(const Material& material);
  void set_paused(bool paused);
  void single_step();  ///< one step while paused
  void reset();
  /// Takes tool `tool` in hand instead (the one held before stays where it is).
  void hold(std::size_t tool);
  void set_overlays(const OverlaySettings& overlays);

  /// Asks for a new frame; take_frame() returns it once the simulation thread has made it.
  void request_frame();
  /// The latest complete frame when one newer than the last taken exists.
  std::optional<RenderScene> take_frame();
  [[nodiscard]] SimStats stats() const;
  /// The session recorded so far; end_step is the current world's step count.
  [[nodiscard]] Session session() const;
  /// The world's report (call after stop()).
  [[nodiscard]] Report report() const;
  /// The error that stopped the thread, if any.
  [[nodiscard]] std::string error() const;

 private:
  struct Command {
    SessionEventKind kind;
    sim::Pose pose;
    Material material;
    std::optional<OverlaySettings> overlays;  ///< set: an overlay change (not recorded)
    bool single_step = false;                 ///< a single step request (not recorded)
    std::size_t tool = 0;                     ///< hold: the tool to take in hand
  };
  void push(Command c);
  void loop();
  void apply(const Command& c);
  void record(SessionEventKind kind, const sim::Pose& pose = {}, const Material& material = {});
  void publish_stats(bool force);
  void serve_frame();
  void take_in_hand();

  Scene m_scene;
  std::size_t m_hand;
  std::optional<World> m_world;
  OverlaySettings m_overlays;

  mutable std::mutex m_mutex;             // guards everything below
  std::condition_variable m_wake;
  std::deque<Command> m_commands;
  Session m_session;
  SimStats m_stats;
  bool m_want_frame = false;
  std::optional<RenderScene> m_frame;
  std::string m_error;
  bool m_stop = false;

  std::thread m_thread;
  // Simulation-thread state: the wall-clock anchor of simulated time, pause, single steps.
  bool m_paused = false;
  int m_single_steps = 0;
  std::chrono::steady_clock::time_point m_wall_anchor;
  double m_sim_anchor = 0.0;
  std::chrono::steady_clock::time_point m_rate_wall;
  double m_rate_sim = 0.0;
  std::vector<double> m_recent_step_ms;
};

}  // namespace octocut::engine
