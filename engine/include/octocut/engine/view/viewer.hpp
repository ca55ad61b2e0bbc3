#pragma once
// `octocut view`: the interactive viewer (GLFW window, Dear ImGui panel) over a World that runs on its own thread,
// with the first tool in the hand, record to a session file, screenshots and frames. Built when GLFW and ImGui are
// found (OCTOCUT_WITH_VIEWER); otherwise run_viewer reports that the build has none. No GLFW type appears here.
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"

namespace octocut::engine {

/// How `octocut view` runs.
struct ViewOptions {
  std::vector<std::string> sets;  ///< the --set overrides the scene was loaded with (recorded in the session)
  std::string record_path;        ///< --record: write the session here on exit; empty: none
  std::string out_dir;            ///< --out: report.json on exit, screenshots and frames; empty: screenshots in "."
  int width = 0, height = 0;      ///< --size, pixels; 0: the scene's render size
  std::string tool;               ///< --tool: the tool in the hand (name); empty: the first tool
};

/// What a viewer session ended with.
struct ViewResult {
  int exit_code = 0;  ///< 0 closed normally, 1 the session failed, 2 bad input or no display
  std::string error;
};

/// True when this build has the viewer.
bool viewer_available();

/// Opens the window and runs until it is closed (Esc or the window's close button). Without a display (or without
/// the viewer in this build) returns exit code 2 and a message before the scene's world is built. Writes the
/// session (--record) and report.json (--out) atomically on exit.
ViewResult run_viewer(const Scene& scene, const ViewOptions& options);

}  // namespace octocut::engine
