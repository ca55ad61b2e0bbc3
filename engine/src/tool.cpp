// Tools at run time: keyframed poses, cylinder blades, and loading and checking the blade and render meshes.
#include "octocut/engine/tool.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include "octocut/engine/mesh_io.hpp"
#include "octocut/engine/scene_loader.hpp"

namespace octocut::engine {
namespace {

Eigen::Quaterniond euler_quaternion(const std::array<double, 3>& degrees) {
  const double k = std::numbers::pi / 180.0;
  return Eigen::AngleAxisd(degrees[2] * k, sim::Vec3::UnitZ()) * Eigen::AngleAxisd(degrees[1] * k, sim::Vec3::UnitY()) *
         Eigen::AngleAxisd(degrees[0] * k, sim::Vec3::UnitX());
}

sim::Vec3 to_vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

/// Loads a tool's mesh file, turning MeshError into SceneError at `pointer`.
sim::TriMesh load_tool_file(const Scene& scene, const std::string& path, double scale, bool self_intersections,
                            const std::string& pointer) {
  try {
    return load_mesh(path, MeshLoadOptions{scale, true, self_intersections}).mesh;
  } catch (const MeshError& error) {
    throw SceneError(scene.file + ": " + pointer + ": " + error.what());
  }
}

}  // namespace

sim::Mat3 euler_xyz_deg(const std::array<double, 3>& degrees) { return euler_quaternion(degrees).toRotationMatrix(); }

ToolPose tool_pose(const ToolSettings& tool, double t) {
  ToolPose pose;
  const std::vector<ToolKeyframe>& keys = tool.keyframes;
  if (keys.empty()) return pose;

  // The keyframe interval holding t, and the fraction s along it; held at both ends.
  std::size_t i = 0;
  while (i + 1 < keys.size() && t > keys[i + 1].t) ++i;
  const ToolKeyframe& a = keys[i];
  const ToolKeyframe& b = i + 1 < keys.size() ? keys[i + 1] : keys[i];
  const double s = b.t > a.t ? std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0) : 0.0;

  // Position linear, rotation slerp.
  pose.position = (1.0 - s) * to_vec(a.position) + s * to_vec(b.position);
  pose.rotation = euler_quaternion(a.rotation_deg).slerp(s, euler_quaternion(b.rotation_deg)).toRotationMatrix();
  return pose;
}

sim::TriMesh cylinder_blade(double radius, double height, int segments) {
  if (!(std::isfinite(radius) && radius > 0.0)) throw std::invalid_argument("cylinder_blade: radius must be > 0");
  if (!(std::isfinite(height) && height > 0.0)) throw std::invalid_argument("cylinder_blade: height must be > 0");
  if (segments < 3) throw std::invalid_argument("cylinder_blade: segments must be >= 3");

  // Vertices: the bottom ring (0..n-1), the top ring (n..2n-1), the bottom centre (2n), the top centre (2n+1).
  sim::TriMesh mesh;
  const int n = segments;
  const double z0 = -0.5 * height, z1 = 0.5 * height;
  for (const double z : {z0, z1}) {
    for (int k = 0; k < n; ++k) {
      const double phi = 2.0 * std::numbers::pi * k / n;
      mesh.vertices.emplace_back(radius * std::cos(phi), radius * std::sin(phi), z);
    }
  }
  mesh.vertices.emplace_back(0.0, 0.0, z0);
  mesh.vertices.emplace_back(0.0, 0.0, z1);
  const int bottom = 2 * n, top = 2 * n + 1;

  // Triangles, counter-clockwise seen from outside: side quads as two triangles, and a fan on each cap.
  for (int k = 0; k < n; ++k) {
    const int k1 = (k + 1) % n;
    mesh.triangles.push_back({k, k1, n + k1});
    mesh.triangles.push_back({k, n + k1, n + k});
    mesh.triangles.push_back({bottom, k1, k});
    mesh.triangles.push_back({top, n + k, n + k1});
  }
  return mesh;
}

sim::TriMesh load_blade(const Scene& scene, std::size_t i) {
  const ToolSettings& tool = scene.tools.at(i);
  if (tool.blade_is_cylinder) return cylinder_blade(tool.cylinder.radius, tool.cylinder.height, tool.cylinder.segments);
  return load_tool_file(scene, tool.blade_path, tool.scale, true, "/tools/" + std::to_string(i) + "/blade");
}

sim::TriMesh load_tool_mesh(const Scene& scene, std::size_t i) {
  const ToolSettings& tool = scene.tools.at(i);
  if (tool.mesh_path.empty()) return {};
  return load_tool_file(scene, tool.mesh_path, tool.scale, false, "/tools/" + std::to_string(i) + "/mesh");
}

std::vector<ToolSummary> validate_tools(const Scene& scene) {
  std::vector<ToolSummary> out;
  for (std::size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSettings& tool = scene.tools[i];
    ToolSummary summary;
    summary.name = tool.name;

    // The blade: a cylinder is valid by construction, a file is validated by load_blade.
    const sim::TriMesh blade = load_blade(scene, i);
    if (tool.blade_is_cylinder) {
      char text[128];
      std::snprintf(text, sizeof text, "cylinder r=%g m h=%g m n=%d", tool.cylinder.radius, tool.cylinder.height,
                    tool.cylinder.segments);
      summary.blade = text;
    } else {
      summary.blade = tool.blade_path;
    }
    summary.blade_vertices = blade.num_vertices();
    summary.blade_triangles = blade.num_triangles();
    summary.blade_volume_m3 = sim::signed_volume(blade);

    // The render mesh, when there is one.
    summary.mesh_triangles = load_tool_mesh(scene, i).num_triangles();
    summary.keyframes = tool.keyframes.size();
    summary.cuts = tool.cuts.size();
    out.push_back(std::move(summary));
  }
  return out;
}

}  // namespace octocut::engine
