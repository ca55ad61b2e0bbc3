#include "octocut/sim/surface.hpp"

namespace octocut::sim {

double signed_volume(const TriMesh& mesh) {
  // Sum of signed tetrahedra (origin, a, b, c), each a·(b×c)/6; exact for any closed mesh.
  double six_v = 0.0;
  for (const auto& t : mesh.triangles) {
    const Vec3& a = mesh.vertices[static_cast<std::size_t>(t[0])];
    const Vec3& b = mesh.vertices[static_cast<std::size_t>(t[1])];
    const Vec3& c = mesh.vertices[static_cast<std::size_t>(t[2])];
    six_v += a.dot(b.cross(c));
  }
  return six_v / 6.0;
}

Box3 bounds(const TriMesh& mesh) {
  Box3 box;
  if (mesh.vertices.empty()) return box;
  box.min = box.max = mesh.vertices.front();
  for (const Vec3& p : mesh.vertices) {
    box.min = box.min.cwiseMin(p);
    box.max = box.max.cwiseMax(p);
  }
  return box;
}

std::vector<Vec3> vertex_normals(const std::vector<Vec3>& positions,
                                 const std::vector<std::array<int32_t, 3>>& triangles) {
  std::vector<Vec3> normals(positions.size(), Vec3::Zero());
  // Accumulate the unnormalised face normal (twice the area times the unit normal) at each corner.
  for (const auto& t : triangles) {
    const Vec3& a = positions[static_cast<std::size_t>(t[0])];
    const Vec3 n = (positions[static_cast<std::size_t>(t[1])] - a).cross(positions[static_cast<std::size_t>(t[2])] - a);
    for (int k = 0; k < 3; ++k) normals[static_cast<std::size_t>(t[k])] += n;
  }
  for (Vec3& n : normals) {
    const double len = n.norm();
    n = len > 0.0 ? Vec3(n / len) : Vec3::Zero();
  }
  return normals;
}

}  // namespace octocut::sim
