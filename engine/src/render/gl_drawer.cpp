// The GL drawing code shared by every render target (SPEC §6): the shaders, Blinn-Phong shading, the overlays and the
// arthroscope mask, drawn into a multisampled framebuffer and resolved, and the read-back into an RGB8 image. Making
// a context current is the target's business: the headless EGL renderer (egl_renderer.cpp) and the viewer's GLFW
// window (engine/src/view) draw through this one class: one renderer, two targets. GL functions come through
// libepoxy, which dispatches to whichever of EGL or GLX made the current context.
#include "render/gl_drawer.hpp"

#include <epoxy/gl.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "octocut/engine/render/renderer.hpp"

namespace octocut::engine {

std::string named_code(const char* name, unsigned code) {
  char code_text[16];
  std::snprintf(code_text, sizeof code_text, "0x%04X", code);
  return std::string(name) + " (" + code_text + ")";
}

namespace {

// ---- GL errors ------------------------------------------------------------------------------------------------------

/// "GL_INVALID_OPERATION (0x0502)" for a GL error code.
std::string gl_error_text(GLenum code) {
  const char* name = "unknown GL error";
  switch (code) {
    case GL_INVALID_ENUM: name = "GL_INVALID_ENUM"; break;
    case GL_INVALID_VALUE: name = "GL_INVALID_VALUE"; break;
    case GL_INVALID_OPERATION: name = "GL_INVALID_OPERATION"; break;
    case GL_INVALID_FRAMEBUFFER_OPERATION: name = "GL_INVALID_FRAMEBUFFER_OPERATION"; break;
    case GL_OUT_OF_MEMORY: name = "GL_OUT_OF_MEMORY"; break;
    default: break;
  }
  return named_code(name, unsigned(code));
}

/// Throws RenderError when GL has recorded an error.
void gl_check(const char* where) {
  const GLenum code = glGetError();
  if (code != GL_NO_ERROR) throw RenderError(std::string("OpenGL: ") + where + ": " + gl_error_text(code));
}

// ---- shaders --------------------------------------------------------------------------------------------------------

constexpr const char* kMeshVertex = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_model;
uniform mat4 u_view_projection;
uniform mat3 u_normal_matrix;
out vec3 v_world;
out vec3 v_normal;
void main() {
  vec4 world = u_model * vec4(a_position, 1.0);
  v_world = world.xyz;
  v_normal = u_normal_matrix * a_normal;
  gl_Position = u_view_projection * world;
}
)";

constexpr const char* kMeshFragment = R"(#version 330 core
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_eye;
uniform vec3 u_base;
uniform vec3 u_cut_color;
uniform float u_ambient;
uniform float u_specular;
uniform float u_shininess;
uniform int u_light_count;
uniform vec3 u_light_position[4];
uniform vec3 u_light_color[4];
uniform int u_has_cut;
uniform samplerBuffer u_cut;
uniform float u_opacity;  // 1: opaque; below: glass, its opacity facing the eye (premultiplied output)
out vec4 o_color;
void main() {
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) n = -n;
  vec3 v = normalize(u_eye - v_world);
  vec3 base = u_base;
  if (u_has_cut != 0 && texelFetch(u_cut, gl_PrimitiveID).r > 0.0) base = u_cut_color;
  vec3 color = u_ambient * base;
  vec3 shine = vec3(0.0);
  for (int i = 0; i < u_light_count; ++i) {
    vec3 l = normalize(u_light_position[i] - v_world);
    vec3 h = normalize(l + v);
    float diffuse = max(dot(n, l), 0.0);
    float specular = diffuse > 0.0 ? pow(max(dot(n, h), 0.0), u_shininess) : 0.0;
    color += u_light_color[i] * (diffuse * base + u_specular * specular * vec3(1.0));
    shine += u_light_color[i] * (u_specular * specular);
  }
  if (u_opacity >= 1.0) {
    o_color = vec4(clamp(color, 0.0, 1.0), 1.0);
    return;
  }
  // Glass: the lit body colour covers a fraction a of what lies behind, a growing towards 1 at grazing angles
  // (Schlick's Fresnel term); the highlights are added on top.
  float a = mix(u_opacity, 1.0, pow(1.0 - abs(dot(n, v)), 5.0));
  o_color = vec4(clamp((color - shine) * a + shine, 0.0, 1.0), a);
}
)";

