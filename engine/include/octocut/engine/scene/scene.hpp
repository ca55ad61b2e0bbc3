#pragma once
// Scene description: the plain, validated data a scene file turns into (SPEC §5). No JSON types appear here; the
// schema and the documentation generator live in engine/src/scene_schema.cpp, the loader in scene_loader.cpp.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace octocut::engine {

/// An axis-aligned box in metres (after `object.scale` for mesh-relative boxes: boxes are always in metres).
struct SceneBox {
  std::array<double, 3> min{};  ///< lower corner, m (3)
  std::array<double, 3> max{};  ///< upper corner, m (3)
};

/// One keyframe of a handle's rigid motion: translation linear, rotation slerp between keyframes (sim::interpolate_pose),
/// moving from the rest pose at t = 0 to the first keyframe, held after the last.
struct HandleKeyframe {
  double t = 0.0;                             ///< time, s
  std::array<double, 3> translation{};        ///< translation of the box, m (3)
  std::array<double, 3> rotation_deg{};       ///< XYZ Euler angles about the box centre, degrees (3)
};

/// A handle: a rest-space box whose DOFs follow a keyframed rigid motion; fixed when it has no keyframes.
struct Handle {
  SceneBox box;
  std::vector<HandleKeyframe> keyframes;  ///< sorted by t (the loader rejects unsorted lists)
};

/// A static refinement region: every leaf overlapping `box` is refined to at least `level`.
struct RefineRegion {
  SceneBox box;
  int level = 0;
};

/// Isotropic linear elastic material with Rayleigh damping (`object.material`).
struct Material {
  double young_modulus = 1e5;      ///< E, Pa
  double poisson_ratio = 0.3;      ///< nu, dimensionless, [0, 0.5)
  double density = 1000.0;         ///< rho, kg/m^3
  double rayleigh_mass = 0.0;      ///< alpha, 1/s
  double rayleigh_stiffness = 0.0; ///< beta, s
  std::string element = "bbar";  ///< hexahedron formulation: "bbar" (the default) or "trilinear"
};

/// How the simulation octree is built (`object.octree`).
struct OctreeSettings {
  bool has_root = false;            ///< true when `octree.root` is given
  std::array<double, 3> root_min{}; ///< root cube lower corner, m (3)
  double root_size = 0.0;           ///< root cube edge, m
  int base_level = 3;               ///< uniform preprocessing level
  int max_level = 8;                ///< bound on all refinement
  bool uniform = false;             ///< refine uniformly (no adaptivity), used by uniform_cut-style scenes
  std::vector<RefineRegion> refine; ///< static refinement regions
};

/// The deformable object (`object`).
struct ObjectSettings {
  bool surface_is_box = true;  ///< true: `surface` is {"box": …}; false: a mesh path
  SceneBox surface_box;        ///< when surface_is_box, m
  std::string surface_path;    ///< absolute path (resolved against the scene file) when !surface_is_box
  double scale = 1.0;          ///< multiplies mesh coordinates to get metres
  Material material;
  OctreeSettings octree;
  double material_graph_cell_size = 0.001;  ///< m (used from the geometry issue on)
  std::vector<Handle> handles;
};

/// Time integration and linear solver (`solver`).
struct SolverSettings {
  std::string mode = "dynamic";            ///< "dynamic" | "static"
  double dt = 1e-3;                        ///< s
  std::array<double, 3> gravity{0.0, 0.0, -9.81};  ///< m/s^2 (3)
  std::string linear_solver = "pcg";       ///< "cholmod" | "pcg"
  double tolerance = 1e-6;                 ///< relative residual
  int max_iterations = 200;                ///< per linear solve (pcg) / per static solve (Newton)
  int factor_lag = 0;                      ///< pcg: solves a background refresh of the factor may take; 0 inline
  int threads = 0;                         ///< 0 = auto (hardware concurrency)
  double max_speed = 100.0;                ///< m/s; a guard: faster DOFs roll the step back
  double energy_guard = 1e-3;              ///< relative; a step whose energy rises without work is rolled back
};

