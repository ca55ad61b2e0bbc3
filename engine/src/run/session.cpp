// Recorded interactive sessions: writing, parsing with validation, and replaying one event. See session.hpp.
#include "octocut/engine/run/session.hpp"

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "octocut/engine/io/io.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {

namespace {

using nlohmann::json;

constexpr SessionEventKind kKinds[] = {SessionEventKind::hold,  SessionEventKind::pose,   SessionEventKind::cut,
                                       SessionEventKind::material, SessionEventKind::pause, SessionEventKind::resume,
                                       SessionEventKind::reset};

// A SceneError "<file>: <pointer>: <what>".
[[noreturn]] void fail(const std::string& file, const std::string& pointer, const std::string& what) {
  throw SceneError(file + ": " + pointer + ": " + what);
}

// Reads the members of one JSON object, each error naming the file and the member's pointer.
class Reader {
 public:
  Reader(const json& j, std::string file, std::string pointer)
      : m_j(j), m_file(std::move(file)), m_pointer(std::move(pointer)) {
    if (!m_j.is_object()) fail(m_file, at(), "expected an object");
  }
  [[nodiscard]] std::string at(const std::string& key = "") const { return key.empty() ? (m_pointer.empty() ? "/" : m_pointer) : m_pointer + "/" + key; }
  [[nodiscard]] bool has(const std::string& key) const { return m_j.contains(key); }
  const json& get(const std::string& key) const {
    if (!m_j.contains(key)) fail(m_file, at(key), "missing");
    return m_j.at(key);
  }
  std::string string(const std::string& key) const {
    const json& v = get(key);
    if (!v.is_string()) fail(m_file, at(key), "expected a string");
    return v.get<std::string>();
  }
  double number(const std::string& key) const {
    const json& v = get(key);
    if (!v.is_number() || !std::isfinite(v.get<double>())) fail(m_file, at(key), "expected a finite number");
    return v.get<double>();
  }
  long integer(const std::string& key, long min) const {
    const json& v = get(key);
    if (!v.is_number_integer() || v.get<long>() < min)
      fail(m_file, at(key), "expected an integer >= " + std::to_string(min));
    return v.get<long>();
  }
  sim::Vec3 vec3(const std::string& key) const {
    const json& v = get(key);
    if (!v.is_array() || v.size() != 3) fail(m_file, at(key), "expected an array of 3 numbers");
    sim::Vec3 r;
    for (int i = 0; i < 3; ++i) {
      if (!v[i].is_number() || !std::isfinite(v[i].get<double>()))
        fail(m_file, at(key) + "/" + std::to_string(i), "expected a finite number");
      r[i] = v[i].get<double>();
    }
    return r;
  }
  const std::string& file() const { return m_file; }

