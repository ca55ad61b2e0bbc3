// Tools at run time: keyframed poses, cylinder blades, and loading and checking the blade and render meshes.
#include "octocut/engine/run/tool.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/run/scene_object.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/primitives.hpp"

namespace octocut::engine {
namespace {

/// Loads a tool's mesh file, turning MeshError into SceneError at `pointer`; what loading repaired goes to `warnings`.
sim::TriMesh load_tool_file(const Scene& scene, const std::string& path, double scale, bool self_intersections,
                            const std::string& pointer, std::vector<std::string>* warnings = nullptr) {
  try {
    LoadedMesh loaded = load_mesh(path, MeshLoadOptions{scale, true, self_intersections});
    if (warnings)
      for (const std::string& w : loaded.warnings) warnings->push_back(pointer + ": " + w);  // w names the file
    return std::move(loaded.mesh);
  } catch (const MeshError& error) {
    throw SceneError(scene.file + ": " + pointer + ": " + error.what());
  }
}

}  // namespace

std::vector<sim::PoseKeyframe> pose_keyframes(const std::vector<PoseKey>& keyframes) {
  std::vector<sim::PoseKeyframe> out;
  out.reserve(keyframes.size());
  for (const PoseKey& k : keyframes) out.push_back({k.t, to_vec3(k.position), to_vec3(k.rotation_deg)});
  return out;
}

ToolPose tool_pose(const ToolSettings& tool, double t) { return sim::interpolate_pose(pose_keyframes(tool.keyframes), t); }

sim::TriMesh load_blade(const Scene& scene, std::size_t i, std::vector<std::string>* warnings) {
  const ToolSettings& tool = scene.tools.at(i);
  if (tool.blade_is_cylinder) return sim::cylinder_mesh(tool.cylinder.radius, tool.cylinder.height, tool.cylinder.segments);
  return load_tool_file(scene, tool.blade_path, tool.scale, true, "/tools/" + std::to_string(i) + "/blade", warnings);
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
    const sim::TriMesh blade = load_blade(scene, i, &summary.warnings);
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
