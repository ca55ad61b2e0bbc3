#include "octocut/engine/render/crease.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <string>

#include "octocut/sim/disjoint_sets.hpp"

namespace octocut::engine {

namespace {

// Vertex -> incident triangles, compressed (begin has |V| + 1 entries).
struct Incidence {
  std::vector<std::int32_t> begin, faces;
};

Incidence incidence(const sim::TriMesh& mesh) {
  Incidence inc;
  inc.begin.assign(mesh.vertices.size() + 1, 0);
  for (const auto& t : mesh.triangles)
    for (std::int32_t v : t) ++inc.begin[std::size_t(v) + 1];
  std::partial_sum(inc.begin.begin(), inc.begin.end(), inc.begin.begin());
  inc.faces.resize(std::size_t(inc.begin.back()));
  std::vector<std::int32_t> fill(inc.begin.begin(), inc.begin.end() - 1);
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
    for (std::int32_t v : mesh.triangles[f]) inc.faces[std::size_t(fill[std::size_t(v)]++)] = std::int32_t(f);
  return inc;
}

int local_index(const std::array<std::int32_t, 3>& t, std::int32_t v) { return t[0] == v ? 0 : t[1] == v ? 1 : t[2] == v ? 2 : -1; }

}  // namespace

CreaseTopology crease_topology(const sim::TriMesh& rest, const std::vector<char>& cut_faces, double crease_angle_deg) {
  const auto& tris = rest.triangles;
  if (!cut_faces.empty() && cut_faces.size() != tris.size())
    throw std::invalid_argument("crease_topology: " + std::to_string(cut_faces.size()) + " cut flags for " +
                                std::to_string(tris.size()) + " triangles");
  for (const auto& t : tris)
    for (std::int32_t v : t)
      if (v < 0 || std::size_t(v) >= rest.vertices.size())
        throw std::invalid_argument("crease_topology: a triangle names vertex " + std::to_string(v) + " of " +
                                    std::to_string(rest.vertices.size()));
  const double cos_limit = std::cos(std::clamp(crease_angle_deg, 0.0, 180.0) * std::numbers::pi / 180.0);
  // Unit rest normals; zero for degenerate triangles.
  std::vector<sim::Vec3> normal(tris.size());
  for (std::size_t f = 0; f < tris.size(); ++f) {
    const sim::Vec3& a = rest.vertices[std::size_t(tris[f][0])];
    const sim::Vec3 n = (rest.vertices[std::size_t(tris[f][1])] - a).cross(rest.vertices[std::size_t(tris[f][2])] - a);
    const double len = n.norm();
    normal[f] = len > 0.0 ? sim::Vec3(n / len) : sim::Vec3::Zero();
  }
  auto cut = [&](std::size_t f) { return !cut_faces.empty() && cut_faces[f] != 0; };
  auto smooth = [&](std::size_t f, std::size_t g) {
    if (cut(f) != cut(g)) return false;
    if (normal[f].isZero() || normal[g].isZero()) return true;
    return normal[f].dot(normal[g]) >= cos_limit - 1e-12;
  };

  // Corners (3 f + k) across each smooth manifold edge join; an edge with other than two faces is a crease.
  const Incidence inc = incidence(rest);
  sim::DisjointSets sets(3 * tris.size());
  for (std::size_t f = 0; f < tris.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const std::int32_t v = tris[f][std::size_t(k)], w = tris[f][std::size_t((k + 1) % 3)];
      int others = 0;
      std::int32_t other = -1;
      for (std::int32_t i = inc.begin[std::size_t(v)]; i < inc.begin[std::size_t(v) + 1]; ++i) {
        const std::int32_t g = inc.faces[std::size_t(i)];
        if (std::size_t(g) != f && local_index(tris[std::size_t(g)], w) >= 0) {
          ++others;
          other = g;
        }
      }
      if (others != 1 || !smooth(f, std::size_t(other))) continue;
      const auto& t = tris[std::size_t(other)];
      sets.unite(int(3 * f) + k, 3 * other + local_index(t, v));
      sets.unite(int(3 * f) + (k + 1) % 3, 3 * other + local_index(t, w));
    }

  // One render vertex per class, numbered in corner order.
  CreaseTopology out;
  out.triangles.resize(tris.size());
  std::vector<std::int32_t> id(3 * tris.size(), -1);
  for (std::size_t c = 0; c < 3 * tris.size(); ++c) {
    const std::size_t root = std::size_t(sets.find(int(c)));
    if (id[root] < 0) {
      id[root] = std::int32_t(out.vertex_of.size());
      out.vertex_of.push_back(tris[c / 3][c % 3]);
    }
    out.triangles[c / 3][c % 3] = id[root];
  }
  return out;
}

RenderMesh crease_mesh(const CreaseTopology& topology, const std::vector<sim::Vec3>& deformed,
                       const std::vector<char>& cut_faces) {
  RenderMesh mesh;
  mesh.material = MaterialKind::tissue;
  mesh.triangles = topology.triangles;
  mesh.positions.reserve(topology.vertex_of.size());
  for (std::int32_t v : topology.vertex_of) {
    if (std::size_t(v) >= deformed.size())
      throw std::invalid_argument("crease_mesh: " + std::to_string(deformed.size()) + " positions for vertex " +
                                  std::to_string(v));
    mesh.positions.push_back(deformed[std::size_t(v)].cast<float>());
  }
  // Area-weighted deformed normals, summed in double over each patch.
  std::vector<sim::Vec3> sum(topology.vertex_of.size(), sim::Vec3::Zero());
  for (const auto& t : topology.triangles) {
    const sim::Vec3& a = deformed[std::size_t(topology.vertex_of[std::size_t(t[0])])];
    const sim::Vec3 n = (deformed[std::size_t(topology.vertex_of[std::size_t(t[1])])] - a)
                            .cross(deformed[std::size_t(topology.vertex_of[std::size_t(t[2])])] - a);
    for (std::int32_t r : t) sum[std::size_t(r)] += n;
  }
  mesh.normals.reserve(sum.size());
  for (const sim::Vec3& n : sum) {
    const double len = n.norm();
    mesh.normals.push_back(len > 0.0 ? Eigen::Vector3f(sim::Vec3(n / len).cast<float>()) : Eigen::Vector3f::Zero());
  }
  mesh.cut.assign(cut_faces.begin(), cut_faces.end());
  return mesh;
}

}  // namespace octocut::engine
