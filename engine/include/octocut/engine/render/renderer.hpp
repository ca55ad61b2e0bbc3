#pragma once
// The renderer interface (SPEC §6). The EGL implementation lives in its own target (engine/src/render/); builds
// without EGL get a null renderer whose factory throws a clear error. This header holds no GL or EGL type.
#include <memory>
#include <stdexcept>
#include <string>

#include "octocut/engine/render/render_scene.hpp"

namespace octocut::engine {

/// Rendering could not start or failed; the message names the EGL or GL error (name and code).
class RenderError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Draws render scenes off-screen into images.
class Renderer {
 public:
  virtual ~Renderer() = default;
  /// Draws `scene` and reads the image back (RGB8, scene.width × scene.height). Throws RenderError on GL failure.
  virtual Image render(const RenderScene& scene) = 0;
  /// A one-line description of the platform, e.g. "EGL device 0: llvmpipe (LLVM 15.0.6), OpenGL 4.5".
  [[nodiscard]] virtual std::string description() const = 0;
};

/// True when this build has the EGL renderer.
bool renderer_available();

/// Starts a headless renderer: the EGL device platform first (`OCTOCUT_EGL_DEVICE=<index>` picks the device;
/// otherwise the first that initialises), Mesa's surfaceless platform as the fallback, an OpenGL 3.3 core context
/// made current with no surface. Throws RenderError with the EGL error name and code when EGL cannot start, or
/// when the build has no EGL. The test hook `OCTOCUT_EGL_FORCE_FAIL=1` makes it fail as if no display initialised.
std::unique_ptr<Renderer> make_renderer();

}  // namespace octocut::engine
