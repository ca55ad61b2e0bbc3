// The viewer's simulation thread. See sim_runner.hpp.
#include "view/sim_runner.hpp"

#include <algorithm>
#include <cstdio>
#include <numeric>

#include "octocut/engine/run/tool.hpp"

namespace octocut::engine {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

}  // namespace

SimRunner::SimRunner(const Scene& scene, std::size_t hand, std::vector<std::string> sets)
    : m_scene(scene), m_hand(hand), m_overlays(scene.render.overlays) {
  m_rate_wall = m_wall_anchor = Clock::now();
  m_world.emplace(m_scene, WorldOptions{true, true});
  m_session.scene_name = scene.name;
  m_session.scene_fingerprint = scene_fingerprint(scene.file);
  m_session.sets = std::move(sets);
  take_in_hand();
  publish_stats(true);
}

SimRunner::~SimRunner() { stop(); }

void SimRunner::start() {
  m_thread = std::thread([this] {
    try {
      loop();
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(m_mutex);
      m_error = e.what();
    }
  });
}

void SimRunner::stop() {
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_stop = true;
  }
  m_wake.notify_all();
  if (m_thread.joinable()) m_thread.join();
}

void SimRunner::push(Command c) {
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_commands.push_back(std::move(c));
  }
  m_wake.notify_all();
}

void SimRunner::set_tool_pose(const sim::Pose& pose) { push({SessionEventKind::pose, pose, {}, {}, false}); }
void SimRunner::cut() { push({SessionEventKind::cut, {}, {}, {}, false}); }
void SimRunner::set_material(const Material& m) { push({SessionEventKind::material, {}, m, {}, false}); }
void SimRunner::set_paused(bool p) {
  push({p ? SessionEventKind::pause : SessionEventKind::resume, {}, {}, {}, false});
}
void SimRunner::single_step() { push({SessionEventKind::pause, {}, {}, {}, true}); }
void SimRunner::hold(std::size_t tool) { push({SessionEventKind::hold, {}, {}, {}, false, tool}); }
void SimRunner::reset() { push({SessionEventKind::reset, {}, {}, {}, false}); }
void SimRunner::set_overlays(const OverlaySettings& o) { push({SessionEventKind::pose, {}, {}, o, false}); }

void SimRunner::request_frame() {
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_want_frame = true;
  }
  m_wake.notify_all();
}

std::optional<RenderScene> SimRunner::take_frame() {
  std::lock_guard<std::mutex> lock(m_mutex);
  std::optional<RenderScene> f = std::move(m_frame);
  m_frame.reset();
  return f;
}

SimStats SimRunner::stats() const {
  std::lock_guard<std::mutex> lock(m_mutex);
  return m_stats;
}

Session SimRunner::session() const {
  std::lock_guard<std::mutex> lock(m_mutex);
  return m_session;
}

Report SimRunner::report() const { return m_world->report(); }

std::string SimRunner::error() const {
  std::lock_guard<std::mutex> lock(m_mutex);
  return m_error;
}

void SimRunner::record(SessionEventKind kind, const sim::Pose& pose, const Material& material) {
  SessionEvent e;
  e.kind = kind;
  e.step = m_world->steps();
  e.t = m_world->time();
  e.tool = m_hand;
  e.pose = pose;
  e.material = material;
  std::lock_guard<std::mutex> lock(m_mutex);
  m_session.events.push_back(e);
  m_session.end_step = m_world->steps();
}

void SimRunner::take_in_hand() {
  m_world->set_overlays(m_overlays);
  if (m_scene.tools.empty()) return;  // nothing to hold: the viewer only watches
  m_world->hold_tool(m_hand);
  record(SessionEventKind::hold);
}

void SimRunner::apply(const Command& c) {
  if (c.overlays) {
    m_overlays = *c.overlays;
    m_world->set_overlays(m_overlays);
    return;
  }
  if (c.single_step) {
    ++m_single_steps;
    return;
  }
  const bool hand_input = c.kind == SessionEventKind::pose || c.kind == SessionEventKind::cut;
  if (hand_input && m_scene.tools.empty()) return;
  switch (c.kind) {
    case SessionEventKind::pose:
      m_world->set_tool_pose(m_hand, c.pose);
      record(c.kind, c.pose);
      break;
    case SessionEventKind::cut: {
      {
        std::lock_guard<std::mutex> lock(m_mutex);
        m_stats.cutting = true;
      }
      record(c.kind);
      const CutSummary s = m_world->cut_now(m_hand);
      std::fprintf(stderr, "[view] cut at t = %.4f s: %s, removed %.6g m^3, %.1f ms%s%s\n", s.t, s.status.c_str(),
                   s.removed_volume_m3, s.ms.back(), s.reason.empty() ? "" : ": ", s.reason.c_str());
      std::lock_guard<std::mutex> lock(m_mutex);
      m_stats.cutting = false;
      m_stats.last_cut = s;
      break;
    }
    case SessionEventKind::material:
      try {
        m_world->set_material(c.material);
        record(c.kind, {}, c.material);
      } catch (const std::invalid_argument& e) {
        std::fprintf(stderr, "[view] material not changed: %s\n", e.what());
      }
      break;
    case SessionEventKind::pause:
    case SessionEventKind::resume:
      if (m_paused == (c.kind == SessionEventKind::pause)) break;
      m_paused = c.kind == SessionEventKind::pause;
      record(c.kind);
      m_wall_anchor = m_rate_wall = Clock::now();
      m_sim_anchor = m_rate_sim = m_world->time();
      break;
    case SessionEventKind::reset: {
      const std::optional<sim::Pose> pose =
          m_scene.tools.empty() ? std::nullopt : std::optional<sim::Pose>(m_world->tool_pose(m_hand));
      m_world.emplace(m_scene, WorldOptions{true, true});
      record(c.kind);
      take_in_hand();
      if (pose) {
        m_world->set_tool_pose(m_hand, *pose);
        record(SessionEventKind::pose, *pose);
      }
      m_wall_anchor = m_rate_wall = Clock::now();
      m_sim_anchor = m_rate_sim = 0.0;
      break;
    }
    case SessionEventKind::hold:
      if (c.tool < m_scene.tools.size() && c.tool != m_hand) {
        m_hand = c.tool;
        take_in_hand();
      }
      break;
  }
}

