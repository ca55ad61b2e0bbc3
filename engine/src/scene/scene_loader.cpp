// Scene loading: read, parse (with positions for syntax errors), apply overrides, validate against the schema, then
// convert the completed document into the plain Scene struct with the checks that span several keys.
#include "octocut/engine/scene/scene_loader.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <string_view>
#include <utility>

#include "octocut/engine/io/io.hpp"
#include "scene/scene_schema.hpp"

namespace octocut::engine {
namespace {

using nlohmann::json;
using schema::fail;
using schema::format_number;

/// Returns nlohmann's exception text without its "[json.exception.…] " tag and "parse error at …: " preamble.
std::string exception_detail(const std::string& what) {
  std::string detail = what;
  if (detail.starts_with("[json.exception.")) {
    if (const auto end = detail.find("] "); end != std::string::npos) detail.erase(0, end + 2);
  }
  if (detail.starts_with("parse error")) {
    if (const auto colon = detail.find(": "); colon != std::string::npos) detail.erase(0, colon + 2);
  }
  return detail;
}

/// A SAX handler for a first pass over the text that builds nothing. It records the byte position of the first
/// syntax error (json::parse gives none for numbers that overflow a double) and stops at a duplicate key, which
/// json::parse would silently resolve to the last value.
class JsonChecker final : public nlohmann::json_sax<json> {
 public:
  bool null() override { return value(); }
  bool boolean(bool) override { return value(); }
  bool number_integer(number_integer_t) override { return value(); }
  bool number_unsigned(number_unsigned_t) override { return value(); }
  bool number_float(number_float_t, const string_t&) override { return value(); }
  bool string(string_t&) override { return value(); }
  bool binary(binary_t&) override { return value(); }

  bool start_object(std::size_t) override {
    value();
    m_stack.emplace_back();
    return true;
  }

  bool key(string_t& key) override {
    Frame& frame = m_stack.back();
    frame.key = key;
    if (frame.keys.insert(key).second) return true;
    m_duplicate_pointer = pointer();
    return false;
  }

  bool end_object() override {
    m_stack.pop_back();
    return true;
  }

  bool start_array(std::size_t) override {
    value();
    m_stack.emplace_back().is_array = true;
    return true;
  }

  bool end_array() override {
    m_stack.pop_back();
    return true;
  }

  bool parse_error(std::size_t byte, const std::string& last_token, const nlohmann::json::exception& error) override {
    // A number overflow (406) is reported after its last digit; point at its first instead.
    m_error_byte = byte;
    if (error.id == 406 && byte > last_token.size()) m_error_byte = byte - last_token.size() + 1;
    m_error = error.what();
    return false;
  }

  /// The pointer of the first duplicate key, or "" when there is none.
  const std::string& duplicate_pointer() const { return m_duplicate_pointer; }
  /// The byte count nlohmann had read when it met the first syntax error (1-based position of that byte).
  std::size_t error_byte() const { return m_error_byte; }
  /// nlohmann's message for the first syntax error.
  const std::string& error() const { return m_error; }

 private:
  /// One open object or array.
  struct Frame {
    bool is_array = false;
    std::size_t count = 0;       ///< array elements started so far
    std::string key;             ///< the object's current key
    std::set<std::string> keys;  ///< the object's keys so far
  };

  /// Called at the start of every value: counts the elements of the enclosing array.
  bool value() {
    if (!m_stack.empty() && m_stack.back().is_array) ++m_stack.back().count;
    return true;
  }

  /// The JSON pointer of the current value.
  std::string pointer() const {
    std::string result;
    for (const Frame& frame : m_stack) {
      result = frame.is_array ? schema::join_pointer(result, frame.count - 1) : schema::join_pointer(result, frame.key);
    }
    return result;
  }

