// Tests of the crease split that keeps tissue normals from smearing across cut rims and sharp edges. The truth is
// counted from the geometry: a closed box grid of n cells per side has 6 (n + 1)^2 corners once its 12 edges are
// creases (each face its own grid), 6 n^2 + 2 vertices when nothing is split, and its face normals are the axes.
#include "octocut/engine/render/crease.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <stdexcept>

#include "octocut/sim/primitives.hpp"

namespace octocut::engine {
namespace {

constexpr int kCells = 4;

sim::TriMesh unit_box() { return sim::closed_box_grid(sim::Box3{sim::Vec3::Zero(), sim::Vec3::Ones()}, kCells); }

// The axis normal of the box face a triangle lies on, from its centroid.
Eigen::Vector3f face_axis(const sim::TriMesh& box, const std::array<std::int32_t, 3>& t) {
  const sim::Vec3 c = (box.vertices[std::size_t(t[0])] + box.vertices[std::size_t(t[1])] + box.vertices[std::size_t(t[2])]) / 3.0;
  Eigen::Vector3f n = Eigen::Vector3f::Zero();
  for (int a = 0; a < 3; ++a) {
    if (c[a] < 1e-12) n[a] = -1.0f;
    if (c[a] > 1.0 - 1e-12) n[a] = 1.0f;
  }
  return n;
}

TEST(CreaseTest, BoxEdgesAreCreasesAndEveryNormalIsItsFacesAxis) {
  const sim::TriMesh box = unit_box();
  ASSERT_EQ(box.vertices.size(), std::size_t(6 * kCells * kCells + 2));
  const CreaseTopology topo = crease_topology(box, {}, 40.0);
  EXPECT_EQ(topo.vertex_of.size(), std::size_t(6 * (kCells + 1) * (kCells + 1)));
  const RenderMesh mesh = crease_mesh(topo, box.vertices, {});
  ASSERT_EQ(mesh.triangles.size(), box.triangles.size());
  for (std::size_t f = 0; f < box.triangles.size(); ++f) {
    const Eigen::Vector3f axis = face_axis(box, box.triangles[f]);
    for (int k = 0; k < 3; ++k) {
      const auto r = std::size_t(mesh.triangles[f][std::size_t(k)]);
      EXPECT_EQ(topo.vertex_of[r], box.triangles[f][std::size_t(k)]);  // the same corner of S
      EXPECT_LT((mesh.normals[r] - axis).norm(), 1e-6f) << "face " << f;
    }
  }
}

TEST(CreaseTest, AWideAngleKeepsTheSurfaceWhole) {
  const sim::TriMesh box = unit_box();
  const CreaseTopology topo = crease_topology(box, {}, 180.0);
  EXPECT_EQ(topo.vertex_of.size(), box.vertices.size());
  // A box corner then averages its three faces' area-weighted normals: the diagonal.
  const RenderMesh mesh = crease_mesh(topo, box.vertices, {});
  for (std::size_t r = 0; r < topo.vertex_of.size(); ++r) {
    if (box.vertices[std::size_t(topo.vertex_of[r])].isZero()) {
      EXPECT_LT((mesh.normals[r] + Eigen::Vector3f::Ones().normalized()).norm(), 1e-6f);
    }
  }
}

TEST(CreaseTest, ACutFaceNeverSharesANormalWithAnUncutOne) {
  const sim::TriMesh box = unit_box();
  // Mark the top face (z = 1) as cut: only its boundary ring of 4 n vertices splits, whatever the angle.
  std::vector<char> cut(box.triangles.size(), 0);
  for (std::size_t f = 0; f < box.triangles.size(); ++f) cut[f] = face_axis(box, box.triangles[f]).z() > 0.5f;
  const CreaseTopology topo = crease_topology(box, cut, 180.0);
  EXPECT_EQ(topo.vertex_of.size(), box.vertices.size() + 4 * kCells);
  const RenderMesh mesh = crease_mesh(topo, box.vertices, cut);
  EXPECT_EQ(mesh.cut.size(), cut.size());
  for (std::size_t f = 0; f < box.triangles.size(); ++f) {
    if (!cut[f]) continue;
    for (std::int32_t r : mesh.triangles[f]) {
      EXPECT_LT((mesh.normals[std::size_t(r)] - Eigen::Vector3f::UnitZ()).norm(), 1e-6f);
    }
  }
}

TEST(CreaseTest, NormalsFollowTheDeformedPositions) {
  const sim::TriMesh box = unit_box();
  const CreaseTopology topo = crease_topology(box, {}, 40.0);
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.7, sim::Vec3(1, 2, 3).normalized()).toRotationMatrix();
  std::vector<sim::Vec3> moved;
  for (const sim::Vec3& p : box.vertices) moved.push_back(rot * p + sim::Vec3(5, 0, 0));
  const RenderMesh mesh = crease_mesh(topo, moved, {});
  for (std::size_t f = 0; f < box.triangles.size(); ++f)
    for (std::int32_t r : mesh.triangles[f]) {
      const Eigen::Vector3f expected = (rot * face_axis(box, box.triangles[f]).cast<double>()).cast<float>();
      EXPECT_LT((mesh.normals[std::size_t(r)] - expected).norm(), 1e-5f);
      EXPECT_LT((mesh.positions[std::size_t(r)].cast<double>() - moved[std::size_t(topo.vertex_of[std::size_t(r)])]).norm(), 1e-5);
    }
}

TEST(CreaseTest, MismatchedInputIsAnErrorNotACrash) {
  const sim::TriMesh box = unit_box();
  EXPECT_THROW(crease_topology(box, std::vector<char>(3, 0), 40.0), std::invalid_argument);
  sim::TriMesh bad = box;
  bad.triangles[0][1] = 100000;
  EXPECT_THROW(crease_topology(bad, {}, 40.0), std::invalid_argument);
  const CreaseTopology topo = crease_topology(box, {}, 40.0);
  EXPECT_THROW(crease_mesh(topo, std::vector<sim::Vec3>(3), {}), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::engine
