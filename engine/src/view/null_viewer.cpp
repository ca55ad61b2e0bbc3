// `octocut view` in a build without GLFW or Dear ImGui (OCTOCUT_WITH_VIEWER off or the packages missing).
#include "octocut/engine/view/viewer.hpp"

namespace octocut::engine {

bool viewer_available() { return false; }

ViewResult run_viewer(const Scene&, const ViewOptions&) {
  return {2, "this build has no viewer: GLFW 3 and Dear ImGui were not found when it was configured (Debian: "
             "libglfw3-dev libimgui-dev, then reconfigure with -DOCTOCUT_WITH_VIEWER=ON)"};
}

}  // namespace octocut::engine
