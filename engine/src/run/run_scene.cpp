// `octocut run`: a thin loop over engine::World, plus the render thread, the frame writer, the surface files, the
// progress line and the report file.
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include "octocut/engine/io/io.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/render/render_thread.hpp"
#include "octocut/engine/render/renderer.hpp"
#include "octocut/engine/run/run.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::engine {

namespace {

namespace fs = std::filesystem;

// Set by SIGINT/SIGTERM: the run stops at the next step and still writes its report.
std::atomic<bool> g_interrupted{false};
extern "C" void on_signal(int) { g_interrupted = true; }

// Installs the run's signal handlers for its lifetime and restores the previous ones.
class SignalGuard {
 public:
  SignalGuard() {
    g_interrupted = false;
    m_int = std::signal(SIGINT, on_signal);
    m_term = std::signal(SIGTERM, on_signal);
  }
  ~SignalGuard() {
    std::signal(SIGINT, m_int);
    std::signal(SIGTERM, m_term);
  }
  SignalGuard(const SignalGuard&) = delete;
  SignalGuard& operator=(const SignalGuard&) = delete;

 private:
  void (*m_int)(int) = SIG_DFL;
  void (*m_term)(int) = SIG_DFL;
};

// One run of `octocut run` over a built World: the outputs it writes and the timings it keeps.
class Run {
 public:
  Run(World& world, const RunOptions& options, fs::path out) : m_world(world), m_options(options), m_out(std::move(out)) {}

  // Starts the render thread when the world draws. It makes the renderer (the EGL context is current on that thread
  // only) before the first step, so an EGL failure is still found here: bad input (exit 2), with the report written.
  // Each image goes to the frame writer, when there is one, in frame order.
  void start_renderer() {
    if (!m_world.renders()) return;
    RenderThread::Factory factory = m_options.renderer_factory;
    if (!factory) factory = [] { return make_renderer(); };
    // On the render thread: lower its priority first, so that it and llvmpipe's rasteriser threads (which start with
    // its context and inherit it) draw with what the simulation leaves of the cores (docs/RESULTS.md, "Frames on a
    // render thread"). Best effort.
    RenderThread::Factory lowered = [factory = std::move(factory)] {
      (void)setpriority(PRIO_PROCESS, id_t(syscall(SYS_gettid)), 19);
      return factory();
    };
    m_render = std::make_unique<RenderThread>(
        std::move(lowered), [this](long index, Image image) {
          if (m_writer) m_writer->push(index, std::move(image));
        },
        kRenderQueue);
  }

  // The whole timeline: the first frame at rest, then steps, frames, surfaces and the progress line.
  // The scene is read through m_world each time: a replayed reset replaces the world (and the scene it holds).
  void run() {
    open_outputs();
    if (m_render) render_frame();
    const bool tty = m_options.progress && isatty(STDERR_FILENO);
    auto last_progress = sim::Clock::now();
    m_loop_start = sim::Clock::now();
    apply_replay_events();
    while (running()) {
      if (g_interrupted) throw std::runtime_error("interrupted by a signal");
      const StepResult step = m_world.step();
      apply_replay_events();
      const long i = m_world.steps();
      if (m_world.scene().output.surface_every > 0 && i % m_world.scene().output.surface_every == 0) {
        char name[32];
        std::snprintf(name, sizeof(name), "surface_%06ld.ply", i);
        write_file_atomic(m_out / "surfaces" / name, encode_ply_binary(m_world.deformed_surface(), ply_precision()));
      }
      if (m_render && i % m_world.scene().render.every == 0) render_frame();
      if (m_world.scene().output.contact_forces) append_contact_rows(step.t);
      if (m_world.scene().output.step_times) append_step_row(step);
      if (tty && (sim::ms_since(last_progress) > 200.0 || !running())) {
        last_progress = sim::Clock::now();
        print_progress(step);
      }
    }
    if (!state_finite(m_world.simulator().state())) throw std::runtime_error("the state is not finite");
    if (m_world.scene().output.surface_final) {
      write_file_atomic(m_out / "surface_final.ply", encode_ply_binary(m_world.deformed_surface(), ply_precision()));
      write_file_atomic(m_out / "surface_rest_final.ply", encode_ply_binary(m_world.rest_surface(), ply_precision()));
    }
    if (m_world.scene().output.contact_forces)
      write_file_atomic(m_out / "contact_forces.csv",
                        m_contact_csv.empty() ? std::string("t,name,fx,fy,fz,max_penetration_m\n") : m_contact_csv);
    // Every queued frame is drawn and on disk before the run counts as done.
    if (m_render) m_render->finish();
    if (m_writer) m_writer->finish();
  }