  std::vector<Frame> m_stack;
  std::string m_duplicate_pointer;
  std::size_t m_error_byte = 0;
  std::string m_error;
};

/// Parses the scene text strictly (no comments, no duplicate keys). Syntax errors name the file, line and column.
json parse_document(const std::string& text, const std::string& file) {
  // A first pass finds syntax errors with their position, and duplicate keys.
  JsonChecker checker;
  if (!json::sax_parse(text, &checker)) {
    if (!checker.duplicate_pointer().empty()) fail(file, checker.duplicate_pointer(), "duplicate key");

    // nlohmann's byte count includes the offending byte; count lines and columns up to it (both 1-based).
    const std::size_t offset = std::min(checker.error_byte() > 0 ? checker.error_byte() - 1 : 0, text.size());
    const std::string_view before = std::string_view(text).substr(0, offset);
    const std::size_t line = 1 + static_cast<std::size_t>(std::count(before.begin(), before.end(), '\n'));
    const std::size_t line_start = before.rfind('\n') == std::string_view::npos ? 0 : before.rfind('\n') + 1;
    const std::size_t column = offset - line_start + 1;
    throw SceneError(file + ":" + std::to_string(line) + ":" + std::to_string(column) +
                     ": malformed JSON: " + exception_detail(checker.error()));
  }

  // The text is valid, so building the document cannot fail.
  return json::parse(text);
}

/// Parses an override's value: JSON when it is valid JSON, otherwise the text itself as a string. A lone number
/// literal beyond the range of a double stays a number (±inf), so that validation reports it as non-finite; such a
/// literal inside an array or object is reported through `overflow` (nlohmann's message).
json parse_override_value(const std::string& text, std::string& overflow) {
  try {
    return json::parse(text);
  } catch (const json::out_of_range& error) {
    char* end = nullptr;
    const double value = std::strtod(text.c_str(), &end);
    const auto is_space = [](char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; };
    if (end != text.c_str() && std::all_of(static_cast<const char*>(end), text.c_str() + text.size(), is_space)) {
      return value;
    }
    overflow = exception_detail(error.what());
    return nullptr;
  } catch (const json::parse_error&) {
    return text;
  }
}

/// Where an override's pointer stands in the schema: an entry, or (with `item`) an element of an object_array entry.
struct SchemaPosition {
  const schema::Entry* entry = nullptr;  ///< nullptr: outside the schema (an unknown key or an array element)
  bool item = false;
};

/// Moves `position` one pointer token down.
SchemaPosition descend(SchemaPosition position, const std::string& token) {
  if (position.entry == nullptr) return {};
  if (position.entry->type == schema::Type::object_array && !position.item) return {position.entry, true};
  for (const schema::Entry& child : position.entry->children) {
    if (child.key == token) return {&child, false};
  }
  return {};
}

/// Applies one `/json/pointer=value` override to `document`, creating missing keys along the way; a created key
/// that the schema does not know is then reported by validation like any unknown key.
void apply_override(json& document, const std::string& text) {
  const auto bad = [&](const std::string& what) { return SceneError("override \"" + text + "\": " + what); };

  // Split at the first '=' and parse the pointer into its tokens.
  const std::size_t equals = text.find('=');
  if (equals == std::string::npos || !text.starts_with('/')) throw bad("expected /json/pointer=value");
  json::json_pointer pointer;
  try {
    pointer = json::json_pointer(text.substr(0, equals));
  } catch (const json::exception& error) {
    throw bad(exception_detail(error.what()));
  }
  std::vector<std::string> tokens;
  for (json::json_pointer rest = pointer; !rest.empty(); rest.pop_back()) tokens.push_back(rest.back());
  std::reverse(tokens.begin(), tokens.end());

  // Walk down the document. A missing (or null) parent is created from its schema default (`[]` for probes,
  // `[0, 0, -9.81]` for gravity), or as an object; array indices must exist, or be "-" to append.
  json* node = &document;
  SchemaPosition position{&schema::scene_schema(), false};
  std::string walked;
  for (const std::string& token : tokens) {
    if (node->is_null()) {
      const bool has_default = position.entry != nullptr && !position.item && position.entry->default_value;
      *node = has_default ? *position.entry->default_value : json::object();
    }
    if (node->is_object()) {
      node = &(*node)[token];
    } else if (node->is_array()) {
      if (token == "-") {
        node->push_back(nullptr);
        node = &node->back();
      } else {
        const bool digits =
            !token.empty() && std::all_of(token.begin(), token.end(), [](char c) { return c >= '0' && c <= '9'; });
        if (!digits || token.size() > 9 || std::stoul(token) >= node->size()) {
          throw bad(walked + " has no element " + token);
        }
        node = &(*node)[std::stoul(token)];
      }
    } else {
      throw bad(walked + " is a " + node->type_name() + ", not an object or array");
    }
    position = descend(position, token);
    walked = schema::join_pointer(walked, token);
  }

  // Parse the value last, so that a bad pointer is reported first.
  std::string overflow;
  json value = parse_override_value(text.substr(equals + 1), overflow);
  if (!overflow.empty()) throw bad(overflow);
  *node = std::move(value);
}

std::array<double, 3> to_vec3(const json& value) {
  return {value[0].get<double>(), value[1].get<double>(), value[2].get<double>()};
}

/// Reads a validated box at `pointer` and checks that max exceeds min in every component.
SceneBox to_box(const json& value, const std::string& pointer, const std::string& file) {
  SceneBox box{to_vec3(value.at("min")), to_vec3(value.at("max"))};
  for (int i = 0; i < 3; ++i) {
    if (!(box.max[i] > box.min[i])) {
      const std::string component = "[" + std::to_string(i) + "]";
      fail(file, pointer + "/max",
           "must be > min in every component, got max" + component + " = " + format_number(box.max[i]) + " <= min" +
               component + " = " + format_number(box.min[i]));
    }
  }
  return box;
}

/// Resolves the mesh path `value` against the scene file's directory and checks that the file exists.
std::string resolve_mesh(const json& value, const std::string& pointer, const std::string& file) {
  const std::filesystem::path resolved =
      std::filesystem::absolute(std::filesystem::path(file).parent_path() / value.get<std::string>()).lexically_normal();
  if (!std::filesystem::is_regular_file(resolved)) fail(file, pointer, "file not found: " + resolved.string());
  return resolved.string();
}

/// Checks that keyframe time `t` at `pointer` (of keyframe k > 0) follows the previous keyframe's `previous`.
void check_increasing(double t, double previous, const std::string& pointer, const std::string& file) {
  if (!(t > previous))
    fail(file, pointer, "must be > the previous keyframe's t (" + format_number(previous) + "), got " + format_number(t));
}

/// Reads the pose keyframes (`t`, `position`, `rotation_deg`) at `pointer`, checking that their times increase.
std::vector<PoseKey> to_pose_keys(const json& keyframes, const std::string& pointer, const std::string& file) {
  std::vector<PoseKey> out;
  for (std::size_t k = 0; k < keyframes.size(); ++k) {
    const json& keyframe = keyframes[k];
    PoseKey frame{keyframe["t"].get<double>(), to_vec3(keyframe["position"]), to_vec3(keyframe["rotation_deg"])};
    if (k > 0) check_increasing(frame.t, out.back().t, pointer + "/" + std::to_string(k) + "/t", file);
    out.push_back(frame);
  }
  return out;
}

/// Reads `tools[]`: names unique and not empty, mesh files present, keyframe and cut times strictly increasing (a
/// cut after the duration is allowed; the run reports that it never happened).
std::vector<ToolSettings> to_tools(const json& tools, const std::string& file) {
  std::vector<ToolSettings> out;
  std::set<std::string> names;
  for (std::size_t i = 0; i < tools.size(); ++i) {
    const json& tool = tools[i];
    const std::string pointer = "/tools/" + std::to_string(i);
    ToolSettings entry;

    // Name, meshes, flags.
    entry.name = tool["name"].get<std::string>();
    if (entry.name.empty()) fail(file, pointer + "/name", "must not be empty");
    if (!names.insert(entry.name).second) fail(file, pointer + "/name", "duplicate tool name \"" + entry.name + "\"");
    if (tool.contains("mesh")) entry.mesh_path = resolve_mesh(tool["mesh"], pointer + "/mesh", file);
    entry.scale = tool["scale"].get<double>();
    const json& blade = tool["blade"];
    entry.blade_is_cylinder = blade.is_object();
    if (entry.blade_is_cylinder) {
      const json& cylinder = blade["cylinder"];
      entry.cylinder.radius = cylinder["radius"].get<double>();
      entry.cylinder.height = cylinder["height"].get<double>();
      entry.cylinder.segments = cylinder["segments"].get<int>();
    } else {
      entry.blade_path = resolve_mesh(blade, pointer + "/blade", file);
    }
    entry.collide = tool["collide"].get<bool>();

    // Keyframes: strictly increasing times (the schema asks for at least one).
    entry.keyframes = to_pose_keys(tool["keyframes"], pointer + "/keyframes", file);

    // Cuts: strictly increasing times.
    for (std::size_t k = 0; k < tool["cuts"].size(); ++k) {
      const ToolCut cut{tool["cuts"][k]["t"].get<double>()};
      const std::string t_pointer = pointer + "/cuts/" + std::to_string(k) + "/t";
      if (k > 0 && !(cut.t > entry.cuts.back().t)) {
        fail(file, t_pointer,
             "must be > the previous cut's t (" + format_number(entry.cuts.back().t) + "), got " + format_number(cut.t));
      }
      // A cut after the end of the run is allowed (a run shortened with --set /duration): the report says it never
      // happened.
      entry.cuts.push_back(cut);
    }
    out.push_back(std::move(entry));
  }
  return out;
}

/// Reads `rigid_bodies`: names unique (also against tools), one shape, mass > 0 for dynamic bodies, keyframes only
/// on kinematic ones (and at least one there), mesh files present.
std::vector<RigidBodySettings> to_rigid_bodies(const json& bodies, const std::vector<ToolSettings>& tools,
                                               double default_friction, const std::string& file) {
  std::vector<RigidBodySettings> out;
  std::set<std::string> names;
  for (const ToolSettings& t : tools) names.insert(t.name);
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const json& body = bodies[i];
    const std::string pointer = "/rigid_bodies/" + std::to_string(i);
    RigidBodySettings b;
    b.name = body["name"].get<std::string>();
    if (b.name.empty()) fail(file, pointer + "/name", "must not be empty");
    if (!names.insert(b.name).second)
      fail(file, pointer + "/name", "duplicate name \"" + b.name + "\" (bodies and tools share one namespace)");
    const json& shape = body["shape"];
    int kinds = 0;
    for (const char* kind : {"sphere", "box", "cylinder", "mesh"}) {
      if (!shape.contains(kind)) continue;
      ++kinds;
      b.shape.kind = kind;
    }
    if (kinds != 1)
      fail(file, pointer + "/shape", "must have exactly one of sphere, box, cylinder or mesh, got " +
                                         std::to_string(kinds));
    if (b.shape.kind == "sphere") b.shape.radius = shape["sphere"]["radius"].get<double>();
    if (b.shape.kind == "box") b.shape.size = to_vec3(shape["box"]["size"]);
    if (b.shape.kind == "cylinder") {
      b.shape.radius = shape["cylinder"]["radius"].get<double>();
      b.shape.height = shape["cylinder"]["height"].get<double>();
    }
    if (b.shape.kind == "mesh") b.shape.mesh_path = resolve_mesh(shape["mesh"], pointer + "/shape/mesh", file);
    b.shape.scale = shape["scale"].get<double>();
    b.motion = body["motion"].get<std::string>();
    if (body.contains("mass")) b.mass = body["mass"].get<double>();
    if (b.motion == "dynamic" && !(b.mass > 0.0))
      fail(file, pointer + (body.contains("mass") ? "/mass" : ""),
           "a dynamic body needs a mass > 0, got " + (body.contains("mass") ? format_number(b.mass) : "none"));
    b.position = to_vec3(body["position"]);
    b.rotation_deg = to_vec3(body["rotation_deg"]);
    b.keyframes = to_pose_keys(body["keyframes"], pointer + "/keyframes", file);
    if (b.motion != "kinematic" && !b.keyframes.empty())
      fail(file, pointer + "/keyframes", "only a kinematic body follows keyframes; this one is " + b.motion);
    if (b.motion == "kinematic" && b.keyframes.empty())
      fail(file, pointer + "/keyframes", "a kinematic body needs at least one keyframe");
    b.friction = body.contains("friction") ? body["friction"].get<double>() : default_friction;
    b.render = body["render"].get<std::string>();
    out.push_back(std::move(b));
  }
  return out;
}

/// Reads `contact`.
ContactSettings to_contact(const json& contact) {
  ContactSettings c;
  c.has_stiffness = contact.contains("stiffness");
  if (c.has_stiffness) c.stiffness = contact["stiffness"].get<double>();
  c.friction = contact["friction"].get<double>();
  c.damping = contact["damping"].get<double>();
  return c;
}

/// Reads `solver`.
SolverSettings to_solver(const json& solver) {
  SolverSettings s;
  s.mode = solver["mode"].get<std::string>();
  s.dt = solver["dt"].get<double>();
  s.gravity = to_vec3(solver["gravity"]);
  s.linear_solver = solver["linear_solver"].get<std::string>();
  s.tolerance = solver["tolerance"].get<double>();
  s.max_iterations = solver["max_iterations"].get<int>();
  s.factor_lag = solver["factor_lag"].get<int>();
  s.threads = solver["threads"].get<int>();
  s.max_speed = solver["max_speed"].get<double>();
  s.energy_guard = solver["energy_guard"].get<double>();
  return s;
}

/// Reads `object/octree`: levels must nest (base <= max, refinement regions <= max).
OctreeSettings to_octree(const json& octree, const std::string& file) {
  OctreeSettings tree;
  tree.has_root = octree.contains("root");
  if (tree.has_root) {
    tree.root_min = to_vec3(octree["root"]["min"]);
    tree.root_size = octree["root"]["size"].get<double>();
  }
  tree.base_level = octree["base_level"].get<int>();
  tree.max_level = octree["max_level"].get<int>();
  tree.uniform = octree["uniform"].get<bool>();
  if (tree.max_level < tree.base_level) {
    fail(file, "/object/octree/max_level",
         "must be >= base_level (" + std::to_string(tree.base_level) + "), got " + std::to_string(tree.max_level));
  }
  for (std::size_t i = 0; i < octree["refine"].size(); ++i) {
    const json& region = octree["refine"][i];
    const std::string pointer = "/object/octree/refine/" + std::to_string(i);
    RefineRegion refine{to_box(region["box"], pointer + "/box", file), region["level"].get<int>()};
    if (refine.level > tree.max_level) {
      fail(file, pointer + "/level",
           "must be <= max_level (" + std::to_string(tree.max_level) + "), got " + std::to_string(refine.level));
    }
    tree.refine.push_back(refine);
  }
  return tree;
}

/// Reads `object/handles`: keyframe times strictly increasing.
std::vector<Handle> to_handles(const json& handles, const std::string& file) {
  std::vector<Handle> out;
  for (std::size_t i = 0; i < handles.size(); ++i) {
    const json& handle_json = handles[i];
    const std::string pointer = "/object/handles/" + std::to_string(i);
    Handle handle;
    handle.box = to_box(handle_json["box"], pointer + "/box", file);
    for (std::size_t k = 0; k < handle_json["keyframes"].size(); ++k) {
      const json& keyframe = handle_json["keyframes"][k];
      HandleKeyframe frame{keyframe["t"].get<double>(), to_vec3(keyframe["translation"]),
                           to_vec3(keyframe["rotation_deg"])};
      if (k > 0)
        check_increasing(frame.t, handle.keyframes.back().t, pointer + "/keyframes/" + std::to_string(k) + "/t", file);
      handle.keyframes.push_back(frame);
    }
    out.push_back(std::move(handle));
  }
  return out;
}

/// Reads `object`: the surface (a box, or a mesh path resolved against the scene file's directory), the material,
/// the octree, the material graph and the handles.
ObjectSettings to_object(const json& object, const std::string& file) {
  ObjectSettings settings;
  const json& surface = object["surface"];
  settings.surface_is_box = surface.is_object();
  if (settings.surface_is_box) {
    settings.surface_box = to_box(surface["box"], "/object/surface/box", file);
  } else {
    settings.surface_path = resolve_mesh(surface, "/object/surface", file);
  }
  settings.scale = object["scale"].get<double>();
  const json& material = object["material"];
  settings.material.young_modulus = material["young_modulus"].get<double>();
  settings.material.poisson_ratio = material["poisson_ratio"].get<double>();
  settings.material.density = material["density"].get<double>();
  settings.material.rayleigh_mass = material["rayleigh_mass"].get<double>();
  settings.material.rayleigh_stiffness = material["rayleigh_stiffness"].get<double>();
  settings.material.element = material["element"].get<std::string>();
  settings.octree = to_octree(object["octree"], file);
  settings.material_graph_cell_size = object["material_graph"]["cell_size"].get<double>();
  settings.handles = to_handles(object["handles"], file);
  return settings;
}

/// Reads `probes`: names unique and not empty.
std::vector<Probe> to_probes(const json& probes, const std::string& file) {
  std::vector<Probe> out;
  std::set<std::string> names;
  for (std::size_t i = 0; i < probes.size(); ++i) {
    const json& probe = probes[i];
    const std::string pointer = "/probes/" + std::to_string(i) + "/name";
    Probe entry{probe["name"].get<std::string>(), to_vec3(probe["point"])};
    if (entry.name.empty()) fail(file, pointer, "must not be empty");
    if (!names.insert(entry.name).second) fail(file, pointer, "duplicate probe name \"" + entry.name + "\"");
    out.push_back(std::move(entry));
  }
  return out;
}

/// Reads `render/camera`: it must have a view direction and an up that is not along it.
CameraSettings to_camera(const json& camera, const std::string& file) {
  CameraSettings c;
  c.has_position = camera.contains("position");
  if (c.has_position) c.position = to_vec3(camera["position"]);
  c.has_target = camera.contains("target");
  if (c.has_target) c.target = to_vec3(camera["target"]);
  c.up = to_vec3(camera["up"]);
  c.fov_deg = camera["fov_deg"].get<double>();
  c.arthroscope = camera["arthroscope"].get<bool>();
  c.mask = camera["mask"].get<bool>();
  c.follow_tool = camera["follow_tool"].get<std::string>();
  if (c.has_position && c.has_target && c.position == c.target)
    fail(file, "/render/camera/target", "must differ from /render/camera/position");
  const auto& u = c.up;
  if (u[0] == 0.0 && u[1] == 0.0 && u[2] == 0.0) fail(file, "/render/camera/up", "must not be zero");
  if (c.has_position && c.has_target) {
    const std::array<double, 3> f{c.target[0] - c.position[0], c.target[1] - c.position[1],
                                  c.target[2] - c.position[2]};
    const std::array<double, 3> x{f[1] * u[2] - f[2] * u[1], f[2] * u[0] - f[0] * u[2], f[0] * u[1] - f[1] * u[0]};
    const double fn = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    const double un = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    if (std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) <= 1e-9 * fn * un)
      fail(file, "/render/camera/up", "must not be parallel to the view direction (target - position)");
  }
  return c;
}