/// A rest-space point whose displacement the report records (`probes[]`).
struct Probe {
  std::string name;
  std::array<double, 3> point{};  ///< rest-space point, m (3)
};

/// The render camera (`render/camera`).
struct CameraSettings {
  bool has_position = false;               ///< false: framed on the object
  std::array<double, 3> position{};        ///< eye, m
  bool has_target = false;                 ///< false: the object's centre
  std::array<double, 3> target{};          ///< point looked at, m
  std::array<double, 3> up{0.0, 0.0, 1.0}; ///< approximate up direction
  double fov_deg = 45.0;                   ///< vertical field of view, degrees
  bool arthroscope = false;                ///< a light at the lens
  bool mask = false;                       ///< circular arthroscope mask
  std::string follow_tool;                 ///< name of the tool (or else render prop) the camera follows; empty: fixed
};

/// Debug overlays drawn over the tissue (`render/overlays`).
struct OverlaySettings {
  bool octree = false;   ///< wireframe of the octree leaves
  bool dofs = false;     ///< the DOFs as points
  bool hanging = false;  ///< the hanging slots as points
  bool contacts = false;  ///< the active contact samples as points, their forces on the tissue as lines
  double contact_force_scale = 0.005;  ///< length of a contact force line per newton, m/N
};

/// One keyframe of a rigid pose (render props and tools): where the local frame is at time t. Poses are interpolated
/// by sim::interpolate_pose: position linear, rotation slerp.
struct PoseKey {
  double t = 0.0;                        ///< time, s
  std::array<double, 3> position{};      ///< where the local origin is, world, m (3)
  std::array<double, 3> rotation_deg{};  ///< XYZ Euler angles of the local frame (fixed axes), degrees (3)
};
using PropKeyframe = PoseKey;  ///< a render prop's pose keyframe
using ToolKeyframe = PoseKey;  ///< a tool's pose keyframe

/// A render-only mesh (`render/props[]`): the knee context, or an instrument shown before tools cut. It takes no
/// part in the simulation.
struct RenderProp {
  std::string name;
  std::string mesh_path;                ///< absolute path (resolved against the scene file)
  double scale = 1.0;                   ///< multiplies mesh coordinates to get metres
  std::string material = "bone";        ///< "bone" | "metal" | "tissue"
  bool collide = false;                 ///< a static collider (Bullet) at its pose at t = 0
  std::vector<PropKeyframe> keyframes;  ///< sorted by t; none: the identity pose
};

/// Off-screen rendering (`render`).
struct RenderSettings {
  bool enabled = false;
  int width = 1280;   ///< pixels
  int height = 720;   ///< pixels
  int every = 1;      ///< render one frame every N steps
  int msaa = 4;       ///< samples per pixel; 0 or 1: off
  double crease_angle_deg = 40.0;  ///< tissue normals are not averaged across sharper edges, degrees
  CameraSettings camera;
  OverlaySettings overlays;
  std::vector<RenderProp> props;  ///< render-only meshes
};

/// Files written besides the report (`output`).
struct OutputSettings {
  bool frames = false;
  bool surface_final = false;
  int surface_every = 0;
  bool ply_float = false;  ///< PLY files in float32 instead of float64 (`ply_precision`)
  bool contact_forces = false;  ///< contact_forces.csv: t,name,fx,fy,fz,max_penetration_m per step and collider
  bool step_times = false;      ///< steps.csv: each step's wall time and where it went (kStepTimesHeader)
  bool stability_track = false;  ///< report stability.track (energy, displacement, volume every step)
};

/// A cylindrical blade in tool coordinates: axis z, centred on the tool origin (`tools[]/blade/cylinder`).
struct CylinderBlade {
  double radius = 0.0;  ///< m, > 0
  double height = 0.0;  ///< along z, from -height/2 to +height/2, m, > 0
  int segments = 32;    ///< sides of the polygonal cross-section, [3, 1024]
};

/// One cut event of a tool (`tools[]/cuts[]`): at time t the blade, posed by the tool, is subtracted.
struct ToolCut {
  double t = 0.0;  ///< time, s, in [0, duration]
};

