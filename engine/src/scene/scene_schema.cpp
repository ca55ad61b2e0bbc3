// The scene schema (SPEC §5): every key of the scene format with its type, range, default and documentation, the
// validator that enforces it, and the Markdown generator for docs/scene-format.md.
#include "scene/scene_schema.hpp"

#include <array>
#include <charconv>
#include <climits>
#include <cmath>
#include <sstream>
#include <utility>

#include "scene/expected_shape.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace schema {

using nlohmann::json;

// ---- ranges ---------------------------------------------------------------------------------------------------------

Range make_range(std::optional<double> min, bool min_exclusive, std::optional<double> max, bool max_exclusive) {
  Range range;
  range.min = min;
  range.min_exclusive = min_exclusive;
  range.max = max;
  range.max_exclusive = max_exclusive;
  return range;
}

Range greater_than(double min) { return make_range(min, true, std::nullopt, false); }
Range at_least(double min) { return make_range(min, false, std::nullopt, false); }
Range closed(double min, double max) { return make_range(min, false, max, false); }
Range open_closed(double min, double max) { return make_range(min, true, max, false); }
Range open(double min, double max) { return make_range(min, true, max, true); }
Range closed_open(double min, double max) { return make_range(min, false, max, true); }

// ---- entry builders: one per type, defaults given in the scene's units ----------------------------------------------

Entry make_entry(std::string key, Type type, std::string doc) {
  Entry entry;
  entry.key = std::move(key);
  entry.type = type;
  entry.doc = std::move(doc);
  return entry;
}

Entry number(std::string key, std::optional<double> default_value, Range range, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::number, std::move(doc));
  if (default_value) entry.default_value = *default_value;
  entry.range = range;
  return entry;
}

Entry integer(std::string key, std::optional<long long> default_value, Range range, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::integer, std::move(doc));
  if (default_value) entry.default_value = *default_value;
  entry.range = range;
  return entry;
}

Entry boolean(std::string key, bool default_value, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::boolean, std::move(doc));
  entry.default_value = default_value;
  return entry;
}

Entry string(std::string key, std::string doc) { return make_entry(std::move(key), Type::string, std::move(doc)); }

Entry choice(std::string key, std::vector<std::string> choices, std::string default_value, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::enumeration, std::move(doc));
  entry.default_value = std::move(default_value);
  entry.choices = std::move(choices);
  return entry;
}

Entry vec3(std::string key, std::optional<std::array<double, 3>> default_value, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::number_array, std::move(doc));
  if (default_value) entry.default_value = *default_value;
  entry.length = 3;
  return entry;
}

/// An object that defaults to `{}`, so that its own children's defaults get filled in.
Entry object(std::string key, std::vector<Entry> children, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::object, std::move(doc));
  entry.default_value = json::object();
  entry.children = std::move(children);
  return entry;
}

/// An array of objects that defaults to `[]`; `item` lists the keys of each element.
Entry object_array(std::string key, std::vector<Entry> item, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::object_array, std::move(doc));
  entry.default_value = json::array();
  entry.children = std::move(item);
  return entry;
}

/// A mesh path or an object with the keys `children`.
Entry box_or_path(std::string key, std::vector<Entry> children, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::box_or_path, std::move(doc));
  entry.children = std::move(children);
  return entry;
}

Entry required(Entry entry) {
  entry.required = true;
  entry.default_value.reset();
  return entry;
}

/// An optional key with no default: when absent it stays absent.
Entry optional(Entry entry) {
  entry.default_value.reset();
  return entry;
}

/// The entry with its numbers (each element of a number array) in `range`.
Entry ranged(Entry entry, Range range) {
  entry.range = range;
  return entry;
}

/// An object of numbers in `range` whose keys are among `keys`, with at least `min_items` of them.
Entry number_map(std::string key, std::vector<std::string> keys, Range range, std::size_t min_items, std::string doc) {
  Entry entry = make_entry(std::move(key), Type::number_map, std::move(doc));
  entry.choices = std::move(keys);
  entry.range = range;
  entry.min_items = min_items;
  return entry;
}