/// Reads `render/props`: names unique, mesh files present, keyframe times strictly increasing.
std::vector<RenderProp> to_props(const json& props, const std::string& file) {
  std::vector<RenderProp> out;
  std::set<std::string> names;
  for (std::size_t i = 0; i < props.size(); ++i) {
    const json& prop = props[i];
    const std::string pointer = "/render/props/" + std::to_string(i);
    RenderProp entry;
    entry.name = prop["name"].get<std::string>();
    if (entry.name.empty()) fail(file, pointer + "/name", "must not be empty");
    if (!names.insert(entry.name).second) fail(file, pointer + "/name", "duplicate prop name \"" + entry.name + "\"");
    entry.mesh_path = resolve_mesh(prop["mesh"], pointer + "/mesh", file);
    entry.scale = prop["scale"].get<double>();
    entry.material = prop["material"].get<std::string>();
    entry.collide = prop["collide"].get<bool>();
    entry.keyframes = to_pose_keys(prop["keyframes"], pointer + "/keyframes", file);
    out.push_back(std::move(entry));
  }
  return out;
}

/// Reads `render`; the camera follows a tool of `tools` or, failing that, a prop.
RenderSettings to_render(const json& render, const std::vector<ToolSettings>& tools, const std::string& file) {
  RenderSettings r;
  r.enabled = render["enabled"].get<bool>();
  r.width = render["width"].get<int>();
  r.height = render["height"].get<int>();
  r.every = render["every"].get<int>();
  r.msaa = render["msaa"].get<int>();
  r.crease_angle_deg = render["crease_angle_deg"].get<double>();
  r.camera = to_camera(render["camera"], file);
  r.props = to_props(render["props"], file);
  const std::string& follow = r.camera.follow_tool;
  if (!follow.empty() &&
      std::none_of(r.props.begin(), r.props.end(), [&](const RenderProp& p) { return p.name == follow; }) &&
      std::none_of(tools.begin(), tools.end(), [&](const ToolSettings& tool) { return tool.name == follow; })) {
    fail(file, "/render/camera/follow_tool", "no tool or prop named \"" + follow + "\"");
  }
  r.overlays.octree = render["overlays"]["octree"].get<bool>();
  r.overlays.dofs = render["overlays"]["dofs"].get<bool>();
  r.overlays.hanging = render["overlays"]["hanging"].get<bool>();
  r.overlays.contacts = render["overlays"]["contacts"].get<bool>();
  r.overlays.contact_force_scale = render["overlays"]["contact_force_scale"].get<double>();
  return r;
}

