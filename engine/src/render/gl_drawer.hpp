#pragma once
// GlDrawer: the GL drawing code of every render target (one renderer, two targets). The headless EGL renderer and
// the viewer's window each make an OpenGL 3.3 core context current and then draw render scenes through it; only
// context creation differs. Private to the engine: no GL type appears here, and the caller keeps a context current
// on the calling thread for the drawer's whole life (construction, every call, destruction).
#include <memory>
#include <string>

#include "octocut/engine/render/render_scene.hpp"

namespace octocut::engine {

/// "NAME (0x1234)": a GL or EGL error name with its code, for messages.
std::string named_code(const char* name, unsigned code);

class GlDrawer {
 public:
  /// Compiles the programs and creates the buffers in the current context. Throws RenderError on GL failure.
  GlDrawer();
  /// Deletes the GL objects; the context must still be current.
  ~GlDrawer();
  GlDrawer(const GlDrawer&) = delete;
  GlDrawer& operator=(const GlDrawer&) = delete;

  /// Draws `scene` (scene.width × scene.height, 1..8192) into the drawer's resolved single-sampled framebuffer:
  /// meshes, overlays and the arthroscope mask. Throws RenderError on bad input or GL failure.
  void draw(const RenderScene& scene);
  /// The last drawn frame as an RGB8 image, rows from the top; width and height those of the last draw().
  Image read_back(int width, int height);
  /// The GL name of the framebuffer that holds the last drawn frame (a window blits it to its own).
  [[nodiscard]] unsigned resolve_framebuffer() const;
  /// "<GL_RENDERER>, OpenGL <GL_VERSION>" of the current context.
  static std::string description();

 private:
  struct Impl;
  std::unique_ptr<Impl> m;
};

}  // namespace octocut::engine