// Tissue: the same Blinn-Phong model evaluated at the vertices (Gouraud), the fragment stage only picks the base
// colour (cut or not) and combines. llvmpipe shades every sample of a multisampled pixel, so a cheap fragment stage
// matters on large tissue areas at 4x MSAA; dense tissue meshes show no visible difference from per-fragment
// lighting.
constexpr const char* kVertexLitVertex = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_model;
uniform mat4 u_view_projection;
uniform mat3 u_normal_matrix;
uniform vec3 u_eye;
uniform float u_ambient;
uniform float u_specular;
uniform float u_shininess;
uniform int u_light_count;
uniform vec3 u_light_position[4];
uniform vec3 u_light_color[4];
out vec3 v_diffuse;
out vec3 v_specular;
void main() {
  vec4 world = u_model * vec4(a_position, 1.0);
  vec3 n = normalize(u_normal_matrix * a_normal);
  vec3 v = normalize(u_eye - world.xyz);
  if (dot(n, v) < 0.0) n = -n;
  vec3 diffuse = vec3(u_ambient);
  vec3 specular = vec3(0.0);
  for (int i = 0; i < u_light_count; ++i) {
    vec3 l = normalize(u_light_position[i] - world.xyz);
    vec3 h = normalize(l + v);
    float d = max(dot(n, l), 0.0);
    diffuse += u_light_color[i] * d;
    specular += u_light_color[i] * (d > 0.0 ? u_specular * pow(max(dot(n, h), 0.0), u_shininess) : 0.0);
  }
  v_diffuse = diffuse;
  v_specular = specular;
  gl_Position = u_view_projection * world;
}
)";

constexpr const char* kVertexLitFragment = R"(#version 330 core
in vec3 v_diffuse;
in vec3 v_specular;
uniform vec3 u_base;
uniform vec3 u_cut_color;
uniform int u_has_cut;
uniform samplerBuffer u_cut;
out vec4 o_color;
void main() {
  vec3 base = u_base;
  if (u_has_cut != 0 && texelFetch(u_cut, gl_PrimitiveID).r > 0.0) base = u_cut_color;
  o_color = vec4(clamp(base * v_diffuse + v_specular, 0.0, 1.0), 1.0);
}
)";

constexpr const char* kOverlayVertex = R"(#version 330 core
layout(location = 0) in vec3 a_position;
uniform mat4 u_view_projection;
uniform float u_point_size;
void main() {
  gl_Position = u_view_projection * vec4(a_position, 1.0);
  gl_PointSize = u_point_size;
}
)";

constexpr const char* kOverlayFragment = R"(#version 330 core
uniform vec3 u_color;
uniform int u_round;
out vec4 o_color;
void main() {
  if (u_round != 0 && length(gl_PointCoord - vec2(0.5)) > 0.5) discard;
  o_color = vec4(u_color, 1.0);
}
)";

// A full-screen triangle from gl_VertexID that blacks out everything outside the arthroscope's circle.
constexpr const char* kMaskVertex = R"(#version 330 core
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
)";

constexpr const char* kMaskFragment = R"(#version 330 core
uniform vec2 u_center;
uniform float u_radius;
out vec4 o_color;
void main() {
  if (length(gl_FragCoord.xy - u_center) <= u_radius) discard;
  o_color = vec4(0.0, 0.0, 0.0, 1.0);
}
)";

GLuint compile(GLenum type, const char* source, const char* name) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    char log[2048] = {};
    glGetShaderInfoLog(shader, sizeof log, nullptr, log);
    glDeleteShader(shader);
    throw RenderError(std::string("OpenGL: cannot compile the ") + name + " shader: " + log);
  }
  return shader;
}

GLuint link(const char* vertex, const char* fragment, const char* name) {
  const GLuint vs = compile(GL_VERTEX_SHADER, vertex, name);
  const GLuint fs = compile(GL_FRAGMENT_SHADER, fragment, name);
  const GLuint program = glCreateProgram();
  glAttachShader(program, vs);
  glAttachShader(program, fs);
  glLinkProgram(program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    char log[2048] = {};
    glGetProgramInfoLog(program, sizeof log, nullptr, log);
    glDeleteProgram(program);
    throw RenderError(std::string("OpenGL: cannot link the ") + name + " program: " + log);
  }
  return program;
}

/// Shading constants of one material kind.
struct Shading {
  Eigen::Vector3f base;
  float specular;
  float shininess;
};

Shading shading_of(MaterialKind kind) {
  switch (kind) {
    case MaterialKind::metal: return {{0.62f, 0.64f, 0.68f}, 0.9f, 80.0f};
    case MaterialKind::bone: return {{0.88f, 0.84f, 0.72f}, 0.08f, 8.0f};
    case MaterialKind::glass: return {{0.55f, 0.62f, 0.70f}, 1.0f, 120.0f};
    case MaterialKind::tissue: break;
  }
  return {{0.86f, 0.58f, 0.56f}, 0.25f, 24.0f};
}

const Eigen::Vector3f kCutColor(0.78f, 0.12f, 0.10f);  ///< fresh-tissue red, RGB
constexpr float kAmbient = 0.15f;
constexpr float kGlassOpacity = 0.12f;  ///< the fraction of the view that glass facing the eye covers