/// A keyframed instrument (`tools[]`): an optional render/contact mesh and a blade, both in tool coordinates, posed
/// by `keyframes` (tool frame to world: x_world = R x_tool + position).
struct ToolSettings {
  std::string name;                     ///< unique, not empty
  std::string mesh_path;                ///< absolute path of the render/contact mesh; empty: none
  double scale = 1.0;                   ///< multiplies mesh and blade file coordinates to get metres
  bool blade_is_cylinder = false;       ///< true: `cylinder`; false: the mesh file `blade_path`
  CylinderBlade cylinder;               ///< when blade_is_cylinder, m (not scaled by `scale`)
  std::string blade_path;               ///< absolute path of the blade mesh when !blade_is_cylinder
  bool collide = false;                 ///< the mesh (or else the blade) takes part in rigid contact (Bullet)
  double friction = 0.3;                ///< Coulomb coefficient against the tissue (default: contact.friction)
  std::vector<ToolKeyframe> keyframes;  ///< sorted by t, strictly increasing, at least one
  std::vector<ToolCut> cuts;            ///< sorted by t, strictly increasing, each in [0, duration]
};

/// How cuts are carried out (`cutting`).
struct CuttingSettings {
  std::string remove_fragments = "all";  ///< "all" | "small" | "none": which pieces cut loose from every handle go
  double fragment_volume = 1e-9;         ///< with "small": pieces below this volume are removed, m^3
  bool verify = true;                    ///< check S after each cut: closed, free of self-intersections
  double min_feature = 3e-4;             ///< minimum feature size of cuts, m (cutting::kDefaultMinFeature)
};

/// The shape of a rigid body (`rigid_bodies[]/shape`), in the body frame.
struct RigidShape {
  std::string kind = "sphere";            ///< "sphere" | "box" | "cylinder" | "mesh"
  double radius = 0.0;                    ///< sphere, cylinder, m
  double height = 0.0;                    ///< cylinder, along z, m
  std::array<double, 3> size{};           ///< box edge lengths, m (3)
  std::string mesh_path;                  ///< mesh: absolute path
  double scale = 1.0;                     ///< mesh: file coordinates to metres
};

/// A rigid body (`rigid_bodies[]`): Bullet integrates the dynamic ones; all collide with the tissue.
struct RigidBodySettings {
  std::string name;
  RigidShape shape;
  std::string motion = "fixed";           ///< "dynamic" | "fixed" | "kinematic"
  double mass = 0.0;                      ///< kg, > 0 for a dynamic body
  std::array<double, 3> position{};       ///< body frame origin at t = 0, m (3)
  std::array<double, 3> rotation_deg{};   ///< XYZ Euler angles at t = 0, degrees (3)
  std::vector<PoseKey> keyframes;         ///< kinematic only, sorted by t
  double friction = 0.3;                  ///< Coulomb coefficient against the tissue
  std::string render = "metal";           ///< "metal" | "bone" | "glass" | "none"
};

/// Contact parameters (`contact`).
struct ContactSettings {
  bool has_stiffness = false;  ///< false: derived from E and the finest leaf (World)
  double stiffness = 0.0;      ///< penalty, Pa/m
  double friction = 0.3;       ///< default Coulomb coefficient
  double damping = 1e-3;       ///< s: damping coefficient = damping * stiffness
};

/// A fully validated scene with defaults filled in.
struct Scene {
  std::string file;        ///< the scene file path as given
  std::string name;
  double duration = 1.0;   ///< s
  std::uint64_t seed = 0;
  SolverSettings solver;
  ObjectSettings object;
  std::vector<ToolSettings> tools;  ///< keyframed instruments, in file order
  std::vector<RigidBodySettings> rigid_bodies;  ///< in file order
  ContactSettings contact;
  CuttingSettings cutting;
  std::vector<Probe> probes;
  RenderSettings render;
  OutputSettings output;
  /// The `expected` block as compact JSON text (an object: JSON pointer into report.json -> check), keys sorted;
  /// empty when the scene has none. See expected.hpp.
  std::string expected_json;
};

}  // namespace octocut::engine