/// True when nothing in the scene moves with time: no tool (tools are keyframed and cut on a timeline) and no handle
/// with keyframes. Render props are scenery and do not count.
bool time_independent(const Scene& scene) {
  return scene.tools.empty() && std::none_of(scene.object.handles.begin(), scene.object.handles.end(),
                                             [](const Handle& h) { return !h.keyframes.empty(); });
}

/// Converts a validated document with defaults filled in to a Scene, checking the rules that span several keys.
/// `duration_given`: the scene (or an override) set `duration`; when it did not, a static scene in which nothing
/// moves with time solves once (duration = dt, one step) instead of repeating the same solve up to the default 1 s.
Scene to_scene(const json& document, const std::string& file, bool duration_given) {
  Scene scene;
  scene.file = file;
  // Top level; the name defaults to the file stem.
  scene.name =
      document.contains("name") ? document["name"].get<std::string>() : std::filesystem::path(file).stem().string();
  scene.duration = document["duration"].get<double>();
  scene.seed = document["seed"].get<std::uint64_t>();
  scene.solver = to_solver(document["solver"]);
  scene.object = to_object(document["object"], file);
  scene.tools = to_tools(document["tools"], file);
  scene.contact = to_contact(document["contact"]);
  for (std::size_t i = 0; i < scene.tools.size(); ++i) {
    const json& tool = document["tools"][i];
    scene.tools[i].friction = tool.contains("friction") ? tool["friction"].get<double>() : scene.contact.friction;
  }
  scene.rigid_bodies = to_rigid_bodies(document["rigid_bodies"], scene.tools, scene.contact.friction, file);
  const json& cutting = document["cutting"];
  scene.cutting.remove_fragments = cutting["remove_fragments"].get<std::string>();
  scene.cutting.fragment_volume = cutting["fragment_volume"].get<double>();
  scene.cutting.verify = cutting["verify"].get<bool>();
  scene.cutting.min_feature = cutting["min_feature"].get<double>();
  if (!duration_given && scene.solver.mode == "static" && time_independent(scene)) scene.duration = scene.solver.dt;
  scene.probes = to_probes(document["probes"], file);
  scene.render = to_render(document["render"], scene.tools, file);
  scene.output.frames = document["output"]["frames"].get<bool>();
  scene.output.surface_final = document["output"]["surface_final"].get<bool>();
  scene.output.surface_every = document["output"]["surface_every"].get<int>();
  scene.output.ply_float = document["output"]["ply_precision"].get<std::string>() == "float";
  scene.output.contact_forces = document["output"]["contact_forces"].get<bool>();
  scene.output.step_times = document["output"]["step_times"].get<bool>();
  scene.output.stability_track = document["output"]["stability_track"].get<bool>();
  // The expected block stays JSON text (validated by the schema); see expected.hpp.
  if (document.contains("expected")) scene.expected_json = document["expected"].dump();
  return scene;
}

}  // namespace

Scene load_scene(const std::string& path, const std::vector<std::string>& overrides) {
  // Read; the I/O error already has the form "<file>: cannot read: <reason>".
  std::string text;
  try {
    text = read_file(path);
  } catch (const std::runtime_error& error) {
    throw SceneError(error.what());
  }

  // Parse, override, validate (filling defaults), convert.
  json document = parse_document(text, path);
  if (!document.is_object()) fail(path, "", std::string("expected a JSON object, got ") + document.type_name());
  for (const std::string& override_text : overrides) apply_override(document, override_text);
  const bool duration_given = document.contains("duration");
  schema::validate(document, schema::scene_schema(), "", path);
  return to_scene(document, path, duration_given);
}

}  // namespace octocut::engine
