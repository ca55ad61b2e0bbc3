// The EGL renderer (SPEC §6): headless EGL (device platform first, the surfaceless platform as the fallback) and an
// OpenGL 3.3 core context current with no surface. Only the context is made here: the drawing (multisampled FBO, Blinn-Phong
// shading, overlays, the arthroscope mask, the read-back into an RGB8 image) is GlDrawer's (gl_drawer.cpp), which
// the viewer's window uses too. Function loading through libepoxy.
#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <dlfcn.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#include "octocut/engine/render/renderer.hpp"
#include "render/gl_drawer.hpp"

namespace octocut::engine {

namespace {

// ---- EGL errors -----------------------------------------------------------------------------------------------------

/// "EGL_BAD_ACCESS (0x3002)" for an EGL error code.
std::string egl_error_text(EGLint code) {
  const char* name = "unknown EGL error";
  switch (code) {
    case EGL_SUCCESS: name = "EGL_SUCCESS"; break;
    case EGL_NOT_INITIALIZED: name = "EGL_NOT_INITIALIZED"; break;
    case EGL_BAD_ACCESS: name = "EGL_BAD_ACCESS"; break;
    case EGL_BAD_ALLOC: name = "EGL_BAD_ALLOC"; break;
    case EGL_BAD_ATTRIBUTE: name = "EGL_BAD_ATTRIBUTE"; break;
    case EGL_BAD_CONFIG: name = "EGL_BAD_CONFIG"; break;
    case EGL_BAD_CONTEXT: name = "EGL_BAD_CONTEXT"; break;
    case EGL_BAD_CURRENT_SURFACE: name = "EGL_BAD_CURRENT_SURFACE"; break;
    case EGL_BAD_DISPLAY: name = "EGL_BAD_DISPLAY"; break;
    case EGL_BAD_MATCH: name = "EGL_BAD_MATCH"; break;
    case EGL_BAD_NATIVE_PIXMAP: name = "EGL_BAD_NATIVE_PIXMAP"; break;
    case EGL_BAD_NATIVE_WINDOW: name = "EGL_BAD_NATIVE_WINDOW"; break;
    case EGL_BAD_PARAMETER: name = "EGL_BAD_PARAMETER"; break;
    case EGL_BAD_SURFACE: name = "EGL_BAD_SURFACE"; break;
    case EGL_CONTEXT_LOST: name = "EGL_CONTEXT_LOST"; break;
    default: break;
  }
  return named_code(name, unsigned(code));
}

/// Throws RenderError "EGL: <what>: <eglGetError()>".
[[noreturn]] void egl_fail(const std::string& what) {
  throw RenderError("EGL: " + what + ": " + egl_error_text(eglGetError()));
}


// ---- RAII for the display and the context ---------------------------------------------------------------------------

/// An initialised EGL display, terminated on destruction.
class EglDisplay {
 public:
  EglDisplay() = default;
  explicit EglDisplay(EGLDisplay display) : m_display(display) {}
  ~EglDisplay() {
    if (m_display != EGL_NO_DISPLAY) eglTerminate(m_display);
  }
  EglDisplay(EglDisplay&& other) noexcept : m_display(other.m_display) { other.m_display = EGL_NO_DISPLAY; }
  EglDisplay& operator=(EglDisplay&& other) noexcept {
    std::swap(m_display, other.m_display);
    return *this;
  }
  [[nodiscard]] EGLDisplay get() const { return m_display; }

