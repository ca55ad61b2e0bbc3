// `octocut view`: a GLFW window drawn by the same GlDrawer as the headless EGL renderer (one renderer, two targets),
// a Dear ImGui panel, the camera controls and the tool in the hand. The simulation runs on SimRunner's thread; this
// thread only draws the latest complete frame and turns input into commands. See viewer.hpp and README "Viewer".
#include <epoxy/gl.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <numbers>
#include <optional>
#include <thread>

#include "octocut/engine/io/io.hpp"
#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/render/renderer.hpp"
#include "octocut/engine/run/tool.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/engine/view/viewer.hpp"
#include "octocut/sim/timing.hpp"
#include "render/gl_drawer.hpp"
#include "view/sim_runner.hpp"
#include "view/view_controls.hpp"

namespace octocut::engine {

namespace {

namespace fs = std::filesystem;

std::string g_glfw_error;  // the last GLFW error, for the messages of a failed start
extern "C" void on_glfw_error(int code, const char* text) {
  g_glfw_error = std::string(text ? text : "unknown GLFW error") + " (GLFW error 0x" + [&] {
    char b[16];
    std::snprintf(b, sizeof b, "%X", unsigned(code));
    return std::string(b);
  }() + ")";
}

// Owns glfwInit/glfwTerminate and the window.
struct Glfw {
  GLFWwindow* window = nullptr;
  ~Glfw() {
    if (window != nullptr) glfwDestroyWindow(window);
    glfwTerminate();
  }
};

// Input that the GLFW callbacks collect for the frame loop.
struct Input {
  bool quit = false, cut = false, screenshot = false, toggle_frames = false, toggle_arthroscope = false;
  bool frame_object = false, toggle_pause = false, single_step = false;
  double depth_steps = 0.0;  // wheel notches or W/S presses, + deeper
  double roll_steps = 0.0;   // A/D presses, + counter-clockwise about the tool axis
  double zoom_steps = 0.0;   // Shift+wheel notches
  bool pose_dirty = false;   // the tool must follow the mouse again
  // Where the pointer was last seen, window pixels; kept from frame to frame. X reports the pointer's position when a
  // window is mapped under it or the pointer enters it (GLFW passes that on as a cursor position): only a position
  // that differs from the last one seen is a move of the hand.
  double pointer_x = 0.0, pointer_y = 0.0;
};

Input& input_of(GLFWwindow* w) { return *static_cast<Input*>(glfwGetWindowUserPointer(w)); }

extern "C" void on_key(GLFWwindow* w, int key, int, int action, int mods) {
  if (action == GLFW_RELEASE || ImGui::GetIO().WantCaptureKeyboard) return;
  Input& in = input_of(w);
  const bool press = action == GLFW_PRESS;
  switch (key) {
    case GLFW_KEY_ESCAPE: in.quit = true; break;
    case GLFW_KEY_C: in.cut |= press; break;
    case GLFW_KEY_F12: in.screenshot |= press; break;
    case GLFW_KEY_R: in.toggle_frames |= press; break;
    case GLFW_KEY_V: in.toggle_arthroscope |= press; break;
    case GLFW_KEY_F: in.frame_object |= press; break;
    case GLFW_KEY_SPACE: in.toggle_pause |= press; break;
    case GLFW_KEY_N: in.single_step |= press; break;
    case GLFW_KEY_W: in.depth_steps += 1.0; in.pose_dirty = true; break;
    case GLFW_KEY_S: in.depth_steps -= 1.0; in.pose_dirty = true; break;
    case GLFW_KEY_A: in.roll_steps += 1.0; in.pose_dirty = true; break;
    case GLFW_KEY_D: in.roll_steps -= 1.0; in.pose_dirty = true; break;
    default: break;
  }
  (void)mods;
}

extern "C" void on_scroll(GLFWwindow* w, double, double dy) {
  if (ImGui::GetIO().WantCaptureMouse) return;
  Input& in = input_of(w);
  if (glfwGetKey(w, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS || glfwGetKey(w, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS) {
    in.zoom_steps += dy;
  } else {
    in.depth_steps += dy;
    in.pose_dirty = true;
  }
}

extern "C" void on_mouse_button(GLFWwindow* w, int button, int action, int) {
  if (ImGui::GetIO().WantCaptureMouse) return;
  if (button == GLFW_MOUSE_BUTTON_LEFT && action == GLFW_PRESS) input_of(w).cut = true;
}

extern "C" void on_cursor(GLFWwindow* w, double x, double y) {
  Input& in = input_of(w);
  const bool moved = x != in.pointer_x || y != in.pointer_y;
  in.pointer_x = x;
  in.pointer_y = y;
  if (moved && !ImGui::GetIO().WantCaptureMouse) in.pose_dirty = true;
}

// The window and its GL context: exit 2 with a clear message when there is no display.
std::optional<std::string> open_display() {
  glfwSetErrorCallback(on_glfw_error);
  if (!glfwInit())
    return "cannot open a window: " + g_glfw_error +
           "; octocut view needs a display (set DISPLAY, or run it under xvfb-run); `octocut run` needs none";
  return std::nullopt;
}

// Gives this thread, and the threads it starts from now on (Mesa llvmpipe's rasteriser threads start with the GL
// context), a lower CPU priority than the simulation thread started before: on a machine whose cores software GL
// and the simulation share, drawing then takes what the simulation leaves. Best effort (nice +19 of this thread):
// under other load the scheduler shares the CPU among sessions first and by nice only inside one, so with +10 the
// window's three threads (this one and llvmpipe's two) took about a quarter of the viewer's share from the simulation
// (viewer step ÷ headless step 1.40 at a load average of 11); +19 leaves them about 4 %.
void lower_drawing_priority() { (void)setpriority(PRIO_PROCESS, pid_t(syscall(SYS_gettid)), 19); }

std::optional<std::string> open_window(Glfw& glfw, const std::string& title, int width, int height) {
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_SAMPLES, 0);  // the drawer multisamples in its own framebuffer
  glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
  glfw.window = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (glfw.window == nullptr) return "cannot create an OpenGL 3.3 core window: " + g_glfw_error;
  glfwMakeContextCurrent(glfw.window);
  glfwSwapInterval(0);
  return std::nullopt;
}

// Everything one viewer session holds besides the window.
class Viewer {
 public:
  Viewer(const Scene& scene, const ViewOptions& options, std::size_t hand)
      : m_scene(scene), m_options(options),
        m_out(options.out_dir.empty() ? fs::path(".") : fs::path(options.out_dir)),
        m_runner(scene, hand, options.sets), m_hand(scene, hand), m_hand_index(hand) {}

  // The frame loop, until Esc or the window's close button.
  void run();
  // Stops the simulation; writes the session and the report. Returns the exit code.
  ViewResult finish();

 private:
  void handle_input(Input& in);
  void draw_frame(Input& in);
  void panel();
  void panel_stats(const SimStats& s);
  void panel_controls(const SimStats& s);
  void save_screenshot(const Image& image);
  void log_line(const SimStats& s);

  const Scene& m_scene;
  const ViewOptions& m_options;
  GLFWwindow* m_window = nullptr;
  fs::path m_out;
  SimRunner m_runner;
  HandTool m_hand;
  std::size_t m_hand_index;            // the tool in the hand, in the scene's tools
  std::optional<GlDrawer> m_drawer;
  std::optional<RenderScene> m_frame;  // the latest complete frame of the simulation
  Camera m_camera;                     // the user's camera (the scene's at the start)
  bool m_camera_set = false;
  OverlaySettings m_overlays;
  Material m_material_edit;
  bool m_material_loaded = false;
  bool m_paused = false;
  std::unique_ptr<FrameWriter> m_writer;
  long m_frame_index = 0;
  int m_screenshots = 0;
  std::vector<double> m_draw_ms;  // per drawn frame, ms
  double m_frame_ms = 0.0;        // the last frame, everything included, ms
  sim::Clock::time_point m_start = sim::Clock::now(), m_last_log = sim::Clock::now();
  std::string m_note;             // the last thing said to the user (screenshot path, frames on/off)
  Eigen::Vector2d m_last_cursor = Eigen::Vector2d::Zero();  // window pixels

 public:
  // The simulation starts before the window exists, so that its thread keeps the normal priority.
  void start_simulation() { m_runner.start(); }
  // The window's GL objects, in its current context.
  void init(GLFWwindow* window) {
    m_window = window;
    m_drawer.emplace();
    m_overlays = m_scene.render.overlays;
  }
};

void Viewer::handle_input(Input& in) {
  if (in.toggle_pause) {
    m_paused = !m_paused;
    m_runner.set_paused(m_paused);
  }
  if (in.single_step && m_paused) m_runner.single_step();
  if (in.toggle_arthroscope) m_camera.arthroscope = m_camera.mask = !m_camera.arthroscope;
  if (in.zoom_steps != 0.0) zoom(m_camera, in.zoom_steps);
  if (in.frame_object && m_frame) frame_object(m_camera, *m_frame);
  // Orbit with the right button, pan with the middle one.
  double x = 0.0, y = 0.0;
  glfwGetCursorPos(m_window, &x, &y);
  double& last_x = m_last_cursor.x();
  double& last_y = m_last_cursor.y();
  const bool over_panel = ImGui::GetIO().WantCaptureMouse;
  if (!over_panel && glfwGetMouseButton(m_window, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS)
    orbit(m_camera, x - last_x, y - last_y);
  if (!over_panel && glfwGetMouseButton(m_window, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS) {
    int w = 0, h = 0;
    glfwGetWindowSize(m_window, &w, &h);
    pan(m_camera, x - last_x, y - last_y, h);
  }
  last_x = x;
  last_y = y;
  // The tool follows the mouse (and W/S, wheel, A/D); a cut goes after the pose it was made at.
  if ((in.pose_dirty || in.cut) && m_frame && !over_panel) {
    int w = 0, h = 0;
    glfwGetWindowSize(m_window, &w, &h);
    m_hand.adjust(in.depth_steps, in.roll_steps);
    if (const std::optional<sim::Pose> pose = m_hand.follow(m_camera, *m_frame, x, y, w, h))
      m_runner.set_tool_pose(*pose);
  }
  if (in.cut) m_runner.cut();
  if (in.screenshot) m_note = "screenshot requested";
  if (in.toggle_frames) {
    if (m_writer) {
      m_writer->finish();
      m_note = "frames: " + std::to_string(m_writer->written()) + " written to " + (m_out / "frames").string();
      m_writer.reset();
    } else {
      fs::create_directories(m_out / "frames");
      m_writer = std::make_unique<FrameWriter>(m_out / "frames", 4);
      m_note = "writing frames to " + (m_out / "frames").string();
    }
    std::fprintf(stderr, "[view] %s\n", m_note.c_str());
  }
}

void Viewer::run() {
  Input in;
  glfwGetCursorPos(m_window, &in.pointer_x, &in.pointer_y);  // where the pointer is as the window opens: no move
  glfwSetWindowUserPointer(m_window, &in);
  const auto frame_period = std::chrono::microseconds(16667);  // at most 60 frames per second
  while (!glfwWindowShouldClose(m_window)) {
    const auto t0 = sim::Clock::now();
    glfwPollEvents();
    if (in.quit) break;
    m_runner.request_frame();
    if (std::optional<RenderScene> f = m_runner.take_frame()) m_frame = std::move(f);
    if (!m_frame) {  // the first frame is on its way
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      continue;
    }
    if (!m_camera_set) {
      m_camera = m_frame->camera;
      m_camera_set = true;
    }
    handle_input(in);
    draw_frame(in);
    in = Input{.pointer_x = in.pointer_x, .pointer_y = in.pointer_y};
    if (const std::string e = m_runner.error(); !e.empty()) throw std::runtime_error(e);
    m_frame_ms = sim::ms_since(t0);
    const auto spent = sim::Clock::now() - t0;
    if (spent < frame_period) std::this_thread::sleep_for(frame_period - spent);
  }
}

void Viewer::draw_frame(Input& in) {
  int w = 0, h = 0;
  glfwGetFramebufferSize(m_window, &w, &h);
  if (w <= 0 || h <= 0) return;  // minimised
  // The simulation's frame seen through the user's camera, at the window's size.
  const auto t0 = sim::Clock::now();
  RenderScene& scene = *m_frame;
  const Camera world_camera = scene.camera;
  scene.camera = m_camera;
  // The tool in the hand where the hand is now, even while the simulation is inside a long step.
  if (m_hand_index < scene.tool_meshes.size() && scene.tool_meshes[m_hand_index] >= 0 && m_hand.placed())
    scene.meshes[std::size_t(scene.tool_meshes[m_hand_index])].model = m_hand.pose().matrix().cast<float>();
  scene.width = w;
  scene.height = h;
  m_drawer->draw(scene);
  scene.camera = world_camera;
  glBindFramebuffer(GL_READ_FRAMEBUFFER, m_drawer->resolve_framebuffer());
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
  glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  if (in.screenshot || m_writer) {
    Image image = m_drawer->read_back(w, h);
    if (in.screenshot) save_screenshot(image);
    if (m_writer) m_writer->push(m_frame_index++, std::move(image));
  }
  m_draw_ms.push_back(sim::ms_since(t0));
  // The panel over the view.
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glViewport(0, 0, w, h);
  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  panel();
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  glfwSwapBuffers(m_window);
  const SimStats s = m_runner.stats();
  if (sim::ms_since(m_last_log) >= 1000.0) log_line(s);
}

void Viewer::log_line(const SimStats& s) {
  m_last_log = sim::Clock::now();
  std::fprintf(stderr, "[view] t = %.3f s  steps %ld  real time x%.2f%s  %.2f ms/step  %.1f ms/frame%s\n", s.t,
               s.steps, s.real_time_factor, s.behind ? " (slower than real time)" : "", s.step_ms, m_frame_ms,
               s.paused ? "  paused" : "");
}

void Viewer::save_screenshot(const Image& image) {
  char name[64];
  std::snprintf(name, sizeof name, "screenshot_%03d.png", m_screenshots++);
  fs::create_directories(m_out);
  const fs::path path = m_out / name;
  write_file_atomic(path, encode_png(image));
  const SimStats s = m_runner.stats();
  m_note = "screenshot: " + path.string();
  std::fprintf(stderr, "[view] screenshot: %s (t = %.4f s)\n", path.string().c_str(), s.t);
}

void Viewer::panel() {
  const SimStats s = m_runner.stats();
  if (!m_material_loaded) {
    m_material_edit = s.material;
    m_material_loaded = true;
  }
  // A fixed width, the height fitted to the content (ImGui's AlwaysAutoResize with the default item widths, which are
  // a fraction of the window's, lets the panel grow over the view frame after frame).
  ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_Once);
  ImGui::SetNextWindowSize(ImVec2(330, 0), ImGuiCond_Always);
  ImGui::SetNextWindowBgAlpha(0.8f);
  ImGui::Begin(m_scene.name.c_str());
  ImGui::PushItemWidth(150);
  panel_stats(s);
  panel_controls(s);
  ImGui::PopItemWidth();
  ImGui::End();
}

void Viewer::panel_stats(const SimStats& s) {
  ImGui::Text("t = %.3f s   real time x%.2f", s.t, s.real_time_factor);
  if (s.paused)
    ImGui::TextColored(ImVec4(1.0f, 0.8f, 0.3f, 1.0f), "paused (Space resumes, N steps)");
  else if (s.behind)
    ImGui::TextColored(ImVec4(1.0f, 0.6f, 0.2f, 1.0f), "slower than real time: time slowed down");
  if (s.cutting) ImGui::TextColored(ImVec4(1.0f, 0.4f, 0.4f, 1.0f), "cutting...");
  const double draw_ms = m_draw_ms.empty() ? 0.0 : m_draw_ms.back();
  ImGui::Text("%.2f ms/step   %.1f ms/frame (draw %.1f)", s.step_ms, m_frame_ms, draw_ms);
  ImGui::Text("elements %ld   DOFs %ld   tets %ld", s.elements, s.dofs, s.tets);
  ImGui::Text("|S| %ld vertices, %ld triangles", s.surface_vertices, s.surface_triangles);
  if (ImGui::CollapsingHeader("last cut", ImGuiTreeNodeFlags_DefaultOpen)) {
    if (!s.last_cut) {
      ImGui::TextDisabled("none yet (left click or C)");
    } else {
      const CutSummary& c = *s.last_cut;
      ImGui::Text("t = %.3f s: %s, %.4g mm^3 removed", c.t, c.status.c_str(), c.removed_volume_m3 * 1e9);
      for (std::size_t k = 0; k < kCutStageKeys.size(); ++k) ImGui::Text("  %-15s %8.2f ms", kCutStageKeys[k], c.ms[k]);
    }
  }
}

void Viewer::panel_controls(const SimStats& s) {
  if (ImGui::CollapsingHeader("overlays", ImGuiTreeNodeFlags_DefaultOpen)) {
    bool changed = ImGui::Checkbox("octree", &m_overlays.octree);
    changed |= ImGui::Checkbox("DOFs", &m_overlays.dofs);
    changed |= ImGui::Checkbox("hanging slots", &m_overlays.hanging);
    if (s.contact) {
      changed |= ImGui::Checkbox("contact points and forces", &m_overlays.contacts);
      double mm_per_n = 1e3 * m_overlays.contact_force_scale;
      ImGui::InputDouble("force line (mm/N)", &mm_per_n, 0.0, 0.0, "%.4g");
      if (ImGui::IsItemDeactivatedAfterEdit() && mm_per_n > 0.0) {
        m_overlays.contact_force_scale = 1e-3 * mm_per_n;
        changed = true;
      }
      for (const ContactForce& f : s.contact_forces) {
        const double n = std::sqrt(f.force_n[0] * f.force_n[0] + f.force_n[1] * f.force_n[1] + f.force_n[2] * f.force_n[2]);
        ImGui::Text("  %s: |F| %.3f N, deepest %.3f mm", f.name.c_str(), n, 1e3 * f.max_penetration_m);
      }
    } else {
      ImGui::TextDisabled("contact points, forces: nothing collides");
    }
    if (changed) m_runner.set_overlays(m_overlays);
  }
  if (ImGui::CollapsingHeader("material", ImGuiTreeNodeFlags_DefaultOpen)) {
    bool edited = false;
    ImGui::InputDouble("E (Pa)", &m_material_edit.young_modulus, 0.0, 0.0, "%.4g");
    edited |= ImGui::IsItemDeactivatedAfterEdit();
    ImGui::InputDouble("nu", &m_material_edit.poisson_ratio, 0.01, 0.05, "%.3f");
    edited |= ImGui::IsItemDeactivatedAfterEdit() || ImGui::IsItemEdited();
    ImGui::InputDouble("alpha (1/s)", &m_material_edit.rayleigh_mass, 0.0, 0.0, "%.4g");
    edited |= ImGui::IsItemDeactivatedAfterEdit();
    ImGui::InputDouble("beta (s)", &m_material_edit.rayleigh_stiffness, 0.0, 0.0, "%.4g");
    edited |= ImGui::IsItemDeactivatedAfterEdit();
    int element = m_material_edit.element == "trilinear" ? 1 : 0;  // the hexahedron (object.material.element)
    if (ImGui::Combo("element", &element, "bbar\0trilinear\0")) {
      m_material_edit.element = element == 1 ? "trilinear" : "bbar";
      edited = true;
    }
    if (edited) m_runner.set_material(m_material_edit);
    if (ImGui::Button("revert")) m_material_edit = s.material;
  }
  if (ImGui::Button(m_paused ? "resume" : "pause")) {
    m_paused = !m_paused;
    m_runner.set_paused(m_paused);
  }
  ImGui::SameLine();
  if (ImGui::Button("step") && m_paused) m_runner.single_step();
  ImGui::SameLine();
  if (ImGui::Button("reset")) m_runner.reset();
  if (m_scene.tools.size() > 1) {
    int picked = int(m_hand_index);
    const auto name = [](void* data, int i, const char** out) {
      *out = static_cast<const Scene*>(data)->tools[std::size_t(i)].name.c_str();
      return true;
    };
    if (ImGui::Combo("tool in hand", &picked, name, const_cast<Scene*>(&m_scene), int(m_scene.tools.size())) &&
        std::size_t(picked) != m_hand_index) {
      m_hand_index = std::size_t(picked);
      m_hand = HandTool(m_scene, m_hand_index);
      m_runner.hold(m_hand_index);
    }
  } else {
    ImGui::TextDisabled("tool in hand: %s", m_hand.name().c_str());
  }
  if (!m_options.record_path.empty()) ImGui::TextDisabled("recording to %s", m_options.record_path.c_str());
  if (m_writer) ImGui::TextColored(ImVec4(1.0f, 0.3f, 0.3f, 1.0f), "writing frames (R stops)");
  if (!m_note.empty()) ImGui::TextDisabled("%s", m_note.c_str());
  if (ImGui::CollapsingHeader("controls")) {
    ImGui::TextUnformatted(
        "mouse: tool in the view plane\nwheel, W/S: tool depth   A/D: roll\nleft click, C: cut\n"
        "right drag: orbit   middle drag: pan\nShift+wheel: zoom   F: frame   V: arthroscope\n"
        "Space: pause   N: step   F12: screenshot\nR: frames on/off   Esc: quit");
  }
}

ViewResult Viewer::finish() {
  ViewResult result;
  m_runner.stop();
  if (m_writer) m_writer->finish();
  Session session = m_runner.session();
  if (!m_options.record_path.empty()) {
    write_file_atomic(m_options.record_path, session_json(session));
    std::fprintf(stderr, "[view] session: %s (%zu events, %ld steps)\n", m_options.record_path.c_str(),
                 session.events.size(), session.end_step);
  }
  Report report = m_runner.report();
  report.subsystems.renderer = true;
  report.subsystems.frame_writer = m_frame_index > 0;
  report.render_ms = TimingSummary::of(m_draw_ms);
  report.frames_rendered = long(m_draw_ms.size());
  report.frames = m_frame_index;
  report.wall_time_s = sim::ms_since(m_start) / 1000.0;
  if (const std::string e = m_runner.error(); !e.empty()) {
    report.status = "failed";
    report.error = e;
    result = {1, e};
  }
  if (!m_options.out_dir.empty()) {
    fs::create_directories(m_out);
    write_file_atomic(m_out / "report.json", report_json(report));
    std::fprintf(stderr, "[view] report: %s\n", (m_out / "report.json").string().c_str());
  }
  return result;
}

}  // namespace

bool viewer_available() { return true; }

ViewResult run_viewer(const Scene& scene, const ViewOptions& options) {
  // The tool in the hand.
  std::size_t hand = 0;
  if (!options.tool.empty()) {
    std::size_t i = 0;
    while (i < scene.tools.size() && scene.tools[i].name != options.tool) ++i;
    if (i == scene.tools.size()) return {2, scene.file + ": /tools: no tool named '" + options.tool + "' (--tool)"};
    hand = i;
  }
  if (!options.record_path.empty()) {
    const fs::path parent = fs::absolute(options.record_path).parent_path();
    if (!fs::is_directory(parent))
      return {2, options.record_path + ": cannot record there: " + parent.string() + " is not a directory"};
  }
  const int width = options.width > 0 ? options.width : scene.render.width;
  const int height = options.height > 0 ? options.height : scene.render.height;

  // The display first: without one nothing else is built. Then the world and its thread, then the window.
  Glfw glfw;
  if (const std::optional<std::string> e = open_display()) return {2, *e};
  std::optional<Viewer> viewer;
  try {
    viewer.emplace(scene, options, hand);
    viewer->start_simulation();
    lower_drawing_priority();
    if (const std::optional<std::string> e = open_window(glfw, "octocut \u2014 " + scene.name, width, height))
      return {2, *e};
    viewer->init(glfw.window);
  } catch (const SceneError& e) {
    return {2, e.what()};
  } catch (const RenderError& e) {
    return {2, std::string("cannot draw into the window: ") + e.what()};
  }
  // ImGui chains the callbacks installed before it.
  glfwSetKeyCallback(glfw.window, on_key);
  glfwSetScrollCallback(glfw.window, on_scroll);
  glfwSetMouseButtonCallback(glfw.window, on_mouse_button);
  glfwSetCursorPosCallback(glfw.window, on_cursor);
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini in the working directory
  ImGui::StyleColorsDark();
  ImGui_ImplGlfw_InitForOpenGL(glfw.window, true);
  ImGui_ImplOpenGL3_Init("#version 330");
  ViewResult result;
  try {
    viewer->run();
  } catch (const std::exception& e) {
    result = {1, e.what()};
  }
  ViewResult finished = viewer->finish();
  if (result.exit_code == 0) result = finished;
  viewer.reset();  // GL objects before the context
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
  return result;
}

}  // namespace octocut::engine