namespace {

/// A required axis-aligned box `{"min": [3], "max": [3]}` in metres; the loader checks max > min.
Entry box(std::string key, std::string doc) {
  return required(
      object(std::move(key),
             {required(vec3("min", std::nullopt, "Lower corner, m.")),
              required(vec3("max", std::nullopt, "Upper corner, m; greater than `min` in every component."))},
             std::move(doc)));
}

constexpr double max_int = INT_MAX;

// ---- the scene format -----------------------------------------------------------------------------------------------

// Rigid bodies (issue 16): Bullet integrates the dynamic ones; all of them collide with the tissue.
Entry make_rigid_bodies() {
  Entry mesh = string("mesh", "A closed triangle mesh file free of self-intersections (path relative to the scene "
                              "file), in the body frame, times `scale`. A dynamic body collides with other rigid "
                              "bodies by the mesh's convex hull.");
  Entry shape = required(object(
      "shape",
      {optional(object("sphere", {required(number("radius", std::nullopt, greater_than(0), "Radius, m."))},
                       "A sphere centred on the body frame.")),
       optional(object("box",
                       {required(make_entry("size", Type::number_array, "Edge lengths along the body's x, y, z, m."))},
                       "A box centred on the body frame.")),
       optional(object("cylinder",
                       {required(number("radius", std::nullopt, greater_than(0), "Radius, m.")),
                        required(number("height", std::nullopt, greater_than(0), "Length along the body's z axis, m."))},
                       "A cylinder along the body's z axis, centred on the body frame.")),
       optional(std::move(mesh)),
       number("scale", 1.0, greater_than(0), "Factor from `mesh` coordinates to metres.")},
      "Exactly one of `sphere`, `box`, `cylinder` or `mesh`."));
  shape.children[1].children[0].length = 3;
  shape.children[1].children[0].range = greater_than(0);
  shape.default_value.reset();
  Entry mass = optional(number("mass", std::nullopt, make_range(std::nullopt, false, 1e6, false),
                               "Mass, kg; required and > 0 for a dynamic body, ignored otherwise."));
  mass.default_doc = "none";
  Entry friction = optional(number("friction", std::nullopt, closed(0, 10),
                                   "Coulomb friction coefficient between this body and the tissue, dimensionless."));
  friction.default_doc = "`contact.friction`";
  return object_array(
      "rigid_bodies",
      {required(string("name", "Body name, unique among bodies and tools, not empty.")),
       std::move(shape),
       choice("motion", {"dynamic", "fixed", "kinematic"}, "fixed",
              "`dynamic`: Bullet integrates it under gravity, contact with the tissue and with other bodies; "
              "`fixed`: it stays at `position`; `kinematic`: it follows `keyframes`, as tools do."),
       std::move(mass),
       vec3("position", std::array{0.0, 0.0, 0.0}, "Where the body frame's origin is at t = 0, world, m."),
       vec3("rotation_deg", std::array{0.0, 0.0, 0.0},
            "XYZ Euler angles of the body frame at t = 0 (fixed axes, as tools), degrees."),
       object_array("keyframes",
                    {required(number("t", std::nullopt, at_least(0), "Time, s; strictly increasing along the list.")),
                     vec3("position", std::array{0.0, 0.0, 0.0}, "Where the body frame's origin is, world, m."),
                     vec3("rotation_deg", std::array{0.0, 0.0, 0.0}, "XYZ Euler angles of the body frame, degrees.")},
                    "Pose over time of a kinematic body (only allowed with `motion` = `kinematic`, at least one): "
                    "position linear, rotation spherical-linear, held before the first and after the last."),
       std::move(friction),
       choice("render", {"metal", "bone", "glass", "none"}, "metal",
              "How the body is drawn (its shape, at its pose); `glass`: clear, what lies behind shows through, with "
              "highlights and a rim that grows opaque at grazing angles; `none`: not drawn.")},
      "Rigid bodies (Bullet) that collide with the tissue.");
}

// Contact between the tissue and rigid shapes (issue 16).
Entry make_contact() {
  Entry stiffness = optional(number("stiffness", std::nullopt, greater_than(0),
                                    "Penalty stiffness, Pa/m: pressure per metre of penetration. The default is 10 E / "
                                    "h_min, E the object's Young's modulus and h_min the edge of its finest leaf at the "
                                    "start: a layer one finest leaf thick shortens by p h_min / E under a pressure p, "
                                    "and the penalty lets the surface sink a tenth of that into the shape."));
  stiffness.default_doc = "10 E / h_min";
  return object("contact",
                {std::move(stiffness),
                 number("friction", 0.3, closed(0, 10),
                        "Coulomb friction coefficient of tools and bodies that set none, dimensionless (static = "
                        "sliding; a contact slower than 0.1 mm/s counts as sticking, see docs/architecture.md)."),
                 number("damping", 1e-3, closed(0, 1),
                        "Contact damping time, s: each collision sample's normal damping coefficient is `damping` "
                        "times its penalty stiffness.")},
                "Contact of the tissue with tools that collide, colliding props and rigid bodies.");
}

// function-length: data table (every key of the scene format)
Entry make_scene_schema() {
  Entry name = string("name", "Scene name, used in the report.");
  name.default_doc = "file stem";
  Entry duration = number("duration", 1.0, greater_than(0),
                          "Simulated time span, s. A static scene (`solver.mode` `static`) in which nothing moves "
                          "with time (no tools, no handle with keyframes; render props do not count) solves once "
                          "when `duration` is not given: its duration is then `solver.dt`, one step.");
  duration.default_doc = "`1`; `solver.dt` for a static scene without tools or handle keyframes";

  Entry surface = required(box_or_path(
      "surface", {box("box", "Box-shaped object, m.")},
      "Rest surface: a closed triangle mesh file (path relative to the scene file), or `{\"box\": …}` for an "
      "axis-aligned box."));

  Entry solver = object(
      "solver",
      {
          choice("mode", {"dynamic", "static"}, "dynamic",
                 "`dynamic` integrates the equations of motion in time; `static` solves for equilibrium at each step (load steps of `dt` up to `duration`; once when nothing moves with time and `duration` is not given)."),
          number("dt", 1e-3, open_closed(0, 1), "Time step, s."),
          ranged(vec3("gravity", std::array{0.0, 0.0, -9.81}, "Gravitational acceleration, m/s^2 (each component)."),
                 closed(-1e4, 1e4)),
          choice("linear_solver", {"cholmod", "pcg"}, "pcg",
                 "Linear solver: `cholmod` (supernodal Cholesky, factorised every step) or `pcg` (warm-started "
                 "conjugate gradients preconditioned by a lagged Cholesky factor that is refreshed when convergence "
                 "slows)."),
          number("tolerance", 1e-6, open(0, 1),
                 "Relative residual at which iterative solves stop (dimensionless): a dynamic step's pcg stops once "
                 "the residual is below it times the larger of the right-hand side and the elastic forces the step "
                 "balances."),
          integer("max_iterations", 200, closed(1, 100000),
                  "Iteration limit per linear solve (pcg) or per static solve (Newton)."),
          integer("factor_lag", 0, closed(0, 64),
                  "`pcg`: when its lagged Cholesky factor is due for a refresh, factorise on a second thread and put "
                  "the new factor in place this many solves later (sooner once the iterations since have cost as "
                  "much as a factorisation), so that no step stalls on the factorisation; after a cut, precondition "
                  "the first solves with the old factor (through the transfer of the DOFs) and an exact solve on "
                  "the cut's region while the new pattern's first factor is computed the same way. Deterministic, "
                  "whatever the timing. 0 factorises inline, in the step that needs it."),
          integer("threads", 0, closed(0, 256), "Worker threads; 0 uses the hardware concurrency."),
          number("max_speed", 100.0, greater_than(0),
                 "Speed guard, m/s: a step that moves any DOF faster is rolled back."),
          number("energy_guard", 1e-3, closed(0, 1),
                 "Energy guard, relative: a step in which no handle moves and whose kinetic + elastic energy rises by "
                 "more than the work of gravity and the rigid shapes (less what the contact penalty springs take up), "
                 "plus this fraction of the largest of those energies, is rolled back and retried as two halves (not "
                 "at the smallest step). A step it accepts that still gains energy (beyond 1e-7 of that scale and of "
                 "the largest energy since the start: below is noise) gives "
                 "the gain back: out of the kinetic energy, the step shortened first where that is not enough "
                 "(report `stability.energy_projections`). 0 turns both off."),
      },
      "Time integration and linear solver.");

  Entry material =
      object("material",
             {
                 number("young_modulus", 1e5, closed(1, 1e12),
                        "Young's modulus E, Pa (from the softest gels, about 10 Pa, to steel and beyond)."),
                 number("poisson_ratio", 0.3, closed_open(0, 0.5), "Poisson's ratio nu (dimensionless)."),
                 number("density", 1000.0, closed(1, 1e5), "Mass density rho, kg/m^3 (soft tissue about 1000)."),
                 number("rayleigh_mass", 0.0, closed(0, 1e6), "Mass-proportional Rayleigh damping alpha, 1/s."),
                 number("rayleigh_stiffness", 0.0, closed(0, 10), "Stiffness-proportional Rayleigh damping beta, s."),
                 choice("element", {"trilinear", "bbar"}, "bbar",
                        "Hexahedron formulation: `bbar` (B-bar, mean dilatation per element: does not lock "
                        "volumetrically as nu approaches 0.5; the default, chosen by the stability and accuracy "
                        "studies in docs/studies/) or `trilinear` (fully integrated: stiff in bending as nu "
                        "approaches 0.5, volumetric locking; 3-4 % stiffer in bending than B-bar even at nu = 0.3 on "
                        "coarse meshes)."),
             },
             "Elastic material of the object.");

  Entry octree = object(
      "octree",
      {
          optional(object("root",
                          {required(vec3("min", std::nullopt, "Lower corner of the root cube, m.")),
                           required(number("size", std::nullopt, greater_than(0), "Edge length of the root cube, m."))},
                          "Root cube of the octree; when absent it is derived from the object's bounds.")),
          integer("base_level", 3, closed(0, 20), "Level to which the object is refined uniformly at the start."),
          integer("max_level", 8, closed(0, 20), "Deepest level any refinement may reach; at least `base_level`."),
          boolean("uniform", false, "Build the whole object at `max_level`, with no adaptivity (uniform-grid comparisons)."),
          object_array("refine",
                       {box("box", "Every leaf overlapping this box is refined, m."),
                        required(integer("level", std::nullopt, closed(0, 20),
                                         "Minimum level of the leaves overlapping the box; at most `max_level`."))},
                       "Static refinement regions."),
      },
      "Simulation octree T: its leaves are the hexahedral elements.");

  Entry keyframes = object_array(
      "keyframes",
      {
          required(number("t", std::nullopt, at_least(0), "Time, s; strictly increasing along the list.")),
          vec3("translation", std::array{0.0, 0.0, 0.0}, "Translation of the box, m."),
          vec3("rotation_deg", std::array{0.0, 0.0, 0.0}, "XYZ Euler angles about the box centre, degrees."),
      },
      "Rigid motion: translation linear and rotation slerp between keyframes (as tools and props), from the rest "
      "pose at t = 0, held after the last keyframe; none: the handle is fixed.");

  Entry object_entry = required(object(
      "object",
      {
          surface,
          number("scale", 1.0, greater_than(0), "Factor from mesh coordinates to metres (0.001 for meshes in mm)."),
          material,
          octree,
          object("material_graph", {number("cell_size", 0.001, greater_than(0), "Target tetrahedron size, m.")},
                 "Material graph M: the tetrahedral mesh of the object in rest space."),
          object_array("handles",
                       {box("box", "Rest-space region whose DOFs the handle drives, m."), std::move(keyframes)},
                       "Boxes whose DOFs follow a keyframed rigid motion (boundary conditions)."),
      },
      "The deformable object."));

  // Tools: keyframed instruments with a blade and cut times (SPEC §4, §5).
  Entry tool_keyframes = required(object_array(
      "keyframes",
      {required(number("t", std::nullopt, at_least(0), "Time, s; strictly increasing along the list.")),
       vec3("position", std::array{0.0, 0.0, 0.0}, "Where the tool's origin is, world, m."),
       vec3("rotation_deg", std::array{0.0, 0.0, 0.0},
            "XYZ Euler angles of the tool frame (about fixed x, then y, then z, as render props), degrees.")},
      "Pose over time, tool frame to world (x_world = R x_tool + position): position linear, rotation "
      "spherical-linear between keyframes, held before the first and after the last."));
  tool_keyframes.min_items = 1;
  Entry tool_mesh = optional(string("mesh", "Render and contact mesh, drawn as metal: a closed triangle mesh file "
                                            "(path relative to the scene file) in tool coordinates, times `scale`."));
  tool_mesh.default_doc = "none";
  Entry blade = required(box_or_path(
      "blade",
      {required(object(
          "cylinder",
          {required(number("radius", std::nullopt, greater_than(0), "Radius, m.")),
           required(number("height", std::nullopt, greater_than(0),
                           "Length along the tool's z axis, m; the cylinder spans z from -height/2 to height/2.")),
           integer("segments", 32, closed(3, 1024), "Sides of the polygon that approximates the cross-section.")},
          "A closed cylinder about the tool's z axis, centred on the tool origin, in metres (not scaled by "
          "`scale`)."))},
      "The volume a cut removes, in tool coordinates: a closed, oriented triangle mesh file free of "
      "self-intersections (path relative to the scene file, times `scale`), or `{\"cylinder\": …}`. A cut's walls "
      "are pieces of the blade's triangles, so long thin ones make thin wall triangles (the cylinder's sides are two "
      "triangles per segment), and every triangle costs the exact boolean time (about 3 µs each on the 50k "
      "meniscus); see docs/RESULTS.md, \"Blades with many triangles per face\"."));
  Entry tool_friction = optional(number("friction", std::nullopt, closed(0, 10),
                                        "Coulomb friction coefficient between this tool and the tissue (static = "
                                        "sliding), dimensionless."));
  tool_friction.default_doc = "`contact.friction`";
  Entry tools = object_array(
      "tools",
      {required(string("name", "Tool name, unique and not empty; `render.camera.follow_tool` may name it.")),
       std::move(tool_mesh),
       number("scale", 1.0, greater_than(0),
              "Factor from mesh and blade file coordinates to metres (0.001 for mm); a cylinder blade is in metres."),
       std::move(blade),
       boolean("collide", false,
               "The tool takes part in rigid contact (Bullet) through its mesh, or its blade when it has no mesh."),
       std::move(tool_friction),
       std::move(tool_keyframes),
       object_array("cuts",
                    {required(number("t", std::nullopt, at_least(0),
                                     "Time of the cut, s; strictly increasing along the list. A cut after `duration` never happens (the "
                                     "report warns)."))},
                    "Cut events: at each time the blade, posed by the tool, is removed from the object in rest "
                    "space (SPEC §4); none: the tool only moves (and collides).")},
      "Keyframed instruments that cut the object.");

  Entry cutting = object(
      "cutting",
      {choice("remove_fragments", {"all", "small", "none"}, "all",
              "Material that a cut separates from every handle: `all` removes every such piece, `small` only pieces "
              "below `fragment_volume`, `none` keeps them all (they move freely)."),
       number("fragment_volume", 1e-9, greater_than(0),
              "Volume below which a loose piece counts as small (with `remove_fragments` = `small`), m^3."),
       boolean("verify", true,
               "After each cut, check that the surface S is closed and free of self-intersections; a cut that "
               "breaks it is undone and reported as skipped."),
       number("min_feature", 3e-4, at_least(0),
              "Minimum feature size of cuts, m: a cut whose blade would remove only material within this depth "
              "below the blade's surface (a re-punch landing a few micrometres beside, or exactly on, the wall an "
              "earlier cut left) keeps that shell whole and is a no-op, instead of shaving slivers off the surface. "
              "The removed volume is then exact to within `min_feature` times the area of the blade's surface inside "
              "the material. Only convex blades at least 2 `min_feature` thick are tested. A rest-space blade within "
              "`min_feature` of a recent cut's blade (the same blade mesh; Hausdorff distance of the two solids inside "
              "S's bounds, exact for convex blades and bounded by the largest move of a corresponding point for "
              "others) or of another unrestricted component's blade of the same cut snaps onto it exactly, "
              "so that near-coincident walls coincide instead of making slivers; the removed volume is that of the "
              "snapped blade. Edges of a cut's result at new vertices shorter than 0.01 `min_feature` collapse where "
              "exact checks allow (the surface moves by less than that there). 0: off.")},
      "How cuts are carried out.");

  Entry expected = make_entry(
      "expected", Type::checks,
      "Regression checks for `octocut run --check`: each key is a JSON pointer into report.json (`/counts/elements`), "
      "each value a check: a bare string, boolean or integer (equal), a bare number (equal within rel 1e-9), "
      "`{\"value\": v, \"rel\": r, \"abs\": a}` (|x - v| <= max(a, r |v|); r, a >= 0, default 0) or "
      "`{\"min\": a, \"max\": b}` (a <= x <= b, either bound optional). A pointer the report lacks fails. "
      "`octocut run --regenerate` rewrites the values. A quantity that rounding decides (what a bite grazing an "
      "earlier hole removes, and in how many pieces) needs a range that holds the spread of runs perturbed within "
      "the solver's accuracy: `scripts/check_expected_perturbed` checks that.");
  expected.default_doc = "none";

  Entry position = optional(vec3("position", std::nullopt, "Eye position, m."));
  position.default_doc = "framed on the object";
  Entry target = optional(vec3("target", std::nullopt, "Point looked at, m."));
  target.default_doc = "the object's centre";
  Entry follow_tool = string("follow_tool", "Name of a tool (or render prop) whose tip, the origin of its frame, the camera "
                                            "follows, keeping its offset; a tool takes precedence over a prop of the "
                                            "same name; empty: a fixed camera.");
  follow_tool.default_value = "";
  Entry render = object(
      "render",
      {
          boolean("enabled", false, "Render frames offscreen (EGL)."),
          integer("width", 1280, closed(16, 8192), "Image width, pixels."),
          integer("height", 720, closed(16, 8192), "Image height, pixels."),
          integer("every", 1, closed(1, max_int), "Render one frame every N steps (frame k after step k * N)."),
          integer("msaa", 4, closed(0, 16), "Multisample anti-aliasing samples per pixel; 0 or 1: off."),
          number("crease_angle_deg", 40.0, closed(0, 180),
                 "Tissue shading: an edge whose faces' rest normals differ by more than this is a crease, and the "
                 "normals are not averaged across it, degrees. A cut face never shares a normal with an uncut one."),
          object("camera",
                 {std::move(position), std::move(target),
                  vec3("up", std::array{0.0, 0.0, 1.0}, "Approximate up direction; not parallel to the view."),
                  number("fov_deg", 45.0, open(0, 180), "Vertical field of view, degrees."),
                  boolean("arthroscope", false, "Arthroscope camera: a light at the lens."),
                  boolean("mask", false, "Black out everything outside the arthroscope's circular view."),
                  std::move(follow_tool)},
                 "The camera."),
          object_array(
              "props",
              {required(string("name", "Prop name, unique and not empty.")),
               required(string("mesh", "Closed triangle mesh file, path relative to the scene file.")),
               number("scale", 1.0, greater_than(0), "Factor from mesh coordinates to metres (0.001 for mm)."),
               choice("material", {"bone", "metal", "tissue"}, "bone", "Shading: bone, metal or tissue."),
               boolean("collide", false,
                       "The prop is a static collider (Bullet, at its pose at t = 0; concave meshes allowed): the "
                       "tissue rests against it. Its mesh must then be closed and free of self-intersections."),
               object_array("keyframes",
                            {required(number("t", std::nullopt, at_least(0),
                                             "Time, s; strictly increasing along the list.")),
                             vec3("position", std::array{0.0, 0.0, 0.0}, "Position of the prop frame's origin, m."),
                             vec3("rotation_deg", std::array{0.0, 0.0, 0.0},
                                  "XYZ Euler angles of the prop frame, degrees.")},
                            "Pose over time: position linear, rotation spherical-linear between keyframes, held "
                            "before the first and after the last; none: the mesh as it is in its file.")},
              "Meshes drawn around the object (the knee context, an instrument); they take no part in the simulation unless "
              "`collide` makes them static colliders."),
          object("overlays",
                 {boolean("octree", false, "Draw the octree leaves as a wireframe (deformed)."),
                  boolean("dofs", false, "Draw the DOFs as points."),
                  boolean("hanging", false, "Draw the hanging slots as points."),
                  boolean("contacts", false,
                          "Draw the collision samples in contact in the last step as points (orange) and, from each, "
                          "the force its contact exerted on the tissue as a line (red), over everything else. "
                          "Nothing without contact."),
                  number("contact_force_scale", 0.005, greater_than(0),
                         "Length of a contact force line per newton of force, m/N (0.005: 1 N draws 5 mm).")},
                 "Debug overlays."),
      },
      "Off-screen rendering (EGL) of the deformed object; frames are written when `output.frames` is set.");

  return object("",
                {
                    std::move(name),
                    std::move(duration),
                    integer("seed", 0, at_least(0), "Seed for every random choice."),
                    std::move(solver),
                    std::move(object_entry),
                    std::move(tools),
                    std::move(cutting),
                    make_rigid_bodies(),
                    make_contact(),
                    object_array("probes",
                                 {required(string("name", "Probe name, unique and not empty.")),
                                  required(vec3("point", std::nullopt, "Rest-space point, m."))},
                                 "Points whose displacement the report records."),
                    std::move(render),
                    object("output",
                           {boolean("frames", false, "Write the rendered frames as PNG files."),
                            boolean("surface_final", false,
                                    "Write, as binary PLY in metres, the rest surface before any cut "
                                    "(`surface_rest.ply`), the rest surface after the cuts (`surface_rest_final.ply`, "
                                    "on which cuts show as holes) and the final deformed surface (`surface_final.ply`)."),
                            boolean("contact_forces", false,
                                    "Write `contact_forces.csv`: one row per step and colliding tool or rigid body, "
                                    "`t,name,fx,fy,fz,max_penetration_m` (the force the tissue exerts on it, N)."),
                            boolean("step_times", false,
                                    "Write `steps.csv`: one row per step, `step,t,ms,cuts,pcg_iterations,refactorized,"
                                    "background,rotations_ms,forces_ms,assembly_ms,contact_ms,solve_ms,queries_ms,"
                                    "recoveries,energy_rejections`: the step's number, its end time (s), its wall time "
                                    "with its cuts (ms; the report's `timing_ms.step` summarises these), the cut events "
                                    "it ran, its PCG iterations, whether a factor was put in place (1) and whether a "
                                    "background refresh computed it (1), its stages (ms; of its last attempt): "
                                    "rotations, forces, assembly, contact terms, the linear solve and the contact "
                                    "queries, and the attempts it rolled back (the report's `stability` counts, per "
                                    "step). Timings differ from run to run; written also when the run fails."),
                            integer("surface_every", 0, closed(0, max_int),
                                    "Write the deformed surface every N steps as `surfaces/surface_<step>.ply` "
                                    "(6 digits, binary PLY, metres), and the rest surface once; 0: never."),
                            choice("ply_precision", {"double", "float"}, "double",
                                   "Coordinates of the PLY files written: `double` (a surface read back is the surface "
                                   "written, bit for bit) or `float` (half the size, for renderers)."),
                            boolean("stability_track", false,
                                    "Track the run's stability every step (an energy evaluation per step) and report "
                                    "`stability.track`: the largest rise of the total mechanical energy (kinetic + "
                                    "elastic + gravitational, plus the energy the contacts' penalty springs took up) "
                                    "over a step in which no handle moved and no cut ran, less the work the rigid "
                                    "shapes put in through contact in it (sum of F . v_rigid dt), J; that work over "
                                    "the run (`contact_work_j`), J; "
                                    "the largest DOF displacement seen, m; and the change of the deformed material "
                                    "volume, final and extreme, relative to rest (`octocut study stability`).")},
                           "Files the run writes besides the report."),
                    std::move(expected),
                },
                "The scene document.");
}

// ---- validation -----------------------------------------------------------------------------------------------------

/// Describes the lower bound of a range: "> 0", ">= 0".
std::string describe_min(const Range& range) {
  return (range.min_exclusive ? "> " : ">= ") + format_number(*range.min);
}

/// Describes the upper bound of a range: "< 0.5", "<= 1".
std::string describe_max(const Range& range) {
  return (range.max_exclusive ? "< " : "<= ") + format_number(*range.max);
}

/// Describes a whole range for the docs: "> 0", "(0, 1]", or "" when unbounded.
std::string describe(const Range& range) {
  if (range.min && range.max) {
    return (range.min_exclusive ? "(" : "[") + format_number(*range.min) + ", " + format_number(*range.max) +
           (range.max_exclusive ? ")" : "]");
  }
  if (range.min) return describe_min(range);
  if (range.max) return describe_max(range);
  return "";
}

/// Formats a JSON number as the user would recognise it.
std::string format_value(const json& value) {
  return value.is_number_float() ? format_number(value.get<double>()) : value.dump();
}

/// Checks a number against `range`, naming the bound it violates; `value` must be a finite number.
void check_range(const json& value, const Range& range, const std::string& pointer, const std::string& file) {
  const double x = value.get<double>();
  if (range.min && !(range.min_exclusive ? x > *range.min : x >= *range.min)) {
    fail(file, pointer, "must be " + describe_min(range) + ", got " + format_value(value));
  }
  if (range.max && !(range.max_exclusive ? x < *range.max : x <= *range.max)) {
    fail(file, pointer, "must be " + describe_max(range) + ", got " + format_value(value));
  }
}

/// Checks that `value` is a finite number within `range`.
void validate_number(const json& value, const Range& range, const std::string& pointer, const std::string& file) {
  if (!value.is_number()) fail(file, pointer, std::string("expected a number, got ") + value.type_name());
  if (!std::isfinite(value.get<double>())) {
    fail(file, pointer, "must be a finite number, got " + format_number(value.get<double>()));
  }
  check_range(value, range, pointer, file);
}

/// Checks that `value` is an integer within `range`, turning an integral float (say from `1e3`) into an integer.
void validate_integer(json& value, const Range& range, const std::string& pointer, const std::string& file) {
  // Floats are accepted when integral and exactly representable.
  if (value.is_number_float()) {
    const double x = value.get<double>();
    if (!std::isfinite(x)) fail(file, pointer, "must be a finite number, got " + format_number(x));
    if (x != std::floor(x) || std::fabs(x) > 9007199254740992.0) {
      fail(file, pointer, "expected an integer, got " + format_number(x));
    }
    value = static_cast<std::int64_t>(x);
  }
  if (!value.is_number_integer()) fail(file, pointer, std::string("expected an integer, got ") + value.type_name());
  check_range(value, range, pointer, file);
}

/// Checks an object's keys: unknown keys are errors, present keys are validated, absent ones get their default.
void validate_object(json& value, const std::vector<Entry>& children, const std::string& pointer,
                     const std::string& file) {
  if (!value.is_object()) fail(file, pointer, std::string("expected an object, got ") + value.type_name());

  // Unknown keys first, so that a misspelt key is reported as such rather than as a missing required key.
  for (const auto& item : value.items()) {
    bool known = false;
    for (const Entry& child : children) known = known || child.key == item.key();
    if (!known) fail(file, join_pointer(pointer, item.key()), "unknown key");
  }

  // Then each known key in schema order.
  for (const Entry& child : children) {
    const std::string child_pointer = join_pointer(pointer, child.key);
    if (const auto found = value.find(child.key); found != value.end()) {
      validate(*found, child, child_pointer, file);
    } else if (child.required) {
      fail(file, child_pointer, "required key missing");
    } else if (child.default_value) {
      // The default of an object is `{}`, which the recursion fills with its children's defaults.
      json& inserted = value[child.key] = *child.default_value;
      validate(inserted, child, child_pointer, file);
    }
  }
}

// ---- documentation --------------------------------------------------------------------------------------------------

/// Escapes a Markdown table cell.
std::string cell(const std::string& text) {
  std::string escaped;
  for (const char c : text) {
    if (c == '|') escaped += '\\';
    escaped += c;
  }
  return escaped;
}

std::string type_text(const Entry& entry) {
  switch (entry.type) {
    case Type::number:
      return "number";
    case Type::integer:
      return "integer";
    case Type::boolean:
      return "boolean";
    case Type::string:
      return "string";
    case Type::enumeration: {
      std::string text = "one of";
      for (std::size_t i = 0; i < entry.choices.size(); ++i) text += (i ? ", `" : " `") + entry.choices[i] + "`";
      return text;
    }
    case Type::number_array:
      return "number[" + std::to_string(entry.length) + "]";
    case Type::object:
      return "object";
    case Type::object_array:
      return "array of objects";
    case Type::box_or_path:
      return "string (mesh path) or object";
    case Type::checks:
      return "object (JSON pointer → check)";
    case Type::number_map:
      return "object of numbers";
  }
  return "";
}

/// Formats a default for the docs: numbers as in messages, arrays as "[0, 0, -9.81]", the rest as JSON.
std::string format_default(const json& value) {
  if (value.is_number()) return format_value(value);
  if (!value.is_array() || value.empty()) return value.dump();
  std::string text = "[";
  for (std::size_t i = 0; i < value.size(); ++i) {
    if (i > 0) text += ", ";
    text += format_default(value[i]);
  }
  text += ']';
  return text;
}

std::string default_text(const Entry& entry) {
  if (entry.required) return "required";
  if (!entry.default_doc.empty()) return entry.default_doc;
  if (entry.default_value) return "`" + format_default(*entry.default_value) + "`";
  return "—";
}

/// Appends one table row for `entry` at `pointer`, then rows for its children.
void append_rows(std::ostringstream& out, const Entry& entry, const std::string& pointer) {
  std::string range = describe(entry.range);
  if (entry.min_items > 0) {
    range = "at least " + std::to_string(entry.min_items) + (entry.min_items == 1 ? " item" : " items");
  }
  out << "| `" << cell(pointer) << "` | " << cell(type_text(entry)) << " | " << cell(range.empty() ? "—" : range)
      << " | " << cell(default_text(entry)) << " | " << cell(entry.doc) << " |\n";
  const std::string prefix = entry.type == Type::object_array ? join_pointer(pointer, "[]") : pointer;
  for (const Entry& child : entry.children) append_rows(out, child, join_pointer(prefix, child.key));
}

}  // namespace