  // The world's report, with what the loop measured and wrote. A failed run keeps every frame written before.
  Report finish(std::chrono::steady_clock::time_point wall0) {
    // The render thread first: it may still be handing frames to the writer.
    if (m_render) {
      try {
        m_render->finish();
      } catch (const std::exception&) {
        // Already reported through the run's error.
      }
    }
    if (m_writer) {
      try {
        m_writer->finish();
      } catch (const std::exception&) {
        // Already reported through the run's error.
      }
    }
    Report report = m_world.report();
    for (std::string& w : m_warnings) report.warnings.push_back(std::move(w));
    if (m_world.scene().output.step_times) {  // also after a failure: the steps up to it
      try {
        write_file_atomic(m_out / "steps.csv", std::string(kStepTimesHeader) + m_steps_csv);
      } catch (const std::exception& e) {
        report.warnings.push_back(std::string("steps.csv not written: ") + e.what());
      }
    }
    report.subsystems.renderer = m_render != nullptr;
    report.subsystems.frame_writer = m_writer != nullptr;
    if (m_writer) {
      report.frame_write_ms = TimingSummary::of(m_writer->write_ms());
      report.frames = m_writer->written();
      m_writer.reset();
    }
    if (m_render) {
      const std::vector<double> render_ms = m_render->render_ms();
      report.render_ms = TimingSummary::of(render_ms);
      report.frames_rendered = long(render_ms.size());
      report.render_wait_ms = TimingSummary::of(m_render->wait_ms());
    }
    report.snapshot_ms = TimingSummary::of(m_snapshot_ms);
    report.wall_time_s = sim::ms_since(wall0) / 1000.0;
    // The loop's own clock: steps, cuts, frames and surface files, not the loading before the first step.
    if (m_loop_start && report.sim_time_s > 0.0)
      report.realtime_factor = report.sim_time_s / (sim::ms_since(*m_loop_start) / 1000.0);
    return report;
  }

 private:
  [[nodiscard]] PlyPrecision ply_precision() const {
    return m_world.scene().output.ply_float ? PlyPrecision::single : PlyPrecision::double_;
  }

  // The steps.csv row of the step just run (see the schema's output.step_times).
  void append_step_row(const StepResult& step) {
    const sim::Simulator& sim = m_world.simulator();
    const sim::StepProfile& p = sim.profile();
    const sim::SolveInfo& solve = sim.last_solve();
    const sim::StabilityStats& st = sim.stats();
    char row[512];
    std::snprintf(row, sizeof row, "%ld,%.17g,%.17g,%zu,%d,%d,%d,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%d,%d\n",
                  m_world.steps(), step.t, step.ms, step.cuts.size(), solve.iterations, int(solve.refactorized),
                  int(solve.background), p.rotations, p.forces, p.assembly, p.contact, p.solve,
                  m_world.contact_timing().queries, st.recoveries - m_recoveries,
                  st.energy_rejections - m_energy_rejections);
    m_recoveries = st.recoveries;
    m_energy_rejections = st.energy_rejections;
    m_steps_csv += row;
  }

  // One contact_forces.csv row per colliding tool and rigid body after the step that ended at t.
  void append_contact_rows(double t) {
    if (m_contact_csv.empty()) m_contact_csv = "t,name,fx,fy,fz,max_penetration_m\n";
    for (const ContactForce& f : m_world.contact_forces()) {
      char row[256];
      std::snprintf(row, sizeof row, ",%.17g,%.17g,%.17g,%.17g\n", f.force_n[0], f.force_n[1], f.force_n[2],
                    f.max_penetration_m);
      char time[40];
      std::snprintf(time, sizeof time, "%.17g,", t);
      m_contact_csv += time + f.name + row;
    }
  }

  // The files written before the first step: S at rest, the surfaces folder, the frame writer.
  void open_outputs() {
    const Scene& scene = m_world.scene();
    if (scene.output.surface_final || scene.output.surface_every > 0)
      write_file_atomic(m_out / "surface_rest.ply", encode_ply_binary(m_world.rest_surface(), ply_precision()));
    if (scene.output.surface_every > 0) fs::create_directories(m_out / "surfaces");
    if (scene.output.frames && m_options.no_render)
      m_warnings.push_back("/output/frames: --no-render given, no frames written");
    if (scene.output.frames && !scene.render.enabled)
      m_warnings.push_back("/output/frames: render.enabled is false, no frames written");
    if (!m_render || !scene.output.frames) return;
    const fs::path frames_dir = m_out / "frames";
    std::error_code ec;
    fs::create_directories(frames_dir, ec);
    if (ec) throw std::runtime_error(frames_dir.string() + ": cannot create the frames directory: " + ec.message());
    m_writer = std::make_unique<FrameWriter>(frames_dir, 4);
  }

