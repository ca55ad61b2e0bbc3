#pragma once
// `octocut run` (SPEC §5, §8): a thin loop over engine::World that adds what a headless run writes: the renderer and
// the frame writer, the surfaces asked for by `output`, the progress line, and report.json.
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocut/engine/render/renderer.hpp"
#include "octocut/engine/run/report.hpp"
#include "octocut/engine/run/session.hpp"
#include "octocut/engine/scene/scene.hpp"

namespace octocut::engine {

/// How `octocut run` runs a scene.
struct RunOptions {
  std::string out_dir = "out";  ///< report.json and outputs go here (created if missing)
  bool no_render = false;       ///< never touch EGL, whatever the scene says
  bool progress = false;        ///< print a progress line to stderr (on a terminal)
  /// Replay this recorded session (`--replay`, checked against the scene with check_session_scene) instead of the
  /// scene's timeline: its events at the steps they took effect, until its end_step, whatever the scene's duration.
  /// The world is built cuttable, as the viewer's was. Null: run the timeline.
  const Session* replay = nullptr;
  /// Makes the renderer, on the render thread; empty: make_renderer() (headless EGL). A seam for tests, which inject
  /// renderers that fail part-way.
  std::function<std::unique_ptr<Renderer>()> renderer_factory;
};

/// The header of steps.csv (`output.step_times`): one row per step, the stages' times in ms (sim::StepProfile, of
/// the step's last attempt) and the contact queries' (ContactTiming::queries), and the attempts the step rolled back
/// (the report's stability.recoveries and energy_rejections, counted per step).
inline constexpr const char* kStepTimesHeader =
    "step,t,ms,cuts,pcg_iterations,refactorized,background,rotations_ms,forces_ms,assembly_ms,contact_ms,solve_ms,"
    "queries_ms,recoveries,energy_rejections\n";

/// What a run ended with.
struct RunResult {
  int exit_code = 0;             ///< 0 ok, 1 the run failed (report written when possible), 2 bad input
  std::string report_path;       ///< where report.json is (or was to be) written
  bool report_written = false;   ///< report.json is on disk at report_path
  std::string error;             ///< the failure, when exit_code != 0
  std::vector<CutSummary> cuts;  ///< every cut event, in order
};

/// Runs a loaded scene to its duration and writes DIR/report.json atomically, also when the run fails part-way: then
/// with "status": "failed" and the reason, and every frame written before the failure stays on disk. Bad input that
/// is only detected while building the World (exit 2) is returned, not thrown, before the output directory is
/// touched. SIGINT and SIGTERM stop the run at the next step, which then fails with its report written.
RunResult run_scene(const Scene& scene, const RunOptions& options);

}  // namespace octocut::engine