const Entry& scene_schema() {
  static const Entry schema = make_scene_schema();
  return schema;
}

void validate(json& value, const Entry& entry, const std::string& pointer, const std::string& file) {
  switch (entry.type) {
    case Type::number:
      validate_number(value, entry.range, pointer, file);
      return;
    case Type::integer:
      validate_integer(value, entry.range, pointer, file);
      return;
    case Type::boolean:
      if (!value.is_boolean()) fail(file, pointer, std::string("expected a boolean, got ") + value.type_name());
      return;
    case Type::string:
      if (!value.is_string()) fail(file, pointer, std::string("expected a string, got ") + value.type_name());
      return;
    case Type::enumeration: {
      if (!value.is_string()) fail(file, pointer, std::string("expected a string, got ") + value.type_name());
      std::string allowed;
      for (const std::string& choice : entry.choices) {
        if (value.get<std::string>() == choice) return;
        allowed += (allowed.empty() ? "\"" : ", \"") + choice + "\"";
      }
      fail(file, pointer, "must be one of " + allowed + ", got " + value.dump());
    }
    case Type::number_array: {
      const std::string expected = "expected " + std::to_string(entry.length) + " numbers, got ";
      if (!value.is_array()) fail(file, pointer, expected + value.type_name());
      if (value.size() != entry.length) fail(file, pointer, expected + "an array of " + std::to_string(value.size()));
      for (std::size_t i = 0; i < value.size(); ++i) {
        validate_number(value[i], entry.range, join_pointer(pointer, i), file);
      }
      return;
    }
    case Type::object:
      validate_object(value, entry.children, pointer, file);
      return;
    case Type::object_array:
      if (!value.is_array()) fail(file, pointer, std::string("expected an array of objects, got ") + value.type_name());
      if (value.size() < entry.min_items) {
        fail(file, pointer,
             "must have at least " + std::to_string(entry.min_items) + (entry.min_items == 1 ? " item" : " items") +
                 ", got " + std::to_string(value.size()));
      }
      for (std::size_t i = 0; i < value.size(); ++i) {
        validate_object(value[i], entry.children, join_pointer(pointer, i), file);
      }
      return;
    case Type::box_or_path:
      if (value.is_string()) return;
      if (!value.is_object()) {
        fail(file, pointer, std::string("expected a mesh path (string) or an object, got ") + value.type_name());
      }
      validate_object(value, entry.children, pointer, file);
      return;
    case Type::number_map: {
      if (!value.is_object()) fail(file, pointer, std::string("expected an object, got ") + value.type_name());
      if (value.size() < entry.min_items)
        fail(file, pointer, "must have at least " + std::to_string(entry.min_items) + " key(s), got " +
                                std::to_string(value.size()));
      for (const auto& item : value.items()) {
        const std::string at = join_pointer(pointer, item.key());
        std::string allowed;
        bool known = false;
        for (const std::string& k : entry.choices) {
          known = known || k == item.key();
          allowed += (allowed.empty() ? "" : ", ") + k;
        }
        if (!known) fail(file, at, "unknown key (expected one of " + allowed + ")");
        validate_number(item.value(), entry.range, at, file);
      }
      return;
    }
    case Type::checks:
      if (!value.is_object()) {
        fail(file, pointer, std::string("expected an object (JSON pointer -> check), got ") + value.type_name());
      }
      for (const auto& item : value.items()) {
        if (const auto problem = expected_detail::member_problem(item.key(), item.value())) {
          fail(file, join_pointer(pointer, item.key()) + problem->where, problem->what);
        }
      }
      return;
  }
}

