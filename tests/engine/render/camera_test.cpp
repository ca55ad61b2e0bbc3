// Camera maths against hand-computed matrices and projections of known points.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "octocut/engine/render/camera.hpp"

namespace octocut::engine {
namespace {

constexpr double kTol = 1e-12;

TEST(Camera, LookAtFromPlusZIsATranslation) {
  // Eye at (0, 0, 5) looking at the origin with +y up: the eye frame is the world frame shifted by -5 in z.
  const Eigen::Matrix4d v = look_at({0, 0, 5}, {0, 0, 0}, {0, 1, 0});
  Eigen::Matrix4d expected = Eigen::Matrix4d::Identity();
  expected(2, 3) = -5.0;
  EXPECT_TRUE(v.isApprox(expected, kTol)) << v;
}

TEST(Camera, LookAtAlongPlusYWithZUp) {
  // Eye at (1, -4, 2) looking along +y with +z up: s = f × up = (1, 0, 0), u = (0, 0, 1), -f = (0, -1, 0).
  const Eigen::Matrix4d v = look_at({1, -4, 2}, {1, 6, 2}, {0, 0, 1});
  Eigen::Matrix4d expected;
  expected << 1, 0, 0, -1,  //
      0, 0, 1, -2,          //
      0, -1, 0, -4,         //
      0, 0, 0, 1;
  EXPECT_TRUE(v.isApprox(expected, kTol)) << v;
  // The target lies on the -z axis of eye space at the distance 10; the eye at the origin.
  EXPECT_TRUE((v * Eigen::Vector4d(1, 6, 2, 1)).isApprox(Eigen::Vector4d(0, 0, -10, 1), kTol));
  EXPECT_TRUE((v * Eigen::Vector4d(1, -4, 2, 1)).isApprox(Eigen::Vector4d(0, 0, 0, 1), kTol));
}

TEST(Camera, LookAtIsRigidForAnObliqueView) {
  const Eigen::Matrix4d v = look_at({0.3, -0.2, 0.7}, {-0.1, 0.4, 0.05}, {0.1, 0.2, 1.0});
  const Eigen::Matrix3d r = v.topLeftCorner<3, 3>();
  EXPECT_TRUE((r * r.transpose()).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  // Distances are kept: |target - eye| becomes the depth of the target.
  const Eigen::Vector4d t = v * Eigen::Vector4d(-0.1, 0.4, 0.05, 1.0);
  EXPECT_NEAR(t.z(), -Eigen::Vector3d(-0.4, 0.6, -0.65).norm(), 1e-12);
  EXPECT_NEAR(t.x(), 0.0, 1e-12);
  EXPECT_NEAR(t.y(), 0.0, 1e-12);
}

TEST(Camera, PerspectiveMatchesGluPerspective) {
  // fov 90°: cot(45°) = 1; aspect 2; near 1, far 3: (f + n) / (n - f) = -2, 2 f n / (n - f) = -3.
  const Eigen::Matrix4d p = perspective(90.0, 2.0, 1.0, 3.0);
  Eigen::Matrix4d expected;
  expected << 0.5, 0, 0, 0,  //
      0, 1, 0, 0,            //
      0, 0, -2, -3,          //
      0, 0, -1, 0;
  EXPECT_TRUE(p.isApprox(expected, kTol)) << p;
  // Near and far planes map to depth -1 and +1.
  const auto ndc_z = [&](double z) {
    const Eigen::Vector4d c = p * Eigen::Vector4d(0, 0, z, 1);
    return c.z() / c.w();
  };
  EXPECT_NEAR(ndc_z(-1.0), -1.0, kTol);
  EXPECT_NEAR(ndc_z(-3.0), 1.0, kTol);
}

TEST(Camera, ProjectsKnownPointsToPixels) {
  Camera camera;
  camera.position = {0, -2, 0};
  camera.target = {0, 0, 0};
  camera.up = {0, 0, 1};
  camera.fov_deg = 60.0;
  camera.near = 0.1;
  camera.far = 10.0;
  const int w = 200, h = 100;
  // The target lands in the image centre.
  const Eigen::Vector3d c = project_to_pixel(camera, w, h, {0, 0, 0});
  EXPECT_NEAR(c.x(), 100.0, 1e-9);
  EXPECT_NEAR(c.y(), 50.0, 1e-9);
  // A point at the top edge of the 60° field: height tan(30°) * distance above the target.
  const double top = std::tan(std::numbers::pi / 6.0) * 2.0;
  const Eigen::Vector3d t = project_to_pixel(camera, w, h, {0, 0, top});
  EXPECT_NEAR(t.x(), 100.0, 1e-9);
  EXPECT_NEAR(t.y(), 0.0, 1e-9);
  // Half-way up and right by half the horizontal half-extent (aspect 2: 2 * top).
  const Eigen::Vector3d q = project_to_pixel(camera, w, h, {0.5 * 2.0 * top, 0, 0.5 * top});
  EXPECT_NEAR(q.x(), 150.0, 1e-9);
  EXPECT_NEAR(q.y(), 25.0, 1e-9);
  // Depth: window z = (1 + ndc z) / 2 with ndc z from the explicit formula at eye depth 2.
  const double n = 0.1, f = 10.0, d = 2.0;
  const double ndc = ((f + n) / (n - f) * -d + 2.0 * f * n / (n - f)) / d;
  EXPECT_NEAR(c.z(), 0.5 * (ndc + 1.0), 1e-12);
  // Behind the eye: not finite.
  EXPECT_FALSE(std::isfinite(project_to_pixel(camera, w, h, {0, -3, 0}).x()));
}

TEST(Camera, FollowToolKeepsTheOffset) {
  Camera camera;
  camera.position = {0.01, -0.05, 0.03};
  camera.target = {0.0, 0.0, 0.0};
  const Eigen::Matrix3d before = view_matrix(camera).topLeftCorner<3, 3>();
  follow_tool(camera, {0.02, 0.01, -0.005});
  EXPECT_TRUE(camera.target.isApprox(Eigen::Vector3d(0.02, 0.01, -0.005), kTol));
  EXPECT_TRUE(camera.position.isApprox(Eigen::Vector3d(0.03, -0.04, 0.025), kTol));
  // The view direction is unchanged, and the tool tip projects to the centre.
  const Eigen::Matrix3d after = view_matrix(camera).topLeftCorner<3, 3>();
  EXPECT_TRUE(after.isApprox(before, kTol));
  const Eigen::Vector3d p = project_to_pixel(camera, 64, 48, {0.02, 0.01, -0.005});
  EXPECT_NEAR(p.x(), 32.0, 1e-9);
  EXPECT_NEAR(p.y(), 24.0, 1e-9);
}

TEST(Camera, DegenerateInputThrows) {
  EXPECT_THROW(look_at({1, 1, 1}, {1, 1, 1}, {0, 0, 1}), std::invalid_argument);
  EXPECT_THROW(look_at({0, 0, 0}, {0, 0, 1}, {0, 0, 2}), std::invalid_argument);
  EXPECT_THROW(perspective(0.0, 1.0, 0.1, 1.0), std::invalid_argument);
  EXPECT_THROW(perspective(180.0, 1.0, 0.1, 1.0), std::invalid_argument);
  EXPECT_THROW(perspective(60.0, 1.0, 1.0, 0.5), std::invalid_argument);
  EXPECT_THROW(perspective(60.0, 0.0, 0.1, 1.0), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::engine
