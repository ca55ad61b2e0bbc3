// The null renderer: builds without EGL (OCTOCUT_WITH_EGL=OFF, or EGL/epoxy not found) link this instead of the EGL
// renderer, so that every run that asks for rendering ends in a clear error rather than a link failure.
#include "octocut/engine/render/renderer.hpp"

namespace octocut::engine {

bool renderer_available() { return false; }

std::unique_ptr<Renderer> make_renderer() {
  throw RenderError("this build of octocut has no renderer (built without EGL: configure with OCTOCUT_WITH_EGL=ON "
                    "and install libegl-dev and libepoxy-dev)");
}

}  // namespace octocut::engine