void fail(const std::string& file, const std::string& pointer, const std::string& what) {
  throw SceneError(pointer.empty() ? file + ": " + what : file + ": " + pointer + ": " + what);
}

std::string join_pointer(const std::string& parent, const std::string& key) {
  std::string pointer = parent;
  pointer += '/';
  for (const char c : key) {
    if (c == '~') {
      pointer += "~0";
    } else if (c == '/') {
      pointer += "~1";
    } else {
      pointer += c;
    }
  }
  return pointer;
}

std::string join_pointer(const std::string& parent, std::size_t index) {
  std::string pointer = parent;
  pointer += '/';
  pointer += std::to_string(index);
  return pointer;
}

std::string format_number(double value) {
  // Small integral values read best without a fraction or exponent.
  if (std::isfinite(value) && value == std::floor(value) && std::fabs(value) < 1e6) {
    return std::to_string(static_cast<long long>(value));
  }
  // Everything else in the shortest form that round-trips.
  std::array<char, 64> buffer{};
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return std::string(buffer.data(), result.ptr);
}

}  // namespace schema

std::string scene_format_markdown() {
  std::ostringstream out;
  out << "# Scene format\n\n"
      << "This reference is generated from the schema in `engine/src/scene/scene_schema.cpp` by `octocut scene-doc`, and a "
         "test checks that it matches; do not edit it by hand. A scene is a JSON object. Units are SI. Paths are "
         "relative to the scene file. Unknown keys are errors, and `[]` in a key stands for every item of an array. "
         "`--set /json/pointer=value` overrides any key from the command line.\n\n"
      << "| key | type | range | default | description |\n"
      << "|---|---|---|---|---|\n";
  for (const schema::Entry& child : schema::scene_schema().children) {
    schema::append_rows(out, child, schema::join_pointer("", child.key));
  }
  return out.str();
}

}  // namespace octocut::engine