/// Which of a mesh's faces a draw keeps.
enum class Faces {
  as_mesh,  ///< the front faces of a closed mesh (RenderMesh::cull_back_faces), all faces of an open one
  front,    ///< those facing the eye
  back,     ///< those facing away (the far side of a glass body, drawn before its near side)
};

/// Whether a renderer's still layer may hold the mesh: a still, opaque mesh (glass is blended over what the layer
/// holds and what is drawn after it, so it is drawn every frame).
bool layer_may_hold(const RenderMesh& mesh) { return mesh.still && mesh.material != MaterialKind::glass; }

}  // namespace

// ---- the drawer ----------------------------------------------------------------------------------------------------

struct GlDrawer::Impl {
  Impl() {
    // GL objects shared by every frame.
    m_mesh_program = link(kMeshVertex, kMeshFragment, "mesh");
    m_tissue_program = link(kVertexLitVertex, kVertexLitFragment, "tissue");
    m_overlay_program = link(kOverlayVertex, kOverlayFragment, "overlay");
    m_mask_program = link(kMaskVertex, kMaskFragment, "mask");
    glGenVertexArrays(1, &m_vao);
    glGenBuffers(1, &m_position_buffer);
    glGenBuffers(1, &m_normal_buffer);
    glGenBuffers(1, &m_index_buffer);
    glGenBuffers(1, &m_cut_buffer);
    glGenTextures(1, &m_cut_texture);
    gl_check("creating buffers");
  }

  ~Impl() {
    // GL objects go before the context (the context's destructor releases it).
    release_framebuffers();
    glDeleteTextures(1, &m_cut_texture);
    const GLuint buffers[] = {m_position_buffer, m_normal_buffer, m_index_buffer, m_cut_buffer};
    glDeleteBuffers(4, buffers);
    glDeleteVertexArrays(1, &m_vao);
    glDeleteProgram(m_mesh_program);
    glDeleteProgram(m_tissue_program);
    glDeleteProgram(m_overlay_program);
    glDeleteProgram(m_mask_program);
  }

