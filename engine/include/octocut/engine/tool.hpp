#pragma once
// Tools at run time (SPEC §4, §5): the pose of a keyframed tool, its blade and its render mesh in tool coordinates.
// The world and the renderer turn these into cut events and metal meshes.
#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "octocut/engine/scene.hpp"
#include "octocut/sim/surface.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::engine {

/// A rigid transform from tool coordinates to world: x_world = rotation * x_tool + position.
struct ToolPose {
  sim::Vec3 position = sim::Vec3::Zero();      ///< the tool origin in world coordinates, m (3)
  sim::Mat3 rotation = sim::Mat3::Identity();  ///< proper rotation, tool axes as columns (3 x 3)
};

/// The rotation of XYZ Euler angles in degrees, as for handles and render props: first about the fixed x axis, then
/// y, then z, R = Rz(z) Ry(y) Rx(x).
sim::Mat3 euler_xyz_deg(const std::array<double, 3>& degrees);

/// The pose of `tool` at time `t` (s), the convention of the render props' prop_pose: between keyframes k and k+1,
/// with s = (t - t_k) / (t_{k+1} - t_k), the position is (1 - s) p_k + s p_{k+1} and the rotation is the
/// quaternion slerp of the keyframes' rotations (the shorter arc); held before the first keyframe and after the
/// last. A tool without keyframes (the loader never makes one) has the identity pose.
ToolPose tool_pose(const ToolSettings& tool, double t);

/// A closed, outward-oriented cylinder of `segments` sides about the z axis, centred on the origin: z spans
/// [-height/2, height/2], the rim vertices lie on the circle of `radius` (m). 2 * segments + 2 vertices (a centre
/// on each cap) and 4 * segments triangles; its volume is segments/2 r^2 sin(2 pi / segments) h. Throws
/// std::invalid_argument for a radius or height that is not a positive finite number, or segments < 3.
sim::TriMesh cylinder_blade(double radius, double height, int segments);

/// The blade of tool `i` of `scene` in tool coordinates, m: the cylinder, or the mesh file loaded with load_mesh
/// (scaled by the tool's `scale`, validated, self-intersections rejected). Throws SceneError
/// "<scene file>: /tools/<i>/blade: <mesh file>: <reason>" for a blade that cannot be read or is not closed,
/// oriented, manifold, free of self-intersections and finite; std::out_of_range for a bad `i`.
sim::TriMesh load_blade(const Scene& scene, std::size_t i);

/// The render and contact mesh of tool `i` in tool coordinates, m (scaled, validated like render props: closed and
/// oriented, self-intersections allowed); an empty mesh when the tool has none. Throws SceneError
/// "<scene file>: /tools/<i>/mesh: <mesh file>: <reason>"; std::out_of_range for a bad `i`.
sim::TriMesh load_tool_mesh(const Scene& scene, std::size_t i);

/// What validate_tools found for one tool.
struct ToolSummary {
  std::string name;
  std::string blade;                 ///< "cylinder r=… h=… n=…" (m) or the blade's mesh path
  std::size_t blade_vertices = 0;
  std::size_t blade_triangles = 0;
  double blade_volume_m3 = 0.0;      ///< enclosed volume of the blade, m^3
  std::size_t mesh_triangles = 0;    ///< 0 when the tool has no mesh
  std::size_t keyframes = 0;
  std::size_t cuts = 0;
};

/// Loads and checks the blade and the mesh of every tool of `scene` (`octocut validate`), in order. Throws
/// SceneError at the first bad one, as load_blade and load_tool_mesh do.
std::vector<ToolSummary> validate_tools(const Scene& scene);

}  // namespace octocut::engine
