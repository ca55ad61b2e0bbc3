// GL-free helpers of the render scene.
#include <Eigen/Geometry>

#include "octocut/engine/render/render_scene.hpp"

namespace octocut::engine {

std::vector<Eigen::Vector3f> mesh_normals(const std::vector<Eigen::Vector3f>& positions,
                                          const std::vector<std::array<std::int32_t, 3>>& triangles) {
  // Sum the unnormalised face normals (their length is twice the area), then normalise.
  std::vector<Eigen::Vector3f> normals(positions.size(), Eigen::Vector3f::Zero());
  for (const auto& t : triangles) {
    const Eigen::Vector3f n = (positions[t[1]] - positions[t[0]]).cross(positions[t[2]] - positions[t[0]]);
    for (const std::int32_t v : t) normals[v] += n;
  }
  for (Eigen::Vector3f& n : normals) {
    const float length = n.norm();
    n = length > 0.0f ? Eigen::Vector3f(n / length) : Eigen::Vector3f::Zero();
  }
  return normals;
}

}  // namespace octocut::engine