  void draw(const RenderScene& scene) {
    if (scene.width <= 0 || scene.height <= 0 || scene.width > 8192 || scene.height > 8192)
      throw RenderError("render: image size " + std::to_string(scene.width) + "x" + std::to_string(scene.height) +
                        " outside 1..8192");
    ensure_framebuffers(scene.width, scene.height, std::max(scene.msaa, 1));

    // Camera and lights.
    const Eigen::Matrix4f view_projection =
        (projection_matrix(scene.camera, scene.width, scene.height) * view_matrix(scene.camera)).cast<float>();
    const Eigen::Vector3f eye = scene.camera.position.cast<float>();
    m_eye = eye;
    std::vector<RenderLight> lights;
    if (scene.camera.arthroscope || scene.lights.empty()) lights.push_back({eye, Eigen::Vector3f::Ones()});
    for (const RenderLight& l : scene.lights)
      if (int(lights.size()) < kMaxLights) lights.push_back(l);

    // Only the pixels that geometry can reach go through the multisampled target: the rest of the frame is the
    // background (or the arthroscope mask) and is cleared at one sample per pixel in the resolve target. On llvmpipe
    // the multisampled clear and resolve cost in proportion to their area.
    const Rect region = active_region(scene, view_projection);
    glClearColor(scene.background.x(), scene.background.y(), scene.background.z(), 1.0f);
    glBindFramebuffer(GL_FRAMEBUFFER, m_resolve_fbo);
    glViewport(0, 0, scene.width, scene.height);
    glDisable(GL_SCISSOR_TEST);
    glClear(GL_COLOR_BUFFER_BIT);

    // Clear the multisampled target inside the region; drawing stays inside it too.
    glBindFramebuffer(GL_FRAMEBUFFER, m_msaa_fbo);
    glViewport(0, 0, scene.width, scene.height);
    glEnable(GL_SCISSOR_TEST);
    glScissor(region.x0, region.y0, std::max(region.x1 - region.x0, 0), std::max(region.y1 - region.y0, 0));
    glClearDepth(1.0);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glCullFace(GL_BACK);
    glFrontFace(GL_CCW);
    glBindVertexArray(m_vao);

    // Meshes.
    for (const GLuint program : {m_mesh_program, m_tissue_program}) {
      glUseProgram(program);
      set_matrix4(program, "u_view_projection", view_projection);
      glUniform3fv(uniform(program, "u_eye"), 1, eye.data());
      glUniform3fv(uniform(program, "u_cut_color"), 1, kCutColor.data());
      glUniform1f(uniform(program, "u_ambient"), kAmbient);
      glUniform1i(uniform(program, "u_light_count"), int(lights.size()));
      for (std::size_t i = 0; i < lights.size(); ++i) {
        const std::string index = "[" + std::to_string(i) + "]";
        glUniform3fv(uniform(program, ("u_light_position" + index).c_str()), 1, lights[i].position.data());
        glUniform3fv(uniform(program, ("u_light_color" + index).c_str()), 1, lights[i].color.data());
      }
      glUniform1i(uniform(program, "u_cut"), 0);
      glUniform1f(uniform(program, "u_opacity"), 1.0f);
    }
    // Faces are pushed back a little so that wireframe lines lying on them win the depth test.
    glEnable(GL_POLYGON_OFFSET_FILL);
    glPolygonOffset(1.0f, 1.0f);
    // The still meshes come from the layer kept from an earlier frame (copied in with its depth), or the region is
    // cleared; then the rest is drawn. Depth decides per sample, so the order changes nothing but exact ties.
    const bool layered = prepare_still_layer(scene, view_projection, lights, region);
    if (!layered) {
      glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    } else if (region.x1 > region.x0 && region.y1 > region.y0) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, m_layer_fbo);
      glBindFramebuffer(GL_DRAW_FRAMEBUFFER, m_msaa_fbo);
      glBlitFramebuffer(region.x0, region.y0, region.x1, region.y1, region.x0, region.y0, region.x1, region.y1,
                        GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT, GL_NEAREST);
      glBindFramebuffer(GL_FRAMEBUFFER, m_msaa_fbo);
    }
    for (const RenderMesh& mesh : scene.meshes)
      if (!(layered && layer_may_hold(mesh)) && mesh.material != MaterialKind::glass) draw_mesh(mesh);
    draw_glass(scene);
    glDisable(GL_POLYGON_OFFSET_FILL);
    glDisable(GL_CULL_FACE);

    // Overlays: lines depth-tested against the meshes, points on top.
    glUseProgram(m_overlay_program);
    set_matrix4(m_overlay_program, "u_view_projection", view_projection);
    glUniform1f(uniform(m_overlay_program, "u_point_size"), 1.0f);
    glUniform1i(uniform(m_overlay_program, "u_round"), 0);
    glDisableVertexAttribArray(1);
    glDepthFunc(GL_LEQUAL);
    for (const bool on_top : {false, true}) {
      if (on_top) glDisable(GL_DEPTH_TEST);
      for (const OverlayLines& lines : scene.lines) {
        if (lines.endpoints.size() < 2 || lines.on_top != on_top) continue;
        upload_positions(lines.endpoints);
        glUniform3fv(uniform(m_overlay_program, "u_color"), 1, lines.color.data());
        glDrawArrays(GL_LINES, 0, GLsizei(lines.endpoints.size() / 2 * 2));
      }
    }
    glDisable(GL_DEPTH_TEST);
    glEnable(GL_PROGRAM_POINT_SIZE);
    glUniform1i(uniform(m_overlay_program, "u_round"), 1);
    for (const OverlayPoints& points : scene.points) {
      if (points.points.empty()) continue;
      upload_positions(points.points);
      glUniform3fv(uniform(m_overlay_program, "u_color"), 1, points.color.data());
      glUniform1f(uniform(m_overlay_program, "u_point_size"), points.size_px);
      glDrawArrays(GL_POINTS, 0, GLsizei(points.points.size()));
    }

    gl_check("drawing");

    // Resolve the samples of the region into the single-sampled target.
    glDisable(GL_SCISSOR_TEST);
    if (region.x1 > region.x0 && region.y1 > region.y0) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, m_msaa_fbo);
      glBindFramebuffer(GL_DRAW_FRAMEBUFFER, m_resolve_fbo);
      glBlitFramebuffer(region.x0, region.y0, region.x1, region.y1, region.x0, region.y0, region.x1, region.y1,
                        GL_COLOR_BUFFER_BIT, GL_NEAREST);
    }

    // Arthroscope mask: black outside the centred circle (decided per pixel centre, so one sample suffices).
    if (scene.camera.mask) {
      glBindFramebuffer(GL_FRAMEBUFFER, m_resolve_fbo);
      glDisable(GL_DEPTH_TEST);
      glUseProgram(m_mask_program);
      glUniform2f(uniform(m_mask_program, "u_center"), 0.5f * float(scene.width), 0.5f * float(scene.height));
      glUniform1f(uniform(m_mask_program, "u_radius"), mask_radius_px(scene));
      glDrawArrays(GL_TRIANGLES, 0, 3);
    }
    gl_check("resolving");
  }

  Image read_back(int width, int height) {
    // Read back, flipping rows so that the image starts at the top.
    glBindFramebuffer(GL_READ_FRAMEBUFFER, m_resolve_fbo);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    Image image;
    image.width = width;
    image.height = height;
    image.rgb.resize(std::size_t(3) * width * height);
    m_readback.resize(image.rgb.size());
    glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, m_readback.data());
    gl_check("reading the frame back");
    const std::size_t row = std::size_t(3) * width;
    for (int y = 0; y < height; ++y)
      std::memcpy(image.rgb.data() + row * y, m_readback.data() + row * (height - 1 - y), row);
    return image;
  }

  static GLint uniform(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

  static void set_matrix4(GLuint program, const char* name, const Eigen::Matrix4f& m) {
    glUniformMatrix4fv(uniform(program, name), 1, GL_FALSE, m.data());  // Eigen is column-major, as GL
  }

  /// A pixel rectangle [x0, x1) x [y0, y1), GL window coordinates (origin at the bottom left).
  struct Rect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  };

  static float mask_radius_px(const RenderScene& scene) {
    return float(scene.camera.mask_radius * 0.5 * scene.height);
  }

  /// The pixels geometry can cover: the projections of every mesh's bounding box (a triangle's projection lies
  /// within the projection of any box that holds it, as long as the box is in front of the eye), grown by two
  /// pixels, within the arthroscope mask's square. The whole frame (within the mask's square) when a box reaches
  /// behind the eye or when overlays are drawn.
  static Rect active_region(const RenderScene& scene, const Eigen::Matrix4f& view_projection) {
    float x0 = 1e30f, y0 = 1e30f, x1 = -1e30f, y1 = -1e30f;
    if (!bounds_on_screen(scene, view_projection, x0, y0, x1, y1)) {
      x0 = y0 = 0.0f;
      x1 = float(scene.width);
      y1 = float(scene.height);
    }
    // Outside the arthroscope mask's square everything is black in the end, whatever was drawn.
    if (scene.camera.mask) {
      const float r = mask_radius_px(scene), cx = 0.5f * float(scene.width), cy = 0.5f * float(scene.height);
      x0 = std::max(x0, cx - r);
      y0 = std::max(y0, cy - r);
      x1 = std::min(x1, cx + r);
      y1 = std::min(y1, cy + r);
    }
    const auto clamp_to = [](float v, int hi) { return int(std::clamp(v, 0.0f, float(hi))); };
    Rect r{clamp_to(std::floor(x0) - 2.0f, scene.width), clamp_to(std::floor(y0) - 2.0f, scene.height),
           clamp_to(std::ceil(x1) + 2.0f, scene.width), clamp_to(std::ceil(y1) + 2.0f, scene.height)};
    if (r.x1 <= r.x0 || r.y1 <= r.y0) r = Rect{};
    return r;
  }

  /// Grows [x0, x1] x [y0, y1] (pixels, GL window coordinates) by the projections of every mesh's bounding box. False
  /// when the frame has no such bound: a box reaches behind the eye, or overlays are drawn.
  static bool bounds_on_screen(const RenderScene& scene, const Eigen::Matrix4f& view_projection, float& x0, float& y0,
                               float& x1, float& y1) {
    if (!scene.lines.empty() || !scene.points.empty()) return false;
    for (const RenderMesh& mesh : scene.meshes) {
      if (mesh.positions.empty() || mesh.triangles.empty()) continue;
      Eigen::Vector3f lo = mesh.positions.front(), hi = lo;
      for (const Eigen::Vector3f& p : mesh.positions) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
      }
      const Eigen::Matrix4f mvp = view_projection * mesh.model;
      for (int k = 0; k < 8; ++k) {
        const Eigen::Vector4f corner(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z(), 1.0f);
        const Eigen::Vector4f clip = mvp * corner;
        if (!(clip.w() > 1e-6f)) return false;
        const float px = (0.5f * clip.x() / clip.w() + 0.5f) * float(scene.width);
        const float py = (0.5f * clip.y() / clip.w() + 0.5f) * float(scene.height);
        x0 = std::min(x0, px);
        y0 = std::min(y0, py);
        x1 = std::max(x1, px);
        y1 = std::max(y1, py);
      }
    }
    return true;
  }

  /// Uploads positions into attribute 0 of the bound VAO.
  void upload_positions(const std::vector<Eigen::Vector3f>& positions) {
    glBindBuffer(GL_ARRAY_BUFFER, m_position_buffer);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(positions.size() * sizeof(Eigen::Vector3f)), positions.data(),
                 GL_STREAM_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(Eigen::Vector3f), nullptr);
  }

  /// The glass meshes, over everything opaque: blended (premultiplied), without writing depth, each one's far side
  /// first and then its near side, so that both show.
  void draw_glass(const RenderScene& scene) {
    bool any = false;
    for (const RenderMesh& mesh : scene.meshes) any = any || mesh.material == MaterialKind::glass;
    if (!any) return;
    glEnable(GL_BLEND);
    glBlendFunc(GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glDepthMask(GL_FALSE);
    for (const RenderMesh& mesh : scene.meshes) {
      if (mesh.material != MaterialKind::glass) continue;
      if (mesh.cull_back_faces) {
        draw_mesh(mesh, Faces::back);
        draw_mesh(mesh, Faces::front);
      } else {
        draw_mesh(mesh);  // an open mesh: both sides in one pass
      }
    }
    glDepthMask(GL_TRUE);
    glDisable(GL_BLEND);
  }

  void draw_mesh(const RenderMesh& mesh, Faces faces = Faces::as_mesh) {
    if (mesh.triangles.empty() || mesh.positions.empty()) return;
    // Validate before GL reads anything out of bounds.
    const std::size_t nv = mesh.positions.size();
    if (!mesh.normals.empty() && mesh.normals.size() != nv)
      throw RenderError("render: a mesh has " + std::to_string(mesh.normals.size()) + " normals for " +
                        std::to_string(nv) + " vertices");
    if (!mesh.cut.empty() && mesh.cut.size() != mesh.triangles.size())
      throw RenderError("render: a mesh has " + std::to_string(mesh.cut.size()) + " cut flags for " +
                        std::to_string(mesh.triangles.size()) + " triangles");
    for (const auto& t : mesh.triangles)
      for (const std::int32_t v : t)
        if (v < 0 || std::size_t(v) >= nv) throw RenderError("render: a triangle index is out of range");

    // Material and transform.
    const Shading shading = shading_of(mesh.material);
    // Tissue and bone are lit per vertex (dense, dull surfaces); metal and glass keep per-fragment highlights.
    const bool per_fragment = mesh.material == MaterialKind::metal || mesh.material == MaterialKind::glass;
    const GLuint program = per_fragment ? m_mesh_program : m_tissue_program;
    glUseProgram(program);
    if (per_fragment)
      glUniform1f(uniform(program, "u_opacity"), mesh.material == MaterialKind::glass ? kGlassOpacity : 1.0f);
    glUniform3fv(uniform(program, "u_base"), 1, shading.base.data());
    glUniform1f(uniform(program, "u_specular"), shading.specular);
    glUniform1f(uniform(program, "u_shininess"), shading.shininess);
    set_matrix4(program, "u_model", mesh.model);
    const Eigen::Matrix3f normal_matrix = mesh.model.topLeftCorner<3, 3>().inverse().transpose();
    glUniformMatrix3fv(uniform(program, "u_normal_matrix"), 1, GL_FALSE, normal_matrix.data());

    // Vertex data.
    upload_positions(mesh.positions);
    const std::vector<Eigen::Vector3f> computed =
        mesh.normals.empty() ? mesh_normals(mesh.positions, mesh.triangles) : std::vector<Eigen::Vector3f>();
    const std::vector<Eigen::Vector3f>& normals = mesh.normals.empty() ? computed : mesh.normals;
    glBindBuffer(GL_ARRAY_BUFFER, m_normal_buffer);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(nv * sizeof(Eigen::Vector3f)), normals.data(), GL_STREAM_DRAW);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(Eigen::Vector3f), nullptr);
    // Closed meshes hide their back faces: they are dropped here already, on the CPU, so that llvmpipe neither shades
    // the vertices only they use nor sets them up (its vertex stage runs on one thread). A triangle is kept when the
    // eye is in front of its plane, with a margin that keeps edge-on triangles for GL's own culling to decide.
    // The far side of a glass body (Faces::back) keeps the others instead, and GL culls its front faces.
    const std::vector<std::array<std::int32_t, 3>>* triangles = &mesh.triangles;
    const std::vector<std::uint8_t>* cut = &mesh.cut;
    const bool cull = faces == Faces::as_mesh ? mesh.cull_back_faces : true;
    const bool keep_back = faces == Faces::back;
    if (cull) {
      const Eigen::Vector3f eye = (mesh.model.inverse() * m_eye.homogeneous()).head<3>();
      m_front_triangles.clear();
      m_front_cut.clear();
      for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
        const auto& t = mesh.triangles[f];
        const Eigen::Vector3f& a = mesh.positions[std::size_t(t[0])];
        const Eigen::Vector3f n =
            (mesh.positions[std::size_t(t[1])] - a).cross(mesh.positions[std::size_t(t[2])] - a);
        const Eigen::Vector3f to_face = a - eye;
        const float margin = 1e-4f * n.norm() * to_face.norm();
        if (keep_back ? n.dot(to_face) < -margin : n.dot(to_face) > margin) continue;
        m_front_triangles.push_back(t);
        if (!mesh.cut.empty()) m_front_cut.push_back(mesh.cut[f]);
      }
      triangles = &m_front_triangles;
      cut = &m_front_cut;
      if (triangles->empty()) return;
    }
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m_index_buffer);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(triangles->size() * sizeof((*triangles)[0])),
                 triangles->data(), GL_STREAM_DRAW);

    // Per-triangle cut flags through a buffer texture indexed by gl_PrimitiveID.
    const bool has_cut = !cut->empty();
    glUniform1i(uniform(program, "u_has_cut"), has_cut ? 1 : 0);
    if (has_cut) {
      glBindBuffer(GL_TEXTURE_BUFFER, m_cut_buffer);
      glBufferData(GL_TEXTURE_BUFFER, GLsizeiptr(cut->size()), cut->data(), GL_STREAM_DRAW);
      glActiveTexture(GL_TEXTURE0);
      glBindTexture(GL_TEXTURE_BUFFER, m_cut_texture);
      glTexBuffer(GL_TEXTURE_BUFFER, GL_R8, m_cut_buffer);
    }
    // Closed meshes hide their back faces anyway: culling them halves llvmpipe's rasterisation work.
    if (cull)
      glEnable(GL_CULL_FACE);
    else
      glDisable(GL_CULL_FACE);
    glCullFace(keep_back ? GL_FRONT : GL_BACK);
    glDrawElements(GL_TRIANGLES, GLsizei(3 * triangles->size()), GL_UNSIGNED_INT, nullptr);
    glCullFace(GL_BACK);
  }

  static bool same_mesh(const RenderMesh& a, const RenderMesh& b) {
    return a.material == b.material && a.cull_back_faces == b.cull_back_faces && a.model == b.model &&
           a.positions == b.positions && a.normals == b.normals && a.triangles == b.triangles && a.cut == b.cut;
  }

  /// Makes sure the still layer holds the scene's still meshes (RenderMesh::still) drawn over the background, with
  /// their depth, at the current size and sample count, for this camera and these lights: reused when all of these
  /// compare equal to the frame it was drawn for, redrawn otherwise (over the whole frame, so that any later region
  /// can be copied from it). False when the scene has no still mesh. Leaves the multisampled target bound with the
  /// scissor at `region`; the mesh programs' frame uniforms must be set.
  bool prepare_still_layer(const RenderScene& scene, const Eigen::Matrix4f& view_projection,
                           const std::vector<RenderLight>& lights, const Rect& region) {
    std::vector<const RenderMesh*> still;
    for (const RenderMesh& mesh : scene.meshes)
      if (layer_may_hold(mesh)) still.push_back(&mesh);
    if (still.empty()) return false;
    const auto same_light = [](const RenderLight& a, const RenderLight& b) {
      return a.position == b.position && a.color == b.color;
    };
    bool valid = m_layer_valid && m_layer_view_projection == view_projection && m_layer_eye == m_eye &&
                 m_layer_background == scene.background && m_layer_lights.size() == lights.size() &&
                 m_layer_meshes.size() == still.size();
    for (std::size_t i = 0; valid && i < lights.size(); ++i) valid = same_light(m_layer_lights[i], lights[i]);
    for (std::size_t i = 0; valid && i < still.size(); ++i) valid = same_mesh(m_layer_meshes[i], *still[i]);
    if (valid) return true;

    // Redraw the layer: the background and the still meshes over the whole frame.
    if (m_layer_fbo == 0) create_layer();
    glBindFramebuffer(GL_FRAMEBUFFER, m_layer_fbo);
    glScissor(0, 0, m_width, m_height);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    for (const RenderMesh* mesh : still) draw_mesh(*mesh);
    gl_check("drawing the still meshes");
    m_layer_valid = true;
    m_layer_view_projection = view_projection;
    m_layer_eye = m_eye;
    m_layer_background = scene.background;
    m_layer_lights = lights;
    m_layer_meshes.clear();
    for (const RenderMesh* mesh : still) m_layer_meshes.push_back(*mesh);
    glBindFramebuffer(GL_FRAMEBUFFER, m_msaa_fbo);
    glScissor(region.x0, region.y0, std::max(region.x1 - region.x0, 0), std::max(region.y1 - region.y0, 0));
    return true;
  }

  /// The still layer's framebuffer: multisampled colour and depth like the drawing target's.
  void create_layer() {
    glGenRenderbuffers(2, m_layer_renderbuffers);
    glGenFramebuffers(1, &m_layer_fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, m_layer_fbo);
    const GLsizei samples = m_samples > 1 ? m_samples : 0;
    glBindRenderbuffer(GL_RENDERBUFFER, m_layer_renderbuffers[0]);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_RGBA8, m_width, m_height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, m_layer_renderbuffers[0]);
    glBindRenderbuffer(GL_RENDERBUFFER, m_layer_renderbuffers[1]);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_DEPTH_COMPONENT24, m_width, m_height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, m_layer_renderbuffers[1]);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw RenderError("OpenGL: the still layer's framebuffer is incomplete");
    gl_check("creating the still layer");
  }

  /// (Re)creates the multisampled and the resolve framebuffers for a new size or sample count.
  void ensure_framebuffers(int width, int height, int samples) {
    if (width == m_width && height == m_height && samples == m_samples) return;
    release_framebuffers();
    GLint max_samples = 1;
    glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
    samples = std::min(samples, int(max_samples));
    glGenRenderbuffers(3, m_renderbuffers);
    glGenFramebuffers(1, &m_msaa_fbo);
    glGenFramebuffers(1, &m_resolve_fbo);
    // Multisampled colour and depth.
    glBindFramebuffer(GL_FRAMEBUFFER, m_msaa_fbo);
    glBindRenderbuffer(GL_RENDERBUFFER, m_renderbuffers[0]);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples > 1 ? samples : 0, GL_RGBA8, width, height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, m_renderbuffers[0]);
    glBindRenderbuffer(GL_RENDERBUFFER, m_renderbuffers[1]);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples > 1 ? samples : 0, GL_DEPTH_COMPONENT24, width, height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, m_renderbuffers[1]);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw RenderError("OpenGL: the multisampled framebuffer is incomplete");
    // Single-sampled resolve target.
    glBindFramebuffer(GL_FRAMEBUFFER, m_resolve_fbo);
    glBindRenderbuffer(GL_RENDERBUFFER, m_renderbuffers[2]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, m_renderbuffers[2]);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw RenderError("OpenGL: the resolve framebuffer is incomplete");
    gl_check("creating the framebuffers");
    m_width = width;
    m_height = height;
    m_samples = samples;
  }

  void release_framebuffers() {
    if (m_layer_fbo != 0) {
      glDeleteFramebuffers(1, &m_layer_fbo);
      glDeleteRenderbuffers(2, m_layer_renderbuffers);
      m_layer_fbo = 0;
    }
    m_layer_valid = false;
    m_layer_meshes.clear();
    if (m_msaa_fbo == 0) return;
    glDeleteFramebuffers(1, &m_msaa_fbo);
    glDeleteFramebuffers(1, &m_resolve_fbo);
    glDeleteRenderbuffers(3, m_renderbuffers);
    m_msaa_fbo = m_resolve_fbo = 0;
    m_width = m_height = m_samples = 0;
  }

  GLuint m_mesh_program = 0;    ///< per-fragment Blinn-Phong: metal
  GLuint m_tissue_program = 0;  ///< per-vertex Blinn-Phong with the per-triangle cut tint: tissue and bone
  GLuint m_overlay_program = 0, m_mask_program = 0;
  GLuint m_vao = 0, m_position_buffer = 0, m_normal_buffer = 0, m_index_buffer = 0, m_cut_buffer = 0;
  GLuint m_cut_texture = 0;
  GLuint m_msaa_fbo = 0, m_resolve_fbo = 0;
  GLuint m_renderbuffers[3] = {0, 0, 0};  ///< MSAA colour, MSAA depth, resolve colour
  int m_width = 0, m_height = 0, m_samples = 0;
  Eigen::Vector3f m_eye = Eigen::Vector3f::Zero();                 ///< camera position of the frame, m
  std::vector<std::array<std::int32_t, 3>> m_front_triangles;     ///< scratch: the triangles facing the eye
  std::vector<std::uint8_t> m_front_cut;                          ///< scratch: their cut flags
  std::vector<std::uint8_t> m_readback;   ///< bottom-up rows from glReadPixels (3 * width * height)
  // The still layer: the still meshes of an earlier frame over the background, multisampled, with depth, and what
  // they were drawn with (compared each frame).
  GLuint m_layer_fbo = 0;
  GLuint m_layer_renderbuffers[2] = {0, 0};  ///< colour, depth
  bool m_layer_valid = false;
  Eigen::Matrix4f m_layer_view_projection = Eigen::Matrix4f::Zero();
  Eigen::Vector3f m_layer_eye = Eigen::Vector3f::Zero();
  Eigen::Vector3f m_layer_background = Eigen::Vector3f::Zero();
  std::vector<RenderLight> m_layer_lights;
  std::vector<RenderMesh> m_layer_meshes;  ///< copies of the still meshes drawn into the layer
};

GlDrawer::GlDrawer() : m(std::make_unique<Impl>()) {}
GlDrawer::~GlDrawer() = default;

void GlDrawer::draw(const RenderScene& scene) { m->draw(scene); }

Image GlDrawer::read_back(int width, int height) { return m->read_back(width, height); }

unsigned GlDrawer::resolve_framebuffer() const { return m->m_resolve_fbo; }

std::string GlDrawer::description() {
  return std::string(reinterpret_cast<const char*>(glGetString(GL_RENDERER))) + ", OpenGL " +
         reinterpret_cast<const char*>(glGetString(GL_VERSION));
}

}  // namespace octocut::engine