  // Takes the frame's snapshot (timed: the simulation waits for it) and queues it for the render thread, which
  // draws it while the simulation goes on (the wait for room in the queue is timed by the thread).
  void render_frame() {
    const auto t0 = sim::Clock::now();
    RenderScene snapshot = m_world.render_scene();
    m_snapshot_ms.push_back(sim::ms_since(t0));
    m_render->push(std::move(snapshot));
    ++m_frame;
  }

  // A replay runs until its last event has been applied and its world has taken the session's end_step steps; a
  // scene's timeline until its duration.
  [[nodiscard]] bool running() const {
    const Session* r = m_options.replay;
    if (r == nullptr) return !m_world.done();
    return m_next_event < r->events.size() || m_world.steps() < r->end_step;
  }

  // The replayed session's events due now: those recorded at the world's current step count. A reset rebuilds the
  // world from the scene, as the viewer did.
  void apply_replay_events() {
    const Session* r = m_options.replay;
    if (r == nullptr) return;
    while (m_next_event < r->events.size() && r->events[m_next_event].step == m_world.steps()) {
      const SessionEvent& e = r->events[m_next_event++];
      if (e.kind == SessionEventKind::reset)
        m_world = World(m_world.scene(), WorldOptions{!m_options.no_render, true});
      else
        apply_session_event(m_world, e);
    }
  }

  void print_progress(const StepResult& step) const {
    const long total = m_options.replay ? m_options.replay->end_step : m_world.total_steps();
    std::fprintf(stderr, "\r[octocut] step %ld/%ld  t = %.4f s  %.2f ms/step", m_world.steps(), total, step.t, step.ms);
    if (m_render) std::fprintf(stderr, "  frame %ld  %.1f ms/frame", m_frame, m_render->last_render_ms());
    std::fprintf(stderr, "   ");
    if (!running()) std::fprintf(stderr, "\n");
  }

  World& m_world;
  std::string m_contact_csv;  // contact_forces.csv so far
  std::string m_steps_csv;    // steps.csv's rows so far
  int m_recoveries = 0, m_energy_rejections = 0;  // the simulator's counts at the last steps.csv row
  const RunOptions& m_options;
  fs::path m_out;
  // Snapshots queued for the render thread at most: memory stays bounded, and a renderer slower than the simulation
  // makes the simulation wait rather than fall behind without limit.
  static constexpr std::size_t kRenderQueue = 2;
  // Declaration order matters: the render thread (whose sink pushes into the writer) goes before the writer.
  std::unique_ptr<FrameWriter> m_writer;
  std::unique_ptr<RenderThread> m_render;
  std::vector<double> m_snapshot_ms;  // per frame, the snapshot's cost on the simulation thread, ms
  std::optional<std::chrono::steady_clock::time_point> m_loop_start;  // when the first step began
  std::vector<std::string> m_warnings;
  long m_frame = 0;
  std::size_t m_next_event = 0;  // the next event of a replayed session
};

// Writes the report atomically; a failure to write it fails the run.
void write_report(RunResult& result, const Report& report) {
  try {
    write_file_atomic(result.report_path, report_json(report));
    result.report_written = true;
  } catch (const std::exception& e) {
    result.exit_code = 1;
    result.error = result.error.empty() ? e.what() : result.error + "; " + e.what();
  }
}

}  // namespace

RunResult run_scene(const Scene& scene, const RunOptions& options) {
  RunResult result;
  const fs::path out(options.out_dir);
  result.report_path = (out / "report.json").string();

  // Everything that is bad input is found before the output directory is touched.
  std::optional<World> world;
  try {
    world.emplace(scene, WorldOptions{!options.no_render, options.replay != nullptr});
  } catch (const SceneError& e) {
    result.exit_code = 2;
    result.error = e.what();
    return result;
  }
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) {
    result.exit_code = 1;
    result.error = options.out_dir + ": cannot create the output directory: " + ec.message();
    return result;
  }

  // The renderer starts only when asked for and not vetoed; if EGL cannot start, the run ends with exit 2 and the
  // EGL error, with the report written.
  const auto wall0 = sim::Clock::now();
  Run run(*world, options, out);
  try {
    run.start_renderer();
  } catch (const std::exception& e) {
    result.exit_code = 2;
    result.error = scene.file + ": /render/enabled: cannot start the renderer: " + e.what() +
                   " (run with --no-render to skip rendering)";
    Report report = run.finish(wall0);
    report.status = "failed";
    report.error = result.error;
    write_report(result, report);
    result.exit_code = 2;  // the render error is the one to report, also when the report could not be written
    return result;
  }

  {
    SignalGuard signals;
    try {
      run.run();
    } catch (const std::exception& e) {
      result.exit_code = 1;
      result.error = e.what();
    }
  }
  Report report = run.finish(wall0);
  if (result.exit_code != 0) {
    report.status = "failed";
    report.error = result.error;
  }
  result.cuts = report.cuts;
  write_report(result, report);
  return result;
}

}  // namespace octocut::engine