 private:
  const json& m_j;
  std::string m_file, m_pointer;
};

json pose_json(const sim::Pose& p) {
  json rows = json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({p.rotation(r, 0), p.rotation(r, 1), p.rotation(r, 2)});
  return {{"position", {p.position.x(), p.position.y(), p.position.z()}}, {"rotation", rows}};
}

sim::Pose parse_pose(const Reader& r) {
  sim::Pose p;
  p.position = r.vec3("position");
  const json& rows = r.get("rotation");
  if (!rows.is_array() || rows.size() != 3) fail(r.file(), r.at("rotation"), "expected 3 rows of 3 numbers");
  for (int i = 0; i < 3; ++i) {
    if (!rows[i].is_array() || rows[i].size() != 3)
      fail(r.file(), r.at("rotation") + "/" + std::to_string(i), "expected an array of 3 numbers");
    for (int k = 0; k < 3; ++k) {
      if (!rows[i][k].is_number() || !std::isfinite(rows[i][k].get<double>()))
        fail(r.file(), r.at("rotation") + "/" + std::to_string(i) + "/" + std::to_string(k), "expected a finite number");
      p.rotation(i, k) = rows[i][k].get<double>();
    }
  }
  const double off = (p.rotation.transpose() * p.rotation - sim::Mat3::Identity()).norm();
  if (off > 1e-6 || p.rotation.determinant() <= 0.0)
    fail(r.file(), r.at("rotation"), "not a proper rotation (orthonormal rows, determinant +1)");
  return p;
}

json material_json(const Material& m) {
  json j = {{"young_modulus", m.young_modulus}, {"poisson_ratio", m.poisson_ratio}, {"density", m.density},
            {"rayleigh_mass", m.rayleigh_mass}, {"rayleigh_stiffness", m.rayleigh_stiffness}};
  if (!m.element.empty()) j["element"] = m.element;
  return j;
}

Material parse_material(const Reader& r) {
  Material m;
  m.young_modulus = r.number("young_modulus");
  m.poisson_ratio = r.number("poisson_ratio");
  m.density = r.number("density");
  m.rayleigh_mass = r.number("rayleigh_mass");
  m.rayleigh_stiffness = r.number("rayleigh_stiffness");
  if (m.young_modulus <= 0.0) fail(r.file(), r.at("young_modulus"), "must be > 0");
  if (m.poisson_ratio < 0.0 || m.poisson_ratio >= 0.5) fail(r.file(), r.at("poisson_ratio"), "must be in [0, 0.5)");
  if (m.density <= 0.0) fail(r.file(), r.at("density"), "must be > 0");
  if (m.rayleigh_mass < 0.0) fail(r.file(), r.at("rayleigh_mass"), "must be >= 0");
  if (m.rayleigh_stiffness < 0.0) fail(r.file(), r.at("rayleigh_stiffness"), "must be >= 0");
  // The element: sessions written before it was recorded have none, and their edits keep the object's element.
  m.element.clear();
  if (r.has("element")) {
    m.element = r.string("element");
    if (m.element != "bbar" && m.element != "trilinear") fail(r.file(), r.at("element"), "must be \"bbar\" or \"trilinear\"");
  }
  return m;
}

SessionEvent parse_event(const json& j, const std::string& file, const std::string& pointer) {
  const Reader r(j, file, pointer);
  SessionEvent e;
  const std::string kind = r.string("kind");
  bool known = false;
  for (const SessionEventKind k : kKinds)
    if (kind == to_string(k)) {
      e.kind = k;
      known = true;
    }
  if (!known) fail(file, r.at("kind"), "unknown event kind '" + kind + "' (hold, pose, cut, material, pause, resume, reset)");
  e.step = r.integer("step", 0);
  e.t = r.number("t");
  if (e.kind == SessionEventKind::hold || e.kind == SessionEventKind::pose || e.kind == SessionEventKind::cut)
    e.tool = std::size_t(r.integer("tool", 0));
  if (e.kind == SessionEventKind::pose) e.pose = parse_pose(Reader(r.get("pose"), file, r.at("pose")));
  if (e.kind == SessionEventKind::material)
    e.material = parse_material(Reader(r.get("material"), file, r.at("material")));
  return e;
}

}  // namespace

const char* to_string(SessionEventKind kind) {
  switch (kind) {
    case SessionEventKind::hold: return "hold";
    case SessionEventKind::pose: return "pose";
    case SessionEventKind::cut: return "cut";
    case SessionEventKind::material: return "material";
    case SessionEventKind::pause: return "pause";
    case SessionEventKind::resume: return "resume";
    case SessionEventKind::reset: return "reset";
  }
  return "?";
}

std::string scene_fingerprint(const std::string& path) {
  const std::string bytes = read_file(path);
  std::uint64_t h = 1469598103934665603ull;
  for (const unsigned char c : bytes) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h));
  return text;
}