 private:
  EGLDisplay m_display = EGL_NO_DISPLAY;
};

/// An EGL context, released and destroyed on destruction (before its display is terminated).
class EglContext {
 public:
  EglContext() = default;
  EglContext(EGLDisplay display, EGLContext context) : m_display(display), m_context(context) {}
  ~EglContext() {
    if (m_context != EGL_NO_CONTEXT) {
      eglMakeCurrent(m_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(m_display, m_context);
    }
  }
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;
  [[nodiscard]] EGLContext get() const { return m_context; }

 private:
  EGLDisplay m_display = EGL_NO_DISPLAY;
  EGLContext m_context = EGL_NO_CONTEXT;
};

/// Initialises `display`; an empty EglDisplay on failure (eglGetError() then says why).
EglDisplay initialise(EGLDisplay display) {
  EGLint major = 0, minor = 0;
  if (display == EGL_NO_DISPLAY || !eglInitialize(display, &major, &minor)) return EglDisplay();
  return EglDisplay(display);
}

/// The first display that initialises: the device platform (all devices, or the one `OCTOCUT_EGL_DEVICE` names),
/// then Mesa's surfaceless platform. `platform` receives a description.
EglDisplay open_display(std::string& platform) {
  // Test hook: behave as if no platform had a display.
  if (const char* force = std::getenv("OCTOCUT_EGL_FORCE_FAIL"); force != nullptr && std::strcmp(force, "1") == 0)
    throw RenderError("EGL: no display could be initialised (forced by OCTOCUT_EGL_FORCE_FAIL=1): " +
                      egl_error_text(EGL_NOT_INITIALIZED));

  // libepoxy aborts the process when it cannot load libEGL: check that it can first.
  if (void* library = dlopen("libEGL.so.1", RTLD_LAZY | RTLD_LOCAL); library == nullptr) {
    const char* reason = dlerror();
    throw RenderError(std::string("EGL: cannot load libEGL.so.1: ") + (reason ? reason : "unknown reason") + ": " +
                      egl_error_text(EGL_NOT_INITIALIZED));
  } else {
    dlclose(library);
  }

  // A missing libEGL client extension query means no usable EGL at all.
  const char* client_extensions = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (client_extensions == nullptr) egl_fail("no EGL client extensions (EGL_EXT_client_extensions missing)");
  const std::string extensions = client_extensions;
  const auto has = [&](const char* name) {
    const std::string padded = " " + extensions + " ";
    return padded.find(std::string(" ") + name + " ") != std::string::npos;
  };

  // EGL devices: the one chosen by the environment, or the first that initialises.
  const char* chosen = std::getenv("OCTOCUT_EGL_DEVICE");
  std::string tried;  // what was attempted, for the error message
  // Enumeration comes as EGL_EXT_device_enumeration (Mesa) or inside EGL_EXT_device_base (NVIDIA's driver lists only
  // that one: with the first name alone, the device platform was never tried on an H200).
  const bool enumerate = has("EGL_EXT_device_enumeration") || has("EGL_EXT_device_base");
  if (has("EGL_EXT_platform_device") && enumerate) {
    EGLDeviceEXT devices[32];
    EGLint count = 0;
    if (!eglQueryDevicesEXT(32, devices, &count)) count = 0;
    if (chosen != nullptr && *chosen != '\0') {
      char* end = nullptr;
      const long index = std::strtol(chosen, &end, 10);
      if (*end != '\0' || index < 0 || index >= count)
        throw RenderError("EGL: OCTOCUT_EGL_DEVICE=" + std::string(chosen) + " names no device; " +
                          std::to_string(count) + " EGL device(s) found");
      EglDisplay display = initialise(eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, devices[index], nullptr));
      if (display.get() == EGL_NO_DISPLAY) egl_fail("cannot initialise EGL device " + std::to_string(index));
      platform = "EGL device " + std::to_string(index);
      return display;
    }
    tried = std::to_string(count) + " EGL device(s) tried";
    for (EGLint i = 0; i < count; ++i) {
      EglDisplay display = initialise(eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr));
      if (display.get() != EGL_NO_DISPLAY) {
        platform = "EGL device " + std::to_string(i);
        return display;
      }
    }
  } else {
    tried = enumerate ? "no EGL_EXT_platform_device" : "no EGL_EXT_device_enumeration or EGL_EXT_device_base";
  }
  if (chosen != nullptr && *chosen != '\0') {
    throw RenderError("EGL: OCTOCUT_EGL_DEVICE is set but EGL devices cannot be used (" + tried + "): " +
                      egl_error_text(eglGetError()));
  }

  // Fallback: the surfaceless platform (EGL_MESA_platform_surfaceless, which NVIDIA's driver offers too). The
  // description says why no device was taken.
  const std::string before_surfaceless = tried;
  tried += has("EGL_MESA_platform_surfaceless") ? ", the surfaceless platform tried" : ", no EGL_MESA_platform_surfaceless";
  if (has("EGL_MESA_platform_surfaceless")) {
    EglDisplay display = initialise(eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr));
    if (display.get() != EGL_NO_DISPLAY) {
      platform = "EGL surfaceless platform (" + before_surfaceless + ")";
      return display;
    }
  }
  egl_fail("no EGL device or surfaceless display could be initialised (" + tried + ")");
}


}  // namespace

// ---- the renderer ---------------------------------------------------------------------------------------------------

namespace {

class EglRenderer final : public Renderer {
 public:
  EglRenderer() {
    // Display, config, context: each failure carries eglGetError().
    std::string platform;
    m_display = open_display(platform);
    if (!eglBindAPI(EGL_OPENGL_API)) egl_fail("eglBindAPI(EGL_OPENGL_API)");
    const EGLint config_attributes[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT,
                                        EGL_NONE};
    EGLConfig config = nullptr;
    EGLint configs = 0;
    if (!eglChooseConfig(m_display.get(), config_attributes, &config, 1, &configs) || configs < 1)
      egl_fail("no EGL config with EGL_PBUFFER_BIT and EGL_OPENGL_BIT");
    const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                                         EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                         EGL_NONE};
    const EGLContext context = eglCreateContext(m_display.get(), config, EGL_NO_CONTEXT, context_attributes);
    if (context == EGL_NO_CONTEXT) egl_fail("cannot create an OpenGL 3.3 core context");
    m_context.emplace(m_display.get(), context);
    if (!eglMakeCurrent(m_display.get(), EGL_NO_SURFACE, EGL_NO_SURFACE, context))
      egl_fail("cannot make the context current with no surface");

    m_drawer.emplace();
    m_description = platform + ": " + GlDrawer::description();
  }

  ~EglRenderer() override { m_drawer.reset(); }  // GL objects go before the context

  [[nodiscard]] std::string description() const override { return m_description; }

  Image render(const RenderScene& scene) override {
    m_drawer->draw(scene);
    return m_drawer->read_back(scene.width, scene.height);
  }

 private:
  // Declaration order matters: the drawer's GL objects go before the context, the context before the display.
  EglDisplay m_display;
  std::optional<EglContext> m_context;
  std::optional<GlDrawer> m_drawer;
  std::string m_description;
};

}  // namespace

bool renderer_available() { return true; }

std::unique_ptr<Renderer> make_renderer() { return std::make_unique<EglRenderer>(); }

}  // namespace octocut::engine