void SimRunner::publish_stats(bool force) {
  // The real-time factor and the mean step time over the last half second of wall time.
  const auto now = Clock::now();
  const double wall = seconds_between(m_rate_wall, now);
  if (!force && wall < 0.5) return;
  const sim::ObjectModel& model = m_world->simulator().model();
  std::lock_guard<std::mutex> lock(m_mutex);
  SimStats& s = m_stats;
  if (wall >= 0.5) {
    s.real_time_factor = m_paused ? 0.0 : (m_world->time() - m_rate_sim) / wall;
    s.behind = !m_paused && s.real_time_factor < 0.95;
    s.step_ms = m_recent_step_ms.empty() ? 0.0
                                         : std::accumulate(m_recent_step_ms.begin(), m_recent_step_ms.end(), 0.0) /
                                               double(m_recent_step_ms.size());
    m_recent_step_ms.clear();
    m_rate_wall = now;
    m_rate_sim = m_world->time();
  }
  s.t = m_world->time();
  s.steps = m_world->steps();
  s.paused = m_paused;
  s.elements = model.num_elements();
  s.dofs = model.num_dofs();
  s.surface_vertices = long(m_world->rest_surface().num_vertices());
  s.surface_triangles = long(m_world->rest_surface().num_triangles());
  s.tets = model.material_graph() ? model.material_graph()->num_tets() : 0;
  s.material = m_world->material();
  s.contact = m_world->has_contact();
  s.contact_forces = m_world->contact_forces();
  m_session.end_step = m_world->steps();
}

void SimRunner::serve_frame() {
  RenderScene frame = m_world->render_scene();
  std::lock_guard<std::mutex> lock(m_mutex);
  m_frame = std::move(frame);
  m_want_frame = false;
}

void SimRunner::loop() {
  const double dt = m_scene.solver.dt;
  m_wall_anchor = m_rate_wall = Clock::now();
  m_sim_anchor = m_rate_sim = m_world->time();
  for (;;) {
    std::deque<Command> commands;
    bool want_frame = false;
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      if (m_stop) break;
      commands.swap(m_commands);
      want_frame = m_want_frame;
    }
    // Inputs between steps; of several poses in a row only the last matters.
    for (std::size_t i = 0; i < commands.size(); ++i) {
      const Command& c = commands[i];
      const bool superseded = c.kind == SessionEventKind::pose && !c.overlays && i + 1 < commands.size() &&
                              commands[i + 1].kind == SessionEventKind::pose && !commands[i + 1].overlays;
      if (!superseded) apply(c);
    }
    // What the inputs did (a cut) shows at once, not only after the next step (which may be long after a cut).
    if (!commands.empty()) {
      serve_frame();
      want_frame = false;
    }

    // Simulated time follows the wall clock from the anchor; when the simulation falls behind by more than a few
    // steps, the anchor moves up to it: time slows down, no step is skipped and none is made up later.
    const auto now = Clock::now();
    const double target = m_sim_anchor + seconds_between(m_wall_anchor, now);
    bool stepped = false;
    if (m_single_steps > 0 || (!m_paused && m_world->time() + 0.5 * dt <= target)) {
      const StepResult r = m_world->step();
      m_recent_step_ms.push_back(r.ms);
      if (m_single_steps > 0) --m_single_steps;
      stepped = true;
      if (target - m_world->time() > std::max(0.05, 5.0 * dt)) {
        m_sim_anchor = m_world->time();
        m_wall_anchor = Clock::now();
      }
    }
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      want_frame = m_want_frame;  // also a request that came during the step
    }
    if (want_frame) serve_frame();
    publish_stats(true);  // cheap: the counts and the time every pass, the rates every half second
    if (!stepped) {
      // Wait for the next step's time, an input or a frame request.
      const double wait_s = m_paused ? 0.05 : std::clamp(m_world->time() + 0.5 * dt - target, 0.0, 0.05);
      std::unique_lock<std::mutex> lock(m_mutex);
      m_wake.wait_for(lock, std::chrono::duration<double>(wait_s),
                      [&] { return m_stop || !m_commands.empty() || m_want_frame; });
    }
  }
  std::lock_guard<std::mutex> lock(m_mutex);
  m_session.end_step = m_world->steps();
}

}  // namespace octocut::engine