std::string session_json(const Session& s) {
  json events = json::array();
  for (const SessionEvent& e : s.events) {
    json j = {{"kind", to_string(e.kind)}, {"step", e.step}, {"t", e.t}};
    if (e.kind == SessionEventKind::hold || e.kind == SessionEventKind::pose || e.kind == SessionEventKind::cut)
      j["tool"] = e.tool;
    if (e.kind == SessionEventKind::pose) j["pose"] = pose_json(e.pose);
    if (e.kind == SessionEventKind::material) j["material"] = material_json(e.material);
    events.push_back(std::move(j));
  }
  const json doc = {{"schema", kSessionSchema},
                    {"scene", {{"name", s.scene_name}, {"fingerprint", s.scene_fingerprint}, {"sets", s.sets}}},
                    {"end_step", s.end_step},
                    {"events", std::move(events)}};
  return doc.dump(1) + "\n";
}

Session parse_session(const std::string& text, const std::string& file) {
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::parse_error& e) {
    fail(file, "/", std::string("not JSON: ") + e.what());
  }
  const Reader r(doc, file, "");
  if (const std::string schema = r.string("schema"); schema != kSessionSchema)
    fail(file, "/schema", "'" + schema + "' is not a session file of this version (expected '" + kSessionSchema + "')");
  Session s;
  const Reader scene(r.get("scene"), file, "/scene");
  s.scene_name = scene.string("name");
  s.scene_fingerprint = scene.string("fingerprint");
  const json& sets = scene.get("sets");
  if (!sets.is_array()) fail(file, "/scene/sets", "expected an array of strings");
  for (std::size_t i = 0; i < sets.size(); ++i) {
    if (!sets[i].is_string()) fail(file, "/scene/sets/" + std::to_string(i), "expected a string");
    s.sets.push_back(sets[i].get<std::string>());
  }
  s.end_step = r.integer("end_step", 0);
  const json& events = r.get("events");
  if (!events.is_array()) fail(file, "/events", "expected an array");
  long last = 0;
  for (std::size_t i = 0; i < events.size(); ++i) {
    const std::string pointer = "/events/" + std::to_string(i);
    SessionEvent e = parse_event(events[i], file, pointer);
    // Steps never go back within one world; a reset starts the next at 0.
    if (e.step < last) fail(file, pointer + "/step", "steps go back (" + std::to_string(e.step) + " after " + std::to_string(last) + ")");
    last = e.kind == SessionEventKind::reset ? 0 : e.step;
    s.events.push_back(std::move(e));
  }
  if (s.end_step < last)
    fail(file, "/end_step", "the session ends (step " + std::to_string(s.end_step) + ") before its last event (step " +
                                std::to_string(last) + ")");
  return s;
}

void check_session_scene(const Session& s, const Scene& scene, const std::string& file) {
  if (s.scene_name != scene.name)
    fail(file, "/scene/name", "recorded for scene '" + s.scene_name + "', not '" + scene.name + "' (" + scene.file + ")");
  if (const std::string f = scene_fingerprint(scene.file); s.scene_fingerprint != f)
    fail(file, "/scene/fingerprint", "recorded for another version of " + scene.file + " (fingerprint " +
                                         s.scene_fingerprint + ", the file now has " + f + ")");
  for (std::size_t i = 0; i < s.events.size(); ++i)
    if (s.events[i].tool >= scene.tools.size())
      fail(file, "/events/" + std::to_string(i) + "/tool",
           "the scene has " + std::to_string(scene.tools.size()) + " tool(s), no tool " + std::to_string(s.events[i].tool));
}

void apply_session_event(World& world, const SessionEvent& e) {
  switch (e.kind) {
    case SessionEventKind::hold: world.hold_tool(e.tool); break;
    case SessionEventKind::pose: world.set_tool_pose(e.tool, e.pose); break;
    case SessionEventKind::cut: world.cut_now(e.tool); break;
    case SessionEventKind::material: world.set_material(e.material); break;
    case SessionEventKind::pause:
    case SessionEventKind::resume:
    case SessionEventKind::reset: break;
  }
}

}  // namespace octocut::engine
