#pragma once
// Tools at run time (SPEC §4, §5): the pose of a keyframed tool, its blade and its render mesh in tool coordinates.
// The world and the renderer turn these into cut events and metal meshes.
#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/pose.hpp"
#include "octocut/sim/surface.hpp"
#include "octocut/sim/types.hpp"

namespace octocut::engine {

/// A rigid transform from tool coordinates to world: x_world = rotation * x_tool + position.
using ToolPose = sim::Pose;

/// Scene keyframes (tools, render props) as the keyframes of sim::interpolate_pose, in order.
std::vector<sim::PoseKeyframe> pose_keyframes(const std::vector<PoseKey>& keyframes);

/// The pose of `tool` at time `t` (s), as for render props and handles (sim::interpolate_pose): position linear and
/// rotation slerp between keyframes, held before the first keyframe and after the last. A tool without keyframes
/// (the loader never makes one) has the identity pose.
ToolPose tool_pose(const ToolSettings& tool, double t);

/// The blade of tool `i` of `scene` in tool coordinates, m: the cylinder (sim::cylinder_mesh), or the mesh file
/// loaded with load_mesh (scaled by the tool's `scale`, validated, self-intersections rejected). Throws SceneError
/// "<scene file>: /tools/<i>/blade: <mesh file>: <reason>" for a blade that cannot be read or is not closed,
/// oriented, manifold, free of self-intersections and finite; std::out_of_range for a bad `i`. What loading
/// repaired (a blade oriented inward is flipped) is appended to `warnings` as "/tools/<i>/blade: <file>: <what>".
sim::TriMesh load_blade(const Scene& scene, std::size_t i, std::vector<std::string>* warnings = nullptr);

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
  std::vector<std::string> warnings;  ///< what loading repaired, e.g. a blade oriented inward that was flipped
};

/// Loads and checks the blade and the mesh of every tool of `scene` (`octocut validate`), in order. Throws
/// SceneError at the first bad one, as load_blade and load_tool_mesh do.
std::vector<ToolSummary> validate_tools(const Scene& scene);

}  // namespace octocut::engine
